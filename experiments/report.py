"""Build docs/results.md from the JSON reports in docs/reports/ (never edit results.md by hand).

Each report is one experiment's JSON (copied there by the experiment scripts of this folder, with an
``experiment`` record: script, arguments, date). Each table says the command that made it, the
machine and the date. Takes a second; tests/test_docs.py checks that docs/results.md equals its output.

    python experiments/report.py            # rewrite docs/results.md and the README's results block
    python experiments/report.py --check    # exit 1 if either differs from what it would write

The README's block between ``<!-- results:begin -->`` and ``<!-- results:end -->`` holds the headline
rows of the same reports (:func:`headlines`).
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # _run, also when this file is loaded by its path
from _run import REPORTS, ROOT, rerun  # noqa: E402

sys.path.insert(0, str(ROOT))  # the checkout's packages, also when not installed
from alcn_cv.bench.detect_report import chosen_trial  # noqa: E402
from alcn_cv.bench.relight_report import METRIC_LABELS  # noqa: E402
from alcn_cv.bench.relight_settings import CONFS  # noqa: E402
from alcn_cv.cli import run_script
from alcn_cv.report import describe_machine, machine_cores, markdown_table  # noqa: E402

RESULTS = ROOT / "docs" / "results.md"
README = ROOT / "README.md"
BEGIN, END = "<!-- results:begin -->", "<!-- results:end -->"
#: The first targets of the speed report the README shows (the ratios to a raw DoG, the frame rate, BGR).
SPEED_HEADLINE_TARGETS = 6
#: The rows of the real-light tables the README shows (each method's better row of default and tuned).
HEADLINE_METHODS = ("none", "clahe", "dog", "dlcn", "tantriggs", "alcn", "alcn:model=lite")

#: Said under every leave-one-scene-out table: the bench tunes the hand-made methods per fold but runs ALCN's
#: shipped files as they are.
LOO_NOTE = (
    "The ALCN rows are the shipped files as they are: the gain models are trained on relit photographs with no known "
    "restriction on use, so no scene is in their training data (the webcam training scenes chose their recipe).\n\n"
)


#: The results' Markdown tables: numbers with one decimal unless a table says otherwise.
table = functools.partial(markdown_table, digits=1)


def provenance(report: dict[str, Any]) -> str:
    """The lines under a table's title: how to rerun it, the command, the machine and the date."""
    exp = report.get("experiment", {})
    script = exp.get("script", "?")
    argv = exp.get("argv", [])
    commands = report.get("commands") or [report.get("command")]
    machine = report.get("machine") or report.get("machine_before")
    return (
        f"Rerun: `{rerun(script, argv)}`. Command: " + "; ".join(f"`{c}`" for c in commands if c) + ".  \n"
        f"Machine: {describe_machine(machine, short=True) if machine else 'not recorded'}.  \n"
        f"Date: {exp.get('date', 'not recorded')}.\n"
    )


def _mean_std(summary: dict[str, Any] | None, seeds: int) -> str | None:
    if not summary:
        return None
    return f"{summary['mean']:.1f}" + (f" ± {summary['std']:.1f}" if seeds > 1 else "")


def _protocol(settings: dict[str, Any]) -> str | None:
    """A relight report's sampling sizes when they are not the benchmark's default preset (``None`` when they are),
    named ``quick protocol`` when they are the quick one's."""
    default, quick = (dataclasses.asdict(CONFS[name]) for name in ("default", "quick"))
    sizes = {key: settings.get(key) for key in default}
    if sizes == default:
        return None
    text = f"{sizes['max_frames']} frames per scene, {sizes['patches']} patches, {sizes['max_pairs']} pairs"
    return f"quick protocol: {text}" if sizes == quick else text


