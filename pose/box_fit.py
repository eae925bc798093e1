"""The object's box from its sparse 3D points (open3d), step 3 of ``alcn pose build``.

:func:`fit_box` runs, in order: statistical outlier removal (:func:`remove_outliers`), RANSAC
removal of the support plane when it extends beyond the object (:func:`remove_support_plane`),
DBSCAN keeping the largest cluster (:func:`largest_cluster`), then the box's frame: the minimal
oriented bounding box, or, with a known box (a cuboid ``.ply``), the frame of its best-seen face
(:func:`face_frame`) with the true size matched to the fitted edges (:func:`match_known_size`)
and placed flush with that face, away from the cameras (:func:`place_known_box`). Why each step is
there, with the measurements: ``docs/journal.md``.
"""

from __future__ import annotations

import contextlib
import itertools
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from alcn_cv.errors import DatasetError
from pose.model import box_corners

logger = logging.getLogger(__name__)


#: The settings of :func:`fit_box`. RANSAC distance for the support plane, as a share of the cloud's extent.
PLANE_THRESHOLD = 0.005
#: Percentile of the object's points left outside the box on each side of each axis.
TRIM = 2.0
#: open3d's random seed (RANSAC), so that a fit is the same every time.
SEED = 0
#: open3d's statistical outlier removal: neighbours and standard-deviation ratio.
OUTLIER_NEIGHBORS = 20
OUTLIER_STD_RATIO = 2.0
#: RANSAC iterations for the support plane.
PLANE_ITERATIONS = 500
#: DBSCAN's ``min_points`` (also the ``k`` of its radius, see :func:`largest_cluster`).
CLUSTER_MIN_POINTS = 4


@dataclass
class BoxFit:
    """An oriented box around the object's points.

    Attributes:
        corners: (8, 3) world-frame corners, in the order of :func:`pose.model.box_corners` in the
            box frame ``x_world = R @ x_box + origin``.
        size: (3,) edge lengths along the box frame's axes (world units).
        R, origin: box frame (columns of R are its axes; origin = corner 0).
        keep: bool mask of the points kept as the object.
        stats: fit statistics (counts, fitted size, known size, error).
    """

    corners: np.ndarray
    size: np.ndarray
    R: np.ndarray
    origin: np.ndarray
    keep: np.ndarray
    stats: dict[str, Any]


def fit_box(
    points: np.ndarray,
    known_size: np.ndarray | None = None,
    *,
    scale_free: bool = False,
    viewpoints: np.ndarray | None = None,
) -> BoxFit:
    """Fit the object's box to a sparse point cloud with open3d.

    Args:
        points: ``(N, 3)`` world points.
        known_size: the true edge lengths (any order) or ``None``. With it the object is a cuboid
            whose frame comes from its best-seen face (:func:`face_frame`), the lengths are matched
            to the fitted edges by :func:`match_known_size` and replace them; without it the box is
            open3d's minimal oriented bounding box.
        scale_free: the points have an unknown scale (incremental reconstruction): the known
            size fixes it; ``stats["scale"]`` is the factor that brings the points to its units.
        viewpoints: ``(M, 3)`` centres of the cameras that saw the points (same frame and units
            as ``points``). When the face's normal is shorter than its known length only the
            faces turned to the cameras carry points (e.g. a box seen from above: only its lid):
            the box is flush with the face and extends away from the cameras. Without viewpoints
            it extends toward the points off the face.

    The fit's settings are this module's constants (:data:`PLANE_THRESHOLD` ...).

    Raises:
        DatasetError: too few points, or a degenerate box (a flat or empty cluster).
    """
    pts = np.asarray(points, np.float64)
    if len(pts) < 10:
        raise DatasetError(f"only {len(pts)} 3D points; the box fit needs at least 10")
    with _one_open3d_thread():
        return _fit_box(pts, known_size, scale_free, viewpoints)


@contextlib.contextmanager
def _one_open3d_thread() -> Iterator[None]:
    """open3d limited to one thread: its RANSAC draws its samples from one seeded generator, in
    the order the threads run (with two threads the cookie-box fit varied from run to run)."""
    import open3d as o3d

    before = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(1)
    try:
        yield
    finally:
        o3d.utility.set_max_threads(before)


