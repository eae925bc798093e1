"""The geometry of a box: its surface parts, its faces turned to a camera, which parts a camera sees.

The box is given by its 8 corners in the order of :func:`pose.model.box_corners` (bit 2 of a
corner's index is x, bit 1 y, bit 0 z); any parallelepiped in that order works, and so does a
flat one (a planar target: one edge of length 0, both its faces in one plane, seen from either
side). Used by the learned part detector at run time (:meth:`pose.corners.CornerDetector.support`)
and by its training data (:mod:`pose.corner_data`).
"""

from __future__ import annotations

import cv2
import numpy as np

from alcn_cv.errors import InputError

__all__ = [
    "BOX_FACES",
    "DIVISIONS",
    "NUM_CORNERS",
    "box_axes",
    "box_coordinates",
    "box_diameter",
    "box_parts",
    "box_size",
    "edge_directions",
    "facing_faces",
    "flat_axes",
    "part_visibility",
    "parts_per_face",
    "project_points",
]

NUM_CORNERS = 8
#: Steps per box edge of the detector's parts (:func:`box_parts`: 2 is the corners, the edges'
#: middles and the faces' centres).
DIVISIONS = 2
#: :func:`part_visibility` with a mask: a part farther than this many pixels from the mask is hidden by something else.
MASK_TOLERANCE = 3


def box_parts(corners: np.ndarray, divisions: int = DIVISIONS) -> np.ndarray:
    """The parts of the box the learned detector finds: the points of its surface at
    ``divisions`` equal steps along every edge, the 8 corners first (in their order), then the
    rest in lattice order.

    ``divisions=1`` gives the 8 corners; ``2`` (the default) adds the middles of the 12 edges and
    the centres of the 6 faces (26 parts): a face centre's window shows the box's own texture
    more than a corner's, which is three quarters background (see :mod:`pose.corner_train`).

    Args:
        corners: ``(8, 3)`` box corners (:func:`pose.model.box_corners` order: bit 2 of a
            corner's index is x, bit 1 y, bit 0 z); any parallelepiped in that order.
        divisions: steps per edge, at least 1.

    Returns:
        ``(n, 3)`` float64, ``n = (d + 1)^3 - (d - 1)^3``.
    """
    if divisions < 1:
        raise InputError(f"divisions must be >= 1, got {divisions}")
    corners = np.asarray(corners, np.float64).reshape(NUM_CORNERS, 3)
    steps = np.stack(np.meshgrid(*[np.arange(divisions + 1)] * 3, indexing="ij"), -1).reshape(-1, 3)
    on_face = (steps == 0) | (steps == divisions)  # per axis: on one of its two faces
    surface = steps[on_face.any(1)]
    corner_first = np.argsort(~on_face[on_face.any(1)].all(1), kind="stable")
    abc = surface[corner_first] / divisions
    return corners[0] + abc @ _edge_vectors(corners).T


def edge_directions(corners: np.ndarray, parts: np.ndarray) -> np.ndarray:
    """``(n, 3)`` float64: for each of ``parts`` (``(n, 3)``, on the surface of the box ``corners``)
    inside one of the box's edges (a middle of :func:`box_parts`), that edge's unit direction;
    zeros for the corners and the points inside a face.

    A detector finds a corner or a face's centre equally well in every direction, but the middle
    of an edge only across the edge: along it the image shows the same straight contour
    (:class:`pose.solver.PoseSolver` weighs its reprojection error accordingly).
    """
    corners = np.asarray(corners, np.float64).reshape(NUM_CORNERS, 3)
    on_low, on_high = _on_faces(corners, np.asarray(parts, np.float64).reshape(-1, 3))
    on = on_low | on_high  # inside an edge: on the faces of two axes, free along the third
    edges = _edge_vectors(corners)  # the free axis is never a flat box's edge of length 0: always "on"
    unit = edges / np.maximum(np.linalg.norm(edges, axis=0), 1e-300)
    return np.where((on.sum(1) == 2)[:, None], unit.T[np.argmin(on, 1)], 0.0)