def relight(report: dict[str, Any], title: str | None = None) -> str:
    """Headline rows of ``alcn bench relight``: every metric's mean over the evaluated scenes (``title``: the
    section's, default from the split and the sampling sizes when not the default)."""
    seeds = len(report["settings"]["seeds"])
    loo = report["split"]["mode"] == "leave-one-out"
    metrics = [m for m in METRIC_LABELS if any(m in r.get("mean_test", {}) for r in report["methods"].values())]
    rows = [
        [label] + [_mean_std(r.get("mean_test", {}).get(m), seeds) for m in metrics]
        for label, r in report["methods"].items()
    ]
    scenes = ", ".join(report["split"]["test"])
    if title is None:
        split = "leave-one-scene-out" if loo else "test scenes"
        tuned = (
            "each scene with parameters tuned on the others"
            if loo
            else "tuned on " + ", ".join(report["split"]["train"])
        )
        protocol = _protocol(report["settings"])
        title = f"Real light, {split} ({tuned}{'; ' + protocol if protocol else ''})"
    spread = "; ± their sample standard deviation" if seeds > 1 else ""
    note = (LOO_NOTE if loo else "") + (
        f"Mean over the scenes {scenes}; {seeds} seed{'s' if seeds > 1 else ''} "
        f"({', '.join(str(s) for s in report['settings']['seeds'])}){spread}. "
        "Identification and matching in %, "
        "pose in % of frame pairs, correct = correct matches per pair.\n"
    )
    return f"## {title}\n\n{provenance(report)}\n{note}\n" + table(
        ["method"] + [METRIC_LABELS[m] for m in metrics], rows
    )


def _targets(report: dict[str, Any]) -> list[dict[str, Any]]:
    targets = report.get("targets") or []
    return targets.get("summary", []) if isinstance(targets, dict) else targets


def _met(target: dict[str, Any]) -> str:
    met = target.get("met")
    return "-" if met is None else "met" if met else "missed"


def speed(report: dict[str, Any], title: str = "Speed") -> str:
    """``alcn bench speed``: its targets, then the time of every method on every frame."""
    out = f"## {title}\n\n{provenance(report)}\n"
    rows = [
        [t.get("target", t.get("name")), t.get("measured"), t.get("goal"), _met(t), t.get("note", "")]
        for t in _targets(report)
    ]
    if rows:
        out += "Targets:\n\n" + table(["target", "measured", "goal", "", "note"], rows, digits=2) + "\n"
    rows = [
        [
            r.get("method"),
            f"{r['width']}x{r['height']}" if "width" in r else _size(r.get("size")),
            r.get("colour"),
            r.get("median_ms"),
            r.get("fps"),
            r.get("ratio_to_dog"),
        ]
        for r in report.get("rows", [])
    ]
    return (
        out + "Time per frame:\n\n" + table(["method", "size", "colour", "median ms", "fps", "x dog"], rows, digits=2)
    )


def device_speed(report: dict[str, Any], title: str = "Speed on a GPU") -> str:
    """``alcn bench speed --device`` (``experiments/gpu_check.sh``): ALCN's batched torch path, frames per second per
    batch, beside kornia's DoG and CLAHE, and the float16 / CPU differences."""
    device = report.get("device", {})
    rows = report.get("rows", [])
    columns = [key for key in rows[0] if key != "batch"] if rows else []
    return (
        f"## {title}\n\n{provenance(report)}\nALCN batched on {device.get('device', '?')}, "
        f"{_size(device.get('size'))} gray, frames per second:\n\n"
        + table(["batch", *columns], [[r.get("batch"), *(r.get(c) for c in columns)] for r in rows])
        + f"\nLargest difference float16 / float32 on the device, on the same image: {device.get('half_max_abs')} "
        f"(the image cast to float16, in float32: {device.get('half_image_max_abs')}); device / CPU "
        f"(float32): {device.get('device_vs_cpu_max_abs')}.\n"
    )


def _size(value: Any) -> Any:
    return "x".join(str(v) for v in value) if isinstance(value, list) else value


def calibration(report: dict[str, Any]) -> str:
    """Calibration on OpenCV's chessboard and the cookie box's build and tracking."""

    def exact(v: Any) -> Any:
        return f"{v:.3f}" if isinstance(v, float) else v

    rows = [[f"calibration {k}", exact(v)] for k, v in report["calibration"].items()]
    rows += [[f"cookie box {k}", exact(v)] for k, v in report.get("cookie_box", {}).items()]
    rows += [[f"tracking {k}", exact(v)] for k, v in report["tracking"].items() if not isinstance(v, (dict, list))]
    return f"## Calibration and the cookie box\n\n{provenance(report)}\n" + table(["quantity", "value"], rows)