def _fit_box(
    pts: np.ndarray,
    known_size: np.ndarray | None,
    scale_free: bool,
    viewpoints: np.ndarray | None,
) -> BoxFit:
    import open3d as o3d

    o3d.utility.random.seed(SEED)
    idx = remove_outliers(pts)
    stats: dict[str, Any] = {"points": len(pts), "after_outlier_removal": len(idx)}
    cur = pts[idx]
    extent = float(np.linalg.norm(np.percentile(cur, 95, 0) - np.percentile(cur, 5, 0)))
    plane_thr = PLANE_THRESHOLD * extent
    rest, support = remove_support_plane(cur, plane_thr)
    if support is not None:
        stats["support_plane_points"] = len(cur) - len(rest)
        idx, cur = idx[rest], cur[rest]
    on_object = largest_cluster(cur, CLUSTER_MIN_POINTS)
    idx, cur = idx[on_object], cur[on_object]
    stats["object_points"] = len(idx)
    check_solid(cur)
    if known_size is None:
        R, center = minimal_box_frame(cur)
        on_face = np.ones(len(cur), bool)
    else:  # a cuboid: its best-seen face gives the frame (see face_frame)
        R, center, on_face = face_frame(cur, plane_thr, SEED)
    lo, hi = robust_extents((cur - center) @ R, on_face, TRIM)
    stats["fitted_size"] = (hi - lo).tolist()
    if known_size is None:
        size, center = hi - lo, center + R @ ((lo + hi) / 2)
    else:
        size, center = place_known_box(
            cur, R, center, on_face, lo, hi, known_size, scale_free, viewpoints, support, stats
        )
    origin = center - R @ (size / 2)
    corners = box_corners(size) @ R.T + origin
    keep = np.zeros(len(pts), bool)
    keep[idx] = True
    logger.info("box fit: %d of %d points on the object", len(idx), len(pts))
    # along the fit's axes (the best-seen face's edges, then its normal): the model's box may be in another order
    logger.debug("box fit: size %s along its face's edges and normal", np.round(size, 4).tolist())
    return BoxFit(corners, size, R, origin, keep, stats)


def remove_outliers(points: np.ndarray) -> np.ndarray:
    """Indices of ``points`` kept by open3d's statistical outlier removal."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, kept = pcd.remove_statistical_outlier(
        nb_neighbors=min(OUTLIER_NEIGHBORS, len(points) - 1), std_ratio=OUTLIER_STD_RATIO
    )
    return np.arange(len(points))[np.asarray(kept)]


def remove_support_plane(points: np.ndarray, threshold: float) -> tuple[np.ndarray, np.ndarray | None]:
    """The largest plane of ``points``, removed only when it reaches well beyond the rest (the
    table the object stands on). Returns the indices of the points off it (all of them when it
    stays) and the plane ``(a, b, c, d)`` (``None`` when it stays)."""
    import open3d as o3d

    everything = np.arange(len(points))
    if len(points) <= 30:
        return everything, None
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    plane, inl = pcd.segment_plane(distance_threshold=threshold, ransac_n=3, num_iterations=PLANE_ITERATIONS)
    inl = np.asarray(inl, np.int64)
    rest = np.setdiff1d(everything, inl)
    if len(rest) < 10 or len(inl) <= 0.2 * len(points):
        return everything, None
    if _spread(points[inl]) <= 1.5 * _spread(points[rest]):
        return everything, None
    return rest, np.asarray(plane, np.float64)


def _spread(points: np.ndarray) -> float:
    return float(np.linalg.norm(np.percentile(points, 90, 0) - np.percentile(points, 10, 0)))


def largest_cluster(points: np.ndarray, min_points: int = 4) -> np.ndarray:
    """Bool mask of the largest DBSCAN cluster of ``points`` (all ``True`` when DBSCAN finds no cluster).

    eps from the k-distance graph (k = ``min_points``; Ester et al. 1996, Schubert et al. 2017):
    the distance within which 99% of the points have k neighbours, so a sparsely textured face
    (a white sky on the cookie box's lid) does not split the object apart.
    """
    import open3d as o3d
    from scipy.spatial import cKDTree

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    kdist = cKDTree(points).query(points, k=min(min_points + 1, len(points)))[0][:, -1]
    eps = float(max(np.percentile(kdist, 99), 1e-9))
    labels = np.asarray(pcd.cluster_dbscan(eps=eps, min_points=min_points))
    if labels.max() < 0:
        return np.ones(len(points), bool)
    return labels == np.bincount(labels[labels >= 0]).argmax()


def check_solid(points: np.ndarray) -> None:
    """Raise :class:`DatasetError` when the object's points are too few, flat or collinear."""
    if len(points) < 8:
        raise DatasetError(f"degenerate box fit: the object cluster has only {len(points)} points")
    sv = np.linalg.svd(points - points.mean(0), compute_uv=False)
    if sv[2] <= 1e-3 * sv[0]:
        raise DatasetError(
            f"degenerate box fit: the object's {len(points)} points are flat or collinear "
            f"(singular values {np.round(sv, 6).tolist()})"
        )


def minimal_box_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation ``(3, 3)`` (right-handed) and centre ``(3,)`` of open3d's minimal oriented bounding box."""
    import open3d as o3d

    try:
        obb = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points)).get_minimal_oriented_bounding_box()
    except RuntimeError as exc:  # Qhull on nearly degenerate input
        raise DatasetError(f"degenerate box fit: {str(exc).splitlines()[0]}") from exc
    R, center = np.asarray(obb.R).copy(), np.asarray(obb.center).copy()
    if np.linalg.det(R) < 0:
        R[:, 2] *= -1
    return R, center


