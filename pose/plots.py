"""Figures of the pose pipeline: the part model with its training cameras, the Table-1 bar chart."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from alcn_cv.report import new_figure, save_figure
from pose.model import BOX_EDGES, PartModel


def plot_model(model: PartModel, camera_centers: np.ndarray, path: str | Path) -> Path:
    """A PNG of the points, the box and the training cameras' centres (object frame)."""
    plt, fig, axes = new_figure(figsize=(7, 6), subplot_kw={"projection": "3d"})
    ax = axes[0, 0]
    p = model.points3d
    ax.scatter(p[:, 0], p[:, 1], p[:, 2], s=1, c=model.colors / 255.0)
    for i, j in BOX_EDGES:
        ax.plot(*np.stack([model.corners[i], model.corners[j]]).T, color="tab:blue")
    c = np.asarray(camera_centers).reshape(-1, 3)
    if len(c):
        ax.scatter(c[:, 0], c[:, 1], c[:, 2], marker="^", color="tab:red", label="training cameras")
        ax.legend(loc="upper right")
    allp = np.vstack([p, model.corners, c])
    mid, r = (allp.max(0) + allp.min(0)) / 2, (allp.max(0) - allp.min(0)).max() / 2
    ax.set(
        xlim=(mid[0] - r, mid[0] + r),
        ylim=(mid[1] - r, mid[1] + r),
        zlim=(mid[2] - r, mid[2] + r),
        xlabel=f"x ({model.units})",
        ylabel="y",
        zlabel="z",
        title=f"{len(p)} points, box {np.round(model.box_size, 2).tolist()} {model.units}",
    )
    return save_figure(plt, fig, path, dpi=110)


def plot_table(
    table: dict[str, dict[str, float]],
    columns: list[str],
    path: str | Path,
    title: str,
    spread: dict[str, dict[str, float]] | None = None,
) -> Path:
    """Bar chart of a Table-1-style report: one group of bars per column (sequence), one bar per
    row, with error bars where ``spread`` has the row."""
    plt, fig, axes = new_figure(figsize=(8, 4))
    ax = axes[0, 0]
    x = np.arange(len(columns))
    w = 0.8 / max(len(table), 1)
    for k, (row, vals) in enumerate(table.items()):
        err = [(spread or {}).get(row, {}).get(c, np.nan) for c in columns]
        ax.bar(
            x + (k - (len(table) - 1) / 2) * w,
            [vals.get(c, np.nan) for c in columns],
            w,
            label=row,
            yerr=None if np.isnan(err).all() else err,
            capsize=2,
        )
    ax.set(xticks=x, xticklabels=columns, ylabel="% correct poses", ylim=(0, 105), title=title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    return save_figure(plt, fig, path, dpi=110)
