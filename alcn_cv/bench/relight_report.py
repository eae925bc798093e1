"""The report of ``alcn bench relight``: ``relight.md``, ``relight.json`` and ``relight.png``."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.io import atomic_paths, atomic_write, write_json
from alcn_cv.report import describe_machine, markdown_table, new_figure, save_figure, spread_cell

__all__ = ["METRIC_LABELS", "write_report"]

#: The metrics in the report's order, SIFT before ORB as in docs/results.md.
_TITLES = {
    "identification": "Patch identification (%)",
    "matching_sift": "Keypoint matching score, SIFT (%)",
    "matching_orb": "Keypoint matching score, ORB (%)",
    "pose_sift": "Real-light pose, SIFT homography (% of pairs)",
    "pose_orb": "Real-light pose, ORB homography (% of pairs)",
    "correct_sift": "Correct SIFT matches per frame pair (count; the matching score's numerator)",
    "correct_orb": "Correct ORB matches per frame pair (count; the matching score's numerator)",
}
#: Each metric's short name, a table column's (also the published tables' of experiments/report.py).
METRIC_LABELS = {
    "identification": "identification",
    "matching_sift": "matching SIFT",
    "matching_orb": "matching ORB",
    "pose_sift": "pose SIFT",
    "pose_orb": "pose ORB",
    "correct_sift": "correct SIFT",
    "correct_orb": "correct ORB",
}


def _cell(summary: dict[str, Any] | None) -> str | None:
    return None if summary is None else spread_cell(summary, 1, runs=len(summary["seeds"]))


def _label(label: str, r: dict[str, Any]) -> str:
    """A method's row label, with its note (weights trained on a test scene of the run) when it has one."""
    return f"{label} ({r['note']})" if r.get("note") else label


def _metrics(result: dict[str, Any]) -> list[str]:
    return [m for m in _TITLES if any(m in s for r in result["methods"].values() for s in r["scenes"].values())]


def _scene_text(name: str, scene: dict[str, Any], settings: dict[str, Any]) -> str:
    """A scene of the report's Scenes line: its group, frames and size, and what it held of the sampling asked."""
    fewer = []
    if (locations := scene["fewest_patches"]) < settings["patches"]:
        fewer.append(f"as few as {locations} patch locations, chance {100 / locations:.1f}%")
    if (gallery := scene["fewest_gallery_frames"]) < settings["gallery"]:
        fewer.append(f"{gallery} gallery frames")
    size = f"{scene['size'][0]}x{scene['size'][1]}"
    return f"{name} ({scene['group']}, {scene['frames']} frames {size}{''.join('; ' + f for f in fewer)})"


def _summary_table(result: dict[str, Any], metrics: list[str]) -> str:
    rows = []
    for label, r in result["methods"].items():
        test = r.get("mean_test", {})
        ms = [s["ms_per_frame"] for n, s in r["scenes"].items() if n in result["split"]["test"]]
        cells = [_cell(test.get(m)) for m in metrics]
        rows.append([_label(label, r), *cells, f"{np.mean(ms):.1f}" if ms else None, r.get("backend")])
    return markdown_table(["method"] + [METRIC_LABELS[m] for m in metrics] + ["ms/frame", "backend"], rows)


def _metric_table(result: dict[str, Any], metric: str) -> str:
    test, train = result["split"]["test"], result["split"]["train"]
    mean_test = "**mean (held out)**" if result["split"]["mode"] == "leave-one-out" else "**mean (test)**"
    headers = ["method"] + test + [mean_test] + ([f"{n} (train)" for n in train] + ["mean (train)"] if train else [])
    rows = []
    for label, r in result["methods"].items():
        scenes = r["scenes"]
        row = [_label(label, r)] + [_cell(scenes.get(n, {}).get(metric)) for n in test]
        row.append(_cell(r.get("mean_test", {}).get(metric)))
        if train:
            row += [_cell(scenes.get(n, {}).get(metric)) for n in train] + [_cell(r.get("mean_train", {}).get(metric))]
        rows.append(row)
    return markdown_table(headers, rows)


