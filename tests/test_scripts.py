"""The scripts of ``experiments/`` and ``examples/``: ``--help`` explains each without running it; the OpenCV app's
example and the GPU check (rehearsed on the CPU) run end to end."""

import os
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


@pytest.mark.shared_data
def test_the_feature_matching_example_runs(shared_data, tmp_path):
    """The OpenCV app's example, end to end on the cookie box: every normalization finds matches that agree."""
    video = shared_data / "cookie_box" / "box.mp4"
    if not video.is_file():
        pytest.skip(f"{video} not found")
    script = ROOT / "examples" / "feature_matching.py"
    cmd = [sys.executable, str(script), "--video", str(video), "--out", str(tmp_path), "--feature", "SIFT"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    agreeing = [int(line.split(", ")[-1].split()[0]) for line in proc.stdout.splitlines() if "agree" in line]
    assert len(agreeing) == 3 and min(agreeing) > 50, proc.stdout
    assert (tmp_path / "matches.png").is_file()


@pytest.mark.parametrize(
    ("script", "args", "code", "line"),
    [
        ("pnp_methods.py", ["MISSING.npz", "box.mp4"], 2, "pnp_methods.py: error: MISSING.npz: part model not found"),
        ("pnp_methods.py", ["MISSING.npz", "box.mp4", "--max-frames", "0"], 2, "--max-frames 0: at least 1"),
        ("feature_matching.py", ["--second", "-1"], 2, "--second -1: a frame number, 0 or more"),
    ],
    ids=["missing-model", "no-frames", "negative-frame"],
)
def test_an_example_given_bad_input_ends_in_one_line(tmp_path, script, args, code, line):
    """A missing part model ended pnp_methods.py in a traceback, --max-frames 0 in a division by zero, and
    feature_matching.py's --second -1 in an error about max_frames."""
    args = [str(tmp_path / a) if a.startswith("MISSING") else a for a in args]
    proc = subprocess.run(
        [sys.executable, str(ROOT / "examples" / script), *args], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == code and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert proc.stderr.strip().splitlines()[-1].endswith(line.replace("MISSING", str(tmp_path / "MISSING")))


def test_the_gpu_check_rehearses_on_the_cpu(tmp_path):
    """experiments/gpu_check.sh with DEVICE=cpu: the script a short GPU slot runs, end to end, so that the slot is
    not spent on a fault of the script (its CUDA tests skip here; the bench measures the CPU's batched path), the
    report to publish written into its folder too (the folder that comes back from a GPU machine), as the shell
    script's run with that folder written OUT (tests/test_experiments.py publishes one)."""
    import json

    out = tmp_path / "came_back"
    env = {**os.environ, "DEVICE": "cpu", "GPU_CHECK_OUT": str(out), "PYTHON": sys.executable}
    proc = subprocess.run(
        ["bash", str(ROOT / "experiments" / "gpu_check.sh")], capture_output=True, text=True, timeout=300, env=env
    )
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "ALCN batched on cpu" in (out / "speed_cpu" / "speed.md").read_text()
    assert (out / "cuda_tests.xml").is_file() and (out / "environment.txt").is_file()
    text = (out / "speed_gpu.json").read_text()
    assert str(tmp_path) not in text and str(ROOT) not in text
    written = json.loads(text)
    assert written["experiment"]["script"] == "experiments/gpu_check.sh" and written["experiment"]["argv"] == []
    command = written["command"]
    assert command.startswith("alcn bench speed --out OUT/speed_cpu ") and " --device cpu " in command, command


def test_a_run_with_other_options_keeps_the_published_report(tmp_path, monkeypatch, capsys):
    """An experiment's smoke run (other options than the published report's) replaced that report; only the same
    options or --keep replace it now."""
    import json
    import types

    monkeypatch.syspath_prepend(str(ROOT / "experiments"))
    import _run

    script = tmp_path / "exp.py"
    script.write_text("")
    monkeypatch.setattr(_run, "ROOT", tmp_path)
    monkeypatch.setattr(_run, "REPORTS", tmp_path / "reports")
    monkeypatch.setitem(sys.modules, "__main__", types.SimpleNamespace(__file__=str(script)))
    report = tmp_path / "run.json"

    def run(*args: str, value: int, command: str | None = None) -> dict:
        monkeypatch.setattr(sys, "orig_argv", [sys.executable, str(script), *args])
        report.write_text(json.dumps({"value": value} | ({"command": command} if command else {})))
        _run.keep(report, name)
        return json.loads((tmp_path / "reports" / f"{name}.json").read_text())

    name = "exp"  # a report without a command of its own: the script's options say what ran
    assert run("--n", "3", value=1)["experiment"]["argv"] == ["--n", "3"]  # the first report is kept
    assert run("--n", "3", value=2)["value"] == 2  # the same options replace it
    assert run("--n", "1", value=3)["value"] == 2 and "not kept" in capsys.readouterr().out
    kept = run("--n", "1", "--keep", value=4)
    assert kept["value"] == 4 and kept["experiment"]["argv"] == ["--n", "1"]
    name = "bench"  # a report of an alcn command: the same command from other options (all parts, say) replaces it
    assert run("--part", "a", value=1, command="alcn bench x --seeds 0")["value"] == 1
    assert run(value=2, command="alcn bench x --seeds 0")["value"] == 2
    assert run("--part", "a", value=3, command="alcn bench x --seeds 1")["value"] == 2
    capsys.readouterr()
    # the same script line, other commands: its message named the line the user had just run as "other settings"
    assert run(value=4, command="alcn bench x --conf preset")["value"] == 2
    assert "other settings (the script ran other commands then: `python exp.py`)" in capsys.readouterr().out


def test_an_experiment_keeps_its_name_after_an_alcn_command(monkeypatch):
    """_run.alcn left sys.argv as ["alcn", ...]: a later error of the script was printed as "alcn: error: ..."."""
    monkeypatch.syspath_prepend(str(ROOT / "experiments"))
    import _run

    monkeypatch.setattr(sys, "argv", ["speed.py", "--conf", "quick"])
    with pytest.raises(SystemExit):
        _run.alcn("bench", "speed", "--conf", "nope", "--out", "unused")
    assert sys.argv == ["speed.py", "--conf", "quick"]
