"""Figures of the benchmarks: precision-recall curves of the detection benchmark, time against
frame size of the speed benchmark. One colour per method, the same in every panel of a run."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.bench.detect_report import images_used, real_images_label, untested_objects
from alcn_cv.bench.detect_settings import DetectSettings, run_key
from alcn_cv.enhance.registry import parse_spec
from alcn_cv.report import new_figure, save_figure

__all__ = ["method_styles", "plot_pr_curves", "plot_speed", "pr_figure_names", "trim_pr_curve", "wrap_label"]

#: tab20's saturated colours first, then its light ones: neighbours in a list of methods get
#: hues that differ clearly (tab20 in its own order pairs each colour with its light variant).
_PALETTE_ORDER = list(range(0, 20, 2)) + list(range(1, 20, 2))


#: Characters per line of a legend entry: the methods of a tied curve on one line took half the figure.
_LEGEND_WIDTH = 40

#: Point markers, one per method in turn: curves that share a stretch stay told apart.
_MARKERS = "osD^vP*Xph<>"


def wrap_label(text: str, width: int) -> str:
    """``text`` on lines of at most ``width`` characters, broken after a space, ``:`` or ``/`` where it can (inside a
    longer piece elsewhere): a method's spec with a weight file's path, or the methods of a tied curve, on one line
    would push the figure's images or axes aside or run off its edge."""
    lines: list[str] = []
    for piece in re.findall(r"[^ :/]+[ :/]?|[ :/]", text):  # each piece ends at its break
        for chunk in (piece[i : i + width] for i in range(0, len(piece), width)):
            if lines and len(lines[-1]) + len(chunk.rstrip()) <= width:
                lines[-1] += chunk
            else:
                lines.append(chunk)
    return "\n".join(line.rstrip() for line in lines)


def method_styles(methods: Sequence[str]) -> dict[str, tuple[Any, str, str]]:
    """A colour, a line style and a marker per method, in list order: the 10 saturated colours of
    tab20 with solid lines, then its 10 light colours with dashed lines, then again dotted."""
    from matplotlib import colormaps

    cmap = colormaps["tab20"]
    return {
        m: (cmap(_PALETTE_ORDER[k % 20]), ("-", "--", ":")[min(k // 10, 2)], _MARKERS[k % len(_MARKERS)])
        for k, m in enumerate(methods)
    }


def trim_pr_curve(recall: Sequence[float], precision: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """The curve up to its last true positive: the detections after it only lower the precision
    at the same recall (a vertical drop that says nothing about the method)."""
    r, p = np.asarray(recall, np.float64), np.asarray(precision, np.float64)
    if not r.size:
        return r, p
    last = int(np.argmax(r >= r[-1]))  # first point at the final recall
    return r[: last + 1], p[: last + 1]


def _ties(curves: dict[str, tuple[list[float], list[float]]]) -> dict[str, list[str]]:
    """Methods whose (trimmed) curves are identical, grouped under the first of them (in order)."""
    groups: dict[str, list[str]] = {}
    for method, curve in curves.items():
        first = next((g for g in groups if curves[g] == curve), None)
        if first is None:
            groups[method] = [method]
        else:
            groups[first].append(method)
    return groups


def pr_figure_names(names: list[str], real_images: list[int]) -> list[str]:
    """The files of :func:`plot_pr_curves`, ``pr_<object>_<n>real.png``, in the order it draws them."""
    return [f"pr_{name}_{n_real}real.png" for name in names for n_real in real_images]


def plot_pr_curves(result: dict[str, Any], names: list[str], paths: list[Path]) -> None:
    """Draw into ``paths``, one for each of :func:`pr_figure_names` (the detection report's temporary files, say), the
    precision-recall of every method (first seed) of each object and number of real images, one panel per input
    policy; identical curves are drawn once and named together in the legend."""
    settings = DetectSettings(**result["settings"])
    styles = method_styles(settings.methods)
    seed = settings.seeds[0]
    untested = untested_objects(result)
    used_by_n = {n_real: images_used(result, n_real) for n_real in settings.real_images}
    targets = iter(paths)
    for name in names:
        for n_real in settings.real_images:
            used = used_by_n[n_real]
            real = real_images_label(n_real, {name: used[name]} if name in used else {})
            plt, fig, axes = new_figure(1, len(settings.policies), figsize=(7.6 * len(settings.policies), 4.8))
            for ax, policy in zip(axes[0], settings.policies):
                curves, aucs = {}, {}
                for method in settings.methods:
                    obj = result["runs"].get(run_key(method, n_real, policy, seed), {}).get("objects", {}).get(name)
                    if obj and obj.get("auc") is not None:
                        recall, precision = trim_pr_curve(obj["pr"]["recall"], obj["pr"]["precision"])
                        curves[method] = (recall.tolist(), precision.tolist())
                        aucs[method] = obj["auc"]
                for method, tied in _ties(curves).items():
                    colour, style, marker = styles[method]
                    recall, precision = curves[method]
                    label = method + (f" (= {', '.join(tied[1:])})" if len(tied) > 1 else "")
                    label = wrap_label(f"{label}: AUC {aucs[method]:.3f}", _LEGEND_WIDTH)
                    ax.plot(
                        recall,
                        precision,
                        linestyle=style,
                        color=colour,
                        marker=marker,
                        markersize=4,
                        markevery=max(1, len(recall) // 12),
                        lw=2.4 if parse_spec(method)[0] == "alcn" else 1.3,
                        label=label,
                    )
                ax.set_xlim(0, 1)
                ax.set_ylim(0, 1.05)
                ax.set_xlabel("recall")
                ax.set_ylabel("precision")
                ax.set_title(f"{name}, {real}, input {policy}, seed {seed}", fontsize=10)
                ax.grid(alpha=0.3)
                if curves:
                    ax.legend(
                        fontsize=7,
                        loc="upper left",
                        bbox_to_anchor=(1.01, 1.0),
                        borderaxespad=0.0,
                        title="method (= same curve)",
                        title_fontsize=7,
                    )
                else:  # an empty panel says why
                    why = f"no instance of {name} in the test images" if name in untested else "every run failed"
                    ax.text(0.5, 0.5, f"no curve: {why}", ha="center", va="center", transform=ax.transAxes)
            fig.tight_layout()
            save_figure(plt, fig, next(targets))


def plot_speed(result: dict[str, Any], path: Path) -> None:
    """``speed.png``: median time of ``apply`` against the pixel count, log-log, every method."""
    plt, fig, axes = new_figure(figsize=(10, 5.5))
    ax = axes[0, 0]
    methods = list(dict.fromkeys(r["method"] for r in result["rows"]))
    for method, (colour, _, _) in method_styles(methods).items():
        for kind, style in (("gray", "-o"), ("bgr", "--s")):
            pts = sorted(
                (r["pixels"], r["median_ms"]) for r in result["rows"] if r["method"] == method and r["colour"] == kind
            )
            if pts:
                ax.plot(*zip(*pts), style, color=colour, label=f"{method} ({kind})", markersize=4)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("pixels per frame")
    ax.set_ylabel("median time per frame (ms)")
    ax.set_title("apply(): time against frame size (solid: grayscale, dashed: BGR)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    fig.tight_layout()
    save_figure(plt, fig, path)
