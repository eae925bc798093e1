"""Invariance of the normalizations on real photographs under different lights (Rad et al. 2017, Sec. 4).

For every object of a photometric-stereo set (the same view under several directional lights,
with an object mask), each method normalizes every photograph; the benchmark reports

* **agreement**: the mean, over all pairs of lights, of the normalized cross-correlation of
  the two normalized images inside the (eroded) object mask. 1 means the method removed the
  change of light entirely (as seen inside the mask);
* **detail**: how much fine structure the normalized images keep, scale-free:
  ``sqrt(mean |grad n|^2) / std(n)`` inside the mask (forward differences), averaged over the
  lights. A method that flattens the image (blurs it, or maps it to a constant) scores low;
  note that noise scores high, so read it beside the agreement.

Expected layout (``../shared/data/psm``; :func:`~alcn_cv.data.scenes.load_photometric`): one folder per object
``NAME/`` holding ``NAME.0.png`` ... ``NAME.{k-1}.png`` and ``NAME.mask.png``. The agreement is
:func:`~alcn_cv.data.scenes.mean_pairwise_ncc`.

Outputs in ``out_dir``: ``invariance.json`` (every number, the settings and the machine),
``invariance.md`` (the table) and, with matplotlib, ``invariance_<object>.png`` (the object under every light for
every method, each shown through the method's fixed output mapping, as ``apply`` gives it).
"""

from __future__ import annotations

import logging
import os
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm.auto import tqdm

from alcn_cv.bench.methods import build_methods
from alcn_cv.bench.plots import wrap_label
from alcn_cv.data.scenes import PhotometricObject, load_photometric, mean_pairwise_ncc
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import available, parse_spec
from alcn_cv.errors import InputError
from alcn_cv.io import atomic_paths, atomic_write, check_no_earlier_output, holds_out_dir, make_folder, write_json
from alcn_cv.report import (
    can_draw,
    command_line,
    describe_machine,
    machine,
    markdown_table,
    new_figure,
    save_figure,
)

__all__ = ["detail", "main"]

logger = logging.getLogger(__name__)

#: Characters per line of a method's row label in the figure (a spec is broken after a ``:`` or ``/``).
_LABEL_WIDTH = 24


def detail(normalized: np.ndarray, mask: np.ndarray) -> float:
    """Scale-free fine-structure measure ``sqrt(mean |grad n|^2) / std(n)`` inside ``mask``, mean over images.

    Gradients are forward differences, counted where both pixels are in the mask. A constant
    image scores 0.
    """
    both_x = mask[:, :-1] & mask[:, 1:]
    both_y = mask[:-1, :] & mask[1:, :]
    scores = []
    for n in normalized.astype(np.float64):
        std = n[mask].std()
        if std <= 1e-12:
            scores.append(0.0)
            continue
        energy = np.concatenate([np.diff(n, axis=1)[both_x], np.diff(n, axis=0)[both_y]]) ** 2
        scores.append(float(np.sqrt(energy.mean()) / std))
    return float(np.mean(scores))


