r"""The Gaussian mixture at the heart of ALCN (Rad, Roth & Lepetit, BMVC 2017, Sec. 3.1 and 3.3).

The normalized image is a linear combination of Gaussian-filtered images:

* Eq. 1, one weight vector for the whole image (or window)::

      ALCN(I) = (sum_i w_i G_{sigma_i}) * I

* Eq. 3, per-pixel weight maps F_k predicted by the Normalizer run fully-convolutionally::

      ALCN(I) = sum_k G_{sigma_k} * (F_k o I)

with ``sigma_i = i / 2`` for ``i = 1..10`` by default (:func:`gaussian_sigmas`).

Kernel definition, identical in every implementation here: a sampled Gaussian
``exp(-x^2 / (2 sigma^2))`` on ``x = -r..r`` with ``r = int(truncate * sigma + 0.5)``
(``truncate = 3``), normalized to sum 1 -- the kernel of
``scipy.ndimage.gaussian_filter(..., truncate=3)``. Border rule: reflect-101
(``cv2.BORDER_REFLECT_101``, scipy's ``mode="mirror"``, torch's ``"reflect"``), OpenCV's default.

Two implementations that agree to 1e-5:

* :func:`alcn_filter` -- NumPy/OpenCV, for inference (``float32`` arrays in and out);
* :func:`~alcn_cv.filters.kornia_mixture.gaussian_mixture2d` and
  :class:`~alcn_cv.filters.kornia_mixture.GaussianMixture2d` -- differentiable, on kornia's
  Gaussian filtering, for training (gradients reach the weights and the image). They live in
  their own module so that this one, and the OpenCV runtime, never import torch.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from alcn_cv.errors import InputError

DEFAULT_NUM_KERNELS = 10
DEFAULT_SIGMA_STEP = 0.5
TRUNCATE = 3.0

__all__ = [
    "alcn_filter",
    "check_sigmas",
    "gaussian_blur_stack",
    "gaussian_kernel1d",
    "gaussian_sigmas",
    "kernel_radius",
]


def gaussian_sigmas(num_kernels: int = DEFAULT_NUM_KERNELS, step: float = DEFAULT_SIGMA_STEP) -> tuple[float, ...]:
    """Standard deviations of the basis: ``sigma_i = i * step`` for ``i = 1..num_kernels`` (pixels)."""
    if num_kernels < 1 or step <= 0:
        raise InputError(f"need num_kernels >= 1 and step > 0, got {num_kernels} and {step}")
    return tuple(float(i * step) for i in range(1, num_kernels + 1))


def kernel_radius(sigma: float) -> int:
    """Half-width of the sampled kernel of ``sigma``: ``int(3 * sigma + 0.5)`` (at least 1)."""
    return max(1, int(TRUNCATE * sigma + 0.5))


def gaussian_kernel1d(sigma: float) -> np.ndarray:
    """The 1D kernel of ``sigma`` as a float64 array of length ``2 * kernel_radius(sigma) + 1``, sum 1."""
    r = kernel_radius(sigma)
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


def check_sigmas(sigmas: Sequence[float]) -> tuple[float, ...]:
    sigmas = tuple(float(s) for s in sigmas)
    if not sigmas or any(not np.isfinite(s) or s <= 0 for s in sigmas):
        raise InputError(f"sigmas must be positive and finite, got {sigmas}")
    return sigmas


def _check_plane(image: np.ndarray) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.ndim != 2 or image.size == 0:
        shape = getattr(image, "shape", None)
        raise InputError(f"image must be a non-empty HxW array, got shape {shape}")
    if image.dtype != np.float32:
        raise InputError(f"image must be float32, got {image.dtype}")
    return image


def gaussian_blur_stack(image: np.ndarray, sigmas: Sequence[float]) -> np.ndarray:
    """Blur one image with every kernel of the basis (OpenCV, reflect-101).

    Args:
        image: ``(H, W)`` float32.
        sigmas: the basis' standard deviations, in pixels.

    Returns:
        ``(N, H, W)`` float32, ``out[i] = G_{sigma_i} * image``.
    """
    image = _check_plane(image)
    sigmas = check_sigmas(sigmas)
    out = np.empty((len(sigmas),) + image.shape, np.float32)
    for i, s in enumerate(sigmas):
        k = gaussian_kernel1d(s)
        cv2.sepFilter2D(image, cv2.CV_32F, k, k, dst=out[i], borderType=cv2.BORDER_REFLECT_101)
    return out


def alcn_filter(image: np.ndarray, weights: np.ndarray, sigmas: Sequence[float] | None = None) -> np.ndarray:
    """ALCN's Gaussian mixture on NumPy arrays (OpenCV filtering, reflect-101 borders).

    Args:
        image: ``(H, W)`` float32 image, intensities nominally in [0, 1].
        weights: ``(N,)`` -- one weight per kernel for the whole image (Eq. 1), or
            ``(N, H, W)`` -- per-pixel weight maps F_k (Eq. 3). float32 or float64.
        sigmas: ``N`` standard deviations in pixels; default :func:`gaussian_sigmas` of ``N``.

    Returns:
        ``(H, W)`` float32 normalized image (unbounded; DoG-like weights give values around 0).

    Example:
        >>> img = np.random.rand(64, 64).astype(np.float32)
        >>> dog = np.zeros(10); dog[0], dog[2] = 1.0, -1.0   # G_0.5 - G_1.5
        >>> alcn_filter(img, dog).shape
        (64, 64)
    """
    image = _check_plane(image)
    weights = np.asarray(weights)
    if weights.ndim not in (1, 3) or weights.shape[0] == 0:
        raise InputError(f"weights must have shape (N,) or (N, H, W), got {weights.shape}")
    if weights.ndim == 3 and weights.shape[1:] != image.shape:
        raise InputError(f"weight maps {weights.shape[1:]} do not match the image {image.shape}")
    if not np.isfinite(weights).all():
        raise InputError("weights contain NaN or inf")
    sigmas = gaussian_sigmas(weights.shape[0]) if sigmas is None else check_sigmas(sigmas)
    if len(sigmas) != weights.shape[0]:
        raise InputError(f"{weights.shape[0]} weights for {len(sigmas)} sigmas")

    out = np.zeros(image.shape, np.float32)
    blurred = np.empty(image.shape, np.float32)
    for i, s in enumerate(sigmas):
        k = gaussian_kernel1d(s)
        if weights.ndim == 1:
            if weights[i] == 0:
                continue
            cv2.sepFilter2D(image, cv2.CV_32F, k, k, dst=blurred, borderType=cv2.BORDER_REFLECT_101)
            cv2.scaleAdd(blurred, float(weights[i]), out, dst=out)
        else:
            product = cv2.multiply(image, weights[i].astype(np.float32, copy=False))
            cv2.sepFilter2D(product, cv2.CV_32F, k, k, dst=blurred, borderType=cv2.BORDER_REFLECT_101)
            cv2.add(out, blurred, dst=out)
    return out
