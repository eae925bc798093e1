"""The scripts of ``experiments/`` and ``examples/``: ``--help`` explains each without running it."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: Where the experiments write (ignored by git; experiments/_run.py's RUNS).
RUNS = ROOT / "runs"
SCRIPTS = sorted(p for folder in ("experiments", "examples") for p in (ROOT / folder).glob("[!_]*.py"))


@pytest.mark.parametrize("script", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_help_says_what_the_script_does_and_writes(script):
    proc = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stdout.startswith("usage:"), proc.stderr[-2000:]
    if script.parent.name == "experiments":  # where an experiment writes: its runs folder (or the docs it rebuilds)
        assert f"{RUNS.name}/" in proc.stdout or "docs/" in proc.stdout, proc.stdout
