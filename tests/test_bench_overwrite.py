"""Every ``alcn bench`` benchmark refuses an ``--out`` that holds an earlier run's report, with one line naming the file
and ``--overwrite``, before any work; ``--overwrite`` replaces it (and is no part of the command the report records)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path

import pytest

from alcn_cv.cli import build_parser
from alcn_cv.cli import main as cli_main
from alcn_cv.io import held_folder
from scene_sets import make_sets


def _detect(tmp: Path) -> list[str]:
    pytest.importorskip("torch")
    from alcn_cv.data.detect import generate

    data = generate(tmp / "data", conf="small", n_test=1, progress=False)
    tiny = ["--methods", "none", "--real-images", "1", "--policy", "raw", "--positives", "4", "--epochs", "1"]
    return ["--data", str(data), "--conf", "small", *tiny, "--threads", "1", "--max-test-images", "1", "--seeds", "0"]


def _fewshot(tmp: Path) -> list[str]:
    pytest.importorskip("torch")
    tiny = ["--objects", "2", "--per-image", "6", "--n-test", "30", "--epochs", "1", "--threads", "1"]
    return ["--methods", "none", "--policy", "raw", "--seeds", "0", *tiny]


def _invariance(tmp: Path) -> list[str]:
    return ["--data", str(make_sets(tmp / "data") / "psm"), "--methods", "none"]


def _relight(tmp: Path) -> list[str]:
    data = make_sets(tmp / "data") / "webcam"
    tiny = ["--patch", "16", "--patches", "20", "--gallery", "1", "--max-pairs", "2", "--no-keypoints"]
    return ["--data", str(data), "--test-scenes", "street", "--no-tune", "--methods", "none", "--seeds", "0", *tiny]


def _speed(tmp: Path) -> list[str]:
    return ["--conf", "quick", "--sizes", "64x48", "--colours", "gray", "--methods", "none", "--video-frames", "0"]


#: The cheapest run of each benchmark: its options but --out, its data made under the folder given.
CHEAPEST: dict[str, Callable[[Path], list[str]]] = {
    "detect": _detect,
    "fewshot": _fewshot,
    "invariance": _invariance,
    "relight": _relight,
    "speed": _speed,
}


def test_every_benchmark_is_here():
    bench = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["bench"]
    benchmarks = next(a for a in bench._actions if isinstance(a, argparse._SubParsersAction)).choices
    assert set(benchmarks) == set(CHEAPEST)


@pytest.mark.parametrize("name", list(CHEAPEST))
def test_an_earlier_report_is_refused_and_replaced_with_overwrite(name, tmp_path, capsys, monkeypatch):
    out = tmp_path / "out"
    argv = ["bench", name, "--out", str(out), "--no-progress", *CHEAPEST[name](tmp_path)]
    out.mkdir()
    report, table = out / f"{name}.json", out / f"{name}.md"
    earlier = {report: '{"earlier": true}\n', table: "earlier\n"}
    for path, text in earlier.items():
        path.write_text(text)
    capsys.readouterr()

    def refused(named: str) -> None:
        assert cli_main(argv) == 2
        assert capsys.readouterr().err.strip() == f"alcn bench {name}: error: {named}"
        assert {p: p.read_text() for p in out.iterdir()} == earlier  # nothing replaced, nothing else written

    refused(f"{report} and 1 more exist (--overwrite replaces them)")
    report.unlink()  # either file of the report is an earlier run's
    del earlier[report]
    refused(f"{table} exists (--overwrite replaces it)")
    report.write_text('{"earlier": true}\n')
    assert cli_main([*argv, "--overwrite"]) == 0
    saved = json.loads(report.read_text())
    assert "earlier" not in saved and table.read_text() != "earlier\n"
    assert f"--out {out}" in saved["command"] and "--overwrite" not in saved["command"]


@pytest.mark.parametrize("name", list(CHEAPEST))
def test_a_folder_another_run_writes_into_is_refused(name, tmp_path, capsys):
    """A second run into a folder while the first runs passed the earlier-report check (no report yet) and the
    last to finish replaced the other's report; now it is refused at once."""
    out = tmp_path / "out"
    argv = ["bench", name, "--out", str(out), "--no-progress", *CHEAPEST[name](tmp_path)]
    capsys.readouterr()
    with held_folder(out):  # the first run, in this process (a second hold conflicts as from another process)
        assert cli_main(argv) == 2
        assert "is in use by another run" in capsys.readouterr().err
        assert [p.name for p in out.iterdir()] == [".alcn.lock"]
    assert cli_main(argv) == 0
    assert (out / f"{name}.json").exists() and not (out / ".alcn.lock").exists()