def columns_table(report: dict[str, Any], title: str) -> str:
    """A report with ``columns`` and a ``table`` of rows (``alcn pose eval``, ``alcn pose planar``)."""
    spread = report.get("spread") or {}
    # The products' tables carry a mean over the columns (sequences, scenes) that their ``columns`` do not name.
    columns = report["columns"] + (["mean"] if all("mean" in v for v in report["table"].values()) else [])
    rows = []
    for label, values in report["table"].items():
        cells = []
        for c in columns:
            v = values.get(c)
            s = spread.get(label, {}).get(c)
            cells.append(None if v is None else f"{v:.1f}" + (f" ± {s:.1f}" if s is not None else ""))
        rows.append([label] + cells)
    return f"## {title}\n\n{provenance(report)}\n% of frames posed within 5 px.\n\n" + table(["method", *columns], rows)


def summary_table(report: dict[str, Any], title: str, caption: str = "") -> str:
    """The numbers of a report's ``summary``, one row per entry (``alcn bench detect``, ``alcn bench fewshot``, the
    rendered-light experiments); ``caption``: what the cells measure, under the provenance."""
    flat: dict[str, dict[str, Any]] = {}

    def walk(prefix: str, value: Any, row: dict[str, Any]) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix} {k}".strip(), v, row)
        elif isinstance(value, (int, float)) and not isinstance(value, bool):
            row[prefix] = float(value)

    for method, value in report["summary"].items():
        walk("", value, flat.setdefault(method, {}))
    keys = sorted({k for row in flat.values() for k in row})
    under = f"{caption}\n" if caption else ""  # a caption is a paragraph of its own, before the table
    return f"## {title}\n\n{provenance(report)}\n{under}" + table(
        ["method", *keys], [[m] + [r.get(k) for k in keys] for m, r in flat.items()]
    )


#: The records of a report beside its results.
RECORDS = ("command", "commands", "machine", "experiment")


def _auc(summary: dict[str, Any] | None, seeds: int) -> str | None:
    """An AUC's ``{"mean", "std"}`` over ``seeds`` seeds as ``0.xxx ± 0.yyy`` (the spread only over several)."""
    if not summary:
        return None
    return f"{summary['mean']:.3f}" + (f" ± {summary['std']:.3f}" if seeds > 1 else "")


def _tuned_row(method: str, chosen: dict[str, Any]) -> list[Any]:
    """A tuned method's row: its name, the chosen parameters and their validation AUC, and the default's (the grid's
    first setting)."""
    params = ":".join(f"{k}={v}" for k, v in chosen["params"].items())
    return [method, params, chosen_trial(chosen)["val_auc"], chosen["trials"][0]["val_auc"]]


def detect(report: dict[str, Any]) -> str:
    """``alcn bench detect``: mean AUC over the objects per method (rows) and number of real images and input policy
    (columns), mean ± standard deviation over the seeds, three decimals; then the settings the tuning chose."""
    settings = report["settings"]
    seeds = len(settings["seeds"])
    cells = [(n, policy) for n in settings["real_images"] for policy in settings["policies"]]
    summary = report["summary"]
    rows = [
        [m] + [_auc(summary.get(f"{m}|{n}|{policy}", {}).get("mean"), seeds) for n, policy in cells]
        for m in settings["methods"]
    ]
    headers = ["method", *(f"{n} real, `{policy}`" for n, policy in cells)]
    tuned = [
        [n, *_tuned_row(m, chosen)]
        for n, methods in (report.get("tuned") or {}).items()
        for m, chosen in methods.items()
    ]
    text = (
        f"## Rendered detection (mean AUC)\n\n{provenance(report)}\nMean over the objects of the area under the "
        "precision-recall curve on the test images, a detector trained from N real images per object and rendered "
        "windows after each normalization (`dog` and `dlcn` at the settings tuned below); `raw` and `local`: the "
        f"input policies of `alcn bench detect`; ± over {seeds} seeds.\n\n" + markdown_table(headers, rows)
    )
    if tuned:
        text += "\nTuned by detection on the validation images (the first seed's runs):\n\n"
        text += markdown_table(["real images", "method", "chosen", "validation AUC", "default's"], tuned, digits=3)
    return text