def _figure(
    obj: PhotometricObject, results: dict[str, np.ndarray], norms: dict[str, Normalization], path: Path
) -> Path:
    names = list(results)
    k = len(obj.images)
    h, w = obj.mask.shape
    cell = 1.3
    images_width, height = cell * k * w / h, cell * len(names) + 0.6
    plt, fig, axes = new_figure(len(names), k, figsize=(images_width, height))
    for r, name in enumerate(names):
        for c in range(k):
            ax = axes[r, c]
            ax.imshow(norms[name].to_unit(results[name][c]), cmap="gray", vmin=0, vmax=1, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if r == 0:
                ax.set_title(f"light {c}", fontsize=8)
            if c == 0:
                ax.set_ylabel(wrap_label(name, _LABEL_WIDTH), fontsize=9, rotation=0, ha="right", va="center")
    # the figure grows to the left by the widest row label, measured: a fixed margin clipped a weight file's path
    labels = max(axes[r, 0].yaxis.label.get_window_extent().width for r in range(len(names))) / fig.dpi
    margin = labels + 0.15  # inches: the label's gap to the image and the figure's edge
    width = margin + images_width + 0.6  # and room for the gaps between the images
    fig.set_size_inches(width, height)
    fig.suptitle(f"{obj.name}: every method under every light (fixed output mapping of apply())", fontsize=10)
    # half an inch on top for the title and the lights' titles, whatever the rows (a fraction let them overlap)
    fig.subplots_adjust(left=margin / width, right=0.995, top=1 - 0.5 / height, bottom=0.01, wspace=0.03, hspace=0.05)
    return save_figure(plt, fig, path, dpi=80)


@holds_out_dir
def main(
    data_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    methods: list[str] | None = None,
    scale: float = 1.0,
    erode: int = 5,
    figure_object: str | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run the invariance benchmark and write its table, JSON and (with matplotlib) figure.

    Args:
        data_dir: photometric-stereo folder (see the module docstring), e.g. ``../shared/data/psm``.
        out_dir: output folder (created).
        methods: registered normalization names, each optionally with parameters
            (``NAME[:KEY=VALUE...]``, e.g. ``alcn:model=paper:mixture=exact``); default every
            available one.
        scale: resize factor applied to the photographs first.
        erode: pixels removed from the mask's border (so that border effects of the
            background edge do not count), at most half the smaller side of the photographs, less one.
        figure_object: the object shown in the figure; default the first one. ``"all"``: one figure each.
        progress: show a progress bar.
        overwrite: replace the report of an earlier run in ``out_dir``.

    Returns:
        The results dictionary also written to ``invariance.json``.

    Raises:
        InputError: before the photographs are read: an ``out_dir`` that holds an earlier run's report (without
            ``overwrite``), an unknown method, or one that cannot be built (a bad parameter or weight file); a
            negative ``erode``, one wider than the photographs, or one that leaves a mask empty.
        DatasetError: see :func:`~alcn_cv.data.scenes.load_photometric`.
    """
    check_no_earlier_output([Path(out_dir) / "invariance.json", Path(out_dir) / "invariance.md"], overwrite)
    if erode < 0:
        raise InputError(f"--erode must be >= 0 pixels, got {erode}")
    methods = list(available()) if methods is None else list(methods)
    if not methods:
        raise InputError("no method to compare: give --methods NAME,... (default: every method)")
    unknown = [m for m in methods if parse_spec(m)[0] not in available()]
    if unknown:
        raise InputError(f"unknown method(s) {', '.join(unknown)}; available: {', '.join(available())}")
    norms = build_methods(methods)
    objects = load_photometric(data_dir, scale)
    if figure_object not in (None, "all") and figure_object not in [o.name for o in objects]:
        raise InputError(f"no object {figure_object!r}; objects: {', '.join(o.name for o in objects)}")
    # a disc wider than the photograph erases every mask but one of the whole photograph (no border to remove), and
    # its kernel alone could fill the memory: refused before it is made
    widest = min(min(o.mask.shape) for o in objects)
    if 2 * erode + 1 > widest:
        raise InputError(
            f"--erode {erode} removes a disc wider than the photographs ({widest} px at --scale {scale:g}): "
            f"give at most {(widest - 1) // 2}"
        )
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * erode + 1, 2 * erode + 1))
    masks = {o.name: cv2.erode(o.mask.astype(np.uint8), kernel) > 0 if erode else o.mask for o in objects}
    empty = [name for name, mask in masks.items() if not mask.any()]
    if empty:
        raise InputError(
            f"the mask of {', '.join(empty)} holds no pixel once eroded by {erode} px: give a smaller --erode"
        )
    out = Path(out_dir)
    make_folder(out)
    # the figures need matplotlib, which the light install has not: without it the tables alone, said before the work
    shown = {o.name for o in objects} if figure_object == "all" else {figure_object or objects[0].name}
    shown = shown if can_draw("alcn bench invariance") else set()

    rows: dict[str, dict[str, Any]] = {}
    shown_results: dict[str, dict[str, np.ndarray]] = {name: {} for name in shown}
    bar = tqdm(methods, desc="invariance", unit="method", disable=not progress)
    for name in bar:
        bar.set_postfix(method=name)
        row: dict[str, Any] = {"objects": {}}
        norm = norms[name]
        try:
            if hasattr(norm, "trained"):
                row["trained"] = bool(norm.trained)
            seconds = 0.0  # the normalization's alone, not the scoring's
            for obj in objects:
                start = time.perf_counter()
                normalized = np.stack([norm.normalize(img) for img in obj.images])
                seconds += time.perf_counter() - start
                row["objects"][obj.name] = {
                    "agreement": mean_pairwise_ncc(normalized, masks[obj.name]),
                    "detail": detail(normalized, masks[obj.name]),
                }
                if obj.name in shown:
                    shown_results[obj.name][name] = normalized
            row["seconds_per_image"] = seconds / sum(len(o.images) for o in objects)
            row["agreement"] = float(np.mean([v["agreement"] for v in row["objects"].values()]))
            row["detail"] = float(np.mean([v["detail"] for v in row["objects"].values()]))
        except Exception as exc:  # its spec was built up front: what fails here is the run's, reported in the table
            logger.error(
                "method %s failed: %s: %s", name, type(exc).__name__, exc, exc_info=logger.isEnabledFor(logging.DEBUG)
            )
            row = {"objects": {}, "error": f"{type(exc).__name__}: {exc}"}
        rows[name] = row

    object_names = [o.name for o in objects]
    command = command_line(
        ["alcn", "bench", "invariance", "--data", data_dir, "--out", out_dir],
        {"--methods": methods, "--scale": scale, "--erode": erode, "--figure-object": figure_object},
    )
    result = {
        "benchmark": "invariance",
        "data": str(Path(data_dir).resolve()),
        "command": command,
        "settings": {
            "methods": methods,
            "scale": scale,
            "erode": erode,
            "lights": {o.name: len(o.images) for o in objects},
        },
        "metrics": {
            "agreement": "mean pairwise normalized cross-correlation inside the eroded object mask",
            "detail": "sqrt(mean |forward-difference gradient|^2) / std inside the mask, mean over lights",
        },
        "machine": machine(),
        "methods": rows,
    }

    headers = ["method"] + [f"agreement {o}" for o in object_names] + ["agreement (mean)", "detail (mean)", "ms/image"]
    table = []
    for name, row in rows.items():
        label = name + (" (untrained weights)" if row.get("trained") is False else "")
        if "error" in row:
            table.append([label] + [None] * (len(object_names) + 3))
            continue
        table.append(
            [label]
            + [row["objects"][o]["agreement"] for o in object_names]
            + [row["agreement"], row["detail"], f"{1000 * row['seconds_per_image']:.1f}"]
        )
    failures = [f"- `{n}` failed: {r['error']}" for n, r in rows.items() if "error" in r]
    text = (
        f"# Invariance of the normalizations on real photographs under different lights\n\n"
        f"- **Machine:** {describe_machine(result['machine'])}\n"
        f"- **Command:** `{command}`\n"
        f"- **Data:** `{result['data']}`\n"
        f"- **Settings:** scale {scale}, mask eroded by {erode} px, methods {', '.join(methods)}\n\n"
        f"Every method normalizes each object's photographs, one per light (lights: "
        f"{', '.join(f'{o.name} {len(o.images)}' for o in objects)}; scale {scale}, mask eroded by "
        f"{erode} px). **agreement**: {result['metrics']['agreement']} "
        f"(1 = light removed). **detail**: {result['metrics']['detail']} (low = flattened; noise is high). "
        "**ms/image**: the method's `normalize()` of one photograph, the scoring left out.\n\n"
        + markdown_table(headers, table)
        + ("\n" + "\n".join(failures) + "\n" if failures else "")
    )
    drawn = [obj for obj in objects if obj.name in shown and shown_results[obj.name]]
    figures = [out / f"invariance_{obj.name}.png" for obj in drawn]
    # all or none: an interrupt leaves an earlier report whole, figures included; an earlier run's figures (named
    # after its objects) go with it
    report = [out / "invariance.json", out / "invariance.md", *figures]
    with atomic_paths(*report, stale=out.glob("invariance_*.png")) as (json_path, md_path, *drawn_paths):
        write_json(json_path, result)
        atomic_write(md_path, text)
        for obj, path in zip(drawn, drawn_paths):
            _figure(obj, shown_results[obj.name], norms, path)
    logger.info("invariance benchmark written to %s", out)
    return result