def box_axes(corners: np.ndarray) -> np.ndarray:
    """``(3, 3)``: the box's x, y and z edges as columns. The edge of length 0 of a flat box is
    replaced by its plane's normal a millionth of the box's size long, so that box coordinates
    (:func:`box_coordinates`) exist; :func:`flat_axes` tells which."""
    axes = _edge_vectors(corners)
    flat = flat_axes(corners)
    if flat.sum() == 1:
        k = int(np.flatnonzero(flat)[0])
        normal = np.cross(axes[:, (k + 1) % 3], axes[:, (k + 2) % 3])
        axes[:, k] = normal / np.linalg.norm(normal) * 1e-6 * np.linalg.norm(axes, axis=0).max()
    return axes


def flat_axes(corners: np.ndarray) -> np.ndarray:
    """``(3,)`` bool: which of the box's x, y and z edges have length 0."""
    lengths = box_size(corners)
    return lengths <= 1e-9 * max(lengths.max(), 1e-300)


def box_size(corners: np.ndarray) -> np.ndarray:
    """Edge lengths ``(3,)`` float64 of the box ``corners`` ``(8, 3)``: the distances from corner 0 to corners 4, 2
    and 1 (its x, y and z edges)."""
    return np.linalg.norm(_edge_vectors(np.asarray(corners, np.float64)), axis=0)


def box_diameter(corners: np.ndarray) -> float:
    """The largest distance between two of the box's ``corners`` ``(8, 3)``: its diagonal."""
    corners = np.asarray(corners, np.float64)
    d = corners[:, None] - corners[None]
    return float(np.sqrt((d**2).sum(-1)).max())


def _edge_vectors(corners: np.ndarray) -> np.ndarray:
    """``(3, 3)``: the box's x, y and z edges as columns, as they are."""
    return np.stack([corners[4] - corners[0], corners[2] - corners[0], corners[1] - corners[0]], 1)