def fewshot(report: dict[str, Any]) -> str:
    """``alcn bench fewshot``: ROC AUC per method (rows) and input policy (columns), mean ± standard deviation over the
    seeds, three decimals, and for each ALCN the seeds on which it is above the best DoG."""
    settings = report["settings"]
    seeds = len(settings["seeds"])
    policies = settings["policies"]
    summary, against = report["summary"], report.get("alcn_vs_dog", {})

    def above(method: str, policy: str) -> str | None:
        seeds_above = against.get(policy, {}).get(method)
        return None if seeds_above is None else f"{sum(s['above'] for s in seeds_above)}/{len(seeds_above)}"

    rows = [
        [m] + [_auc(summary[p].get(m, {}).get("auc"), seeds) for p in policies] + [above(m, p) for p in policies]
        for m in settings["methods"]
    ]
    headers = ["method", *(f"`{p}`" for p in policies), *(f"above the best DoG, `{p}`" for p in policies)]
    tuned = report.get("tuned") or {}
    text = (
        f"## Few-shot validation (ROC AUC)\n\n{provenance(report)}\nObject against background under held-out "
        f"lights ({', '.join(settings['test_lighting'])}), a detector trained from {settings['real_images']} image "
        f"of each of {settings['n_objects']} new rendered objects under one light"
        + (f" ({', '.join(f'`{m}`' for m in tuned)} at the settings tuned below)" if tuned else "")
        + f"; ± over {seeds} seeds; above the best DoG: the seeds on which an ALCN's AUC exceeds that of the better "
        "DoG row.\n\n" + markdown_table(headers, rows)
    )
    if tuned:
        text += "\nTuned on a validation draw of new objects and windows (AUC averaged over the policies):\n\n"
        text += markdown_table(
            ["method", "chosen", "validation AUC", "default's"],
            [_tuned_row(m, chosen) for m, chosen in tuned.items()],
            digits=3,
        )
    return text


def middlebury(report: dict[str, Any]) -> str:
    """``alcn pose eval --middlebury``: per set, normalization and light, the views posed correctly and at all, the
    median errors."""
    rows = [
        [
            key,
            f"{v['correct']}/{v['views']}",
            f"{v['posed']}/{v['views']}",
            v["median_rot_deg"],
            v["median_trans_mm"],
            v["median_center_mm"],
            " / ".join(map(str, v["model_points"])),
        ]
        for key, v in report.items()
        if key not in RECORDS
    ]
    headers = [
        "set/normalization/light",
        "views posed correctly",
        "views posed",
        "median rotation error (deg)",
        "median translation error (mm)",
        "median camera-centre error (mm)",
        "model points",
    ]
    caption = (
        "Each view of a set posed from a model built on the views on either side (SIFT; two folds: the even views' "
        "model poses the odd ones, the odd views' the even ones); correctly: within 5 deg and 5 cm; light: the "
        "photographs as taken (`original`) or darkened by a ramp and a gamma (`relit`); errors: medians over the "
        "posed views (-: none posed); model points: the two models' 3D points.\n"
    )
    return f"## Pose on Middlebury's real photographs (views posed)\n\n{provenance(report)}\n{caption}\n" + table(
        headers, rows
    )


