"""Part detectors: image -> 2D-3D correspondences for the pose solver, after a normalizer.

Both detectors first normalize the image with ``alcn_cv.create(name)`` (``"none"``, ``"dog"``,
``"alcn"`` or any registered name), as in Sec. 4.4 of Rad, Roth & Lepetit, "ALCN: Meta-Learning
for Contrast Normalization Applied to Robust 3D Pose Estimation", BMVC 2017:

* :class:`FeaturePartDetector` (classical): OpenCV keypoints and descriptors (ORB by default,
  SIFT or AKAZE on request) on the normalized image, matched to the descriptors of the part
  model's 3D points (brute force, Lowe's ratio test).
* :class:`pose.corners.CornerDetector` (learned): a small CNN on normalized windows
  that finds the box corners, run through ``cv2.dnn`` (ONNX), so tracking needs no torch.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np

from alcn_cv.errors import InputError
from alcn_cv.io import to_gray
from pose.model import PartModel

logger = logging.getLogger(__name__)

FEATURES = ("ORB", "SIFT", "AKAZE")


class Normalizer(Protocol):
    def apply(self, img: np.ndarray) -> np.ndarray: ...


def get_normalizer(spec: str) -> Normalizer:
    """The normalizer ``spec``: a registered name with optional parameters, ``NAME[:KEY=VALUE...]``
    (:func:`alcn_cv.enhance.registry.parse_spec`), e.g. ``"alcn:model=lite:mixture=pyramid"``
    (the real-time ALCN), given to ``alcn_cv.create``."""
    import alcn_cv
    from alcn_cv.enhance.registry import parse_spec

    name, params = parse_spec(spec)
    return alcn_cv.create(name, **params)


def create_feature(name: str, n_features: int = 1000) -> cv2.Feature2D:
    """An OpenCV keypoint detector + descriptor: ``"ORB"``, ``"SIFT"`` or ``"AKAZE"``."""
    name = name.upper()
    if name == "ORB":
        return cv2.ORB_create(nfeatures=n_features, scaleFactor=1.2, nlevels=8, fastThreshold=10)
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


@dataclass
class Correspondences:
    """2D-3D correspondences found in one image.

    Attributes:
        object_points: ``(M, 3)`` float32, the model's units.
        image_points: ``(M, 2)`` float32 pixels.
        keypoints: number of keypoints detected in the image.
    """

    object_points: np.ndarray
    image_points: np.ndarray
    keypoints: int = 0


class FeaturePartDetector:
    """Classical part detector: features of the normalized image matched to the model's 3D points.

    Args:
        model: the part model (its ``feature`` names the OpenCV feature used to build it).
        normalizer: a normalizer for :func:`get_normalizer` (name and optional parameters).
        n_features: keypoints per image.
        ratio: Lowe's ratio-test threshold.
        search_radius: guided matching window (pixels) around the prior pose's projections.
        min_guided: fewer guided matches than this: match globally instead.
    """

    def __init__(self, model: PartModel, normalizer: str = "none", *, n_features: int = 2000,
                 ratio: float = 0.8, search_radius: float = 20.0, min_guided: int = 20) -> None:
        if len(model.points3d) < 4:
            raise InputError(f"the part model has {len(model.points3d)} 3D points; at least 4 are needed")
        self.model = model
        self.normalizer_name = normalizer
        self.normalizer = get_normalizer(normalizer)
        self.feature = create_feature(model.feature, n_features)
        self.norm = descriptor_norm(model.feature)
        self.ratio = ratio
        self.search_radius, self.min_guided = search_radius, min_guided
        # a match without a second candidate nearby: accept only a close descriptor
        self.max_lone_distance = 50.0 if self.norm == cv2.NORM_HAMMING else 250.0
        self._matcher = cv2.BFMatcher(self.norm)
        self._matcher.add([model.descriptors])
        self._matcher.train()

    def normalize(self, image: np.ndarray) -> np.ndarray:
        """The normalized grayscale uint8 image the features are computed on."""
        return self.normalizer.apply(to_gray(image))

    def detect(self, image: np.ndarray, prior: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
               ) -> Correspondences:
        """Correspondences between ``image`` (BGR or gray uint8) and the model's 3D points.

        Args:
            image: the frame.
            prior: ``(rvec, tvec, K)`` of the previous frame, or ``None``. With a prior, a keypoint
                is matched only to model points that project within :attr:`search_radius` pixels
                of it (guided matching); when that yields fewer than :attr:`min_guided` matches,
                the global matching runs instead.
        """
        gray = self.normalize(image)
        kps, desc = self.feature.detectAndCompute(gray, None)
        if desc is None or len(kps) == 0:
            return Correspondences(np.zeros((0, 3), np.float32), np.zeros((0, 2), np.float32), 0)
        pts2d = np.array([k.pt for k in kps], np.float32)
        pairs = None
        if prior is not None:
            pairs = self._guided(pts2d, desc, prior)
            if len(pairs) < self.min_guided:
                pairs = None
        if pairs is None:
            pairs = self._ratio_pairs(self._matcher.knnMatch(desc, k=2))
        return Correspondences(self.model.points3d[pairs[:, 1]], pts2d[pairs[:, 0]], len(kps))

    def _ratio_pairs(self, knn) -> np.ndarray:
        pairs = [(m[0].queryIdx, m[0].trainIdx) for m in knn
                 if len(m) == 2 and m[0].distance < self.ratio * m[1].distance]
        return np.array(pairs, np.int64).reshape(-1, 2)

    def _guided(self, pts2d: np.ndarray, desc: np.ndarray, prior: tuple[np.ndarray, np.ndarray, np.ndarray]
                ) -> np.ndarray:
        rvec, tvec, K = prior
        R = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
        cam = self.model.points3d @ R.T + np.ravel(tvec)
        front = np.flatnonzero(cam[:, 2] > 0)
        if len(front) < 2:
            return np.zeros((0, 2), np.int64)
        uv = cam[front, :2] / cam[front, 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
        from scipy.spatial import cKDTree

        # candidate (keypoint, model point) pairs within the search radius, via a k-d tree
        near = cKDTree(uv).query_ball_point(pts2d, self.search_radius)
        kp = np.repeat(np.arange(len(near)), [len(c) for c in near])
        if len(kp) == 0:
            return np.zeros((0, 2), np.int64)
        mp = front[np.concatenate([np.asarray(c, np.int64) for c in near])]
        if self.norm == cv2.NORM_HAMMING:
            dist = np.bitwise_count(desc[kp] ^ self.model.descriptors[mp]).sum(1).astype(np.float32)
        else:
            dist = np.linalg.norm(desc[kp].astype(np.float32) - self.model.descriptors[mp], axis=1)
        order = np.lexsort((dist, kp))  # by keypoint, then distance
        kp, mp, dist = kp[order], mp[order], dist[order]
        first = np.r_[True, kp[1:] != kp[:-1]]
        i1 = np.flatnonzero(first)
        has2 = np.r_[i1[1:], len(kp)] - i1 > 1  # a second candidate exists
        d2 = np.where(has2, dist[np.minimum(i1 + 1, len(kp) - 1)], np.inf)
        # ratio test among the candidates near each keypoint; a lone candidate must be close
        ok = np.where(has2, dist[i1] < self.ratio * d2, dist[i1] < self.max_lone_distance)
        return np.stack([kp[i1][ok], mp[i1][ok]], 1).astype(np.int64)
