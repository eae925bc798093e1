"""Figures for calibration and registration (matplotlib, Agg backend, PNG)."""

from __future__ import annotations

import os
import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from alcn_cv.report import new_figure, save_figure

from .quality import COVERAGE_GRID, OUTLIER_RULE, coverage, coverage_hint, outlier_px, outliers

if TYPE_CHECKING:
    from .camera import Calibration

__all__ = ["plot_calibration", "plot_registration"]


def _figure(ncols: int, width: float = 13.0, height: float = 5.0):
    """``(plt, fig, axes)``: one row of ``ncols`` axes, the first a little wider."""
    plt, fig, axes = new_figure(
        1, ncols, figsize=(width, height), gridspec_kw={"width_ratios": [1.2] + [1] * (ncols - 1)}
    )
    return plt, fig, axes[0]


def _save(plt: Any, fig: Any, path: str | os.PathLike) -> Path:
    fig.tight_layout()
    return save_figure(plt, fig, path)


def plot_calibration(calib: Calibration, path: str | os.PathLike) -> Path:
    """Board coverage (every detected corner of every view over the image frame, each view's
    outline; the title counts the image cells covered and gives :func:`calib.quality.coverage_hint`) and per-view
    RMS reprojection errors with the overall RMS, outliers (:func:`calib.quality.outliers`) in red.

    Returns:
        ``path``.
    """
    import cv2

    plt, fig, (ax0, ax1) = _figure(2)
    w, h = calib.image_size
    cmap = plt.get_cmap("viridis")
    n = max(len(calib.image_points), 1)
    for k, pts in enumerate(calib.image_points):
        colour = cmap(k / max(n - 1, 1))
        hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2)
        ax0.fill(hull[:, 0], hull[:, 1], color=colour, alpha=0.08)
        ax0.plot(*np.vstack([hull, hull[:1]]).T, color=colour, lw=0.8)
        ax0.scatter(pts[:, 0], pts[:, 1], s=4, color=colour)
    ax0.add_patch(plt.Rectangle((0, 0), w, h, fill=False, ec="k", lw=1.5))
    ax0.set_xlim(-0.02 * w, 1.02 * w)
    ax0.set_ylim(1.02 * h, -0.02 * h)
    ax0.set_aspect("equal")
    K = calib.K
    ax0.plot(K[0, 2], K[1, 2], "r+", ms=14, mew=2, label="principal point")
    ax0.legend(loc="lower right", fontsize=8)
    cells, corners = coverage(calib)
    title = (
        f"board coverage: {len(calib.image_points)} views, {cells}/{COVERAGE_GRID[0] * COVERAGE_GRID[1]} image "
        f"cells covered, {corners}/4 corner cells"
    )
    hint = coverage_hint(calib)
    ax0.set_title(title + "".join(f"\n{line}" for line in textwrap.wrap(hint, 75)), fontsize=9)
    ax0.set_xlabel("x (px)")
    ax0.set_ylabel("y (px)")

    errors = np.asarray(calib.view_errors)
    order = np.arange(len(errors))
    colours = np.where(outliers(calib), "tab:red", "tab:blue")
    ax1.bar(order, errors, color=colours)
    ax1.axhline(calib.rms, color="k", ls="--", label=f"overall RMS {calib.rms:.3f} px")
    threshold = outlier_px(calib)
    ax1.axhline(threshold, color="tab:red", ls=":", label=f"outliers (red) above {OUTLIER_RULE} = {threshold:.2f} px")
    ax1.set_xticks(order)
    ax1.set_xticklabels(calib.view_names, rotation=60, ha="right", fontsize=7)
    ax1.set_ylabel("RMS reprojection error (px)")
    d = calib.dist
    ax1.set_title(
        f"fx {K[0, 0]:.2f}  fy {K[1, 1]:.2f}  cx {K[0, 2]:.2f}  cy {K[1, 2]:.2f}\n"
        f"k1 {d[0]:.3f}  k2 {d[1]:.3f}  p1 {d[2]:.4f}  p2 {d[3]:.4f}" + (f"  k3 {d[4]:.3f}" if len(d) > 4 else ""),
        fontsize=10,
    )
    ax1.legend(fontsize=8)
    return _save(plt, fig, path)


def plot_registration(
    names: Sequence[str],
    errors: Sequence[float],
    kept: Sequence[bool],
    centers: np.ndarray,
    path: str | os.PathLike,
    title: str = "",
) -> Path:
    """Per-frame reprojection errors (dropped frames in red) and the registered camera
    centres projected on their two main axes (world units).

    Args:
        names: frame names.
        errors: per-frame RMS reprojection error (px; NaN where no pose was found).
        kept: whether each frame was registered.
        centers: float (K, 3) centres of the kept frames, world units.
        path: output PNG.
    """
    plt, fig, (ax0, ax1) = _figure(2, height=4.5)
    errors = np.asarray(errors, float)
    kept = np.asarray(kept, bool)
    x = np.arange(len(errors))
    shown = np.nan_to_num(errors, nan=0.0)
    ax0.bar(x[kept], shown[kept], color="tab:blue", label="registered")
    if (~kept).any():
        ax0.bar(x[~kept], shown[~kept], color="tab:red")
        ax0.plot(x[~kept], np.zeros((~kept).sum()), "rx", ms=8, mew=2, label="dropped (bar: error of the pose tried)")
    ax0.set_xlabel("frame")
    ax0.set_ylabel("RMS reprojection error (px)")
    ax0.set_title(title or f"{kept.sum()} of {len(kept)} frames registered")
    if len(names) <= 40:
        ax0.set_xticks(x)
        ax0.set_xticklabels(names, rotation=60, ha="right", fontsize=7)
    ax0.legend(fontsize=8)
    centers = np.asarray(centers, float).reshape(-1, 3)
    if len(centers):
        # Seen along the direction in which the centres spread least (a ring looks like a ring).
        mean = centers.mean(axis=0)
        axes = np.linalg.svd(centers - mean)[2] if len(centers) > 2 else np.eye(3)
        uv = (centers - mean) @ axes[:2].T
        origin = (-mean) @ axes[:2].T
        ax1.plot(uv[:, 0], uv[:, 1], "o", ms=4, label="camera centres (labels: frames, as on the left)")
        if len(names) <= 40:  # as the left panel names its frames
            for k, (u, v) in zip(np.flatnonzero(kept), uv):
                ax1.annotate(names[k], (u, v), fontsize=7, xytext=(3, 3), textcoords="offset points")
        ax1.plot(*origin, "k+", ms=12, label="world origin")
        ax1.set_aspect("equal", adjustable="datalim")
        ax1.legend(fontsize=8)
    ax1.set_title("camera centres on their two main axes")
    ax1.set_xlabel("first axis")
    ax1.set_ylabel("second axis")
    return _save(plt, fig, path)
