"""Part detectors: image -> 2D-3D correspondences for the pose solver, after a normalization.

Both detectors first normalize the image with a normalization built from its spec
(:func:`alcn_cv.enhance.registry.from_spec`: ``"none"``, ``"dog"``, ``"alcn"`` or any registered
name, with optional ``:KEY=VALUE`` parameters), as in Sec. 4.4 of Rad, Roth & Lepetit, "ALCN: Meta-Learning
for Contrast Normalization Applied to Robust 3D Pose Estimation", BMVC 2017:

* :class:`FeaturePartDetector` (classical): OpenCV keypoints and descriptors (ORB by default,
  SIFT or AKAZE on request) on the normalized image, matched to the descriptors of the part
  model's 3D points (brute force, Lowe's ratio test).
* :class:`pose.corners.CornerDetector` (learned): a small CNN on normalized windows
  that finds the box corners, run through ``cv2.dnn`` (ONNX), so tracking needs no torch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from alcn_cv.enhance.registry import from_spec
from alcn_cv.errors import InputError
from alcn_cv.io import to_gray
from pose.box import project_points
from pose.model import PartModel

FEATURES = ("ORB", "SIFT", "AKAZE")


#: ORB needs a cap on its keypoints; "all of them" (``n_features=0``) means this many.
ORB_ALL = 100_000


def create_feature(name: str, n_features: int = 1000) -> cv2.Feature2D:
    """An OpenCV keypoint detector + descriptor: ``"ORB"``, ``"SIFT"`` or ``"AKAZE"``, keeping the
    ``n_features`` strongest keypoints (0: all; AKAZE keeps all in any case)."""
    name = name.upper()
    if name == "ORB":
        return cv2.ORB_create(nfeatures=n_features or ORB_ALL, scaleFactor=1.2, nlevels=8, fastThreshold=10)
    if name == "SIFT":  # a low contrast threshold: weakly textured objects (Middlebury's temple)
        return cv2.SIFT_create(nfeatures=n_features, contrastThreshold=0.02)
    if name == "AKAZE":  # OpenCV 5 moved AKAZE to the contrib module xfeatures2d
        return cv2.xfeatures2d.AKAZE_create(threshold=5e-4)
    raise InputError(f"unknown feature {name!r}; choose one of {FEATURES}")


def descriptor_norm(name: str) -> int:
    """The OpenCV norm that compares descriptors of feature ``name``."""
    return cv2.NORM_L2 if name.upper() == "SIFT" else cv2.NORM_HAMMING


def match_descriptors(query: np.ndarray, train: np.ndarray, norm: int, ratio: float = 0.8) -> np.ndarray:
    """Lowe's ratio-test matches ``(M, 2)`` int64 of (query index, train index)."""
    if len(query) < 1 or len(train) < 2:
        return np.zeros((0, 2), np.int64)
    knn = cv2.BFMatcher(norm).knnMatch(query, train, k=2)
    pairs = [(m[0].queryIdx, m[0].trainIdx) for m in knn if len(m) == 2 and m[0].distance < ratio * m[1].distance]
    return np.array(pairs, np.int64).reshape(-1, 2)


def same_frame(kept: np.ndarray | None, image: np.ndarray) -> bool:
    """Whether ``image`` holds the pixels of ``kept``, a copy of the last frame a detector computed on: what it
    keeps is reused for the tracker's second search of a frame. Compared by content, not identity: an app that
    reads every frame into one buffer gives new pixels in the same array."""
    return kept is not None and kept.shape == image.shape and kept.dtype == image.dtype and np.array_equal(kept, image)


@dataclass
class Correspondences:
    """2D-3D correspondences found in one image.

    Attributes:
        object_points: ``(M, 3)`` float32, the model's units.
        image_points: ``(M, 2)`` float32 pixels.
        keypoints: number of keypoints detected in the image.
        directions: ``(M, 3)`` float32 unit vectors of the object frame along which an image
            point was found less precisely than across (the edge a part lies in the middle of,
            :func:`pose.box.edge_directions`), zeros where it is equally precise in every direction;
            ``None``: all are.
    """

    object_points: np.ndarray
    image_points: np.ndarray
    keypoints: int = 0
    directions: np.ndarray | None = None


