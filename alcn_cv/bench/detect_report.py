"""``detect.md``, the report of the detection benchmark: machine, command, settings, input
policies, the AUC tables (mean and spread over seeds) and the tuned parameters."""

from __future__ import annotations

import os
from typing import Any

from alcn_cv.bench.detect_settings import POLICY_DESCRIPTIONS, DetectSettings
from alcn_cv.enhance.registry import format_spec
from alcn_cv.report import command_line, describe_machine, markdown_table, spread_cell

__all__ = ["chosen_trial", "detect_command", "detect_markdown", "images_used", "real_images_label", "untested_objects"]


def detect_command(
    data_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    settings: DetectSettings,
    working_scale: float | None = None,
    box_size: float | None = None,
) -> str:
    """The ``alcn bench detect`` command line that runs these settings (``max_detections`` and
    the preset aside, every setting spelled out)."""
    # the seeds in the space form of --seeds (command_line joins a list with commas, --methods' form)
    seeds = ["--seeds", *map(str, settings.seeds)]
    return command_line(
        ["alcn", "bench", "detect", "--data", data_dir, "--out", out_dir, *seeds],
        {
            "--methods": settings.methods,
            "--real-images": settings.real_images,
            "--policy": settings.policies,
            "--positives": settings.positives_per_object,
            "--negatives-ratio": settings.negatives_ratio,
            "--epochs": settings.epochs,
            "--batch-size": settings.batch_size,
            "--lr": settings.lr,
            "--tune": settings.tune,
            "--cnn-sweep": [f"{d}x{w}" for d, w in settings.cnn_sweep],
            "--nms-iou": settings.nms_iou,
            "--match-iou": settings.match_iou,
            "--max-test-images": settings.max_test_images,
            "--working-scale": working_scale,
            "--box-size": box_size,
            "--threads": settings.threads,
            "--device": settings.device,
        },
    )


def images_used(result: dict[str, Any], n_real: int) -> dict[str, int]:
    """Real training images per object of the runs that asked for ``n_real``: fewer where the data set has fewer
    (every such run uses the same ones); empty when none of them finished."""
    return next(
        (r["images_used"] for r in result["runs"].values() if r.get("real_images") == n_real and "images_used" in r),
        {},
    )


def real_images_label(n_real: int, used: dict[str, int], unit: str = "") -> str:
    """The real images (``unit``: e.g. " per object") a table or figure shows: those used, with the number asked for
    where the data set had fewer (``--real-images 10`` on a set with 3 per object trains on 3, and "10" would
    misread the result)."""
    short = {name: n for name, n in used.items() if n != n_real}
    if not short:
        return f"{n_real} real image(s){unit}"
    counts = sorted(set(used.values()))
    if len(counts) == 1:
        return f"{counts[0]} real image(s){unit} ({n_real} requested)"
    fewer = ", ".join(f"{name} {n}" for name, n in short.items())
    return f"{counts[0]}-{counts[-1]} real image(s){unit} ({n_real} requested; {fewer})"


def untested_objects(result: dict[str, Any]) -> list[str]:
    """The objects without an instance in the test images: nothing to detect, so no AUC (``-`` in the tables)."""
    return sorted(
        {name for r in result["runs"].values() for name, obj in r.get("objects", {}).items() if obj.get("num_gt") == 0}
    )


def _tuned(result: dict[str, Any]) -> list[str]:
    """The methods a result tuned (in their order), none without ``--tune``."""
    return list(dict.fromkeys(m for tuned in result.get("tuned", {}).values() for m in tuned))


def chosen_trial(tuned: dict[str, Any]) -> dict[str, Any]:
    """The chosen trial of a tuning record ``{"params", "trials"}`` (``alcn bench detect`` or ``fewshot --tune``)."""
    return next(t for t in tuned["trials"] if t["params"] == tuned["params"])


