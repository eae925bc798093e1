"""Build docs/results.md from the JSON reports in docs/reports/ (never edit results.md by hand).

Each report is one experiment's JSON (copied there by the experiment scripts of this folder, with an
``experiment`` record: script, arguments, date). Each table says the command that made it, the
machine and the date. Takes a second; tests/test_docs.py checks that docs/results.md equals its output.

    python experiments/report.py            # rewrite docs/results.md
    python experiments/report.py --check    # exit 1 if docs/results.md differs from what it would write
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
REPORTS = ROOT / "docs" / "reports"
RESULTS = ROOT / "docs" / "results.md"

RELIGHT_METRICS = {"identification": "identification", "matching_sift": "matching SIFT", "matching_orb": "matching ORB",
                   "pose_sift": "pose SIFT", "pose_orb": "pose ORB", "correct_sift": "correct SIFT",
                   "correct_orb": "correct ORB"}


def table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table; floats with one decimal, ``None`` as ``-``."""
    def cell(v: Any) -> str:
        if v is None:
            return "-"
        if isinstance(v, float):
            return f"{v:.1f}"
        return str(v).replace("|", "\\|")

    lines = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    return "\n".join(lines + ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]) + "\n"


def describe(machine: dict[str, Any] | None) -> str:
    """One line of a report's ``machine`` record: CPU, cores, load, versions, GPU."""
    if not machine:
        return "not recorded"
    parts = [f"{machine.get('cpu_model', machine.get('processor', '?'))}, "
             f"{machine.get('cpus_available', machine.get('cpu_count', '?'))} CPUs"]
    if "load_average_1_5_15" in machine:
        parts.append("load " + ", ".join(str(v) for v in machine["load_average_1_5_15"]))
    versions = [f"{k} {machine[k]}" for k in ("python", "numpy", "opencv", "torch") if machine.get(k)]
    parts.append(", ".join(versions))
    parts.append(f"GPU: {machine.get('cuda') or 'none'}")
    return "; ".join(parts)


def provenance(report: dict[str, Any]) -> str:
    """The lines under a table's title: how to rerun it, the command, the machine and the date."""
    exp = report.get("experiment", {})
    rerun = " ".join(["python", exp.get("script", "?"), *exp.get("argv", [])])
    commands = report.get("commands") or [report.get("command")]
    machine = report.get("machine") or report.get("machine_before")
    return (f"Rerun: `{rerun}`. Command: " + "; ".join(f"`{c}`" for c in commands if c) + ".  \n"
            f"Machine: {describe(machine)}.  \nDate: {exp.get('date', 'not recorded')}.\n")


def _mean_std(summary: dict[str, Any] | None, seeds: int) -> str | None:
    if not summary:
        return None
    return f"{summary['mean']:.1f}" + (f" ± {summary['std']:.1f}" if seeds > 1 else "")


def relight(report: dict[str, Any]) -> str:
    """Headline rows of ``alcn bench relight``: every metric's mean over the evaluated scenes."""
    seeds = len(report["settings"]["seeds"])
    loo = report["split"]["mode"] == "leave-one-out"
    metrics = [m for m in RELIGHT_METRICS if any(m in r.get("mean_test", {}) for r in report["methods"].values())]
    rows = [[label] + [_mean_std(r.get("mean_test", {}).get(m), seeds) for m in metrics]
            for label, r in report["methods"].items()]
    scenes = ", ".join(report["split"]["test"])
    title = ("Real light, leave-one-scene-out (each scene with parameters tuned on the others)" if loo else
             f"Real light, test scenes (tuned on {', '.join(report['split']['train'])})")
    note = (f"Mean over the scenes {scenes}; {seeds} seed{'s' if seeds > 1 else ''} "
            f"({', '.join(str(s) for s in report['settings']['seeds'])}). Identification and matching in %, "
            "pose in % of frame pairs, correct = correct matches per pair.\n")
    return f"## {title}\n\n{provenance(report)}\n{note}\n" + table(["method"] + [RELIGHT_METRICS[m] for m in metrics], rows)


def speed(report: dict[str, Any]) -> str:
    """``alcn bench speed``: its targets, then the time of every method on every frame."""
    out = f"## Speed\n\n{provenance(report)}\n"
    if report.get("targets"):
        rows = [[t.get("name"), t.get("measured"), t.get("goal"), {True: "met", False: "missed"}.get(t.get("met"), "-"),
                 t.get("note", "")] for t in report["targets"]]
        out += "Targets:\n\n" + table(["target", "measured", "goal", "", "note"], rows) + "\n"
    keys = [k for k in ("method", "size", "colour", "median_ms", "fps", "ratio_to_dog") if any(k in r for r in report["rows"])]
    rows = [[_size(r.get(k)) if k == "size" else r.get(k) for k in keys] for r in report["rows"]]
    return out + "Time per frame:\n\n" + table(keys, rows)