def orb_orientation(report: dict[str, Any]) -> str:
    """``experiments/orb_orientation.py``: the bench's metrics per method and set of scenes, beside ORB's with the
    keypoints' orientation fixed (``_upright``)."""
    found = {k for row in report["summary"].values() for k in row}
    keys = [k for m in METRIC_LABELS for k in (m, f"{m}_upright") if k in found]
    keys += sorted(found - set(keys))  # a metric this renderer does not know yet, as its key
    headers = [
        METRIC_LABELS[k.removesuffix("_upright")] + (" upright" if k.endswith("_upright") else "")
        if k.removesuffix("_upright") in METRIC_LABELS
        else k
        for k in keys
    ]
    s = report["settings"]
    caption = (
        f"Mean over each set's scenes and the seeds {', '.join(map(str, report['seeds']))}, with `alcn bench "
        f"relight`'s quick protocol ({s['max_frames']} frames per scene, {s['patches']} patches, {s['max_pairs']} "
        "pairs). Identification and matching in %, pose in % of frame pairs, correct = correct matches per pair; "
        "upright: ORB with every keypoint's orientation set to 0 (the cameras do not rotate). Exposure scenes: "
        "exposure-only copies, 8 of the default's training photographs each relit 6 times by a global gain "
        "(0.03-1, with the sensor's noise); the default saw them under another light, so they are not held out.\n"
    )
    title = "Why ALCN lowers ORB matching: ORB's orientation, and a wide band that restores it (quick protocol)"
    return f"## {title}\n\n{provenance(report)}\n{caption}\n" + table(
        ["method", *headers], [[m] + [r.get(k) for k in keys] for m, r in report["summary"].items()]
    )


def directional_light(report: dict[str, Any]) -> str:
    """``experiments/directional_light.py``: the probes identified per elevation, each hand-made method at its
    default and tuned (``method (tuned)``), then each tuned method's chosen setting and validation scores."""
    s = report["settings"]
    sizes = " and ".join(str(size) for size in s["sizes"])
    grid = len(next(iter(report["tuning"].values()))["scores"])
    caption = (
        f"Cells: % of probes identified ({s['identities']} identities, {s['azimuths']} light azimuths per elevation) "
        "as their most correlated frontal-lit gallery image; elevation: the light's angle above the ground (degrees); "
        "N px: the side the normalized images are resized to before identification. `method (tuned)`: the method at "
        f"the setting of `alcn bench relight`'s grid for it ({grid} settings each, the default first) with the best "
        f"mean identification over the elevations at {sizes} px on a validation rendering "
        f"({s['validation_identities']} identities, seed {s['validation_seed']}; the test's: seed {s['seed']}); the "
        "first best wins. ALCN is not tuned: `alcn` is the shipped default, `alcn, band W` diagnostics (its wide band "
        "at the weight W; 0: none).\n"
    )
    title = "Whole-image identification under hard directional light (rendered, a stand-in for faces)"
    rows = []
    for method, t in report["tuning"].items():
        scores = list(t["scores"].values())  # the grid's first setting is the default
        rows.append(
            [
                f"{method} (tuned)",
                f"`{t['chosen']}`",
                t["scores"][t["chosen"]],
                scores[0],
                f"{min(scores):.1f}-{max(scores):.1f}",
            ]
        )
    return (
        summary_table(report, title, caption)
        + f"\nThe tuned settings (score: the mean % over the elevations at {sizes} px of the validation rendering):\n\n"
        + table(["method", "chosen", "validation %", "default's validation %", "range over grid"], rows)
    )


def relight_headline(report: dict[str, Any]) -> str:
    """The README's rows of a real-light report: :data:`HEADLINE_METHODS`, each at the better of its
    default and tuned rows by identification."""
    seeds = len(report["settings"]["seeds"])
    metrics = ["identification", "matching_sift", "matching_orb", "pose_sift", "pose_orb"]
    rows = []
    for name in HEADLINE_METHODS:
        candidates = [
            (label, r)
            for label, r in report["methods"].items()
            if label in (name, f"{name} (tuned)") and "identification" in r.get("mean_test", {})
        ]
        if candidates:
            label, r = max(candidates, key=lambda c: c[1]["mean_test"]["identification"]["mean"])
            rows.append([label] + [_mean_std(r["mean_test"].get(m), seeds) for m in metrics])
    loo = report["split"]["mode"] == "leave-one-out"
    title = "leave-one-scene-out" if loo else f"test scenes {', '.join(report['split']['test'])}"
    protocol = _protocol(report["settings"])
    if protocol:
        title += f"; {protocol}"
    return (
        f"**Real light** ({title}; `alcn bench relight`, {seeds} seed{'s' if seeds > 1 else ''}, "
        f"{report['experiment']['date'][:10]}):\n\n"
        + (LOO_NOTE if loo else "")
        + table(["method"] + [METRIC_LABELS[m] for m in metrics], rows)
    )