def robust_extents(coords: np.ndarray, on_face: np.ndarray, trim: float) -> tuple[np.ndarray, np.ndarray]:
    """Low and high ends ``(3,)`` of the box along its axes, from the points' box coordinates ``coords``.

    Percentiles, so that stray points (a hand, the background) do not inflate the box; along the
    face's edges only the face's points ``on_face`` count (a badly triangulated side may spill over).
    """
    lo = np.r_[np.percentile(coords[on_face, :2], trim, axis=0), np.percentile(coords[:, 2], trim)]
    hi = np.r_[np.percentile(coords[on_face, :2], 100 - trim, axis=0), np.percentile(coords[:, 2], 100 - trim)]
    ext = hi - lo
    if ext.min() <= 1e-6 * max(ext.max(), 1e-12):
        raise DatasetError(f"degenerate box fit: the object's points span a flat box {ext}")
    return lo, hi


def place_known_box(
    points: np.ndarray,
    R: np.ndarray,
    center: np.ndarray,
    on_face: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    known_size: np.ndarray,
    scale_free: bool,
    viewpoints: np.ndarray | None,
    support: np.ndarray | None,
    stats: dict[str, Any],
) -> tuple[np.ndarray, np.ndarray]:
    """The known box in the fitted frame ``R``: its edge lengths ``(3,)`` (matched to the fitted
    extents ``hi - lo``) and its centre ``(3,)`` (scaled by ``stats["scale"]`` when ``scale_free``).

    Adds the fit's error against the known size to ``stats``.
    """
    coords = (points - center) @ R
    ext = hi - lo
    matched, s = match_known_size(ext, known_size, scale_free)
    if scale_free:
        stats["scale"] = s
        ext, center, lo, hi, coords = ext * s, center * s, lo * s, hi * s, coords * s
    mid = (lo + hi) / 2
    # The face is one of the box's faces: the box is flush with it and extends away from the
    # cameras (into the part nobody saw when only the faces turned to them carry points, e.g. a box
    # seen from above: its lid); without viewpoints, toward the other points. Centring the box on the
    # points' extent along the normal instead, when that extent reached the true height, let the
    # hand above the cookie box's lid lift the box by 1.1 cm (its bottom edge 20-30 px above the
    # object's in `alcn pose overlay-error`).
    if viewpoints is not None and len(viewpoints):
        toward = float(np.median((np.asarray(viewpoints, np.float64).reshape(-1, 3) * s - center) @ R[:, 2]))
    else:
        toward = -float(np.median(coords[~on_face, 2])) if np.any(~on_face) else 1.0
    mid[2] = -np.sign(toward or 1.0) * matched[2] / 2
    center = center + R @ mid
    stats.update(size_errors(ext, matched))
    if support is not None and not scale_free:
        # the box stands on the support plane: move it along the plane's normal to touch it
        n, d = support[:3] / np.linalg.norm(support[:3]), support[3] / np.linalg.norm(support[:3])
        if np.dot(n, center) + d < 0:
            n, d = -n, -d
        half = 0.5 * np.abs(R.T @ n) @ matched  # half-extent of the box along n
        center = center + (half - (np.dot(n, center) + d)) * n
    return matched, center