class PartDetector(Protocol):
    """What the pose tracker needs of a part detector (:class:`FeaturePartDetector`,
    :class:`pose.corners.CornerDetector`): correspondences in an image, optionally searched
    around a prior pose ``(rvec, tvec, K)`` (when :attr:`uses_prior`), a last word on a pose
    solved from them (:meth:`verify`: ``""`` to keep it, else why not), and, for a frame where
    no pose came of them, a pose of its own to search around (:meth:`propose`, or ``None``; the
    pose solved around it is verified with ``proposed=True``). With a :attr:`refine_search_scale`
    above 0 the tracker searches the parts of a frame again around the frame's own verified pose,
    in gates of that share of a prediction's, and solves again."""

    uses_prior: bool
    refine_search_scale: float

    def detect(
        self,
        image: np.ndarray,
        prior: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        *,
        search_scale: float = 1.0,
    ) -> Correspondences: ...

    def verify(
        self, image: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray, *, proposed: bool = False
    ) -> str: ...

    def propose(self, image: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None: ...


class FeaturePartDetector:
    """Classical part detector: features of the normalized image matched to the model's 3D points.

    With a prior pose the keypoints are detected only inside the object's predicted region (the
    projected box, grown by ``search_radius``), at most ``n_features`` of them. Without one (first
    frame, tracking lost) the object may be anywhere and *all* keypoints of the frame are used
    (``n_features_global``): the strongest ``n_features`` of a cluttered frame can all lie on the
    background (``docs/journal.md``). Each of them is matched to every descriptor of the model (brute force), the
    cost of a frame without the object, which ``n_features_global`` bounds (its times with the cookie box's model:
    ``docs/pose.md``, Speed).

    Built by hand, its defaults are not ``alcn pose track``'s (1000 keypoints around the prediction):
    :func:`pose.track.open_tracker` builds the command's detector and tracker.

    Args:
        model: the part model (its ``feature`` names the OpenCV feature used to build it).
        normalization: the normalization applied first, ``NAME[:KEY=VALUE...]``
            (:func:`alcn_cv.enhance.registry.from_spec`), e.g. ``"alcn:model=lite:mixture=pyramid"``.
        n_features: the strongest keypoints kept inside the predicted region (with a prior pose).
        n_features_global: the strongest keypoints kept without a prior (0: all).
        ratio: Lowe's ratio-test threshold.
        search_radius: guided matching window (pixels) around the prior pose's projections.
        max_candidates: at most this many model points (those projected nearest to a keypoint in
            the window) are compared with it. 64 bounds the time on a dense model;
            fewer let wrong matches through the ratio test (``docs/journal.md``).
        min_guided: fewer guided matches than this: match globally instead.
        cross_check: keep a global match only when the keypoint is also the nearest of one of
            the point's descriptors among the image's keypoints (mutual nearest neighbours). It helps
            a small model in a large image (``docs/journal.md``).
    """

    uses_prior = True
    #: No second search around a frame's own pose: guided matching already matches every keypoint
    #: of the predicted region, and a second one would detect and describe them again.
    refine_search_scale = 0.0

    def __init__(
        self,
        model: PartModel,
        normalization: str = "none",
        *,
        n_features: int = 2000,
        n_features_global: int = 0,
        ratio: float = 0.8,
        search_radius: float = 20.0,
        max_candidates: int = 64,
        min_guided: int = 20,
        cross_check: bool = False,
    ) -> None:
        if len(model.points3d) < 4:
            raise InputError(f"the part model has {len(model.points3d)} 3D points; at least 4 are needed")
        self.model = model
        self.normalization_spec = normalization
        self.normalization = from_spec(normalization)
        self.feature = create_feature(model.feature, 0)
        self.n_features, self.n_features_global = n_features, n_features_global
        self.norm = descriptor_norm(model.feature)
        self.ratio = ratio
        self.search_radius, self.max_candidates, self.min_guided = search_radius, max_candidates, min_guided
        self.cross_check = cross_check
        # a match without a second candidate nearby: accept only a close descriptor
        self.max_lone_distance = 50.0 if self.norm == cv2.NORM_HAMMING else 250.0
        self._matcher = cv2.BFMatcher(self.norm)
        self._matcher.add([model.descriptors])
        self._matcher.train()
        # the descriptors of each point: rows _order[_start[p]:_start[p] + _count[p]] of model.descriptors
        owner = model.descriptor_point
        self._order = np.argsort(owner, kind="stable")
        self._count = np.bincount(owner, minlength=len(model.points3d))
        self._start = np.r_[0, np.cumsum(self._count)[:-1]]
        self._model_words = (
            _as_words(model.descriptors) if self.norm == cv2.NORM_HAMMING else model.descriptors.astype(np.float32)
        )
        # the last frame's normalized image and whole-frame correspondences: the tracker's second search of a frame
        # (the whole frame, after a guided search) costs no normalization, and no detection when the guided search
        # already fell back to the whole frame
        self._frame: np.ndarray | None = None  # a copy of that frame
        self._normalized: np.ndarray | None = None
        self._whole: Correspondences | None = None

    def normalize(self, image: np.ndarray) -> np.ndarray:
        """The normalized grayscale uint8 image the features are computed on."""
        return self.normalization.apply(to_gray(image))

    def verify(
        self, image: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray, *, proposed: bool = False
    ) -> str:
        """``""``: every pose the solver accepts is kept (its inliers, each a descriptor match,
        are the evidence)."""
        return ""

    def propose(self, image: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """``None``: RANSAC over the descriptor matches of the whole frame is this detector's
        whole search."""
        return None

    def detect(
        self,
        image: np.ndarray,
        prior: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        *,
        search_scale: float = 1.0,
    ) -> Correspondences:
        """Correspondences between ``image`` (BGR or gray uint8) and the model's 3D points.

        Args:
            image: the frame.
            prior: ``(rvec, tvec, K)`` of the previous frame, or ``None``. With a prior, keypoints
                are detected in the object's predicted region and a keypoint is matched only to
                model points that project within :attr:`search_radius` pixels of it (guided
                matching); when that yields fewer than :attr:`min_guided` matches, the global
                detection and matching run instead.
            search_scale: multiplies :attr:`search_radius` (the tracker widens the search when
                its prediction is uncertain).
        """
        if not same_frame(self._frame, image):
            self._frame, self._normalized, self._whole = image.copy(), self.normalize(image), None
        gray = self._normalized
        if prior is not None:
            radius = self.search_radius * search_scale
            region = self._region(gray.shape, prior, radius)
            if region is not None:
                pts2d, desc, n = self._detect(gray, region, self.n_features)
                pairs = self._guided(pts2d, desc, prior, radius) if n else np.zeros((0, 2), np.int64)
                if len(pairs) >= self.min_guided:
                    return Correspondences(self.model.points3d[pairs[:, 1]], pts2d[pairs[:, 0]], n)
        if self._whole is None:
            pts2d, desc, n = self._detect(gray, None, self.n_features_global)
            pairs = self._global(desc) if n else np.zeros((0, 2), np.int64)
            self._whole = Correspondences(self.model.points3d[pairs[:, 1]], pts2d[pairs[:, 0]], n)
        return self._whole

    def _detect(
        self, gray: np.ndarray, region: np.ndarray | None, keep: int
    ) -> tuple[np.ndarray, np.ndarray | None, int]:
        """Keypoints ``(n, 2)``, descriptors and ``n``: the ``keep`` strongest (0: all) in
        ``region`` (a uint8 mask, or ``None``: the whole image).

        OpenCV's SIFT and ORB keep their ``nfeatures`` strongest keypoints of the whole image
        *before* applying a mask (few of a region's keypoints are left; ``docs/journal.md``), so the detector runs
        uncapped on the region's bounding
        box (padded so that its border rules do not eat the region's edge) and the strongest
        are kept afterwards."""
        x0 = y0 = 0
        if region is not None:
            x, y, w, h = cv2.boundingRect(region)
            pad = 32  # ORB ignores 31 px at the border
            x0, y0 = max(x - pad, 0), max(y - pad, 0)
            x1, y1 = min(x + w + pad, gray.shape[1]), min(y + h + pad, gray.shape[0])
            gray, region = gray[y0:y1, x0:x1], region[y0:y1, x0:x1]
        if keep:
            kps = self.feature.detect(gray, region)
            if len(kps) > keep:
                kps = sorted(kps, key=lambda k: -k.response)[:keep]
            kps, desc = self.feature.compute(gray, kps)
        else:
            kps, desc = self.feature.detectAndCompute(gray, region)
        if desc is None or len(kps) == 0:
            return np.zeros((0, 2), np.float32), None, 0
        return np.array([k.pt for k in kps], np.float32) + np.float32([x0, y0]), desc, len(kps)

    def _region(
        self, shape: tuple[int, ...], prior: tuple[np.ndarray, np.ndarray, np.ndarray], radius: float
    ) -> np.ndarray | None:
        """uint8 mask of the object's predicted region: the convex hull of the box's corners
        projected with the prior pose, grown by ``radius`` pixels; ``None`` when the box is
        not in front of the camera or misses the image."""
        front, uv = _project_in_front(self.model.corners, prior)
        if len(front) < len(self.model.corners):
            return None
        uv = np.clip(uv, -4 * max(shape[:2]), 5 * max(shape[:2]))  # corners near the camera plane: no overflow
        mask = np.zeros(shape[:2], np.uint8)
        cv2.fillConvexPoly(mask, cv2.convexHull(np.round(uv).astype(np.int32)), 255)
        r = int(np.ceil(radius))
        mask = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1)))
        return mask if mask.any() else None

    def _global(self, desc: np.ndarray) -> np.ndarray:
        """(keypoint, model point) pairs by Lowe's ratio test between the closest descriptor and
        the closest one of *another* point (a point may have several descriptors); with
        :attr:`cross_check`, only mutual nearest neighbours."""
        k = min(int(self._count.max()) + 1, len(self.model.descriptors))
        knn = self._matcher.knnMatch(desc, k=k)
        idx = np.zeros((len(knn), k), np.int64)
        dist = np.full((len(knn), k), np.inf, np.float32)
        for q, m in enumerate(knn):
            idx[q, : len(m)] = [x.trainIdx for x in m]
            dist[q, : len(m)] = [x.distance for x in m]
        owner = self.model.descriptor_point[idx]
        other = (owner != owner[:, :1]) & np.isfinite(dist)
        d2 = np.where(other.any(1), dist[np.arange(len(knn)), np.argmax(other, axis=1)], np.inf)
        ok = dist[:, 0] < self.ratio * d2
        pairs = np.stack([np.flatnonzero(ok), owner[ok, 0]], 1).astype(np.int64)
        if self.cross_check and len(pairs):
            nearest = np.array([m.trainIdx for m in cv2.BFMatcher(self.norm).match(self.model.descriptors, desc)])
            mutual = np.unique(self.model.descriptor_point * len(desc) + nearest)  # (point, keypoint) codes
            pairs = pairs[np.isin(pairs[:, 1] * len(desc) + pairs[:, 0], mutual)]
        return pairs

    def _guided(
        self, pts2d: np.ndarray, desc: np.ndarray, prior: tuple[np.ndarray, np.ndarray, np.ndarray], radius: float
    ) -> np.ndarray:
        front, uv = _project_in_front(self.model.points3d, prior)
        if len(front) < 2:
            return np.zeros((0, 2), np.int64)
        from scipy.spatial import cKDTree

        # candidate (keypoint, model point) pairs: the max_candidates points projected nearest to each
        # keypoint within the search radius (k-d tree), grouped by keypoint
        k = min(self.max_candidates, len(uv))
        dist, idx = cKDTree(uv).query(pts2d, k=k, distance_upper_bound=radius)
        dist, idx = dist.reshape(len(pts2d), k), idx.reshape(len(pts2d), k)
        found = np.isfinite(dist)
        kp = np.nonzero(found)[0]
        if len(kp) == 0:
            return np.zeros((0, 2), np.int64)
        mp = front[idx[found]]
        cnt = self._count[mp]
        kp, mp, cnt = kp[cnt > 0], mp[cnt > 0], cnt[cnt > 0]
        if len(kp) == 0:
            return np.zeros((0, 2), np.int64)
        # every descriptor of every candidate point; a point's distance is that of its closest descriptor.
        # The candidates come grouped by keypoint and each point's descriptors are consecutive, so
        # minima over groups (np.minimum.reduceat) replace sorting.
        group = np.cumsum(cnt) - cnt
        rows = self._order[np.repeat(self._start[mp] - group, cnt) + np.arange(int(cnt.sum()))]
        d_point = np.minimum.reduceat(self._distances(desc, np.repeat(kp, cnt), rows), group)
        k_start = np.flatnonzero(np.r_[True, kp[1:] != kp[:-1]])
        k_size = np.diff(np.r_[k_start, len(kp)])
        d1 = np.minimum.reduceat(d_point, k_start)
        pos = np.where(d_point == np.repeat(d1, k_size), np.arange(len(kp)), len(kp))
        i1 = np.minimum.reduceat(pos, k_start)  # the closest point of each keypoint
        rest = d_point.copy()
        rest[i1] = np.inf
        d2 = np.minimum.reduceat(rest, k_start)  # the closest other point (inf when it is alone)
        # ratio test among the points near each keypoint; a lone candidate must be close
        ok = np.where(k_size > 1, d1 < self.ratio * d2, d1 < self.max_lone_distance)
        return np.stack([kp[i1][ok], mp[i1][ok]], 1).astype(np.int64)

    def _distances(self, desc: np.ndarray, query: np.ndarray, rows: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
        """Descriptor distances ``(len(query),)`` float32 between ``desc[query]`` and the model's
        ``descriptors[rows]`` (Hamming for binary descriptors, L2 otherwise), in chunks."""
        model = self._model_words
        if self.norm == cv2.NORM_HAMMING:
            desc = _as_words(desc)
        else:
            desc = desc.astype(np.float32)
        out = np.empty(len(query), np.float32)
        for a in range(0, len(query), chunk):
            q, m = desc[query[a : a + chunk]], model[rows[a : a + chunk]]
            if self.norm == cv2.NORM_HAMMING:
                out[a : a + chunk] = np.bitwise_count(q ^ m).sum(1)
            else:
                out[a : a + chunk] = np.sqrt(np.maximum(((q - m) ** 2).sum(1), 0))
        return out


def _project_in_front(
    points: np.ndarray, prior: tuple[np.ndarray, np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the points ``(N, 3)`` in front of the camera of ``prior = (rvec, tvec, K)`` and
    their pixels ``(n, 2)`` (pinhole, no distortion: the search regions are tens of pixels wide)."""
    rvec, tvec, K = prior
    uv, depth = project_points(
        points, cv2.Rodrigues(np.asarray(rvec, np.float64))[0], np.ravel(tvec), K, min_depth=1e-9
    )
    front = np.flatnonzero(depth > 0)
    return front, uv[front]


def _as_words(desc: np.ndarray) -> np.ndarray:
    """Binary descriptors ``(N, B)`` uint8 as ``(N, B / 8)`` uint64 words when ``B`` allows (fewer,
    wider XOR / popcount operations; the Hamming distance is unchanged)."""
    desc = np.ascontiguousarray(desc)
    return desc.view(np.uint64) if desc.shape[1] % 8 == 0 else desc
