"""The experiment scripts of ``experiments/`` without their long runs: the rerun line docs/results.md gives runs the
command its report records, a shell script's report is kept and rendered, and a report records what was measured."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import sys
import types
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXPERIMENTS = ROOT / "experiments"
REPORTS = ROOT / "docs" / "reports"


@pytest.fixture
def experiments(monkeypatch: pytest.MonkeyPatch) -> types.ModuleType:
    """experiments/_run.py, imported as the scripts import it."""
    monkeypatch.syspath_prepend(str(EXPERIMENTS))
    return importlib.import_module("_run")


def _report_module() -> types.ModuleType:
    spec = importlib.util.spec_from_file_location("experiments_report", EXPERIMENTS / "report.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _kept(name: str) -> dict[str, Any]:
    return json.loads((REPORTS / f"{name}.json").read_text(encoding="utf-8"))


@pytest.mark.parametrize("rendered", [False, True], ids=["recorded", "rendered"])
@pytest.mark.parametrize(
    ("script", "name"),
    [("relight", "relight_split"), ("relight", "relight_leave_one_out"), ("learning", "relight_learning")],
)
def test_the_rerun_line_runs_the_published_command(
    experiments: types.ModuleType,
    monkeypatch: pytest.MonkeyPatch,
    tmp_path: Path,
    script: str,
    name: str,
    rendered: bool,
) -> None:
    """The quick protocol's options came from copies in each script, relight.py's --only is --part now and its
    seeds default to the published ones: the arguments a kept report records (as recorded, and as docs/results.md
    renders them) still run exactly the command it records."""
    module = importlib.import_module(script)
    commands: list[str] = []
    monkeypatch.setattr(module, "RUNS", tmp_path)
    monkeypatch.setattr(module, "alcn", lambda *argv: commands.append(" ".join(["alcn", *argv])))
    monkeypatch.setattr(module, "keep", lambda *args, **kwargs: None)
    if hasattr(module, "untrained_start"):
        monkeypatch.setattr(module, "untrained_start", lambda trained, path, description: Path(path))
    report = _kept(name)
    exp = report["experiment"]
    renamed = _report_module().RENAMED_OPTIONS
    argv = [renamed.get((exp["script"], a), a) for a in exp["argv"]] if rendered else exp["argv"]
    monkeypatch.setattr(sys, "argv", [f"{script}.py", *argv])
    module.main()
    assert report["command"] in [c.replace(str(tmp_path), "OUT") for c in commands]


def test_a_shell_scripts_report_is_kept_and_rendered(
    experiments: types.ModuleType, monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """experiments/gpu_check.sh kept no report: it keeps its bench's now, recorded as its own run (no arguments, the
    run folder written OUT), and the results page renders it with a rerun line that runs the shell script."""
    out = experiments.RUNS / "gpu_check" / "speed_cuda"  # the real run folder, which the kept report writes OUT
    monkeypatch.setattr(experiments, "ROOT", tmp_path)
    monkeypatch.setattr(experiments, "REPORTS", tmp_path / "reports")
    speed = _kept("speed")
    speed["command"] = f"alcn bench speed --device cuda --out {out}"
    report = tmp_path / "speed.json"
    report.write_text(json.dumps(speed), encoding="utf-8")
    kept = json.loads(experiments.keep(report, "speed_gpu", script="experiments/gpu_check.sh").read_text())
    assert kept["experiment"]["script"] == "experiments/gpu_check.sh" and kept["experiment"]["argv"] == []
    assert kept["command"] == "alcn bench speed --device cuda --out OUT/gpu_check/speed_cuda"
    text = _report_module().RENDERERS["speed_gpu"](kept)
    assert text.startswith("## Speed on a GPU\n") and "Rerun: `bash experiments/gpu_check.sh`." in text


def test_the_quick_protocol_is_the_benchs_preset(experiments: types.ModuleType) -> None:
    """The scripts spell out ``alcn bench relight --quick``'s settings from the library's preset."""
    from alcn_cv.bench.relight import PRESETS

    options = experiments.quick_protocol()
    assert dict(zip(options[::2], map(int, options[1::2]))) == {
        f"--{k.replace('_', '-')}": v for k, v in PRESETS["quick"].items()
    }


def test_a_report_records_what_was_measured_not_keep(experiments: types.ModuleType) -> None:
    """relief_training.py's report recorded ``keep`` among its settings."""
    args = argparse.Namespace(keep=True, out=Path("/x/y"), identities=40)
    assert experiments.recorded_settings(args) == {"out": "/x/y", "identities": 40}


def test_relight_titles_say_their_protocol_and_the_speed_headline_its_cores() -> None:
    """The leave-one-scene-out section did not say it ran the quick protocol; the speed headline said 2 shared cores
    whatever the report's machine."""
    report = _report_module()
    loo = _kept("relight_leave_one_out")
    assert report.relight(loo).startswith(
        "## Real light, leave-one-scene-out (each scene with parameters tuned on the others; quick protocol: "
        "12 frames per scene, 150 patches, 12 pairs)\n"
    )
    assert report.relight(_kept("relight_split")).startswith(
        "## Real light, test scenes (tuned on courbevoie, frankfurt, panorama)\n"
    )
    speed = _kept("speed")
    speed["machine_before"] = {**speed["machine_before"], "cpus_available": 16}
    assert " on 16 cores, " in report.speed_headline(speed)
