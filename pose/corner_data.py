"""Training frames of the corner detector (:mod:`pose.corners`), from a registered sequence.

Every view of the training sequence is downscaled, then copied with the data engine's kinds of
augmentation applied to the whole frame: a random homography (in-plane rotation, scaling,
perspective and shift: the viewpoints between and around the training views), the background
(outside the BOP ``mask_visib``) replaced by the data engine's random textures
(:func:`alcn_cv.data.textures.display_texture`), and an intensity change ``a I + b`` with noise
(the ranges of :func:`alcn_cv.data.synthetic.augment`'s). The box corners follow the homography.
Each frame is normalized whole, as at test time, and labelled on the network's output grid
(:func:`label_grid`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.errors import InputError
from pose.corners import (
    NUM_CORNERS, PAD, STRIDE, downscale, grid_centres, grid_shape, normalization_for, to_scaled,
)
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


def label_grid(uv: np.ndarray, classes: np.ndarray, hidden: np.ndarray, shape: tuple[int, int], *,
               pos_radius: float = 4.0, neg_radius: float = 7.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Targets of the network's output grid for one frame.

    Args:
        uv: ``(m, 2)`` visible corners (pixels of the frame the network sees).
        classes: ``(m,)`` their corner indices (0..7).
        hidden: ``(p, 2)`` corners inside the frame but not visible.
        shape: ``(gh, gw)`` of the grid (:func:`pose.corners.grid_centres`).
        pos_radius: a cell whose window centre is within this of a visible corner is that
            corner's (the nearest); with the stride of 4 every corner has at least one cell.
        neg_radius: cells between ``pos_radius`` and this from a corner (visible or hidden) are
            ignored; the rest is background.

    Returns:
        ``labels (gh, gw)`` int64 (-1 ignored, 0 background, ``k + 1`` corner ``k``),
        ``offsets (2, gh, gw)`` float32, the nearest visible corner minus the window centre in
        strides, for the cells within ``neg_radius`` of it (0 elsewhere; the neighbours of a
        peak vote for the corner's position too, :meth:`pose.corners.CornerDetector.peaks`), and
        ``owner (gh, gw)`` int64, the index of that corner (-1: no offset target).
    """
    centres = grid_centres(shape)
    labels = np.zeros(shape, np.int64)
    offsets = np.zeros((2, *shape), np.float32)
    owner = np.full(shape, -1, np.int64)
    everything = np.concatenate([np.reshape(uv, (-1, 2)), np.reshape(hidden, (-1, 2))])
    if len(everything):
        d_all = np.linalg.norm(centres[None] - everything[:, None, None], axis=3).min(0)
        labels[d_all <= neg_radius] = -1
    if len(uv):
        d = np.linalg.norm(centres[None] - np.asarray(uv)[:, None, None], axis=3)
        nearest = d.argmin(0)
        pos = d.min(0) <= pos_radius
        labels[pos] = np.asarray(classes)[nearest[pos]] + 1
        near = d.min(0) <= neg_radius
        off = (np.asarray(uv)[nearest] - centres) / STRIDE
        offsets[:, near] = off[near].T
        owner[near] = np.asarray(classes)[nearest[near]]
    return labels, offsets, owner


def random_homography(rng: np.random.Generator, shape: tuple[int, int], *, max_rotation_deg: float = 15.0,
                      scale: tuple[float, float] = (0.8, 1.25), perspective: float = 0.06,
                      max_shift: float = 0.1) -> np.ndarray:
    """A 3x3 homography about the frame's centre: rotation, scaling, the image corners moved by
    up to ``perspective`` of the frame's size, a shift of up to ``max_shift`` of it."""
    h, w = shape
    c = np.array([(w - 1) / 2, (h - 1) / 2])
    src = np.array([[0, 0], [w - 1, 0], [w - 1, h - 1], [0, h - 1]], np.float64)
    dst = src + rng.uniform(-perspective, perspective, (4, 2)) * [w, h]
    P = cv2.getPerspectiveTransform(src.astype(np.float32), dst.astype(np.float32))
    A = np.eye(3)
    A[:2] = cv2.getRotationMatrix2D(tuple(c), rng.uniform(-max_rotation_deg, max_rotation_deg), rng.uniform(*scale))
    A[:2, 2] += rng.uniform(-max_shift, max_shift, 2) * [w, h]
    return A @ P


def _transform(H: np.ndarray, uv: np.ndarray) -> np.ndarray:
    return cv2.perspectiveTransform(np.asarray(uv, np.float64).reshape(-1, 1, 2), H).reshape(-1, 2)


def _intensity_noise(gray: np.ndarray, rng: np.random.Generator, scale: tuple[float, float], offset: float,
                     noise: float) -> np.ndarray:
    """``a I + b`` plus Gaussian noise on a uint8 frame (intensities in [0, 1])."""
    x = gray.astype(np.float32) / np.float32(255)
    x = rng.uniform(*scale) * x + rng.uniform(-offset, offset)
    x += rng.normal(0, rng.uniform(0, noise), x.shape).astype(np.float32)
    return np.clip(x * 255 + 0.5, 0, 255).astype(np.uint8)


