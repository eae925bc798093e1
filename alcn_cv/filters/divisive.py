"""Divisive normalization per pixel: the gain Normalizer's last step before its equalization.

After Jarrett et al., ICCV 2009 (DLCN: the response divided by its local standard deviation, floored by the
image's mean of it): ``response / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)`` with ``e = sqrt(G_sigma * r^2)`` and
``f = scale * mean(e)``. Invariant to a gain of the whole response; a flat region of a contrasted image stays
flat. The torch form, differentiable, is :mod:`alcn_cv.filters.torch_divisive`.
"""

from __future__ import annotations

import cv2
import numpy as np

from alcn_cv.checks import check_gray
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d

__all__ = [
    "ABSOLUTE_FLOOR",
    "blurred_square",
    "divide_by_energy",
    "divisive_floor",
    "divisive_normalization",
    "gaussian_energy",
]

#: Added (squared) to every divisor, in intensity units ([0, 1]): a 40th of an 8-bit level, far
#: below any real texture, so that a flat image's response, float rounding only, stays near zero
#: instead of being divided up to order one (and differently by each runtime).
ABSOLUTE_FLOOR = 1e-4


def blurred_square(response: np.ndarray, sigma: float, dst: np.ndarray | None = None) -> np.ndarray:
    """``(H, W)`` float32: ``e^2 = G_sigma * response^2``, reflect-101 beyond the borders, in ``dst`` when given
    (OpenCV's ``dst``). Never negative, float rounding included: every term of the blur is a positive weight
    times a square, so no clip is needed."""
    kernel = gaussian_kernel1d(sigma)
    square = cv2.multiply(check_gray(response, finite=False), response)  # OpenCV's errors name no argument
    return cv2.sepFilter2D(square, cv2.CV_32F, kernel, kernel, dst=dst, borderType=cv2.BORDER_REFLECT_101)


def gaussian_energy(response: np.ndarray, sigma: float) -> np.ndarray:
    """``(H, W)`` float32: ``sqrt(G_sigma * response^2)``, the kernel of
    :func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d`, reflect-101 beyond the borders."""
    return cv2.sqrt(blurred_square(response, sigma))


def divisive_normalization(
    response: np.ndarray, sigma: float, scale: float, floor: float | None = None, multiplier: float = 1.0
) -> np.ndarray:
    """``multiplier * response / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)`` (see the module).

    Args:
        response: ``(H, W)`` float32, unbounded.
        sigma: the Gaussian window of the energy :func:`gaussian_energy` (pixels).
        scale: ``c`` in ``f = c * mean(e)`` (> 0).
        floor: ``f`` itself, overriding ``c * mean(e)`` (an image normalized in strips passes
            ``c`` times the mean of :func:`gaussian_energy` over the whole image).
        multiplier: a factor of the result, folded into its division (the gain Normalizer's
            ``1 / tau``): no pass of its own.

    Returns:
        ``(H, W)`` float32.

    Example:
        >>> r = np.random.default_rng(0).normal(size=(32, 32)).astype(np.float32)
        >>> divisive_normalization(r, sigma=2.0, scale=1.0).shape
        (32, 32)
    """
    squared = blurred_square(response, sigma)
    if floor is None:
        floor = divisive_floor(cv2.sqrt(squared), scale)
    return divide_by_energy(response, squared, floor, multiplier)


def divisive_floor(energy: np.ndarray, scale: float) -> float:
    """The floor ``f = scale * mean(e)`` of an image's energy ``e`` (:func:`gaussian_energy`)."""
    return scale * float(cv2.mean(energy)[0])


def divide_by_energy(response: np.ndarray, squared: np.ndarray, floor: float, multiplier: float = 1.0) -> np.ndarray:
    """``multiplier * response / sqrt(squared + floor^2 + ABSOLUTE_FLOOR^2)``: :func:`divisive_normalization`'s
    division, for a caller that computes ``e^2`` (``squared``, the :func:`blurred_square` of the response) and
    the floor itself (over an image's rows in parts). The result is computed in ``squared``, which it returns."""
    # e^2 is the blurred square itself: OpenCV passes on it, no square root squared again
    divisor = cv2.sqrt(cv2.add(squared, floor * floor + ABSOLUTE_FLOOR**2, dst=squared), dst=squared)
    return cv2.divide(response, divisor, dst=divisor, scale=multiplier)