def _tuning_text(result: dict[str, Any], settings: DetectSettings) -> list[str]:
    """The section on the tuned parameters: on what they were chosen, and each chosen setting's validation AUC
    against the default's (the grid's first) and the grid's range."""
    methods = _tuned(result)
    first = result["tuned"][str(settings.real_images[0])][methods[0]]["trials"]
    lines = [
        "\n## Tuned parameters (mean AUC on the validation images)\n",
        f"{', '.join(methods)}: each of {len(first)} settings (the default first) normalizes the training windows of "
        f"seed {settings.seeds[0]}, the detector is trained on them as in that seed's runs (input "
        f"{' and '.join(f'`{p}`' for p in settings.policies)}), and the setting scores the mean AUC over objects on "
        f"the {len(result['val_images'])} validation images (`val.json`, apart from the test images)"
        f"{', averaged over the policies' if len(settings.policies) > 1 else ''}; the first best setting serves every "
        "seed. Every setting's AUC: `detect.json`, `tuned`.\n",
    ]
    rows, tied = [], []
    for n_real, tuned in result["tuned"].items():
        for method, t in tuned.items():
            aucs = [x["val_auc"] for x in t["trials"] if x["val_auc"] is not None]
            chosen = chosen_trial(t)
            if aucs and min(aucs) == max(aucs):
                tied.append(f"{method} ({n_real})")
            rows.append(
                [
                    n_real,
                    f"`{format_spec(method, t['params'])}`",
                    _auc(chosen["val_auc"]),
                    _auc(t["trials"][0]["val_auc"]),
                    f"{min(aucs):.3f}-{max(aucs):.3f}" if aucs else "-",
                ]
            )
    lines.append(markdown_table(["real images", "chosen", "validation AUC", "default's", "range over grid"], rows))
    if tied:
        lines.append(
            f"\nEvery setting scored the same for {', '.join(tied)}: the default was kept, and the validation images "
            "cannot tell the settings apart (too few or too easy; render more with `alcn data detect`).\n"
        )
    return lines


