"""The paper's "simple synthetic images" made from a few real images of a target (Sec. 4.1).

To train a new detector from 1 or 10 real images under one lighting, the paper augments each
real image with Gaussian noise, replaces its background by a uniform colour or a crop of another
image, and applies small affine changes of intensity ``I' = a I + b``. :func:`augment` does that
(plus a small geometric jitter) and returns 64x64 windows centred on the object, in the layout
of :mod:`alcn_cv.data.phos` (the Normalizer sees the centre 48x48, the detector the centre
32x32). :func:`sample_negatives` gives matching background windows: crops of the training
images away from the object, off-centre views of the object, and natural-photograph and
procedural-texture crops, with the same intensity changes.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from alcn_cv.data.textures import display_texture
from alcn_cv.errors import InputError

__all__ = ["augment", "sample_negatives", "object_box"]

WINDOW = 64


def _as_float(image: np.ndarray) -> np.ndarray:
    """``image`` as a float32 gray image in [0, 1]."""
    img = np.asarray(image)
    if img.size == 0 or img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3)):
        raise InputError(f"image must be HxW or HxWx3, got shape {img.shape}")
    if img.dtype == np.uint8:
        f = img.astype(np.float32) / 255.0
    elif img.dtype == np.uint16:
        f = img.astype(np.float32) / 65535.0
    elif img.dtype == np.float32:
        if not np.isfinite(img).all():
            raise InputError("image contains NaN or inf")
        f = img.copy()
    else:
        raise InputError(f"unsupported image dtype {img.dtype}; use uint8, uint16 or float32")
    if f.ndim == 3 and f.shape[2] == 1:
        f = f[..., 0]
    return cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) if f.ndim == 3 else f


def object_box(
    image_shape: tuple[int, ...], mask_or_bbox: np.ndarray | Sequence[float]
) -> tuple[np.ndarray, np.ndarray | None]:
    """Normalise a mask or a COCO box to ``(bbox [x, y, w, h] float64, mask float32 or None)``: a boolean mask or one of
    values in [0, 1] is the object where nonzero, a 0..255 one where above 127 (as :func:`~alcn_cv.io.read_mask`)."""
    arr = np.asarray(mask_or_bbox)
    if arr.ndim == 2 and arr.shape == tuple(image_shape[:2]):
        mask = (arr > 0).astype(np.float32) if arr.dtype == bool or arr.max() <= 1 else (arr > 127).astype(np.float32)
        ys, xs = np.nonzero(mask)
        if len(xs) == 0:
            raise InputError("object mask is empty")
        return np.array([xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1], np.float64), mask
    if arr.shape == (4,):
        box = arr.astype(np.float64)
        if not np.isfinite(box).all() or box[2] <= 0 or box[3] <= 0:
            raise InputError(f"bbox must be [x, y, w, h] with positive w and h, got {box.tolist()}")
        return box, None
    raise InputError(
        f"mask_or_bbox must be a mask of shape {image_shape[:2]} or a bbox [x, y, w, h], got shape {arr.shape}"
    )


def _intensity_noise(
    win: np.ndarray, rng: np.random.Generator, a_range: tuple[float, float], b_max: float, noise_max: float
) -> np.ndarray:
    n = len(win)
    shp = (n,) + (1,) * (win.ndim - 1)
    a = rng.uniform(*a_range, n).reshape(shp).astype(np.float32)
    b = rng.uniform(-b_max, b_max, n).reshape(shp).astype(np.float32)
    sigma = rng.uniform(0, noise_max, n).reshape(shp).astype(np.float32)
    out = a * win + b + sigma * rng.standard_normal(win.shape, dtype=np.float32)
    return np.rint(np.clip(out, 0, 1) * 255).astype(np.uint8)


def _background(rng: np.random.Generator, backgrounds: Sequence[np.ndarray] | None) -> np.ndarray:
    """A 64x64 gray background: a uniform level, a crop of ``backgrounds`` or a random texture."""
    u = rng.random()
    if u < 0.4:
        return np.full((WINDOW, WINDOW), rng.uniform(0, 1, 1)[0], np.float32)
    if backgrounds and u < 0.7:
        src = _as_float(backgrounds[int(rng.integers(len(backgrounds)))])
        h, w = src.shape[:2]
        s = rng.uniform(0.5, 2.0)
        ch, cw = min(h, int(WINDOW / s) + 1), min(w, int(WINDOW / s) + 1)
        y0, x0 = int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))
        return cv2.resize(src[y0 : y0 + ch, x0 : x0 + cw], (WINDOW, WINDOW), interpolation=cv2.INTER_LINEAR)
    return display_texture(rng, WINDOW, p_photo=0.6)


def augment(
    image: np.ndarray,
    mask_or_bbox: np.ndarray | Sequence[float],
    n: int,
    rng: np.random.Generator,
    *,
    extent: float | None = 40.0,
    backgrounds: Sequence[np.ndarray] | None = None,
    replace_background: float = 0.8,
    intensity_scale: tuple[float, float] = (0.8, 1.2),
    intensity_offset: float = 0.05,
    noise: float = 0.03,
    max_shift: float = 2.0,
    max_rotation_deg: float = 10.0,
    max_scale_change: float = 0.1,
) -> np.ndarray:
    """Synthetic positive windows of an object from one real image.

    Args:
        image: the real image, HxW gray or HxWx3 BGR; uint8, uint16 or float32 in [0, 1].
        mask_or_bbox: the object's mask (HxW: nonzero, or above 127 for a 0..255 one; :func:`object_box`) or
            its COCO box [x, y, w, h].
            With a mask, the background is replaced outside the mask; with a box, outside the box.
        n: number of windows.
        rng: random generator.
        extent: the object's larger side in output pixels (before jitter); None keeps the
            image's scale (for images already at the working scale).
        backgrounds: images whose crops may replace the background (besides uniform colours and
            random textures).
        replace_background: probability of replacing the background of a window.
        intensity_scale: range of ``a`` in ``I' = a I + b``.
        intensity_offset: ``|b|`` at most this (intensities in [0, 1]).
        noise: largest standard deviation of the additive Gaussian noise (in [0, 1] units).
        max_shift, max_rotation_deg, max_scale_change: geometric jitter (pixels, degrees,
            relative scale).

    Returns:
        uint8 gray windows (n, 64, 64), the object centred.
    """
    if n < 0:
        raise InputError(f"n must be >= 0, got {n}")
    img = _as_float(image)
    box, mask = object_box(img.shape, mask_or_bbox)
    if mask is None:
        mask = np.zeros(img.shape[:2], np.float32)
        x, y, w, h = box
        # clamped at 0: a box that starts above or left of the image would otherwise slice from the far side
        mask[
            max(0, int(np.floor(y))) : max(0, int(np.ceil(y + h))),
            max(0, int(np.floor(x))) : max(0, int(np.ceil(x + w))),
        ] = 1.0
    cx, cy = box[0] + (box[2] - 1) / 2, box[1] + (box[3] - 1) / 2
    base = 1.0 if extent is None else extent / max(box[2], box[3])
    c = (WINDOW - 1) / 2
    out = np.empty((n, WINDOW, WINDOW), np.float32)
    for i in range(n):
        s = base * (1 + rng.uniform(-max_scale_change, max_scale_change))
        M = cv2.getRotationMatrix2D((cx, cy), rng.uniform(-max_rotation_deg, max_rotation_deg), s)
        M[:, 2] += np.array([c, c]) - (cx, cy) + rng.uniform(-max_shift, max_shift, 2)
        interp = cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR
        win = cv2.warpAffine(img, M, (WINDOW, WINDOW), flags=interp, borderMode=cv2.BORDER_REFLECT_101)
        if rng.random() < replace_background:
            a = cv2.warpAffine(mask, M, (WINDOW, WINDOW), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)
            win = win * a + _background(rng, backgrounds) * (1 - a)
        out[i] = win
    return _intensity_noise(out, rng, intensity_scale, intensity_offset, noise)


def sample_negatives(
    images: Sequence[np.ndarray],
    masks_or_bboxes: Sequence,
    n: int,
    rng: np.random.Generator,
    *,
    extent: float | None = 40.0,
    natural_fraction: float = 0.4,
    off_centre_fraction: float = 0.2,
    intensity_scale: tuple[float, float] = (0.8, 1.2),
    intensity_offset: float = 0.05,
    noise: float = 0.03,
) -> np.ndarray:
    """Background windows matching :func:`augment`.

    A fraction ``natural_fraction`` are crops of natural photographs and procedural textures;
    ``off_centre_fraction`` show the object 14-26 px (output pixels) off the centre; the rest
    are crops of the training images whose centre 32x32 does not overlap the object's box.

    Args:
        images: the real training images (as :func:`augment`).
        masks_or_bboxes: one mask or box per image.
        n: number of windows.
        rng: random generator.
        extent: as :func:`augment`: the scale applied to each image (from its object's size).
        intensity_scale, intensity_offset, noise: as :func:`augment`.

    Returns:
        uint8 gray windows (n, 64, 64).
    """
    if n < 0:
        raise InputError(f"n must be >= 0, got {n}")
    if len(images) != len(masks_or_bboxes) or not images:
        raise InputError("need one mask or box per image, and at least one image")
    prepared = []
    for im, mb in zip(images, masks_or_bboxes):
        f = _as_float(im)
        box, _ = object_box(f.shape, mb)
        s = 1.0 if extent is None else extent / max(box[2], box[3])
        prepared.append((f, box, s))
    c = (WINDOW - 1) / 2
    out = np.empty((n, WINDOW, WINDOW), np.float32)
    for i in range(n):
        u = rng.random()
        if u < natural_fraction:
            out[i] = _background(rng, None)
            continue
        f, box, s = prepared[int(rng.integers(len(prepared)))]
        h, w = f.shape[:2]
        ocx, ocy = box[0] + (box[2] - 1) / 2, box[1] + (box[3] - 1) / 2
        if u < natural_fraction + off_centre_fraction:
            a = rng.uniform(0, 2 * np.pi)
            d = rng.uniform(14, 26) / s
            px, py = ocx + d * np.cos(a), ocy + d * np.sin(a)
        else:
            # Rejection-sample a centre whose 32x32 view (in output pixels) misses the box.
            half = 16 / s
            for _ in range(50):
                px, py = rng.uniform(0, w - 1), rng.uniform(0, h - 1)
                if (
                    px + half < box[0]
                    or px - half > box[0] + box[2]
                    or py + half < box[1]
                    or py - half > box[1] + box[3]
                ):
                    break
            else:
                out[i] = _background(rng, None)
                continue
        M = cv2.getRotationMatrix2D((px, py), rng.uniform(-10, 10), s)
        M[:, 2] += np.array([c, c]) - (px, py)
        interp = cv2.INTER_AREA if s < 1 else cv2.INTER_LINEAR
        out[i] = cv2.warpAffine(f, M, (WINDOW, WINDOW), flags=interp, borderMode=cv2.BORDER_REFLECT_101)
    return _intensity_noise(out, rng, intensity_scale, intensity_offset, noise)
