"""The pose sequences' rasteriser (alcn_cv.data.raster)."""

from __future__ import annotations

import numpy as np

from alcn_cv.data.raster import rasterize


def test_triangles_all_culled_give_empty_buffers():
    """A mesh wholly off the buffer (or behind the camera) raised "need at least one array to concatenate"."""
    xy = np.array([[-100.0, -100.0], [-90.0, -100.0], [-100.0, -90.0], [2.0, 2.0], [6.0, 2.0], [2.0, 6.0]])
    depth = np.array([5.0, 5.0, 5.0, 0.5, 0.5, 0.5])  # the second triangle nearer than ``near``
    faces = np.array([[0, 1, 2], [3, 4, 5]])
    zbuf, tri, bary = rasterize(xy, depth, faces, 8, 8)
    assert np.isinf(zbuf).all() and (tri == -1).all() and bary.shape == (8, 8, 3) and not bary.any()
    zbuf, tri, bary = rasterize(xy, depth, faces[:1], 8, 8, with_attributes=False)
    assert zbuf.shape == (8, 8) and np.isinf(zbuf).all() and tri is None and bary is None
    zbuf, _, _ = rasterize(xy, depth, faces[1:], 8, 8, perspective=False)  # the same triangle, drawn orthographic
    assert np.isfinite(zbuf).sum() > 0