def size_errors(fitted: np.ndarray, known: np.ndarray, normal: int = 2) -> dict[str, Any]:
    """The error of a box fit's extents ``fitted`` ``(3,)`` against the known lengths ``known`` along the same axes,
    as :attr:`BoxFit.stats`: ``known_size``, ``size_error`` (``fitted - known``), ``relative_size_error``,
    ``mean_abs_relative_size_error`` (over the three), and ``seen_relative_size_error``, the error on what the points
    cover: the face's two edges, measured in full, and the face's normal (axis ``normal``) only where it is longer
    than true, by as much as it is (it may be seen in part: a box seen from above has points on its lid only)."""
    fitted, known = np.asarray(fitted, np.float64), np.asarray(known, np.float64)
    rel = (fitted - known) / known
    seen = [max(float(r), 0.0) if axis == normal else abs(float(r)) for axis, r in enumerate(rel)]
    return {
        "known_size": known.tolist(),
        "size_error": (fitted - known).tolist(),
        "relative_size_error": rel.tolist(),
        "mean_abs_relative_size_error": float(np.abs(rel).mean()),
        "seen_relative_size_error": float(np.mean(seen)),
    }


def face_frame(points: np.ndarray, threshold: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The frame of a cuboid from its best-seen face.

    The largest plane among ``points`` ``(N, 3)`` (RANSAC from ``threshold``, see the code) is
    one of the box's faces: its normal is the frame's third axis, and the two others are the
    edges of the face's points' minimal-area rectangle (``cv2.minAreaRect``; the points are those
    left by the outlier removal and clustering of :func:`fit_box`). Unlike the minimal oriented
    bounding box of all points, this stays aligned with the box when the other faces are few,
    partial or badly triangulated (a box seen from above).

    Returns:
        ``R`` (3, 3) (columns: face edge, face edge, face normal; ``det(R) = 1``), ``center``
        (3,) a point of the face plane, and the bool mask ``(N,)`` of the face's points.
    """
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    o3d.utility.random.seed(seed)
    _, inl = pcd.segment_plane(distance_threshold=threshold, ransac_n=3, num_iterations=1000)
    on_face = np.zeros(len(points), bool)
    on_face[np.asarray(inl, np.int64)] = True
    # The face's thickness (the triangulation noise) is unknown: the face is the points within 2.5
    # robust standard deviations (1.4826 x the median absolute distance) of the least-squares plane of
    # the face's points, iterated from RANSAC's inliers (a truncated spread grows towards the true one).
    # Doubling RANSAC's threshold while it gained inliers instead grew the face of the cookie box's
    # noisy lid (spread 0.3 cm) into the sides and tilted its normal by 13 degrees, which drew the box
    # up to 30 px off the object's edges (`alcn pose overlay-error`).
    for _ in range(10):
        face = points[on_face]
        mean = face.mean(0)
        n = np.linalg.svd(face - mean, full_matrices=False)[2][2]
        dist = (points - mean) @ n
        spread = 1.4826 * float(np.median(np.abs(dist[on_face])))
        grown = np.abs(dist) <= max(2.5 * spread, threshold)
        if grown.sum() < 3 or np.array_equal(grown, on_face):
            break
        on_face = grown
    u = np.cross(n, np.eye(3)[np.argmin(np.abs(n))])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    face = points[on_face]
    center = face.mean(0)
    q = (face - center) @ np.stack([u, v], 1)
    a = np.radians(cv2.minAreaRect(q.astype(np.float32))[2])
    e1 = np.cos(a) * u + np.sin(a) * v
    e2 = np.cross(n, e1)
    return np.stack([e1, e2, n], 1), center, on_face


def match_known_size(fitted: np.ndarray, known_size: np.ndarray, scale_free: bool = False) -> tuple[np.ndarray, float]:
    """Match a cuboid's known edge lengths (any order) to the fitted extents of :func:`face_frame`'s
    axes (face edge, face edge, face normal); returns the matched lengths ``(3,)`` and the scale
    that brings the fitted extents to the known units (1 unless ``scale_free``).

    The face's two edges are measured fully; the normal may be seen only in part (shorter than
    true, never longer). The assignment (of the 6) minimises the face edges' log-ratio error
    (with ``scale_free``: the disagreement of their two scales, the face's aspect ratio) plus
    the amount by which the normal exceeds its assigned length. Sorting all three by length
    instead would give the true height to the seen part of it, which may be any length.
    """
    fitted = np.asarray(fitted, np.float64)
    known = np.asarray(known_size, np.float64).ravel()
    best, best_cost, best_s = known, np.inf, 1.0
    for perm in itertools.permutations(range(3)):
        k = known[list(perm)]
        r = np.log(fitted / k)
        s_log = -(r[0] + r[1]) / 2 if scale_free else 0.0
        cost = abs(r[0] - r[1]) if scale_free else abs(r[0]) + abs(r[1])
        cost += max(0.0, r[2] + s_log)
        if cost < best_cost - 1e-12:
            best, best_cost, best_s = k, cost, float(np.exp(s_log))
    return best, best_s