def _differences_section(result: dict[str, Any], metrics: list[str]) -> list[str]:
    """The section of ``paired_differences`` (:func:`~alcn_cv.bench.relight.paired_differences`): its title and table,
    none without one."""
    paired = result.get("paired_differences")
    if not paired:
        return []
    seeds = result["settings"]["seeds"]
    reference = paired["reference"]

    def cell(d: dict[str, Any] | None) -> str | None:
        if d is None:
            return None
        return f"{d['mean']:+.1f}" + (f" ± {d['std']:.1f}" if len(seeds) > 1 else "")

    caption = (
        f"For each seed, a method's mean over the test scenes minus `{reference}`'s (the first method listed): for a "
        "seed both are scored on the same frames, patches and pairs. "
        + (
            f"Cells: the mean of these differences over seeds {seeds} ± their sample standard deviation: a difference "
            "within about its ± of 0 is not told apart from the seeds' draws (the per-method ± of the other tables "
            "also hold the draws that both methods share)"
            if len(seeds) > 1
            else f"Cells: the difference on the one seed ({seeds[0]}), with no spread to tell it from the seed's draws"
        )
        + "; points of %, counts for correct matches.\n"
    )
    rows = [
        [_label(label, result["methods"][label]), *(cell(diff.get(m)) for m in metrics)]
        for label, diff in paired["methods"].items()
    ]
    return [
        f"## Difference from `{reference}` (paired {paired['pairing']})\n",
        caption,
        markdown_table(["method"] + [METRIC_LABELS[m] for m in metrics], rows),
    ]


def _tuning_text(result: dict[str, Any]) -> str:
    if not result["tuning"]:
        if result["settings"]["tuning_requested"]:
            return "No tuning: none of the methods listed has a tuning grid (default parameters only).\n"
        return "No tuning asked (`--no-tune`: default parameters only).\n"
    loo = result["split"]["mode"] == "leave-one-out"
    rows = []
    for method, folds in result["tuning"].items():
        for fold, t in folds.items():
            scores = list(t["scores"].values())  # the grid's first setting is the default
            rows.append(
                [method]
                + ([f"all but {fold}"] if loo else [])
                + [
                    f"`{t['chosen']}`",
                    f"{t['scores'][t['chosen']]:.1f}",
                    f"{scores[0]:.1f}",
                    f"{min(scores):.1f}-{max(scores):.1f}",
                ]
            )
    s = result["settings"]
    grids = s["tuning_grids"]
    sizes = {len(grid) for grid in grids.values()}
    counted = (
        f"{sizes.pop()} settings"
        if len(sizes) == 1
        else f"settings ({', '.join(f'{method} {len(grid)}' for method, grid in grids.items())})"
    )
    untuned = [label for label in result["methods"] if not label.endswith(" (tuned)") and label not in grids]
    text = (
        f"Each method's {counted} (`relight.json`: settings.tuning_grids) scored by identification on "
        f"{s['tune_frames']} evenly spaced frames of each training scene (all of a scene that has fewer; seed "
        f"{s['tune_seed']}); the first best setting is chosen."
        + (f" Not tuned (no grid): {', '.join(f'`{m}`' for m in untuned)}." if untuned else "")
        + "\n\n"
    )
    headers = (
        ["method"] + (["tuned on"] if loo else []) + ["chosen", "identification %", "default's %", "range over grid"]
    )
    return text + markdown_table(headers, rows)


def _figure(result: dict[str, Any], path: Path) -> Path:
    labels = [k for k, r in result["methods"].items() if "mean_test" in r]
    panels = [
        ("identification", ["identification"], "%"),
        ("matching score", ["matching_sift", "matching_orb"], "%"),
        ("pose success", ["pose_sift", "pose_orb"], "%"),
        ("correct matches per pair", ["correct_sift", "correct_orb"], "count"),
    ]
    panels = [
        (t, [m for m in ms if any(m in result["methods"][k]["mean_test"] for k in labels)], unit)
        for t, ms, unit in panels
    ]
    panels = [(t, ms, unit) for t, ms, unit in panels if ms]
    plt, fig, axes = new_figure(1, len(panels), figsize=(5.5 * len(panels), 4.8))
    x = np.arange(len(labels))
    spread = len(result["settings"]["seeds"]) > 1  # one seed has no error bar to draw
    for ax, (title, metrics, unit) in zip(axes[0], panels):
        width = 0.8 / len(metrics)
        for j, m in enumerate(metrics):
            means = [result["methods"][k]["mean_test"][m]["mean"] for k in labels]
            ax.bar(
                x + (j - (len(metrics) - 1) / 2) * width,
                means,
                width,
                yerr=[result["methods"][k]["mean_test"][m]["std"] for k in labels] if spread else None,
                capsize=2,
                label=METRIC_LABELS[m].split()[-1] if len(metrics) > 1 else None,
            )
        ax.set_xticks(x)
        ax.set_xticklabels(labels, rotation=60, ha="right", fontsize=8)
        ax.set_ylabel(unit)
        ax.set_title(f"{title} (mean over test scenes)", fontsize=10)
        ax.grid(axis="y", alpha=0.3)
        if len(metrics) > 1:
            ax.legend(fontsize=8)
    fig.suptitle(
        f"alcn bench relight: test scenes {', '.join(result['split']['test'])}; "
        + (
            f"error bars: sample std over seeds {result['settings']['seeds']}"
            if spread
            else f"one seed ({result['settings']['seeds'][0]})"
        ),
        fontsize=10,
    )
    fig.tight_layout()
    return save_figure(plt, fig, path, dpi=90)