def speed_headline(report: dict[str, Any]) -> str:
    """The README's rows of the speed report: its targets."""
    rows = [[t.get("target", t.get("name")), t.get("measured"), t.get("goal"), _met(t)] for t in _targets(report)]
    rows = rows[:SPEED_HEADLINE_TARGETS]
    argv = " ".join(report["experiment"]["argv"])
    machine = report.get("machine_before") or {}
    return (
        f"**Speed** (`python experiments/speed.py {argv}`, {report['experiment']['date'][:10]}; load average "
        f"{', '.join(str(v) for v in machine.get('load_average_1_5_15', []))} "
        f"on {machine_cores(machine)} cores, {machine.get('cpu_model', 'CPU not recorded')}):\n\n"
        + table(["target", "measured", "goal", ""], rows, digits=2)
    )


def calibration_headline(report: dict[str, Any]) -> str:
    """The README's line of the calibration report."""
    c, box, track = report["calibration"], report.get("cookie_box", {}), report["tracking"]
    return (
        f"**Calibration and the cookie box** ({report['experiment']['date'][:10]}): chessboard RMS "
        f"{c['rms_px']:.3f} px, fx {c['fx']:.2f} (OpenCV's reference: 0.409 px, 536.07); the cookie box's "
        f"model within {box.get('box_size_error_percent', float('nan')):.1f}% of its true size, "
        f"{track['tracked']} of {track['frames']} frames tracked.\n"
    )


HEADLINES: dict[str, Callable[[dict[str, Any]], str]] = {
    "relight_split": relight_headline,
    "relight_leave_one_out": relight_headline,
    "speed": speed_headline,
    "calibration": calibration_headline,
}


def _reports(reports: Path) -> dict[str, dict[str, Any]]:
    return {p.stem: json.loads(p.read_text(encoding="utf-8")) for p in sorted(reports.glob("*.json"))}


def headlines(reports: Path = REPORTS) -> str:
    """The README's results block: the headline rows of the reports that have them."""
    found = _reports(reports)
    return "\n".join(HEADLINES[name](found[name]) for name in HEADLINES if name in found)


def readme_with_headlines(readme: str, reports: Path = REPORTS) -> str:
    """``readme`` with the text between :data:`BEGIN` and :data:`END` replaced by :func:`headlines`."""
    start, end = readme.index(BEGIN) + len(BEGIN), readme.index(END)
    return readme[:start] + "\n" + headlines(reports) + readme[end:]


#: The reports of a GPU machine (``experiments/gpu_check.sh``), which the page does not count among the long runs.
GPU_REPORTS = ("speed_gpu",)