def _size(value: Any) -> Any:
    return "x".join(str(v) for v in value) if isinstance(value, list) else value


def calibration(report: dict[str, Any]) -> str:
    """Calibration on OpenCV's chessboard and the cookie box's build and tracking."""
    rows = [[f"calibration {k}", v] for k, v in report["calibration"].items()]
    rows += [[f"cookie box {k}", v] for k, v in report["tracking"].items() if not isinstance(v, (dict, list))]
    return f"## Calibration and the cookie box\n\n{provenance(report)}\n" + table(["quantity", "value"], rows)


def columns_table(report: dict[str, Any], title: str) -> str:
    """A report with ``columns`` and a ``table`` of rows (``alcn pose eval``, ``alcn pose planar``)."""
    spread = report.get("spread") or {}
    rows = []
    for label, values in report["table"].items():
        cells = []
        for c in report["columns"]:
            v = values.get(c)
            s = spread.get(label, {}).get(c)
            cells.append(None if v is None else f"{v:.1f}" + (f" ± {s:.1f}" if s is not None else ""))
        rows.append([label] + cells)
    return f"## {title}\n\n{provenance(report)}\n% of frames posed within 5 px.\n\n" + table(["method", *report["columns"]], rows)


def summary_table(report: dict[str, Any], title: str, key: str | None = "summary") -> str:
    """The numbers of a report's ``key`` (every entry but the records when None), one row per entry
    (``alcn bench detect``, ``alcn bench fewshot``, Middlebury)."""
    flat: dict[str, dict[str, Any]] = {}

    def walk(prefix: str, value: Any, row: dict[str, Any]) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix} {k}".strip(), v, row)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            row[prefix] = float(value)

    records = {"command", "commands", "machine", "experiment"}
    entries = report[key] if key else {k: v for k, v in report.items() if k not in records and isinstance(v, dict)}
    for method, value in entries.items():
        walk("", value, flat.setdefault(method, {}))
    keys = sorted({k for row in flat.values() for k in row})
    return (f"## {title}\n\n{provenance(report)}\n" + table(["method", *keys], [[m] + [r.get(k) for k in keys]
                                                                                for m, r in flat.items()]))


RENDERERS: dict[str, Callable[[dict[str, Any]], str]] = {
    "relight_split": relight,
    "relight_leave_one_out": relight,
    "speed": speed,
    "detect": lambda r: summary_table(r, "Rendered detection (mean AUC)"),
    "fewshot": lambda r: summary_table(r, "Few-shot validation (ROC AUC)"),
    "pose_table1_features": lambda r: columns_table(r, "Pose Table 1, SIFT parts (rendered sequences)"),
    "pose_table1_corners": lambda r: columns_table(r, "Pose Table 1, corner CNN (rendered sequences)"),
    "pose_table1_control": lambda r: columns_table(r, "Pose Table 1, corner CNN under the training light"),
    "pose_table1_heldout": lambda r: columns_table(r, "Pose Table 1, corner CNN, held-out scene"),
    "pose_middlebury": lambda r: summary_table(r, "Pose on Middlebury's real photographs (views posed)", key=None),
    "pose_planar_features": lambda r: columns_table(r, "Pose on real light, 500 SIFT keypoints"),
    "pose_planar_corners": lambda r: columns_table(r, "Pose on real light, corner CNN"),
    "calibration": calibration,
}


def build(reports: Path = REPORTS) -> str:
    """The text of docs/results.md from the JSON files in ``reports``, in the order of :data:`RENDERERS`."""
    found = {p.stem: p for p in sorted(reports.glob("*.json"))}
    unknown = sorted(set(found) - set(RENDERERS))
    if unknown:
        raise SystemExit(f"no renderer for docs/reports/{unknown[0]}.json (add one to experiments/report.py)")
    sections = [RENDERERS[name](json.loads(found[name].read_text(encoding="utf-8"))) for name in RENDERERS if name in found]
    missing = [name for name in RENDERERS if name not in found]
    head = ("# Results\n\nGenerated by `python experiments/report.py` from the JSON reports in `docs/reports/`; do not "
            "edit by hand. Each table gives the script that reruns it, the product command it ran, the machine and "
            "the date. History and older measurements: [journal.md](journal.md).\n")
    if missing:
        head += ("\nNot run for this page (long; their scripts are in `experiments/` and the journal keeps the numbers "
                 "as measured then): " + ", ".join(f"`{m}`" for m in missing) + ".\n")
    return "\n".join([head, *sections])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = parser.parse_args()
    text = build()
    if args.check:
        same = RESULTS.exists() and RESULTS.read_text(encoding="utf-8") == text
        print("docs/results.md is up to date" if same else "docs/results.md differs: run python experiments/report.py")
        sys.exit(0 if same else 1)
    RESULTS.write_text(text, encoding="utf-8")
    print(f"wrote {RESULTS.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