def write_report(result: dict[str, Any], out: Path, draw: bool = True) -> None:
    """Write ``relight.json`` (everything), ``relight.md`` (the tables) and, with ``draw`` (matplotlib installed:
    :func:`~alcn_cv.report.can_draw`), ``relight.png`` (bars; where a method has a result) into ``out``, all or none
    of them (:func:`~alcn_cv.io.atomic_paths`: an interrupt leaves an earlier report whole); an earlier figure that
    this report has none for is removed."""
    metrics = _metrics(result)
    s, split = result["settings"], result["split"]
    scenes = ", ".join(_scene_text(n, v, s) for n, v in result["scenes"].items())
    failures = [
        f"- `{label}` failed on {scene}: {err}"
        for label, r in result["methods"].items()
        for scene, err in r.get("errors", {}).items()
    ]
    text = [
        "# Normalizations on real changes of light (`alcn bench relight`)\n",
        f"Command: `{result['command'] or 'alcn_cv.bench.relight.main(...)'}`; "
        f"wall time {result['seconds'] / 60:.1f} min.  ",
        f"Machine: {describe_machine(result['machine'])}.\n",
        f"Split: {split['mode']}; test {', '.join(split['test'])}"
        + (f"; train{' (tuning)' if s['tuning'] else ''} {', '.join(split['train'])}" if split["train"] else "")
        + ".  ",
        f"Scenes: {scenes}.\n",
        f"Every method normalizes whole grayscale frames through its own `apply()` (uint8 in, float32 out); "
        f"{s['gallery']} gallery frames per scene and seed, each paired with the other frames ("
        + (f"at most {s['max_pairs']} pairs per scene and seed" if s["max_pairs"] else "every pair")
        + f"). Identification: {s['patches']} textured "
        f"{s['patch']}x{s['patch']} patch locations (fewer where a scene's frames hold fewer: Scenes), NCC over all of "
        f"them (chance {100 / s['patches']:.2f}%), each pair first registered to the pixel: the query frame's patches "
        f"moved by the one move of at most {s['shift_px']} px that best matches the gallery's (a fixed camera shakes). "
        + (
            f"Keypoints: {s['keypoints']} per frame on apply()'s uint8 output, ratio test {s['ratio']}, correct within "
            f"{s['match_px']} px; matching score: the correct one-to-one matches over the pair's smaller keypoint "
            f"count (Mikolajczyk & Schmid); pose: RANSAC homography ({s['ransac_px']} px), success when every corner "
            f"moves less than {s['pose_px']} px. "
            if s["keypoint_protocols"]
            else "Identification only (no keypoint protocols). "
        )
        + (
            f"Cells: mean ± sample standard deviation over seeds {s['seeds']}"
            if len(s["seeds"]) > 1
            else f"Cells: one seed ({s['seeds'][0]}), so no spread"
        )
        + " (the seed draws the gallery frames, patch locations and pairs). ms/frame: `apply()` on the test "
        "scenes' frames; backend: what ran each ALCN method, which the time depends on (`opencv`: cv2.dnn, the "
        "shipped files' default; `fast`: the network in torch on the CPU, a user's weight file's default; `torch`: "
        "all in torch).\n",
        "## Summary (mean over test scenes)\n",
        _summary_table(result, metrics),
        *_differences_section(result, metrics),
    ]
    for m in metrics:
        text += [f"## {_TITLES[m]}\n", _metric_table(result, m)]
    text += ["## Tuning (training scenes only)\n", _tuning_text(result)]
    if failures:
        text += ["## Failures\n", "\n".join(failures) + "\n"]
    figure = draw and any("mean_test" in r for r in result["methods"].values())
    names = ["relight.json", "relight.md", *(["relight.png"] if figure else [])]
    # the folder made by the atomic writes; an earlier figure goes with them when this report has none
    with atomic_paths(*(out / name for name in names), stale=[out / "relight.png"]) as paths:
        write_json(paths[0], result)
        atomic_write(paths[1], "\n".join(text))
        if figure:
            _figure(result, paths[2])