RENDERERS: dict[str, Callable[[dict[str, Any]], str]] = {
    "relight_split": relight,
    "relight_leave_one_out": relight,
    "relight_learning": lambda r: relight(
        r, "Does learning matter? The default, its untrained start, the same recipe on webcam frames (quick protocol)"
    ),
    "relight_unet": lambda r: relight(
        r, "The free-form U-Net against ALCN: the same data, objective and budget (quick protocol)"
    ),
    "relight_gain_lite_split": lambda r: relight(
        r, "The distilled gain-lite against the default, test scenes (quick protocol, no method tuned)"
    ),
    "relight_gain_lite_leave_one_out": lambda r: relight(
        r, "The distilled gain-lite against the default, leave-one-scene-out (quick protocol, no method tuned)"
    ),
    "orb_orientation": orb_orientation,
    "directional_light": directional_light,
    "relief_training": lambda r: summary_table(
        r,
        "Training with rendered directional light: the faces stand-in at 12 degrees, and real light (quick protocol)",
        "Faces N px: % of the stand-in's probes identified, the normalized images resized to N px before "
        "identification (as in the table above); test / train: `alcn bench relight`'s quick protocol (seed 0, no "
        "tuning) on the test / webcam training scenes, identification and matching in %.\n",
    ),
    "dog_band": lambda r: summary_table(
        r,
        "The band-pass ALCN starts from, with the pairs registered, and what training does with it (quick protocol)",
        "test / webcams: `alcn bench relight`'s quick protocol (seeds 0-2, no tuning) on the test scenes / on the four "
        "webcams (`--leave-one-out`); identification and matching in %, pose in % of frame pairs.\n",
    ),
    "gamma": lambda r: summary_table(
        r,
        "The gain Normalizer on compressed intensities, ((I + 0.2) / 1.2) ** 0.3, trained so (quick protocol)",
        "Faces N px: % of the stand-in's probes identified at 12 degrees, the normalized images resized to N px "
        "(as above); test / webcams: `alcn bench relight`'s quick protocol (seeds 0-2, no tuning) on the test scenes "
        "/ on the four webcams (`--leave-one-out`); identification and matching in %, pose in % of frame pairs; "
        "middlebury SET LIGHT: its views of 16 posed correctly by `alcn pose eval --middlebury` (within 5 deg and 5 "
        "cm), the photographs as taken (original) or relit.\n",
    ),
    "speed": speed,
    "speed_gpu": device_speed,
    "detect": detect,
    "fewshot": fewshot,
    "pose_table1_features": lambda r: columns_table(r, "Pose Table 1, SIFT parts (rendered sequences)"),
    "pose_table1_corners": lambda r: columns_table(r, "Pose Table 1, corner CNN (rendered sequences)"),
    "pose_table1_control": lambda r: columns_table(r, "Pose Table 1, corner CNN under the training light"),
    "pose_table1_heldout": lambda r: columns_table(r, "Pose Table 1, corner CNN, held-out scene"),
    "pose_middlebury": middlebury,
    "pose_planar_features": lambda r: columns_table(r, "Pose on real light, 500 SIFT keypoints"),
    "pose_planar_corners": lambda r: columns_table(r, "Pose on real light, corner CNN"),
    "calibration": calibration,
}


def build(reports: Path = REPORTS) -> str:
    """The text of docs/results.md from the JSON files in ``reports``, in the order of :data:`RENDERERS`."""
    found = _reports(reports)
    unknown = sorted(set(found) - set(RENDERERS))
    if unknown:
        raise SystemExit(f"no renderer for docs/reports/{unknown[0]}.json (add one to experiments/report.py)")
    sections = [RENDERERS[name](found[name]) for name in RENDERERS if name in found]
    missing = [name for name in RENDERERS if name not in found and name not in GPU_REPORTS]
    head = (
        "# Results\n\nGenerated by `python experiments/report.py` from the JSON reports in `docs/reports/`; do not "
        "edit by hand. Each table gives the script that reruns it, the product command it ran, the machine and "
        "the date. History and older measurements: [journal.md](journal.md).\n"
    )
    if missing:
        head += (
            "\nNot run for this page (long; their scripts are in `experiments/` and the journal keeps the numbers "
            "as measured then): " + ", ".join(f"`{m}`" for m in missing) + ".\n"
        )
    if any(name not in found for name in GPU_REPORTS):
        head += "\nThe speed on a GPU (`experiments/gpu_check.sh`, on a GPU machine) is not run for this page.\n"
    return "\n".join([head, *sections])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--check", action="store_true", help="compare only; exit 1 on a difference")
    args = parser.parse_args()
    readme = README.read_text(encoding="utf-8")
    wanted = {RESULTS: build(), README: readme_with_headlines(readme)}
    stale = [path for path, text in wanted.items() if not path.exists() or path.read_text(encoding="utf-8") != text]
    if args.check:
        print(
            "up to date"
            if not stale
            else "out of date: " + ", ".join(p.name for p in stale) + " (run python experiments/report.py)"
        )
        sys.exit(1 if stale else 0)
    for path in stale:
        path.write_text(wanted[path], encoding="utf-8")
        print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    run_script(main)
