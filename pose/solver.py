"""The pose solver: 2D-3D part correspondences -> object pose, robust to wrong matches.

``cv2.solvePnPRansac`` gives a first pose and its inliers; ``cv2.solvePnPRefineLM`` then
minimises the reprojection error of the inliers (Levenberg-Marquardt). With a video, the pose
predicted from the previous frames (:class:`PoseTracker`) is a prior: the correspondences that
agree with it are refined directly, and the full RANSAC runs only when too few do. A frame with
too few inliers is reported *lost* (no pose) rather than given a wrong one; :class:`PoseTracker`
logs when tracking is lost and recovered.
Refining from the prior alone kept wrong local minima after large motions, hence the competition
with RANSAC (measurements: ``docs/journal.md``).

Parts on one face of a box seen from afar fit two poses almost equally well (the two minima of
a plane under weak perspective): every refinement therefore also starts from the two IPPE poses
of its inliers' best-fitting plane and keeps the lowest MSAC cost, or with a prior, among the
poses whose costs are nearly equal, the one closest to the prior. A pose whose inliers cover
only a small part of the object's outline is rejected.

Correspondences that come with directions (the learned detector's edge middles, found well
across their edge and poorly along it) get a last Gauss-Newton refinement of the accepted pose in
which the error along each direction counts :attr:`PoseSolver.along_sigma` times less
(:data:`ALONG_SIGMA`): the pose the detector's uncertainty makes most likely.

Default RANSAC setting: ``method="usac_default"``, 4 px threshold. Where the matches are few and noisy,
USAC's default posed more frames than the classical RANSAC loops, and on the data engine's sequences #1 and #6
it gave as many correct poses as MAGSAC++ and USAC-accurate, 4 px slightly more than 6 px (``docs/journal.md``;
the few, noisy matches were those of the cookie-box video with the model of OpenCV's real-time pose tutorial, which
this repository neither ships nor loads, so that this measurement cannot be rerun here). Where the matches are many
and clean, the methods are not told apart: on the model ``examples/track_cookie_box.py`` builds (about 2000
inliers per frame), every method poses each of the first 40 frames of the video with practically the same inliers
and error. ``examples/pnp_methods.py`` measures the methods on any model and video.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import cv2
import numpy as np

from alcn_cv.errors import InputError

if TYPE_CHECKING:
    from pose.parts import Correspondences, PartDetector

logger = logging.getLogger(__name__)

#: RANSAC variants understood by :class:`PoseSolver` -> ``solvePnPRansac`` flags.
METHODS: dict[str, int] = {
    "ransac_epnp": cv2.SOLVEPNP_EPNP,
    "ransac_sqpnp": cv2.SOLVEPNP_SQPNP,
    "ransac_ap3p": cv2.SOLVEPNP_AP3P,
    "ransac_iterative": cv2.SOLVEPNP_ITERATIVE,
    "usac_default": cv2.USAC_DEFAULT,
    "usac_magsac": cv2.USAC_MAGSAC,
    "usac_accurate": cv2.USAC_ACCURATE,
    "usac_fast": cv2.USAC_FAST,
}

#: How many times less precisely the learned detector finds the middle of an edge along the edge
#: than across it (:func:`pose.box.edge_directions`); measured on the rendered sequences (``docs/journal.md``).
ALONG_SIGMA = 3.0
#: ``(degrees, fraction)``: a pose is near a prior pose (:class:`PoseSolver`'s ``min_inliers_near_prior``) when their
#: rotations differ by less than ``degrees`` and their translations by less than ``fraction`` of the prior's distance
#: to the camera.
NEAR_PRIOR = (5.0, 0.05)
#: With a prior pose, the pose refined from it is kept without running RANSAC when at least this share of the
#: matches are its inliers; otherwise RANSAC runs too and the two solutions compete as ambiguous poses do
#: (:class:`PoseSolver`'s ``ambiguity_tolerance``; a large motion between frames can leave the refinement from the
#: prior in a wrong local minimum).
PRIOR_INLIER_RATIO = 0.8


@dataclass
class PoseEstimate:
    """Result of one pose estimation.

    Attributes:
        ok: whether a pose was found (``False``: the frame is lost; ``rvec``/``tvec`` are ``None``).
        rvec, tvec: ``(3, 1)`` float64, object-to-camera (``x_cam = R x_obj + t``), OpenCV convention.
        inliers: indices ``(K,)`` of the correspondences consistent with the pose.
        num_matches: number of correspondences given.
        reprojection_error: mean reprojection error of the inliers, pixels.
        used_prior: whether the prior pose was enough (no full RANSAC ran).
        reason: why the frame is lost, empty when ``ok``.
    """

    ok: bool
    rvec: np.ndarray | None = None
    tvec: np.ndarray | None = None
    inliers: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    num_matches: int = 0
    reprojection_error: float = float("nan")
    used_prior: bool = False
    reason: str = ""

    @property
    def R(self) -> np.ndarray:
        """Rotation matrix ``(3, 3)`` object-to-camera."""
        if self.rvec is None:
            raise InputError("no pose: the frame is lost")
        return cv2.Rodrigues(self.rvec)[0]


def camera_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """The 3x3 intrinsic matrix (OpenCV convention: pixel centre of the top-left pixel at (0, 0))."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def check_intrinsics(K: np.ndarray) -> np.ndarray:
    """``K`` as a float64 ``(3, 3)`` camera matrix.

    Raises:
        InputError: not a finite 3x3 matrix with positive focal lengths (one line: the matrix as nested lists).
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.isfinite(K).all() or K[0, 0] <= 0 or K[1, 1] <= 0:
        given = K.tolist() if K.shape == (3, 3) else f"shape {K.shape}"
        raise InputError(f"K must be a finite 3x3 intrinsic matrix with positive focal lengths, got {given}")
    return K


def rotation_error_deg(R: np.ndarray, R_gt: np.ndarray) -> float:
    """Angle (degrees) of ``R @ R_gt.T``."""
    c = (np.trace(np.asarray(R) @ np.asarray(R_gt).T) - 1) / 2
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def project(
    points: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray, dist: np.ndarray | None = None
) -> np.ndarray:
    """Project object points ``(N, 3)`` to pixels ``(N, 2)`` float64."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(pts) == 0:
        return np.zeros((0, 2))
    return cv2.projectPoints(pts, rvec, tvec, K, dist)[0].reshape(-1, 2)


