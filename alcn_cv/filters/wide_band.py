"""The wide band added to the gain Normalizer's output, so that ORB can orient its keypoints.

ORB orients a keypoint by the intensity centroid of its 31-pixel disc (Rublee et al., ICCV 2011), i.e. by the
patch's gradient at a scale of about 10 pixels, which ALCN's band-pass (sigma 1-2 after the division) removes:
the orientation then follows noise and changes with the light. The band ``tanh(dn(G_8 * I - G_32 * I) / tau)``,
the DoG of sigma 8 and 32 divided by its own local energy (sigma 32, :mod:`alcn_cv.filters.divisive`) and
equalized as ALCN's output, gives the patch that gradient again, invariant to the light's strength as the rest;
weighted by ``weight`` (0.15 in the default model), it leaves patch identification and SIFT unchanged
(``experiments/orb_orientation.py``). On rendered relief scenes under hard directional light the band also
carries the relief's shading, which a larger weight lets into the output (``experiments/directional_light.py``).

The band is computed on blocks of :data:`BLOCK` x :data:`BLOCK` pixels (their means; the image reflected
beyond its bottom and right borders to whole blocks) and interpolated back bilinearly (pixel centres, as
``cv2.resize``): its blurs are 16 times cheaper, and it is smooth at that scale. The torch form is
:mod:`alcn_cv.filters.torch_wide_band`.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from alcn_cv.checks import check_gray
from alcn_cv.errors import WeightFileError
from alcn_cv.filters.divisive import divisive_floor, divisive_normalization, gaussian_energy
from alcn_cv.filters.equalization import tanh
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d, kernel_radius

__all__ = [
    "BLOCK",
    "ENERGY_SIGMA",
    "SIGMAS",
    "band_meta",
    "band_reach",
    "block_means",
    "check_band_meta",
    "wide_band",
    "wide_band_floor",
]

#: Input pixels per side of the blocks the band is computed on.
BLOCK = 4
#: The band's DoG sigmas (input pixels).
SIGMAS = (8.0, 32.0)
#: The sigma of the band's divisive energy (input pixels).
ENERGY_SIGMA = 32.0


def band_meta(weight: float) -> dict[str, Any]:
    """The weight file's ``band`` entry of a model whose output adds ``weight`` times the band."""
    return {"weight": float(weight), "sigmas": list(SIGMAS), "energy_sigma": ENERGY_SIGMA, "block": BLOCK}


def check_band_meta(meta: dict[str, Any]) -> float:
    """The weight of a weight file's ``band`` entry (:func:`band_meta`).

    Raises:
        WeightFileError: a band of other sigmas or blocks than this version computes, or without a numeric weight.
    """
    expected = {k: v for k, v in band_meta(0.0).items() if k != "weight"}
    if not isinstance(meta, dict) or {k: v for k, v in meta.items() if k != "weight"} != expected:
        raise WeightFileError(f"a wide band this version does not compute: {meta}")
    try:
        return float(meta["weight"])
    except (KeyError, TypeError, ValueError):
        raise WeightFileError(f"the wide band's weight is missing or not a number: {meta}") from None


def band_reach() -> int:
    """How many input rows beyond its own a row of the band depends on (its blurs, its energy, the interpolation)."""
    return BLOCK * (kernel_radius(SIGMAS[1] / BLOCK) + kernel_radius(ENERGY_SIGMA / BLOCK) + 2)


def block_means(gray: np.ndarray) -> np.ndarray:
    """``(H, W)`` float32 -> ``(ceil(H / BLOCK), ceil(W / BLOCK))``: the mean of each block, the image reflected
    (reflect-101) beyond its bottom and right borders to whole blocks."""
    h, w = check_gray(gray, finite=False).shape  # a uint8 image would be averaged as 0-255 intensities
    bottom, right = -h % BLOCK, -w % BLOCK
    if bottom or right:
        gray = cv2.copyMakeBorder(gray, 0, bottom, 0, right, cv2.BORDER_REFLECT_101)
    # cv2.INTER_AREA at an integer factor: the exact block means, 10x faster than NumPy's
    return cv2.resize(gray, (gray.shape[1] // BLOCK, gray.shape[0] // BLOCK), interpolation=cv2.INTER_AREA)


def _band_response(small: np.ndarray) -> np.ndarray:
    fine, coarse = (
        cv2.sepFilter2D(small, cv2.CV_32F, k, k, borderType=cv2.BORDER_REFLECT_101)
        for k in (gaussian_kernel1d(s / BLOCK) for s in SIGMAS)
    )
    return cv2.subtract(fine, coarse)


def wide_band_floor(small: np.ndarray, scale: float) -> float:
    """The band's divisive floor ``c * mean(e)`` over a whole image from its :func:`block_means` (an image
    normalized in strips computes it once)."""
    return divisive_floor(gaussian_energy(_band_response(small), ENERGY_SIGMA / BLOCK), scale)


def wide_band(gray: np.ndarray, tau: float, scale: float = 1.0, floor: float | None = None) -> np.ndarray:
    """The band ``tanh(dn(G_8 * I - G_32 * I) / tau)`` of an image, in (-1, 1).

    Args:
        gray: ``(H, W)`` float32 intensities in [0, 1].
        tau: the equalization's scale (the model's own).
        scale: ``c`` of the divisive floor ``c * mean(e)``.
        floor: the floor itself (:func:`wide_band_floor` of the whole image), overriding ``c * mean(e)``.

    Returns:
        ``(H, W)`` float32.

    Example:
        >>> wide_band(np.random.default_rng(0).random((64, 80), dtype=np.float32), tau=3.0).shape
        (64, 80)
    """
    h, w = gray.shape
    small = divisive_normalization(
        _band_response(block_means(gray)), ENERGY_SIGMA / BLOCK, scale, floor, multiplier=1.0 / tau
    )
    band = cv2.resize(tanh(small, out=small), (small.shape[1] * BLOCK, small.shape[0] * BLOCK))
    return band if band.shape == (h, w) else np.ascontiguousarray(band[:h, :w])