def _auc(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def _header(result: dict[str, Any], settings: DetectSettings) -> list[str]:
    seeds = settings.seeds
    tuned = _tuned(result)
    parameters = (
        f"{', '.join(tuned)} tuned by detection on the validation images (below), the others with their defaults"
        if tuned
        else "every method with its defaults"
    )
    lines = [
        "# Detection benchmark (rendered objects, few real images): ALCN against the other normalizations\n",
        "ALCN against the classical normalizations and deep baselines (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3): "
        "for every method the same detector is trained on the same synthetic windows, normalized by the method, "
        "and scored on every window of the test images. AUC = area under the precision-recall curve (PASCAL VOC "
        f"average precision), PASCAL criterion IoU >= {settings.match_iou} with fixed-size boxes.\n",
        f"- **Machine:** {describe_machine(result['machine'])}",
        f"- **Command:** `{result['command']}`",
        f"- **Data:** `{result['data']}`, {len(result['test_images'])} test images at working scale "
        f"{result['working_scale']} (boxes of {result['box_size']} px)",
        f"- **Settings:** real training images per object {settings.real_images}; "
        f"{settings.positives_per_object} synthetic object windows per object and {settings.negatives_ratio}x "
        f"background windows; detector training {settings.epochs} epochs, batch {settings.batch_size}, "
        f"Adam lr {settings.lr}, device {settings.device}; non-maximum suppression IoU {settings.nms_iou}, "
        f"{settings.max_detections} detections per object and image; {parameters}; "
        f"plain CNN sweep {', '.join(f'{d}x{w}' for d, w in settings.cnn_sweep)} (depth x width). "
        f"Total time {result['seconds']:.0f} s.",
        "- **Input policies** (how the normalized windows reach the detector; the same for every method):",
    ]
    lines += [
        f"  - `{name}`{'' if name in settings.policies else ' (not run here)'}: {text}."
        for name, text in POLICY_DESCRIPTIONS.items()
    ]
    if len(seeds) > 1:
        lines.append(
            f"- **Seeds:** {len(seeds)} ({', '.join(map(str, seeds))}); every cell is the mean ± standard "
            "deviation over the seeds (a seed draws other training windows, detector initialisation and "
            "batch order)."
        )
    else:
        lines.append(
            f"- **Seeds:** one ({seeds[0]}), so there is no spread: a single seed's AUC moves by several "
            "hundredths with the training windows and the detector's initialisation; read small "
            "differences with care, or rerun with `--seeds 0 1 2`."
        )
    short = {n: used for n in settings.real_images if (used := images_used(result, n)) and set(used.values()) != {n}}
    if short:
        lines.append(
            "- **Real images used:** the data set has fewer training images than requested; "
            + "; ".join(
                f"{n} requested: " + ", ".join(f"{o} {k}" for o, k in used.items()) for n, used in short.items()
            )
            + " (`images_used` in detect.json). The tables and figures say what was used."
        )
    instances = next(
        ({n: o.get("num_gt") for n, o in r["objects"].items()} for r in result["runs"].values() if r.get("objects")),
        {},
    )
    if instances and None not in instances.values():
        few = min(instances.values()) <= 3
        lines.append(
            "- **Test instances per object:** "
            + ", ".join(f"{name} {count}" for name, count in instances.items())
            + (
                "; with this few an AUC takes few values (one instance: 1 where the first detection is it, else "
                "1/rank of the first that is): read them as a check that the pipeline runs, not as a measurement."
                if few
                else "."
            )
        )
    untested = untested_objects(result)
    if untested:
        lines.append(
            f"- **`-` cells:** the test images hold no instance of {', '.join(untested)}, so there is nothing to "
            "detect and no AUC; the mean is over the other objects."
        )
    lines.append("")
    if result.get("alcn_trained") is False:
        lines.append(
            "**The `alcn` row used UNTRAINED Normalizer weights** (the shipped file's `trained` flag is false).\n"
        )
    return lines


def detect_markdown(result: dict[str, Any], names: list[str]) -> str:
    """The Markdown report of a benchmark result (the contents of ``detect.json``), one column per
    object of ``names``."""
    settings = DetectSettings(**result["settings"])
    lines = _header(result, settings)
    for n_real in settings.real_images:
        for policy in settings.policies:
            rows = []
            for method in settings.methods:
                summary = result["summary"][f"{method}|{n_real}|{policy}"]
                if "error" in summary:
                    rows.append([method] + ["failed"] * (len(names) + 1))
                    continue
                failed = f" ({len(summary['failed_seeds'])} seed(s) failed)" if summary["failed_seeds"] else ""
                rows.append(
                    [method + failed]
                    + [spread_cell(summary["objects"][n]) for n in names]
                    + [spread_cell(summary["mean"])]
                )
            label = real_images_label(n_real, images_used(result, n_real), " per object")
            lines.append(f"\n## {label}, input policy `{policy}`\n")
            lines.append(markdown_table(["method"] + names + ["mean"], rows))
    agreement = result.get("window_agreement") or {}
    if agreement:
        lines.append("\n## Training windows against test images\n")
        lines.append(
            "Correlation between the 32x32 centres of 64x64 test-image windows normalized alone (what the "
            "detector trains on) and the same pixels of the normalized whole image (what it is tested on), "
            "200 random windows; 1 = the same, lower = the detector is tested on another response than it "
            "learnt (methods with a context wider than the window).\n"
        )
        lines.append(
            markdown_table(
                ["method", "agreement"],
                [
                    [m, ", ".join("-" if v is None else f"{v:.3f}" for v in by_params.values())]
                    for m, by_params in agreement.items()
                ],
            )
        )
    failures = [f"- `{k}`: {v['error']}" for k, v in result["runs"].items() if "error" in v]
    if failures:
        lines.append("\n## Failures\n\n" + "\n".join(failures) + "\n")
    if _tuned(result):
        lines += _tuning_text(result, settings)
    if result.get("cnn"):
        lines.append(
            "\n## Plain CNN sweep (chosen by accuracy on relit held-out training windows; per run: real images, "
            "input policy, seed)\n"
        )
        for key, c in result["cnn"].items():
            lines.append(
                f"- {key.replace('|', ', ')}: chosen depth {c['chosen']['depth']} width {c['chosen']['width']}; "
                + ", ".join(f"{s['depth']}x{s['width']}: {s['val_acc']:.3f}" for s in c["sweep"])
            )
        lines.append("")
    return "\n".join(lines) + "\n"
