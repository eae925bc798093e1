"""Synthetic points on a box, for the tests of :mod:`pose.build`'s box fit."""

from __future__ import annotations

import numpy as np


def box_faces(rng: np.random.Generator, size, n: int) -> np.ndarray:
    """``(n, 3)`` points on the 5 visible faces of the axis-aligned box ``[0, size]`` (its bottom unseen)."""
    size = np.asarray(size, np.float64)
    face = rng.integers(0, 5, n)
    p = rng.uniform(0, 1, (n, 3)) * size
    p[face == 0, 2] = size[2]
    p[face == 1, 0] = 0
    p[face == 2, 0] = size[0]
    p[face == 3, 1] = 0
    p[face == 4, 1] = size[1]
    return p
