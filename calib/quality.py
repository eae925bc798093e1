"""How a calibration is judged beyond its overall RMS, by one rule each for the log and views.json of
:mod:`calib.camera` and the figure of :mod:`calib.report`: outlier views (:func:`outliers`) and the coverage of the
image by the board's corners (:func:`coverage`, :func:`coverage_hint`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .camera import Calibration

__all__ = ["OUTLIER_RULE", "COVERAGE_GRID", "LOW_COVERAGE", "outlier_px", "outliers", "coverage", "coverage_hint"]

#: A view is an outlier when its RMS reprojection error exceeds both this many times the overall RMS and
#: :data:`OUTLIER_MIN_PX`: the rule :data:`OUTLIER_RULE`.
OUTLIER_FACTOR = 2.0
OUTLIER_MIN_PX = 1.0
OUTLIER_RULE = f"max({OUTLIER_FACTOR:g} x RMS, {OUTLIER_MIN_PX:g} px)"
#: The coverage of the image by the board is counted in the cells (columns, rows) of this grid over the image.
COVERAGE_GRID = (8, 6)
#: A coverage is low (:func:`coverage_hint`) below this share of the grid's cells, or without a corner in any of its
#: four corner cells: the distortion, which grows toward the image's corners, is then extrapolated there.
LOW_COVERAGE = 0.75


def outlier_px(calib: Calibration) -> float:
    """The per-view RMS reprojection error (px) above which a view of ``calib`` is an outlier: :data:`OUTLIER_RULE`."""
    return max(OUTLIER_FACTOR * calib.rms, OUTLIER_MIN_PX)


def outliers(calib: Calibration) -> np.ndarray:
    """bool (V,): the views of ``calib`` whose error is above :func:`outlier_px`."""
    return np.asarray(calib.view_errors) > outlier_px(calib)


def coverage(calib: Calibration) -> tuple[int, int]:
    """How the corners detected in the views of ``calib`` cover the image: the cells of the :data:`COVERAGE_GRID`
    that hold one, and how many of those are the grid's four corner cells."""
    cols, rows = COVERAGE_GRID
    w, h = calib.image_size
    points = np.vstack(calib.image_points) if calib.image_points else np.zeros((0, 2))
    cells = {(int(c), int(r)) for c, r in np.floor(points / [w / cols, h / rows]).clip(0, [cols - 1, rows - 1])}
    return len(cells), len(cells & {(0, 0), (cols - 1, 0), (0, rows - 1), (cols - 1, rows - 1)})


def coverage_hint(calib: Calibration) -> str:
    """Advice, which starts with the rule, when the views of ``calib`` cover the image poorly (:data:`LOW_COVERAGE`);
    else ``""``."""
    cells, corners = coverage(calib)
    if cells >= LOW_COVERAGE * COVERAGE_GRID[0] * COVERAGE_GRID[1] and corners:
        return ""
    return (
        f"low (under {LOW_COVERAGE:.0%} of the cells, or none in a corner): add views with the board near the "
        "image's borders and corners, or pass --fix-k3 (few or central views)"
    )
