"""Reflectance estimates from one image: ``intrinsic`` (Retinex) and ``sqi`` (self-quotient image).

Both work in the log domain of a float32 ``HxW`` image in [0, 1] and use the Gaussian kernels
of :mod:`alcn_cv.filters.gaussian_mixture` (reflect-101 borders).
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from alcn_cv.checks import check_positive
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import check_sigmas, gaussian_blur_stack, gaussian_kernel1d

__all__ = ["IntrinsicImage", "SelfQuotientImage", "poisson_reconstruct"]


def poisson_reconstruct(gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """The zero-mean image whose forward differences best match ``(gx, gy)`` in least squares.

    Solves ``laplacian(u) = div(g)`` with Neumann borders by the discrete cosine transform
    (Simchony, Chellappa & Shao, PAMI 1990).

    Args:
        gx: ``(H, W)`` forward differences along x (``u[:, j+1] - u[:, j]``; last column ignored).
        gy: ``(H, W)`` forward differences along y (last row ignored).

    Returns:
        ``(H, W)`` float64 with mean 0.
    """
    h, w = gx.shape
    gx = gx.astype(np.float64, copy=True)
    gy = gy.astype(np.float64, copy=True)
    gx[:, -1] = 0.0
    gy[-1, :] = 0.0
    div = gx.copy()
    div[:, 1:] -= gx[:, :-1]
    div += gy
    div[1:, :] -= gy[:-1, :]
    eig = (2 * np.cos(np.pi * np.arange(h) / h) - 2)[:, None] + (2 * np.cos(np.pi * np.arange(w) / w) - 2)[None, :]
    eig[0, 0] = 1.0
    from scipy import fft  # here: importing alcn_cv would take twice as long with scipy (OpenCV's DCT is even-sized)

    coef = fft.dctn(div, type=2, norm="ortho") / eig
    coef[0, 0] = 0.0
    return fft.idctn(coef, type=2, norm="ortho")


@register
class IntrinsicImage(Normalization):
    """Intrinsic-image (reflectance) estimate by grayscale Retinex.

    Land & McCann, "Lightness and Retinex theory", JOSA 1971; Horn, "Determining lightness
    from an image", CGIP 1974; the Retinex baseline of Grosse, Johnson, Adelson & Freeman,
    "Ground truth dataset and baseline evaluations for intrinsic image algorithms", ICCV 2009:
    in ``log(I + eps)``, gradients smaller than ``threshold`` are attributed to shading and
    set to zero, the rest to reflectance; the log-reflectance is the least-squares
    reintegration of the kept gradients (:func:`poisson_reconstruct`), returned with mean 0.

    Args:
        threshold: gradient magnitude (log-intensity per pixel) below which a gradient is
            shading. Default 0.1.
        eps: added to the intensity before the log (keeps dark pixels finite). Default 0.01.
    """

    name = "intrinsic"
    summary = "intrinsic image (Retinex): small log-gradients taken as shading and removed"
    reference = "Land & McCann, JOSA 1971; Grosse, Johnson, Adelson & Freeman, ICCV 2009"
    output_range = (-2.0, 2.0)

    def __init__(self, threshold: float = 0.1, eps: float = 0.01) -> None:
        if not np.isfinite(threshold) or threshold < 0:
            raise InputError(f"threshold must be >= 0, got {threshold}")
        self.threshold = float(threshold)
        self.eps = check_positive("eps", eps)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        log = np.log(gray.astype(np.float64) + self.eps)
        gx = np.zeros_like(log)
        gy = np.zeros_like(log)
        gx[:, :-1] = np.diff(log, axis=1)
        gy[:-1, :] = np.diff(log, axis=0)
        gx[np.abs(gx) < self.threshold] = 0.0
        gy[np.abs(gy) < self.threshold] = 0.0
        return poisson_reconstruct(gx, gy).astype(np.float32)


def _weighted_gaussian_mean(gray: np.ndarray, sigma: float) -> np.ndarray:
    """Wang et al.'s anisotropic smoothing: the Gaussian mean over the larger side of the window.

    Around each pixel, the window's pixels are split by the window's (Gaussian-weighted) mean
    tau into ``I <= tau`` and ``I > tau``; only the side holding more pixels is averaged, with
    Gaussian weights, so the smoothed image does not cross strong edges (no halo).
    """
    k = gaussian_kernel1d(sigma)
    r = len(k) // 2
    tau = gaussian_blur_stack(gray, (sigma,))[0]
    padded = cv2.copyMakeBorder(gray, r, r, r, r, cv2.BORDER_REFLECT_101)
    h, w = gray.shape
    num_low = np.zeros((h, w), np.float32)
    den_low = np.zeros((h, w), np.float32)
    count_low = np.zeros((h, w), np.float32)
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            shifted = padded[dy : dy + h, dx : dx + w]
            low = (shifted <= tau).astype(np.float32)
            weight = np.float32(k[dy] * k[dx])
            count_low += low
            low *= weight
            den_low += low
            num_low += low * shifted
    # the kernel sums to 1, so the high side holds what the low side does not
    keep_low = 2 * count_low >= (2 * r + 1) ** 2
    tiny = np.float32(1e-12)
    return np.where(keep_low, num_low / np.maximum(den_low, tiny), (tau - num_low) / np.maximum(1 - den_low, tiny))


@register
class SelfQuotientImage(Normalization):
    """Self-quotient image (SQI), multi-scale.

    Wang, Li & Wang, "Self quotient image for face recognition", ICIP 2004 (and "Face
    recognition under varying lighting conditions using self quotient image", FG 2004):
    ``Q_k = I / (F_k * I)`` with ``F_k`` a *weighted* Gaussian of scale ``sigma_k`` (only the
    larger side of the window's mean contributes, see :func:`_weighted_gaussian_mean`),
    mapped through the logarithm and averaged over the scales:
    ``SQI(I) = mean_k log((I + eps) / (F_k * I + eps))``.

    Args:
        sigmas: scales of the smoothing kernels (pixels). Default ``(1.0, 2.0, 4.0)``.
        eps: added to the numerator and denominator (intensity units). Default 0.01.
        weighted: use Wang et al.'s weighted Gaussian (default); ``False`` uses the plain
            Gaussian (faster; equals multi-scale Retinex, Jobson et al. 1997, up to the eps).
    """

    name = "sqi"
    summary = (
        "self-quotient image: the log of the image over its edge-preserving smoothing, multi-scale (slow: the "
        "weighted smoothing is a loop over its kernel's offsets; weighted=False is a Gaussian's)"
    )
    reference = "Wang, Li & Wang, ICIP 2004"
    output_range = (-1.0, 1.0)

    def __init__(self, sigmas: Sequence[float] = (1.0, 2.0, 4.0), eps: float = 0.01, weighted: bool = True) -> None:
        self.sigmas = check_sigmas(sigmas)
        self.eps = check_positive("eps", eps)
        self.weighted = bool(weighted)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        if self.weighted:
            smooth = [_weighted_gaussian_mean(gray, s) for s in self.sigmas]
        else:
            smooth = list(gaussian_blur_stack(gray, self.sigmas))
        numerator = np.log(gray + np.float32(self.eps))
        out = np.zeros_like(gray)
        for s in smooth:
            out += numerator - np.log(np.maximum(s, 0.0) + np.float32(self.eps))
        return out / np.float32(len(smooth))
