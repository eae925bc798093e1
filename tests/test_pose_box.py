"""The box geometry of the learned part detector (:mod:`pose.box`)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.errors import InputError
from pose import box
from pose.model import box_corners
from pose.solver import camera_matrix


def test_visibility_of_a_box_seen_from_above():
    corners = box_corners([100, 60, 40], [-50, -30, -20])
    K = camera_matrix(500, 500, 319.5, 239.5)
    R = np.diag([1.0, -1.0, -1.0])  # camera on the +z side of the box, looking down -z
    t = np.array([0.0, 0.0, 600.0])
    uv, vis = box.part_visibility(corners, R, t, K, (480, 640))
    np.testing.assert_array_equal(vis, [False, True] * 4)  # the top face (z bit set) only
    assert np.allclose(uv[1], [319.5 - 500 * 50 / 580, 239.5 + 500 * 30 / 580])
    mask = np.zeros((480, 640), np.uint8)  # an occluder hides everything but corner 7
    mask[int(uv[7, 1]) - 1 : int(uv[7, 1]) + 2, int(uv[7, 0]) - 1 : int(uv[7, 0]) + 2] = 255
    _, vis = box.part_visibility(corners, R, t, K, (480, 640), mask)
    assert np.flatnonzero(vis).tolist() == [7]
    _, vis = box.part_visibility(corners, R, t + [2000, 0, 0], K, (480, 640))  # out of the image
    assert not vis.any()
    # the 26 parts: the 9 of the top face (z = 20) are seen; the side faces are edge-on, the bottom turned away
    parts = box.box_parts(corners)
    uv, vis = box.part_visibility(corners, R, t, K, (480, 640), parts=parts)
    np.testing.assert_array_equal(vis, parts[:, 2] == 20)
    np.testing.assert_allclose(uv[vis].mean(0), [319.5, 239.5], atol=1e-9)
    # the camera turned towards the -x side: that face's 9 parts show as well (15 in all)
    R2 = cv2.Rodrigues(np.array([0.0, -0.5, 0.0]))[0] @ R
    _, vis2 = box.part_visibility(corners, R2, t, K, (480, 640), parts=parts)
    np.testing.assert_array_equal(vis2, (parts[:, 2] == 20) | (parts[:, 0] == -50))
    assert vis2.sum() == 15


def test_box_parts_are_the_surface_lattice():
    corners = box_corners([100, 60, 40], [-50, -30, -20])
    np.testing.assert_array_equal(box.box_parts(corners, 1), corners)
    parts = box.box_parts(corners, 2)
    assert parts.shape == (26, 3) and len(np.unique(parts, axis=0)) == 26
    np.testing.assert_array_equal(parts[:8], corners)  # the corners keep their indices
    on_faces = (np.abs(np.abs(parts) - [50, 30, 20]) < 1e-9).sum(1)
    assert sorted(on_faces.tolist()) == [1] * 6 + [2] * 12 + [3] * 8  # face centres, edge middles, corners
    assert len(box.box_parts(corners, 3)) == 4**3 - 2**3
    with pytest.raises(InputError, match="divisions"):
        box.box_parts(corners, 0)


def test_a_flat_box_is_seen_from_either_side():
    """A planar target (:mod:`pose.planar`): a box with an edge of length 0."""
    corners = box_corners([100, 60, 0], [-50, -30, 0])
    assert box.flat_axes(corners).tolist() == [False, False, True]
    assert abs(np.linalg.det(box.box_axes(corners))) > 0
    K = camera_matrix(500, 500, 319.5, 239.5)
    parts = box.box_parts(corners)
    above = (np.diag([1.0, -1.0, -1.0]), np.array([0.0, 0.0, 600.0]))  # looking down -z
    below = (np.eye(3), np.array([0.0, 0.0, 600.0]))  # looking up +z
    for R, t in (above, below):
        _, vis = box.part_visibility(corners, R, t, K, (480, 640), parts=parts)
        assert vis.all()
    # the box_parts lattice of a flat box: 26 points (9 distinct) of its one plane, all on both its faces
    assert box.parts_per_face(corners, parts) == len(parts)


def test_visibility_of_a_batch_of_poses_is_that_of_each():
    corners = box_corners([100, 60, 40], [-50, -30, -20])
    parts = box.box_parts(corners)
    K = camera_matrix(500, 500, 319.5, 239.5)
    rng = np.random.default_rng(3)
    R = np.stack([cv2.Rodrigues(rng.normal(0, 1.5, 3))[0] for _ in range(40)])
    t = np.column_stack([rng.normal(0, 150, (40, 2)), rng.uniform(-100, 900, 40)])  # some behind the camera
    mask = np.zeros((480, 640), np.uint8)
    mask[100:300, 200:500] = 255
    uv, vis = box.part_visibility(corners, R, t, K, (480, 640), mask, parts=parts)
    assert uv.shape == (40, 26, 2) and vis.shape == (40, 26) and 0 < vis.sum() < vis.size
    for b in range(40):
        uv1, vis1 = box.part_visibility(corners, R[b], t[b], K, (480, 640), mask, parts=parts)
        np.testing.assert_array_equal(vis[b], vis1)
        np.testing.assert_allclose(uv[b], uv1)
    np.testing.assert_allclose(box.box_coordinates(corners, R, t)[7], box.box_coordinates(corners, R[7], t[7]))


def test_parts_per_face():
    corners = box_corners([100, 60, 40], [-50, -30, -20])
    assert box.parts_per_face(corners, corners) == 4
    assert box.parts_per_face(corners, box.box_parts(corners)) == 9
    assert box.parts_per_face(corners, box.box_parts(corners, 3)) == 16


@pytest.mark.parametrize("size", [[100, 60, 40], [100, 60, 0]])
def test_edge_directions_are_those_of_the_edges_the_middles_lie_on(size):
    corners = box_corners(size, [-50, -30, -20])
    parts = box.box_parts(corners, 3)
    d = box.edge_directions(corners, parts)
    assert d.shape == parts.shape
    np.testing.assert_array_equal(d[:8], 0)  # the corners
    on_edge = np.linalg.norm(d, axis=1) > 0
    np.testing.assert_allclose(np.linalg.norm(d[on_edge], axis=1), 1)
    for k in np.flatnonzero(on_edge):  # the part lies between the two corners of the edge along d
        ends = corners[np.abs(np.cross(corners - parts[k], d[k])).max(1) < 1e-9]
        assert len(ends) >= 2 and np.ptp((ends - parts[k]) @ d[k]) > 0
    # 2 points inside each of the 12 edges (of the 4 edges of a flat box's plane), none inside a face
    assert len(np.unique(parts[on_edge], axis=0)) == (24 if size[2] else 8)
