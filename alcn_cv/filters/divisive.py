"""Divisive normalization, on a grid or per pixel: the gain Normalizer's last step before its equalization.

After Jarrett et al., ICCV 2009 (DLCN: the response divided by its local standard deviation,
floored by the image's mean of it), computed on a coarse grid so that it costs two
full-resolution passes (the squared response averaged over cells, the divisor interpolated
back): ``response / sqrt(e^2 + f^2)`` with ``e`` the root-mean-square of the response over the
cells of side ``stride`` centred on the grid points ``(stride*i, stride*j)`` and ``f = scale *
mean(e)``. Invariant to a gain of the whole response; a flat region of a contrasted image stays
flat. The torch form, differentiable, is :meth:`alcn_cv.nets.gain.GainNormalizer.divide`.

With ``sigma`` the energy is per pixel instead, ``e = sqrt(G_sigma * r^2)`` (:func:`gaussian_energy`,
the local standard deviation of DLCN itself with a Gaussian window, no grid): it follows the
response's edges at the scale of the kernels, not of the cells.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d, upsample_grid

__all__ = ["ABSOLUTE_FLOOR", "cell_rms", "divisive_normalization", "gaussian_energy"]

#: Added (squared) to every divisor, in intensity units ([0, 1]): a 40th of an 8-bit level, far
#: below any real texture, so that a flat image's response, float rounding only, stays near zero
#: instead of being divided up to order one (and differently by each runtime).
ABSOLUTE_FLOOR = 1e-4


def cell_rms(response: np.ndarray, stride: int) -> np.ndarray:
    """``(ceil((H-1)/s)+1, ceil((W-1)/s)+1)`` float32: the root-mean-square of ``response``
    ``(H, W)`` over the cells of side ``s = stride`` centred on the grid points (reflect-101
    beyond the borders)."""
    before = stride // 2
    after = 2 * stride - 2 - before  # H + 2s - 2 rows hold exactly ceil((H-1)/s)+1 cells
    h, w = response.shape
    gh, gw = math.ceil((h - 1) / stride) + 1, math.ceil((w - 1) / stride) + 1
    padded = cv2.copyMakeBorder(response * response, before, after, before, after, cv2.BORDER_REFLECT_101)
    cells = cv2.resize(padded[: gh * stride, : gw * stride], (gw, gh), interpolation=cv2.INTER_AREA)
    return np.sqrt(np.maximum(cells, 0.0))


def _blurred_square(response: np.ndarray, sigma: float) -> np.ndarray:
    """``G_sigma * response^2``, reflect-101 beyond the borders. Never negative, float rounding
    included: every term of the blur is a positive weight times a square, so no clip is needed."""
    kernel = gaussian_kernel1d(sigma)
    return cv2.sepFilter2D(cv2.multiply(response, response), cv2.CV_32F, kernel, kernel, borderType=cv2.BORDER_REFLECT_101)


def gaussian_energy(response: np.ndarray, sigma: float) -> np.ndarray:
    """``(H, W)`` float32: ``sqrt(G_sigma * response^2)``, the kernel of
    :func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d`, reflect-101 beyond the borders."""
    return cv2.sqrt(_blurred_square(response, sigma))


def divisive_normalization(
    response: np.ndarray,
    stride: int,
    scale: float,
    floor: float | None = None,
    sigma: float | None = None,
    multiplier: float = 1.0,
) -> np.ndarray:
    """``multiplier * response / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)`` (see the module): ``e`` on
    the grid, the divisor interpolated bilinearly between the grid points, or per pixel with ``sigma``.

    Args:
        response: ``(H, W)`` float32, unbounded.
        stride: the grid's spacing in pixels (>= 1; unused with ``sigma``).
        scale: ``c`` in ``f = c * mean(e)`` (> 0).
        floor: ``f`` itself, overriding ``c * mean(e)`` (an image normalized in strips passes
            ``c`` times the mean of :func:`gaussian_energy` over the whole image).
        sigma: the Gaussian window of a per-pixel energy :func:`gaussian_energy` (pixels), instead
            of the grid's cells.
        multiplier: a factor of the result, folded into its division (the gain Normalizer's
            ``1 / tau``): no pass of its own.

    Returns:
        ``(H, W)`` float32.
    """
    if sigma is not None:
        # e^2 is the blurred square itself: OpenCV passes on it, no square root squared again
        squared = _blurred_square(response, sigma)
        f = scale * float(cv2.mean(cv2.sqrt(squared))[0]) if floor is None else floor
        divisor = cv2.sqrt(cv2.add(squared, f * f + ABSOLUTE_FLOOR**2, dst=squared), dst=squared)
        return cv2.divide(response, divisor, dst=divisor, scale=multiplier)
    e = cell_rms(response, stride)
    f = scale * float(e.mean()) if floor is None else floor
    inverse = (multiplier / np.sqrt(e * e + np.float32(f * f + ABSOLUTE_FLOOR**2))).astype(np.float32)
    upsampled = upsample_grid(inverse, stride, response.shape)
    return cv2.multiply(response, upsampled, dst=upsampled)