@dataclass
class CornerFrames:
    """Training frames of the corner detector, normalized, padded and labelled.

    Attributes:
        images: ``(n, h + 2 PAD, w + 2 PAD)`` float32 normalized frames standardized by
            ``(x - input_mean) / input_std`` (constants over the frames) and padded
            (``BORDER_REFLECT_101``) as :meth:`pose.corners.CornerDetector.logits` pads.
        labels: ``(n, gh, gw)`` int64 grid labels (:func:`label_grid`).
        offsets: ``(n, 2, gh, gw)`` float32 offset targets and ``owner`` ``(n, gh, gw)`` int64
            their corners (:func:`label_grid`).
        corners: per frame, ``(m, 3)`` visible corners: x, y (pixels of the downscaled frame), index.
        view: ``(n,)`` the training view each frame comes from.
    """

    images: np.ndarray
    labels: np.ndarray
    offsets: np.ndarray
    owner: np.ndarray
    corners: list[np.ndarray]
    view: np.ndarray
    input_mean: float
    input_std: float


def build_frames(sequence: TrainingSequence, corners: np.ndarray, normalizer: str = "none", *, scale: float = 0.5,
                 copies: int = 11, backgrounds: float = 0.8, intensity_scale: tuple[float, float] = (0.4, 1.6),
                 intensity_offset: float = 0.2, noise: float = 0.03, pos_radius: float = 4.0,
                 neg_radius: float = 7.0, seed: int = 0) -> CornerFrames:
    """The labelled training frames of a registered sequence (:func:`pose.sequence.load_sequence`).

    Args:
        sequence: a :class:`pose.sequence.TrainingSequence` with poses (world = object frame).
        corners: ``(8, 3)`` box corners in the object frame (:func:`pose.model.box_corners` order).
        normalizer: a spec for :func:`pose.corners.normalization_for`.
        scale: downscaling of the frames before normalization and detection.
        copies: augmented copies per view (:func:`random_homography`, new background, intensity
            change and noise), besides the view itself.
        backgrounds: probability that a copy gets a new background (where the view has a mask).
        intensity_scale, intensity_offset, noise: the intensity change of a copy.
        pos_radius, neg_radius: see :func:`label_grid` (downscaled pixels).
        seed: random seed.

    Raises:
        InputError: an unregistered sequence, or no visible corner in any view.
    """
    from alcn_cv import io

    if not sequence.registered:
        raise InputError("the training sequence must be registered (a pose for every image)")
    norm = normalization_for(normalizer)
    rng = np.random.default_rng(seed)
    mask_dir = sequence.image_dir.parent / "mask_visib"
    images, labels, offsets, owners, visible, views = [], [], [], [], [], []
    for v, view in enumerate(sequence.views):
        gray = to_gray(io.read_image(sequence.image_dir / view.name))
        mask = _read_mask(mask_dir / f"{Path(view.name).stem}_000000.png", gray.shape)
        uv, vis = corner_visibility(corners, view.R_w2c, view.t_w2c, view.K, gray.shape, mask)
        small = downscale(gray, scale)
        small_mask = None if mask is None else downscale(mask, scale)
        suv = to_scaled(uv, scale)
        h, w = small.shape
        for c in range(copies + 1):
            image, m, xy = small, small_mask, suv
            if c:
                H = random_homography(rng, (h, w))
                image = cv2.warpPerspective(small, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101)
                xy = _transform(H, suv)
                if m is not None:
                    m = cv2.warpPerspective(m, H, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
                    if rng.random() < backgrounds:
                        image = replace_background(image, m, rng)
                image = _intensity_noise(image, rng, intensity_scale, intensity_offset, noise)
            inside = (xy[:, 0] >= 0) & (xy[:, 0] <= w - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= h - 1)
            shown = vis & inside
            normed = norm.normalize(image.astype(np.float32) / np.float32(255))
            lab, off, own = label_grid(xy[shown], np.flatnonzero(shown), xy[inside & ~vis], grid_shape(h, w),
                                  pos_radius=pos_radius, neg_radius=neg_radius)
            images.append(normed.astype(np.float32))
            labels.append(lab)
            offsets.append(off)
            owners.append(own)
            visible.append(np.concatenate([xy[shown], np.flatnonzero(shown)[:, None]], 1))
            views.append(v)
    if not any((lab > 0).any() for lab in labels):
        raise InputError("no box corner is visible in any training image")
    # one fixed affine map for every input (the normalizers' output ranges differ widely), from
    # the views themselves
    originals = images[:: copies + 1]
    mean = float(np.mean([im.mean() for im in originals]))
    std = float(np.sqrt(np.mean([im.var() for im in originals]))) + 1e-6
    padded = np.stack([cv2.copyMakeBorder((im - mean) / std, PAD, PAD, PAD, PAD, cv2.BORDER_REFLECT_101)
                       for im in images]).astype(np.float32)
    frames = CornerFrames(padded, np.stack(labels), np.stack(offsets), np.stack(owners), visible, np.asarray(views),
                          mean, std)
    logger.info("corner frames: %d (%d views x %d), %d corner cells", len(images), len(sequence.views), copies + 1,
                int((frames.labels > 0).sum()))
    return frames
