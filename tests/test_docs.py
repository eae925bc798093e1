"""The documentation is rebuilt, not edited: docs/results.md from docs/reports/, docs/figure.png by its script, no
tracked file citing the ignored runs/ folder outside experiments/, every path the README and docs/ cite exists in git,
and every docstring example runs."""

from __future__ import annotations

import copy
import doctest
import fnmatch
import importlib
import importlib.util
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
IGNORED_RUNS = "runs" + "/"  # written split, so that this file does not cite it


def _tracked() -> list[str]:
    if shutil.which("git") is None or not (ROOT / ".git").exists():
        pytest.skip("not a git checkout")
    out = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    return [line for line in out.splitlines() if (ROOT / line).exists()]


def _report_module():
    spec = importlib.util.spec_from_file_location("experiments_report", ROOT / "experiments" / "report.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_results_md_is_what_the_report_script_writes() -> None:
    report = _report_module()
    assert (ROOT / "docs" / "results.md").read_text(encoding="utf-8") == report.build(), (
        "docs/results.md is out of date: run python experiments/report.py"
    )


@pytest.mark.shared_data
def test_the_readme_figure_is_what_its_script_renders(shared_data: Path, tmp_path: Path) -> None:
    """docs/figure.png went stale when ALCN's output changed: a fresh render (a second) must match it but for another
    CPU's float rounding, which moved 29 of its 512,200 pixels, two of them by 2 gray levels (a changed method moves
    most of its column)."""
    import cv2

    out = tmp_path / "figure.png"
    script = ROOT / "experiments" / "figure.py"
    proc = subprocess.run([sys.executable, str(script), "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    fresh, published = (cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in (out, ROOT / "docs" / "figure.png"))
    difference = np.abs(fresh.astype(int) - published) if fresh.shape == published.shape else None
    assert difference is not None and np.count_nonzero(difference) < 500 and difference.max() <= 3, (
        "docs/figure.png is out of date: run python experiments/figure.py --publish"
    )


def test_report_script_rejects_a_report_it_cannot_render(tmp_path: Path) -> None:
    (tmp_path / "mystery.json").write_text("{}", encoding="utf-8")
    with pytest.raises(SystemExit, match="mystery"):
        _report_module().build(tmp_path)


def test_no_tracked_file_cites_the_ignored_runs_folder() -> None:
    offenders = []
    for name in _tracked():
        if name.startswith("experiments/") or name == ".gitignore" or name == "tests/test_docs.py":
            continue
        path = ROOT / name
        if path.suffix in {".npz", ".onnx", ".png", ".jpg", ".mp4"}:
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        if re.search(r"(?<![\w.])" + re.escape(IGNORED_RUNS), text):
            offenders.append(name)
    assert not offenders, f"cite the ignored runs folder (only experiments/ may): {offenders}"


def _cited_paths(text: str, top_level: set[str]) -> set[str]:
    candidates = re.findall(r"`([^`\s]+)`", text) + re.findall(r"\]\(([^)\s#]+)", text)
    paths = set()
    for c in candidates:
        c = c.rstrip(".,:;")
        if "://" in c or "=" in c:
            continue
        if c.split("/")[0] in top_level and ("/" in c or "." in c):
            paths.add(c)
    return paths


def test_every_path_the_docs_cite_exists_in_git() -> None:
    tracked = _tracked()
    top_level = {name.split("/")[0] for name in tracked} - {"docs"}
    docs = ["README.md"] + [
        n for n in tracked if n.startswith("docs/") and n.endswith(".md") and n != "docs/journal.md"
    ]
    missing = []
    for doc in docs:
        base = (ROOT / doc).parent
        text = (ROOT / doc).read_text(encoding="utf-8")
        cited = _cited_paths(text, top_level | {"docs"})
        # links relative to the document (results.md -> journal.md)
        cited |= {
            str((base / link).resolve().relative_to(ROOT))
            for link in re.findall(r"\]\(([\w./-]+\.md)\)", text)
            if (base / link).resolve().is_relative_to(ROOT)
        }
        for path in sorted(cited):
            path = path.rstrip("/")
            if not any(t == path or t.startswith(path + "/") or fnmatch.fnmatch(t, path) for t in tracked):
                missing.append(f"{doc}: {path}")
    assert not missing, f"cited but not in git: {missing}"


def test_readme_results_block_is_what_the_report_script_writes() -> None:
    report = _report_module()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert readme == report.readme_with_headlines(readme), (
        "the README's results block is out of date: run python experiments/report.py"
    )


def _kept(name: str) -> dict:
    return json.loads((ROOT / "docs" / "reports" / f"{name}.json").read_text(encoding="utf-8"))


def test_middlebury_table_says_its_units_and_counts_views_as_integers() -> None:
    text = _report_module().middlebury(_kept("pose_middlebury"))
    header = next(line for line in text.splitlines() if line.startswith("| set/"))
    assert "median rotation error (deg)" in header and "median camera-centre error (mm)" in header
    assert "_" not in header  # no raw JSON key
    assert "| templeSparseRing/none/original | 13/16 | 13/16 |" in text and "| 102 / 196 |" in text


def test_orb_orientation_table_names_its_columns_and_defines_exposure_scenes() -> None:
    report = _kept("orb_orientation")
    text = _report_module().orb_orientation(report)
    header = next(line for line in text.splitlines() if line.startswith("| method"))
    assert "_" not in header and "| matching ORB | matching ORB upright |" in header
    assert "Exposure scenes: exposure-only copies" in text
    # the cells are the report's numbers, under their readable headers
    row = next(line for line in text.splitlines() if line.startswith("| none, test scenes"))
    cells = dict(zip(header.strip("| ").split(" | "), row.strip("| ").split(" | ")))
    assert cells["correct ORB upright"] == f"{report['summary']['none, test scenes']['correct_orb_upright']:.1f}"


@pytest.mark.parametrize("name", ["directional_light", "relief_training"])
def test_rendered_light_tables_say_what_their_cells_measure(name: str) -> None:
    text = _report_module().RENDERERS[name](_kept(name))
    caption = text.split("Date: ")[1].split("|")[0]  # between the provenance and the table
    assert "probes identified" in caption and "N px" in caption and "resized to" in caption


def test_relight_tables_take_reports_with_and_without_backends() -> None:
    """``alcn bench relight`` records each ALCN method's backend since it exists; the kept reports predate it."""
    report = _report_module()
    old = _kept("relight_split")
    new = copy.deepcopy(old)
    for label, entry in new["methods"].items():
        if label.startswith("alcn"):
            entry["backend"] = "opencv"
    assert report.relight(new) == report.relight(old) and report.relight_headline(new) == report.relight_headline(old)


def _runs_an_example(text: str) -> bool:
    """A ``>>>`` line doctest runs: not one marked ``doctest: +SKIP`` (those check nothing)."""
    return any(line.lstrip().startswith(">>> ") and "doctest: +SKIP" not in line for line in text.splitlines())


def _modules_with_examples() -> list[str]:
    return sorted(
        ".".join(path.relative_to(ROOT).with_suffix("").parts)
        for package in ("alcn_cv", "pose", "calib")
        for path in (ROOT / package).rglob("*.py")
        if _runs_an_example(path.read_text(encoding="utf-8"))
    )


def test_some_modules_have_examples() -> None:
    assert len(_modules_with_examples()) > 10  # an empty list would make the test below check nothing


@pytest.mark.parametrize("module", _modules_with_examples())
def test_docstring_examples_run(module: str) -> None:
    """Every ``>>>`` example of a docstring runs and prints what it says."""
    try:
        imported = importlib.import_module(module)
    except ImportError as exc:  # an optional extra (torch, kornia) not installed here
        pytest.skip(f"{module}: {exc}")
    result = doctest.testmod(imported, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{module}: doctest found none of its examples"
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples failed"


def test_detection_table_has_a_column_per_real_images_and_policy_and_says_what_was_tuned() -> None:
    report = _kept("detect")
    text = _report_module().detect(report)
    header = next(line for line in text.splitlines() if line.startswith("| method"))
    assert header == "| method | 1 real, `raw` | 1 real, `local` | 10 real, `raw` | 10 real, `local` |"
    alcn = report["summary"]["alcn|10|local"]["mean"]
    assert "| alcn | " in text and f"{alcn['mean']:.3f} ± {alcn['std']:.3f}" in text  # AUC to three decimals
    chosen = report["tuned"]["1"]["dog"]
    params = ":".join(f"{k}={v}" for k, v in chosen["params"].items())
    default = chosen["trials"][0]["val_auc"]
    assert f"| 1 | dog | {params} | " in text and f"| {default:.3f} |" in text


def test_fewshot_table_gives_auc_per_policy_and_the_seeds_above_the_best_dog() -> None:
    report = _kept("fewshot")
    text = _report_module().fewshot(report)
    auc = report["summary"]["local"]["alcn"]["auc"]
    above = sum(s["above"] for s in report["alcn_vs_dog"]["raw"]["alcn"])
    row = next(line for line in text.splitlines() if line.startswith("| alcn |"))
    assert f"| {auc['mean']:.3f} ± {auc['std']:.3f} |" in row and f"| {above}/3 |" in row
    assert next(line for line in text.splitlines() if line.startswith("| dog |")).endswith("| - | - |")


def test_the_readmes_table_of_methods_is_the_registry() -> None:
    """The README lists every method ``create()`` builds, and no other: a method registered later shows there."""
    import alcn_cv

    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    start = lines.index("| method | what it does | reference |")
    rows = []
    for line in lines[start + 2 :]:
        if not line.startswith("|"):
            break
        rows.append(line.split("|")[1].strip())
    assert rows == list(dict.fromkeys(rows)) and set(rows) == set(alcn_cv.available())