class PoseSolver:
    """PnP + RANSAC + Levenberg-Marquardt refinement with an optional prior pose.

    Args:
        K: intrinsics ``(3, 3)``.
        dist: distortion coefficients (OpenCV order) or ``None``.
        method: a key of :data:`METHODS`.
        reprojection_error: RANSAC inlier threshold, pixels.
        confidence: RANSAC confidence.
        iterations: RANSAC iteration cap.
        min_inliers: fewer inliers than this -> the frame is lost.
        min_inliers_near_prior: with a prior pose, a pose near it (:data:`NEAR_PRIOR`) needs only
            this many inliers (``None``: ``min_inliers``). A wrong pose that also agrees with the
            motion predicted from the previous frames is far less likely than one anywhere.
        min_inlier_ratio: fewer than this fraction of the matches as inliers -> lost.
        outline: ``(M, 3)`` object points whose projections outline the object (e.g. the 8
            corners of its box), or ``None``; with it, a pose whose inliers' convex hull in the
            image covers less than ``min_coverage`` of the hull of the projected outline is
            rejected: parts clustered in a small part of the object leave the pose poorly
            constrained (``docs/journal.md``).
        min_coverage: see ``outline``.
        ambiguity_tolerance: with a prior pose, candidate poses whose MSAC cost is within this
            fraction of the lowest are ambiguous; the one closest to the prior is chosen.
        along_sigma: how many times less precisely an image point is found along its direction
            (:meth:`solve`'s ``directions``) than across it (see :data:`ALONG_SIGMA`).
    """

    def __init__(
        self,
        K: np.ndarray,
        dist: np.ndarray | None = None,
        *,
        method: str = "usac_default",
        reprojection_error: float = 4.0,
        confidence: float = 0.999,
        iterations: int = 500,
        min_inliers: int = 12,
        min_inliers_near_prior: int | None = None,
        min_inlier_ratio: float = 0.0,
        outline: np.ndarray | None = None,
        min_coverage: float = 0.15,
        ambiguity_tolerance: float = 0.15,
        along_sigma: float = ALONG_SIGMA,
    ) -> None:
        K = check_intrinsics(K)
        if method not in METHODS:
            raise InputError(f"unknown PnP method {method!r}; choose one of {sorted(METHODS)}")
        if min_inliers < 4:
            raise InputError(f"min_inliers must be >= 4 (PnP needs 4 points), got {min_inliers}")
        if not (reprojection_error > 0 and 0 < confidence < 1 and iterations >= 1):
            raise InputError(
                "need reprojection_error > 0, confidence in (0, 1) and iterations >= 1, "
                f"got {reprojection_error}, {confidence} and {iterations}"
            )
        self.K, self.dist = K, None if dist is None else np.asarray(dist, np.float64)
        self.method, self.flags = method, METHODS[method]
        self.reprojection_error, self.confidence, self.iterations = reprojection_error, confidence, iterations
        near = min_inliers if min_inliers_near_prior is None else min_inliers_near_prior
        if not 4 <= near <= min_inliers:
            raise InputError(f"min_inliers_near_prior must be in [4, min_inliers={min_inliers}], got {near}")
        self.min_inliers, self.min_inliers_near_prior = min_inliers, near
        self.min_inlier_ratio = min_inlier_ratio
        if not 0 <= min_coverage < 1:
            raise InputError(f"min_coverage must be in [0, 1), got {min_coverage}")
        self.outline = None if outline is None else np.asarray(outline, np.float64).reshape(-1, 3)
        self.min_coverage = min_coverage
        if ambiguity_tolerance < 0:
            raise InputError(f"ambiguity_tolerance must be >= 0, got {ambiguity_tolerance}")
        self.ambiguity_tolerance = ambiguity_tolerance
        if along_sigma < 1:
            raise InputError(f"along_sigma must be >= 1, got {along_sigma}")
        self.along_sigma = along_sigma
        self._criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 20, 1e-8)

    def _errors(self, obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
        err = np.linalg.norm(project(obj, rvec, tvec, self.K, self.dist) - img, axis=1)
        # points behind the camera are never inliers
        depth = (cv2.Rodrigues(rvec)[0] @ obj.T + tvec.reshape(3, 1))[2]
        err[depth <= 0] = np.inf
        return err

    def _refine(
        self, obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Two rounds of LM on the inliers of the current pose; returns rvec, tvec, inliers."""
        inl = np.flatnonzero(self._errors(obj, img, rvec, tvec) < self.reprojection_error)
        for _ in range(2):
            if len(inl) < 4:
                break
            rvec, tvec = cv2.solvePnPRefineLM(
                obj[inl], img[inl], self.K, self.dist, rvec.copy(), tvec.copy(), self._criteria
            )
            inl = np.flatnonzero(self._errors(obj, img, rvec, tvec) < self.reprojection_error)
        return rvec, tvec, inl

    def _cost(self, obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> float:
        """MSAC cost of a pose: squared reprojection errors truncated at the inlier threshold."""
        return float((np.minimum(self._errors(obj, img, rvec, tvec), self.reprojection_error) ** 2).sum())

    def _planar_alternatives(
        self, obj: np.ndarray, img: np.ndarray, inl: np.ndarray
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """The two IPPE poses (Collins & Bartoli, IJCV 2014) of the inliers projected on their
        best-fitting plane: the two minima of a plane seen under weak perspective."""
        if len(inl) < 4:
            return []
        pts = obj[inl]
        centre = pts.mean(0)
        axes = np.linalg.svd(pts - centre)[2]  # rows: in-plane axes, then the normal
        axes[2] *= np.sign(np.linalg.det(axes))  # a rotation, not a reflection
        plane = (pts - centre) @ axes.T
        plane[:, 2] = 0
        try:
            _, rvecs, tvecs, _ = cv2.solvePnPGeneric(plane, img[inl], self.K, self.dist, flags=cv2.SOLVEPNP_IPPE)
        except cv2.error:  # degenerate (e.g. collinear) points
            return []
        out = []
        for r, t in zip(rvecs, tvecs):
            R = cv2.Rodrigues(r)[0] @ axes  # x_cam = R_plane axes (x - centre) + t
            out.append((cv2.Rodrigues(R)[0], t.reshape(3, 1) - (R @ centre).reshape(3, 1)))
        return out

    def _polish(
        self,
        obj: np.ndarray,
        img: np.ndarray,
        rvec: np.ndarray,
        tvec: np.ndarray,
        prior: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`_refine` from ``(rvec, tvec)`` and from the planar alternatives of its inliers,
        then :meth:`_select` among them.

        Parts on one face of a box seen from afar leave two poses with nearly the same
        reprojection error: the refinement from RANSAC's minimal sample (or from the previous
        frame) often falls in the wrong one."""
        start = self._refine(obj, img, rvec, tvec)
        return self._select(
            obj,
            img,
            [start] + [self._refine(obj, img, r, t) for r, t in self._planar_alternatives(obj, img, start[2])],
            prior,
        )

    def _select(
        self,
        obj: np.ndarray,
        img: np.ndarray,
        candidates: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
        prior: tuple[np.ndarray, np.ndarray] | None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The candidate pose with the lowest MSAC cost; with a prior pose, the one closest to it
        (rotation angle) among those within :attr:`ambiguity_tolerance` of the lowest cost: when
        the correspondences cannot tell two poses apart, the previous frame's pose does."""
        costs = np.nan_to_num([self._cost(obj, img, r, t) for r, t, _ in candidates], nan=np.inf)
        if prior is None:
            return candidates[int(np.argmin(costs))]
        R0 = cv2.Rodrigues(np.asarray(prior[0], np.float64))[0]
        near = np.flatnonzero(costs <= (1 + self.ambiguity_tolerance) * costs.min())
        angle = [rotation_error_deg(cv2.Rodrigues(candidates[i][0])[0], R0) for i in near]
        return candidates[int(near[int(np.argmin(angle))])]

    def _is_near(self, rvec: np.ndarray, tvec: np.ndarray, prior: tuple[np.ndarray, np.ndarray] | None) -> bool:
        """Whether the pose is within :data:`NEAR_PRIOR` of ``prior``."""
        if prior is None or not (np.isfinite(rvec).all() and np.isfinite(tvec).all()):
            return False
        angle = rotation_error_deg(cv2.Rodrigues(rvec)[0], cv2.Rodrigues(prior[0])[0])
        shift = np.linalg.norm(tvec.ravel() - prior[1].ravel())
        return bool(angle < NEAR_PRIOR[0] and shift < NEAR_PRIOR[1] * np.linalg.norm(prior[1]))

    def _accept(
        self,
        obj: np.ndarray,
        img: np.ndarray,
        rvec: np.ndarray,
        tvec: np.ndarray,
        inl: np.ndarray,
        used_prior: bool,
        prior: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> PoseEstimate:
        n = len(obj)
        need = self.min_inliers_near_prior if self._is_near(rvec, tvec, prior) else self.min_inliers
        need = max(need, math.ceil(self.min_inlier_ratio * n))
        if len(inl) < need:
            return PoseEstimate(
                False, num_matches=n, inliers=inl, reason=f"{len(inl)} inliers of {n} matches (need {need})"
            )
        if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()) or tvec.ravel()[2] <= 0:
            return PoseEstimate(False, num_matches=n, reason="degenerate pose (object behind the camera)")
        if self.outline is not None and self.min_coverage > 0:
            silhouette = cv2.contourArea(
                cv2.convexHull(project(self.outline, rvec, tvec, self.K, self.dist).astype(np.float32))
            )
            covered = cv2.contourArea(cv2.convexHull(img[inl].astype(np.float32)))
            if covered < self.min_coverage * silhouette:
                return PoseEstimate(
                    False,
                    num_matches=n,
                    inliers=inl,
                    reason=f"the inliers cover {covered / max(silhouette, 1e-9):.0%} of the object "
                    f"(need {self.min_coverage:.0%})",
                )
        err = self._errors(obj[inl], img[inl], rvec, tvec)
        return PoseEstimate(True, rvec, tvec, inl, n, float(err.mean()), used_prior)

    def _refine_along(
        self,
        obj: np.ndarray,
        img: np.ndarray,
        directions: np.ndarray,
        rvec: np.ndarray,
        tvec: np.ndarray,
        iterations: int = 10,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton on the reprojection errors of ``obj``, ``img`` split along and across the
        projection of each point's direction (``(N, 3)``, zeros: none), the part along it divided
        by :attr:`along_sigma`: the maximum-likelihood pose when an edge's middle is found that
        much less precisely along the edge than across it."""
        p = np.concatenate([np.ravel(rvec), np.ravel(tvec)]).astype(np.float64)
        step = 1e-3 * np.linalg.norm(p[3:])  # a small length in the object's units at its distance
        sliding = directions.any(1)
        ahead_points = obj[sliding] + step * directions[sliding]

        def whitened(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            uv, jac = cv2.projectPoints(obj, p[:3], p[3:], self.K, self.dist)
            uv, jac = uv.reshape(-1, 2), jac[:, :6].reshape(-1, 2, 6)
            along = cv2.projectPoints(ahead_points, p[:3], p[3:], self.K, self.dist)[0].reshape(-1, 2) - uv[sliding]
            along /= np.maximum(np.linalg.norm(along, axis=1, keepdims=True), 1e-300)
            # rows: across, along / sigma; a point without direction keeps the identity
            w = np.tile(np.eye(2), (len(obj), 1, 1))
            w[sliding] = np.stack([np.stack([-along[:, 1], along[:, 0]], 1), along / self.along_sigma], 1)
            return np.einsum("nij,nj->ni", w, uv - img).ravel(), np.einsum("nij,njk->nik", w, jac).reshape(-1, 6)

        r, jac = whitened(p)
        cost = float(r @ r)
        for _ in range(iterations):
            h = jac.T @ jac
            try:
                dp = -np.linalg.solve(h + 1e-6 * np.diag(np.diag(h)), jac.T @ r)
            except np.linalg.LinAlgError:  # the points do not determine the pose
                break
            r_new, jac_new = whitened(p + dp)
            if not float(r_new @ r_new) < cost:
                break
            p, r, jac, cost = p + dp, r_new, jac_new, float(r_new @ r_new)
            if np.abs(dp).max() < 1e-10 * max(1.0, np.abs(p).max()):
                break
        return p[:3].reshape(3, 1), p[3:].reshape(3, 1)

    def solve(
        self,
        object_points: np.ndarray,
        image_points: np.ndarray,
        prior: tuple[np.ndarray, np.ndarray] | None = None,
        directions: np.ndarray | None = None,
    ) -> PoseEstimate:
        """Estimate the pose from correspondences.

        Args:
            object_points: ``(N, 3)`` object-frame points (the model's units).
            image_points: ``(N, 2)`` pixels.
            prior: ``(rvec, tvec)`` of the previous frame, or ``None``.
            directions: ``(N, 3)`` object-frame unit vectors along which an image point is less
                precise (:attr:`pose.parts.Correspondences.directions`), or ``None``. With them,
                the pose found is refined once more on its inliers with the errors along those
                directions weighed down (see :attr:`along_sigma`).

        Returns:
            A :class:`PoseEstimate`; ``ok=False`` when the pose is not reliable.
        """
        obj = np.ascontiguousarray(object_points, dtype=np.float64).reshape(-1, 3)
        img = np.ascontiguousarray(image_points, dtype=np.float64).reshape(-1, 2)
        if len(obj) != len(img):
            raise InputError(f"{len(obj)} object points but {len(img)} image points")
        if directions is not None:
            directions = np.asarray(directions, np.float64).reshape(-1, 3)
            if len(directions) != len(obj):
                raise InputError(f"{len(obj)} object points but {len(directions)} directions")
        est = self._solve(obj, img, prior)
        if directions is None or not est.ok:
            return est
        inl = est.inliers
        if not directions[inl].any():
            return est
        rvec, tvec = self._refine_along(obj[inl], img[inl], directions[inl], est.rvec, est.tvec)
        if not (np.isfinite(rvec).all() and np.isfinite(tvec).all()) or tvec.ravel()[2] <= 0:
            return est
        err = self._errors(obj[inl], img[inl], rvec, tvec)
        return replace(est, rvec=rvec, tvec=tvec, reprojection_error=float(err.mean()))

    def _solve(self, obj: np.ndarray, img: np.ndarray, prior: tuple[np.ndarray, np.ndarray] | None) -> PoseEstimate:
        """:meth:`solve` without the directions, on ``float64`` arrays."""
        n = len(obj)
        need = self.min_inliers if prior is None else self.min_inliers_near_prior
        if n < max(4, need):
            return PoseEstimate(False, num_matches=n, reason=f"only {n} matches (need {need})")
        from_prior = None
        if prior is not None:
            prior = (np.asarray(prior[0], np.float64).reshape(3, 1), np.asarray(prior[1], np.float64).reshape(3, 1))
            rvec, tvec, inl = self._polish(obj, img, *prior, prior=prior)
            from_prior = self._accept(obj, img, rvec, tvec, inl, used_prior=True, prior=prior)
            if from_prior.ok and len(from_prior.inliers) >= PRIOR_INLIER_RATIO * n:
                return from_prior
        try:
            ok, rvec, tvec, inl = cv2.solvePnPRansac(
                obj,
                img,
                self.K,
                self.dist,
                iterationsCount=self.iterations,
                reprojectionError=self.reprojection_error,
                confidence=self.confidence,
                flags=self.flags,
            )
        except cv2.error as exc:  # degenerate samples (e.g. SQPnP on nearly coincident points)
            ok, reason = False, f"PnP failed: {exc.err}"
        else:
            reason = "RANSAC found no pose"
            ok = ok and inl is not None and len(inl) >= 4
        if ok:
            rvec, tvec, inl = self._polish(obj, img, rvec, tvec, prior=prior)
            est = self._accept(obj, img, rvec, tvec, inl, used_prior=False, prior=prior)
        else:
            est = PoseEstimate(False, num_matches=n, reason=reason)
        # the prior's local optimum competes with the global RANSAC solution (:meth:`_select`)
        if from_prior is None or not from_prior.ok:
            return est
        if not est.ok:
            return from_prior
        best = self._select(
            obj, img, [(from_prior.rvec, from_prior.tvec, from_prior.inliers), (est.rvec, est.tvec, est.inliers)], prior
        )
        return from_prior if best[0] is from_prior.rvec else est


class PoseTracker:
    """Frame-to-frame use of a :class:`PoseSolver`: a predicted pose as prior, lost/recovered events.

    The prior for the next frame is predicted from the last two accepted poses at constant
    velocity (rotation vector and translation per frame, as in the motion model of ORB-SLAM, Mur-
    Artal et al., T-RO 2015), or is the last pose when only one is known. It also survives up to
    ``coast`` lost frames after the last accepted pose, so that the detector keeps searching
    around the predicted pose (guided matching, with a much higher share of correct matches than
    matching the whole frame) instead of falling back to the whole frame at once.

    Each frame (:meth:`step`) is first searched around the prediction, ``wide_search`` times
    wider than usual when the motion is unknown or extrapolated over lost frames, then, when no
    pose comes of it, in the whole frame; the wide search helps after a fast first motion
    (``docs/journal.md``).

    A pose solved from the parts found around the prediction must be borne out by them: the
    detector matches a part found there to the model points projected near it, so around a wrong
    prediction the matches lean toward the prediction, and a wrong pose near it fits a fair share
    of them, but a smaller one than a right prediction's matches give the right pose. When fewer
    than ``trusted_guided_ratio`` of the matches are its inliers, the whole frame is searched
    as well, and its pose, found without the prediction, is taken; when the whole frame gives
    none, the pose found around the prediction is kept if at least ``min_guided_ratio`` of the
    matches are its inliers, and the frame is lost otherwise. Both ``0`` (the default here): every
    pose found around the prediction is kept; ``alcn pose track`` checks a feature detector's with
    0.6 and 0.3 (:data:`pose.track.TRUSTED_GUIDED_RATIO`; :func:`pose.track.make_tracker` and
    :func:`pose.track.open_tracker` build its tracker).

    ``events`` collects ``(frame, "lost" | "recovered", reason)`` tuples, also logged: ``frame`` is the ``name`` given
    to :meth:`step` or :meth:`update` (the frame's name in its source, ``frame_000030``), else its index. The index
    counts the frames given (the motion model's time: the prediction is one index ahead), which differs from the
    frame's place in its source when frames are skipped (``alcn pose track --step``).

    Frame indices are expected to increase from one call to the next; a frame given again
    replaces the pose recorded for it, and an earlier one starts a new motion (the poses recorded
    for it and later frames are forgotten).
    """

    def __init__(
        self,
        solver: PoseSolver,
        coast: int = 3,
        wide_search: float = 2.5,
        *,
        trusted_guided_ratio: float = 0.0,
        min_guided_ratio: float = 0.0,
    ) -> None:
        if not 0 <= min_guided_ratio <= trusted_guided_ratio < 1:
            raise InputError(
                "need 0 <= min_guided_ratio <= trusted_guided_ratio < 1, "
                f"got {min_guided_ratio} and {trusted_guided_ratio}"
            )
        self.solver = solver
        self.wide_search = wide_search
        self.coast = coast
        self.trusted_guided_ratio, self.min_guided_ratio = trusted_guided_ratio, min_guided_ratio
        self.events: list[tuple[int | str, str, str]] = []
        self._poses: list[tuple[int, np.ndarray, np.ndarray]] = []  # the last two accepted (frame, rvec, tvec)
        self._frame: int | None = None  # the last frame given to update
        self._lost = True
        self._started = False

    @property
    def prior(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(rvec, tvec)`` predicted for the frame after the last update, or ``None``."""
        if not self._poses or self._frame is None or self._frame - self._poses[-1][0] > self.coast:
            return None
        f1, r1, t1 = self._poses[-1]
        if len(self._poses) < 2:
            return r1, t1
        f0, r0, t0 = self._poses[0]
        steps = (self._frame + 1 - f1) / (f1 - f0)  # in units of the last inter-pose interval
        R0, R1 = cv2.Rodrigues(r0)[0], cv2.Rodrigues(r1)[0]
        w = cv2.Rodrigues(R1 @ R0.T)[0] * steps
        return cv2.Rodrigues(cv2.Rodrigues(w)[0] @ R1)[0], t1 + (t1 - t0) * steps

    @property
    def search_scale(self) -> float:
        """How much wider than usual the detector should search around :attr:`prior`: 1 when the
        last frame was posed and an earlier pose gives the velocity, ``wide_search`` when the
        motion is unknown (a single known pose) or extrapolated over lost frames."""
        if len(self._poses) < 2 or self._poses[-1][0] != self._frame:
            return self.wide_search
        return 1.0

    def update(
        self, frame_index: int, object_points: np.ndarray, image_points: np.ndarray, *, name: str | None = None
    ) -> PoseEstimate:
        """Solve frame ``frame_index`` from its correspondences with :attr:`prior` and record it (``name``: what the
        events and the log call it)."""
        return self._record(frame_index, self.solver.solve(object_points, image_points, self.prior), name)

    def step(
        self, frame_index: int, image: np.ndarray, detector: PartDetector, *, name: str | None = None
    ) -> tuple[PoseEstimate, Correspondences]:
        """Detect the parts of ``image`` around the predicted pose, solve, let the detector verify
        the pose (:meth:`pose.parts.PartDetector.verify`), and record the frame.

        When the guided search around the prediction gives no pose, the whole frame is searched
        again before the frame is declared lost: after a single known pose (no velocity yet) or
        a sudden change of motion the object can leave the search window. So it is when the
        pose it gives has fewer than :attr:`trusted_guided_ratio` of its matches as inliers: the
        whole frame's pose replaces it, and without one it is kept only with at least
        :attr:`min_guided_ratio` (the class docstring says why).

        When that gives no pose either, the detector may propose one from its own evidence
        (:meth:`pose.parts.PartDetector.propose`; the learned detector's scores where a pose
        shows the parts, :meth:`pose.corners.CornerDetector.propose`): its parts are searched
        around it as around a prediction, and the pose solved from them is verified as proposed.

        A verified pose is refined when the detector asks for it
        (:attr:`pose.parts.PartDetector.refine_search_scale`): the parts are searched again around
        the frame's own pose, in narrower gates, and the pose solved from them replaces it when
        verified.

        ``name``: what the events and the log call the frame (default: ``frame_index``).

        Returns:
            The estimate and the correspondences it was solved from.
        """
        prior = self.prior
        est, corr = self._search(image, detector, prior, prior, search_scale=self.search_scale)
        k, n = len(est.inliers), est.num_matches
        if prior is not None and detector.uses_prior and not (est.ok and k >= self.trusted_guided_ratio * n):
            found, whole = self._search(image, detector, None, prior)
            if found.ok or not est.ok:
                est, corr = found, whole
            elif k < self.min_guided_ratio * n:
                est = PoseEstimate(
                    False,
                    num_matches=n,
                    inliers=est.inliers,
                    reason=f"{k} inliers of {n} matches around the prediction ({k / n:.0%}, need "
                    f"{self.min_guided_ratio:.0%}); whole frame: {found.reason}",
                )
        if not est.ok:
            proposal = detector.propose(image, self.solver.K)
            if proposal is not None:
                found, near = self._search(image, detector, proposal, proposal, proposed=True)
                if found.ok:
                    est, corr = found, near
        if est.ok and detector.refine_search_scale > 0:
            solved = (est.rvec, est.tvec)
            refined, near = self._search(image, detector, solved, solved, search_scale=detector.refine_search_scale)
            if refined.ok:
                est, corr = refined, near
        return self._record(frame_index, est, name), corr

    def _search(
        self,
        image: np.ndarray,
        detector: PartDetector,
        around: tuple[np.ndarray, np.ndarray] | None,
        prior: tuple[np.ndarray, np.ndarray] | None,
        *,
        search_scale: float = 1.0,
        proposed: bool = False,
    ) -> tuple[PoseEstimate, Correspondences]:
        """Detect the parts of ``image`` around the pose ``around`` (the whole frame for ``None``;
        gates ``search_scale`` times the usual), solve with ``prior``, and verify (:meth:`_verified`)."""
        corr = detector.detect(image, None if around is None else (*around, self.solver.K), search_scale=search_scale)
        est = self.solver.solve(corr.object_points, corr.image_points, prior, corr.directions)
        return self._verified(est, image, detector, proposed=proposed), corr

    def _verified(
        self, est: PoseEstimate, image: np.ndarray, detector: PartDetector, *, proposed: bool = False
    ) -> PoseEstimate:
        """``est``, or a lost frame when the detector rejects its pose (``detector.verify``): a
        wrong pose kept would also become the next frame's prior."""
        if est.ok:
            why = detector.verify(image, est.rvec, est.tvec, self.solver.K, proposed=proposed)
            if why:
                return PoseEstimate(False, num_matches=est.num_matches, inliers=est.inliers, reason=why)
        return est

    def _record(self, frame_index: int, est: PoseEstimate, name: str | None = None) -> PoseEstimate:
        frame = frame_index if name is None else name
        # only poses of earlier frames predict this one's successor (equal indices: no velocity)
        self._poses = [p for p in self._poses if p[0] < frame_index]
        self._frame = frame_index
        if est.ok:
            self._poses = (self._poses + [(frame_index, est.rvec, est.tvec)])[-2:]
            if self._lost and self._started:
                self.events.append((frame, "recovered", ""))
                logger.info("frame %s: tracking recovered (%d inliers)", frame, len(est.inliers))
            self._lost = False
        else:
            if self._poses and frame_index - self._poses[-1][0] > self.coast:
                self._poses = []  # lost for too long: the next pose starts a new motion
            if not self._lost:
                self.events.append((frame, "lost", est.reason))
                logger.info("frame %s: tracking lost (%s)", frame, est.reason)
            self._lost = True
        self._started = True
        return est