def project_points(
    points: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray, *, min_depth: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projections (no lens distortion) of points under one pose or a batch of ``b`` poses: the batched
    counterpart of :func:`pose.solver.project` (``cv2.projectPoints``), for poses given as ``R, t``.

    Args:
        points: ``(n, 3)`` object points.
        R, t: object-to-camera pose (``x_cam = R x + t``): ``(3, 3)`` and ``(3,)``, or a batch ``(b, 3, 3)`` and
            ``(b, 3)``.
        K: ``(3, 3)`` intrinsics.
        min_depth: divide by the depth clipped below at this (finite pixels for points at or behind the camera);
            ``None``: by the depth as it is (a point behind the camera projects as in homogeneous coordinates).

    Returns:
        ``uv (n, 2)`` float64 pixels and ``depth (n,)`` float64 (the camera frame's z), or ``(b, n, 2)`` and
        ``(b, n)`` for a batch.
    """
    points = np.asarray(points, np.float64).reshape(-1, 3)
    R, t = np.asarray(R, np.float64), np.asarray(t, np.float64)
    batch = R.shape[:-2]
    R, t = R.reshape(*batch, 3, 3), t.reshape(*batch, 3)
    cam = np.einsum("...ij,nj->...ni", R, points) + t[..., None, :]
    depth = cam[..., 2]
    z = depth if min_depth is None else np.maximum(depth, min_depth)
    uv = np.stack([K[0, 0] * cam[..., 0] / z + K[0, 2], K[1, 1] * cam[..., 1] / z + K[1, 2]], -1)
    return uv, depth


def part_visibility(
    corners: np.ndarray,
    R: np.ndarray,
    t: np.ndarray,
    K: np.ndarray,
    shape: tuple[int, int],
    mask: np.ndarray | None = None,
    parts: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Projections of points on the box's surface and which of them are visible, for one pose
    or a batch of ``b`` poses.

    Args:
        corners: ``(8, 3)`` box corners (:func:`box_parts`' order).
        R, t: object-to-camera pose (``x_cam = R x + t``): ``(3, 3)`` and ``(3,)``, or a batch
            ``(b, 3, 3)`` and ``(b, 3)``.
        K: ``(3, 3)`` intrinsics.
        shape: ``(H, W)`` of the image.
        mask: optional ``(H, W)`` visible-object mask (BOP ``mask_visib``); a point farther
            than :data:`MASK_TOLERANCE` pixels from it is hidden by something else.
        parts: ``(n, 3)`` points on the box's surface (:func:`box_parts`); default the corners.

    Returns:
        ``uv (n, 2)`` float64 pixels and ``visible (n,)`` bool (``(b, n, 2)`` and ``(b, n)`` for a
        batch): in front of the camera, inside the image, on at least one face turned towards the
        camera, and on the mask.
    """
    corners = np.asarray(corners, np.float64).reshape(NUM_CORNERS, 3)
    parts = corners if parts is None else np.asarray(parts, np.float64).reshape(-1, 3)
    R, t = np.asarray(R, np.float64), np.asarray(t, np.float64)
    batch = R.shape[:-2]
    R, t = R.reshape(*batch, 3, 3), t.reshape(*batch, 3)
    uv, depth = project_points(parts, R, t, K, min_depth=1e-9)
    h, w = shape
    visible = (depth > 0) & (uv[..., 0] >= 0) & (uv[..., 0] <= w - 1) & (uv[..., 1] >= 0) & (uv[..., 1] <= h - 1)
    # in box coordinates (0..1 along each edge) a face is turned towards the camera when the
    # camera centre lies beyond its plane; a part is on the faces where its coordinate is 0 or 1
    # (both faces of a flat box's edge of length 0: one plane, seen from either side)
    eye = box_coordinates(corners, R, t)[..., None, :]
    on_low, on_high = _on_faces(corners, parts)
    visible &= (on_low & (eye < 0) | on_high & (eye > 1)).any(-1)
    if mask is not None:
        near = cv2.dilate((mask > 0).astype(np.uint8), np.ones((2 * MASK_TOLERANCE + 1,) * 2, np.uint8))
        ij = np.clip(np.round(uv).astype(int), 0, [w - 1, h - 1])
        visible &= near[ij[..., 1], ij[..., 0]] > 0
    return uv, visible


def parts_per_face(corners: np.ndarray, parts: np.ndarray) -> int:
    """How many of ``parts`` (``(n, 3)``, on the surface of the box ``corners``) lie on its
    fullest face: ``(d + 1)^2`` for :func:`box_parts` with ``d`` divisions."""
    on_low, on_high = _on_faces(
        np.asarray(corners, np.float64).reshape(NUM_CORNERS, 3), np.asarray(parts, np.float64).reshape(-1, 3)
    )
    return int(max(on_low.sum(0).max(), on_high.sum(0).max()))


def _on_faces(corners: np.ndarray, parts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(n, 3)`` bool twice: whether each part lies on the box's face at coordinate 0, and at
    coordinate 1, of each axis (both for the edge of length 0 of a flat box)."""
    abc = np.linalg.solve(box_axes(corners), (parts - corners[0]).T).T
    tol = 1e-6
    return np.abs(abc) < tol, (np.abs(abc - 1) < tol) | flat_axes(corners)


#: The 6 faces of a box as its corners in turn around each (:func:`pose.model.box_corners` order:
#: bit 2 of a corner's index is x, bit 1 y, bit 0 z), with the axis and side of each face.
BOX_FACES = tuple(
    (axis, side, tuple(np.array(quad) + (side << (2 - axis))))
    for axis, quad in ((0, (0, 1, 3, 2)), (1, (0, 1, 5, 4)), (2, (0, 2, 6, 4)))
    for side in (0, 1)
)


def box_coordinates(corners: np.ndarray, R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The camera centre in box coordinates (0..1 inside the box along each of its edges):
    ``(3,)`` for a pose ``R (3, 3), t (3,)``, ``(b, 3)`` for a batch ``(b, 3, 3), (b, 3)``."""
    R, t = np.asarray(R, np.float64), np.asarray(t, np.float64)
    eye = -np.einsum("...ji,...j->...i", R, t.reshape(*R.shape[:-2], 3))  # -R^T t
    return (eye - corners[0]) @ np.linalg.inv(box_axes(corners)).T


def facing_faces(corners: np.ndarray, R: np.ndarray, t: np.ndarray) -> list[tuple[int, ...]]:
    """The faces of :data:`BOX_FACES` (their corner quads) turned towards the camera of pose ``R, t``."""
    a = box_coordinates(corners, R, t)
    return [quad for axis, side, quad in BOX_FACES if (a[axis] > 1 if side else a[axis] < 0)]
