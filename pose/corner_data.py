"""Training windows of the corner detector (:mod:`pose.corners`), from a registered sequence.

See the module docstring of :mod:`pose.corners` for how windows are labelled and augmented.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.errors import InputError
from pose.corners import NUM_CORNERS, WINDOW, downscale, normalization_for, to_scaled
from pose.parts import to_gray
from pose.sequence import TrainingSequence

logger = logging.getLogger(__name__)


def corner_visibility(corners: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray, shape: tuple[int, int],
                      mask: np.ndarray | None = None, mask_tolerance: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Projections of the box corners and which of them are visible.

    Args:
        corners: ``(8, 3)`` corners in the order of :func:`pose.model.box_corners` (corner ``i``
            is at the far end of the x edge when bit 2 of ``i`` is set, y: bit 1, z: bit 0); any
            parallelepiped in that order.
        R, t: object-to-camera pose (``x_cam = R x + t``).
        K: ``(3, 3)`` intrinsics.
        shape: ``(H, W)`` of the image.
        mask: optional ``(H, W)`` visible-object mask (BOP ``mask_visib``); a corner farther
            than ``mask_tolerance`` pixels from it is hidden by something else.

    Returns:
        ``uv (8, 2)`` float64 pixels and ``visible (8,)`` bool: in front of the camera, inside
        the image, on at least one face turned towards the camera, and on the mask.
    """
    corners = np.asarray(corners, np.float64).reshape(NUM_CORNERS, 3)
    R, t = np.asarray(R, np.float64).reshape(3, 3), np.asarray(t, np.float64).reshape(3)
    cam = corners @ R.T + t
    z = np.maximum(cam[:, 2], 1e-9)
    uv = np.stack([K[0, 0] * cam[:, 0] / z + K[0, 2], K[1, 1] * cam[:, 1] / z + K[1, 2]], 1)
    h, w = shape
    visible = (cam[:, 2] > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    # box coordinates of the camera centre: a face is turned towards the camera when the centre
    # lies beyond its plane
    axes = np.stack([corners[4] - corners[0], corners[2] - corners[0], corners[1] - corners[0]], 1)
    a = np.linalg.solve(axes, -R.T @ t - corners[0])
    bits = (np.arange(NUM_CORNERS)[:, None] >> np.array([2, 1, 0])) & 1
    visible &= np.where(bits == 1, a > 1, a < 0).any(1)
    if mask is not None:
        near = cv2.dilate((mask > 0).astype(np.uint8), np.ones((2 * mask_tolerance + 1,) * 2, np.uint8))
        ij = np.clip(np.round(uv).astype(int), 0, [w - 1, h - 1])
        visible &= near[ij[:, 1], ij[:, 0]] > 0
    return uv, visible


def crop_windows(image: np.ndarray, centers: np.ndarray, size: int) -> np.ndarray:
    """``(n, size, size)`` float32 windows of ``image`` centred on ``centers (n, 2)`` (bilinear)."""
    out = np.empty((len(centers), size, size), np.float32)
    for i, (x, y) in enumerate(centers):
        out[i] = cv2.getRectSubPix(image, (size, size), (float(x), float(y)))
    return out


def _sample_negatives(rng: np.random.Generator, n: int, shape: tuple[int, int], corners_uv: np.ndarray,
                      mask: np.ndarray | None, radius: float) -> np.ndarray:
    """``n`` window centres farther than ``radius`` from every ``corners_uv``; half on ``mask``."""
    h, w = shape
    on = np.argwhere(mask > 0)[:, ::-1].astype(np.float64) if mask is not None and mask.any() else None
    out = []
    for _ in range(20):
        m = 2 * n
        pts = rng.uniform([0, 0], [w - 1, h - 1], (m, 2))
        if on is not None:
            k = m // 2
            pts[:k] = on[rng.integers(len(on), size=k)] + rng.uniform(-0.5, 0.5, (k, 2))
        if len(corners_uv):
            d = np.linalg.norm(pts[:, None] - corners_uv[None], axis=2).min(1)
            pts = pts[d > radius]
        out.append(pts)
        if sum(len(p) for p in out) >= n:
            break
    pts = np.concatenate(out)
    return pts[rng.permutation(len(pts))[:n]]


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray | None:
    if not path.is_file():
        return None
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    return m if m is not None and m.shape == shape else None


def replace_background(gray: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``gray`` uint8 with the pixels outside ``mask`` (uint8, 255 = object; intermediate
    values blend) replaced by a random texture (:func:`alcn_cv.data.textures.display_texture`,
    gamma-encoded like a photograph)."""
    from alcn_cv.data.textures import display_texture

    texture = display_texture(rng, gray.shape, gray=True)
    alpha = mask.astype(np.float32) / np.float32(255)
    out = alpha * gray.astype(np.float32) + (1 - alpha) * np.float32(255) * texture
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


@dataclass
class CornerDataset:
    """Training windows of the corner detector.

    Attributes:
        windows: ``(n, 32, 32)`` float32 normalized windows, standardized by
            ``(x - input_mean) / input_std`` (constants over the training frames).
        labels: ``(n,)`` int64; 0 background, ``k + 1`` corner ``k``.
        centers: ``(n, 2)`` float64 window centres, pixels of the downscaled frame.
        frames: ``(n,)`` int64 index into :attr:`normalized` of the frame each window comes
            from (a training view or one of its copies with a new background).
        augmented: ``(n,)`` bool: made by :func:`alcn_cv.data.synthetic.augment`.
        normalized: per frame (each training view, then its copies with new backgrounds), the
            downscaled normalized frame ``(h, w)`` float32, standardized like the windows.
        visible: per frame, ``(m, 2)`` downscaled pixels of its visible corners.
    """

    windows: np.ndarray
    labels: np.ndarray
    centers: np.ndarray
    frames: np.ndarray
    augmented: np.ndarray
    normalized: list[np.ndarray]
    visible: list[np.ndarray]
    input_mean: float
    input_std: float

    def add_negatives(self, windows: np.ndarray, centers: np.ndarray, frames: np.ndarray) -> None:
        """Append background windows (e.g. mined hard negatives)."""
        self.windows = np.concatenate([self.windows, windows])
        self.labels = np.concatenate([self.labels, np.zeros(len(windows), np.int64)])
        self.centers = np.concatenate([self.centers, centers])
        self.frames = np.concatenate([self.frames, frames])
        self.augmented = np.concatenate([self.augmented, np.zeros(len(windows), bool)])


def build_dataset(sequence: TrainingSequence, corners: np.ndarray, normalizer: str = "none", *, scale: float = 0.5,
                  jitter: int = 6, pos_radius: float = 1.0, neg_radius: float = 5.0, negatives_per_frame: int = 200,
                  augment_per_corner: int = 16, backgrounds: int = 2, seed: int = 0) -> CornerDataset:
    """Corner windows from a registered training sequence (:func:`pose.sequence.load_sequence`).

    Args:
        sequence: a :class:`pose.sequence.TrainingSequence` with poses (world = object frame).
        corners: ``(8, 3)`` box corners in the object frame (:func:`pose.model.box_corners` order).
        normalizer: a spec for :func:`pose.corners.normalization_for`.
        scale: downscaling of the frames before normalization and detection.
        jitter: positive windows per visible corner, centred within ``pos_radius`` (downscaled
            pixels) of it.
        pos_radius, neg_radius: see the module docstring (downscaled pixels).
        negatives_per_frame: background windows per frame, half of them on the object's mask
            when there is one.
        augment_per_corner: synthetic windows (:func:`alcn_cv.data.synthetic.augment`) per
            visible corner, and as many background ones per frame.
        backgrounds: where the view has a ``mask_visib``, this many copies of it with the
            background replaced (:func:`replace_background`) give windows too: half of a
            corner's window is background, which the 30 views of a training sequence show
            in few variations.
        seed: random seed.

    Raises:
        InputError: no training view with a visible corner, or an unregistered sequence.
    """
    from alcn_cv import io
    from alcn_cv.data.synthetic import augment
    from alcn_cv.train.stage2 import normalize_windows

    if not sequence.registered:
        raise InputError("the training sequence must be registered (a pose for every image)")
    norm = normalization_for(normalizer)
    rng = np.random.default_rng(seed)
    parts: dict[str, list] = {k: [] for k in ("windows", "labels", "centers", "frames", "augmented")}

    def add(windows, labels, centers, frame, augmented):
        parts["windows"].append(windows)
        parts["labels"].append(np.asarray(labels, np.int64))
        parts["centers"].append(np.asarray(centers, np.float64).reshape(-1, 2))
        parts["frames"].append(np.full(len(windows), frame, np.int64))
        parts["augmented"].append(np.full(len(windows), augmented, bool))

    normalized_frames, visible_corners = [], []
    mask_dir = sequence.image_dir.parent / "mask_visib"
    aug_kw = {"extent": None, "replace_background": 0.0, "intensity_scale": (0.4, 1.6), "intensity_offset": 0.2,
              "noise": 0.03, "max_shift": pos_radius, "max_rotation_deg": 25.0, "max_scale_change": 0.2}
    for view in sequence.views:
        gray = to_gray(io.read_image(sequence.image_dir / view.name))
        mask = _read_mask(mask_dir / f"{Path(view.name).stem}_000000.png", gray.shape)
        uv, vis = corner_visibility(corners, view.R_w2c, view.t_w2c, view.K, gray.shape, mask)
        small = downscale(gray, scale)
        small_mask = None if mask is None else downscale(mask, scale)
        suv = to_scaled(uv[vis], scale)
        labels = np.flatnonzero(vis) + 1
        variants = [small] + ([] if small_mask is None else
                              [replace_background(small, small_mask, rng) for _ in range(backgrounds)])
        for image in variants:
            f = len(normalized_frames)  # this frame's index in `normalized` and `visible`
            normed = norm.normalize(image.astype(np.float32) / np.float32(255))
            normalized_frames.append(normed)
            visible_corners.append(suv)
            if len(suv):
                a = rng.uniform(0, 2 * np.pi, (len(suv), jitter))
                r = pos_radius * np.sqrt(rng.uniform(0, 1, (len(suv), jitter)))
                centers = (suv[:, None] + np.stack([r * np.cos(a), r * np.sin(a)], 2)).reshape(-1, 2)
                add(crop_windows(normed, centers, WINDOW), np.repeat(labels, jitter), centers, f, False)
            neg = _sample_negatives(rng, negatives_per_frame, image.shape, suv, small_mask, neg_radius)
            add(crop_windows(normed, neg, WINDOW), np.zeros(len(neg), np.int64), neg, f, False)
            if augment_per_corner:
                # the data engine's simple synthetic images around each point, normalized afterwards
                aug_neg = neg[: augment_per_corner]
                for label, (x, y) in [*zip(labels, suv), *zip(np.zeros(len(aug_neg), np.int64), aug_neg)]:
                    n = augment_per_corner if label else 1
                    raw = augment(image, [x, y, 1.0, 1.0], n, rng, **aug_kw)
                    add(normalize_windows(raw, norm, policy="raw"), np.full(n, label), np.tile([x, y], (n, 1)), f,
                        True)
    if not any(len(lab) and lab.max() > 0 for lab in parts["labels"]):
        raise InputError("no box corner is visible in any training image")
    # one fixed affine map for every input (the normalizers' output ranges differ widely)
    mean = float(np.mean([im.mean() for im in normalized_frames]))
    std = float(np.sqrt(np.mean([im.var() for im in normalized_frames]))) + 1e-6

    def standardize(x: np.ndarray) -> np.ndarray:
        return ((x - mean) / std).astype(np.float32)

    data = CornerDataset(**{k: np.concatenate(v) for k, v in parts.items()},
                         normalized=[standardize(im) for im in normalized_frames], visible=visible_corners,
                         input_mean=mean, input_std=std)
    data.windows = standardize(data.windows)
    logger.info("corner dataset: %d windows (%d corner, %d augmented) from %d frames (%d with new backgrounds)",
                len(data.labels), int((data.labels > 0).sum()), int(data.augmented.sum()), len(sequence.views),
                len(normalized_frames) - len(sequence.views))
    return data
