"""Linear and local-contrast normalizations: the classical baselines of ALCN's Sec. 4.3.

All work on a float32 ``HxW`` image in [0, 1] (:meth:`Normalization.normalize`) with the
Gaussian kernels of :mod:`alcn_cv.filters.gaussian_mixture` (sampled, truncated at 3 sigma,
reflect-101 borders), so a sigma means the same thing here as in ALCN's mixture. Sigmas and
window sizes are in pixels of the image they are applied to.

* ``ns`` -- :class:`Standardization`
* ``dog`` -- :class:`DifferenceOfGaussians`
* ``whitening`` -- :class:`Whitening`
* ``slcn`` / ``dlcn`` -- :class:`SubtractiveLCN` / :class:`DivisiveLCN`
* ``lrn`` -- :class:`LocalResponseNormalization`
"""

from __future__ import annotations

import cv2
import numpy as np

from alcn_cv.checks import check_positive, to_unit_float
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import gaussian_blur_stack, kernel_radius

__all__ = [
    "DifferenceOfGaussians",
    "DivisiveLCN",
    "LocalResponseNormalization",
    "Standardization",
    "SubtractiveLCN",
    "Whitening",
]


def _blur(gray: np.ndarray, sigma: float) -> np.ndarray:
    return gaussian_blur_stack(gray, (sigma,))[0]


@register
class Standardization(Normalization):
    """Normalization by standardization (NS): zero mean and unit variance over the image.

    ``NS(I) = (I - mean(I)) / (std(I) + eps)``, the input normalization of most CNNs
    (e.g. LeCun et al., "Efficient BackProp", 1998), one of the baselines of Rad et al. 2017.

    Args:
        eps: added to the standard deviation (intensity units) so a flat image stays finite.
    """

    name = "ns"
    summary = "standardization: zero mean and unit variance over the whole image"
    reference = "LeCun, Bottou, Orr & Mueller, Efficient BackProp, 1998"
    output_range = (-3.0, 3.0)

    def __init__(self, eps: float = 1e-6) -> None:
        self.eps = check_positive("eps", eps)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return self._standardize(gray, cv2.meanStdDev(gray))

    def _standardize(self, gray: np.ndarray, mean_std: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        mean, std = mean_std
        return (gray - np.float32(mean[0, 0])) / np.float32(std[0, 0] + self.eps)

    def _apply_gray_uint8(self, gray8: np.ndarray) -> np.ndarray:
        # a function of the intensity given the image's mean and deviation: one lookup
        mean_std = cv2.meanStdDev(to_unit_float(gray8))
        return self._lookup_uint8(gray8, lambda levels: self._standardize(levels, mean_std))


@register
class DifferenceOfGaussians(Normalization):
    """Difference of Gaussians (DoG): a band-pass filter ``G_sigma1 * I - G_sigma2 * I``.

    The classical centre-surround normalization (Marr & Hildreth, "Theory of edge detection",
    Proc. R. Soc. Lond. B 1980); a fixed special case of ALCN's mixture (Eq. 1 with two
    non-zero weights +1 and -1). Agrees with ``skimage.filters.difference_of_gaussians(I,
    sigma1, sigma2, mode="mirror", truncate=3)``.

    Args:
        sigma1: standard deviation of the centre Gaussian (pixels). Default 0.5. (``tantriggs``'s ``sigma1``, the
            paper's name, is its surround.)
        sigma2: standard deviation of the surround Gaussian (pixels), ``> sigma1``. Default
            1.5 (how the default pair was chosen: ``docs/journal.md``).

    Raises:
        InputError: a sigma not positive and finite, or ``sigma2 <= sigma1``.
    """

    name = "dog"
    summary = "difference of Gaussians G_sigma1 * I - G_sigma2 * I, a band-pass filter"
    reference = "Marr & Hildreth, Theory of edge detection, Proc. R. Soc. Lond. B 1980"
    output_range = (-0.1, 0.1)

    def __init__(self, sigma1: float = 0.5, sigma2: float = 1.5) -> None:
        self.sigma1 = check_positive("sigma1", sigma1)
        self.sigma2 = check_positive("sigma2", sigma2)
        if self.sigma2 <= self.sigma1:
            raise InputError(f"sigma2 must be larger than sigma1, got {self.sigma1} and {self.sigma2}")

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        centre, surround = gaussian_blur_stack(gray, (self.sigma1, self.sigma2))
        return centre - surround

    def _tiling(self, shape: tuple[int, int]) -> tuple[int, int]:
        return kernel_radius(self.sigma2), 1


@register
class SubtractiveLCN(Normalization):
    """Subtractive local contrast normalization (SLCN): ``v = I - G_sigma * I``.

    Jarrett, Kavukcuoglu, Ranzato & LeCun, "What is the best multi-stage architecture for
    object recognition?", ICCV 2009 (the subtractive step, with a normalized Gaussian
    weighting window).

    Args:
        sigma: standard deviation of the Gaussian weighting window (pixels). Default 2.0.
    """

    name = "slcn"
    summary = "subtractive local contrast normalization: the image minus its Gaussian local mean"
    reference = "Jarrett, Kavukcuoglu, Ranzato & LeCun, ICCV 2009"
    output_range = (-0.1, 0.1)

    def __init__(self, sigma: float = 2.0) -> None:
        self.sigma = check_positive("sigma", sigma)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return gray - _blur(gray, self.sigma)

    def _tiling(self, shape: tuple[int, int]) -> tuple[int, int]:
        return kernel_radius(self.sigma), 1


@register
class DivisiveLCN(Normalization):
    """Divisive local contrast normalization (DLCN), after the subtractive step.

    Jarrett et al., ICCV 2009: ``v = I - G_sigma * I``, ``s = sqrt(G_sigma * v^2)``,
    ``y = v / max(c, s)`` with ``c = mean(s)`` over the image (so that flat regions are not
    amplified), and a floor ``eps`` for a flat image.

    Args:
        sigma: standard deviation of the Gaussian weighting window (pixels). Default 2.0.
        eps: smallest divisor (intensity units). Default 1e-3.
    """

    name = "dlcn"
    summary = "divisive local contrast normalization: slcn divided by the local standard deviation"
    reference = "Jarrett, Kavukcuoglu, Ranzato & LeCun, ICCV 2009"
    output_range = (-3.0, 3.0)

    def __init__(self, sigma: float = 2.0, eps: float = 1e-3) -> None:
        self.sigma = check_positive("sigma", sigma)
        self.eps = check_positive("eps", eps)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        v = gray - _blur(gray, self.sigma)
        s = np.sqrt(np.maximum(_blur(v * v, self.sigma), 0.0))
        divisor = np.maximum(s, max(float(s.mean()), self.eps))
        return v / divisor


@register
class LocalResponseNormalization(Normalization):
    """Local response normalization (LRN) within the image plane.

    Krizhevsky, Sutskever & Hinton, "ImageNet classification with deep convolutional neural
    networks", NIPS 2012, Sec. 3.3: ``b = a / (k + alpha / n * sum a^2)^beta``. A grayscale
    image has a single channel, so the sum runs over the ``size x size`` spatial
    neighbourhood (Caffe's ``WITHIN_CHANNEL`` mode, ``alpha`` divided by ``size^2``, sum
    with reflect-101 borders). The activity ``a`` is the zero-mean image ``I - mean(I)``
    (the networks' usual input; on raw positive intensities LRN is a pointwise gamma).
    On an image constant along one axis this equals ``torch.nn.LocalResponseNorm(size,
    alpha, beta, k)`` run across that axis (away from the borders).

    Args:
        size: side of the square neighbourhood (pixels, odd). Default 9.
        alpha: scale of the summed energy. Default 1.0 (intensities are in [0, 1], not
            the 0-255 activations of Krizhevsky's k=2, alpha=1e-4).
        beta: exponent. Default 0.75 (Krizhevsky et al.).
        k: additive constant. Default 0.01.
    """

    name = "lrn"
    summary = "local response normalization: divided by the energy of a size x size neighbourhood"
    reference = "Krizhevsky, Sutskever & Hinton, NIPS 2012, Sec. 3.3"
    output_range = (-2.0, 2.0)

    def __init__(self, size: int = 9, alpha: float = 1.0, beta: float = 0.75, k: float = 0.01) -> None:
        if int(size) != size or size < 1 or size % 2 == 0:
            raise InputError(f"size must be a positive odd integer, got {size}")
        self.size = int(size)
        self.alpha = check_positive("alpha", alpha)
        self.beta = check_positive("beta", beta)
        self.k = check_positive("k", k)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        a = gray - np.float32(gray.mean())
        energy = cv2.boxFilter(
            a * a, cv2.CV_32F, (self.size, self.size), normalize=True, borderType=cv2.BORDER_REFLECT_101
        )
        return a / np.power(self.k + self.alpha * np.maximum(energy, 0.0), self.beta)


@register
class Whitening(Normalization):
    """Spectral whitening of natural images (Olshausen & Field, "Sparse coding with an
    overcomplete basis set", Vision Research 1997).

    Natural images have an amplitude spectrum falling as 1/f; the filter
    ``W(f) = f exp(-(f / f0)^4)`` flattens it up to a cut-off ``f0`` (the exponential tames
    the noise at high frequencies). The result is scaled to unit variance over the image
    (whitened data has unit variance), which also removes a global gain. The image is
    mirrored (reflect-101) by half its size on every side before the FFT so the periodic
    boundary does not create edges.

    Args:
        f0: cut-off frequency in cycles per pixel (0.5 is Nyquist). Default 0.4 (Olshausen
            & Field: 200 cycles per 512-pixel picture).
        eps: added to the standard deviation before the division.
    """

    name = "whitening"
    summary = (
        "spectral whitening: the 1/f amplitude spectrum of natural images flattened (one FFT of the whole image: "
        "seconds and gigabytes for a 24-megapixel photograph)"
    )
    reference = "Olshausen & Field, Vision Research 1997"
    output_range = (-3.0, 3.0)

    def __init__(self, f0: float = 0.4, eps: float = 1e-6) -> None:
        self.f0 = check_positive("f0", f0)
        self.eps = check_positive("eps", eps)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        h, w = gray.shape
        ph, pw = h // 2, w // 2
        padded = cv2.copyMakeBorder(gray, ph, ph, pw, pw, cv2.BORDER_REFLECT_101)
        fy = np.fft.fftfreq(padded.shape[0])[:, None]
        fx = np.fft.rfftfreq(padded.shape[1])[None, :]
        f = np.sqrt(fx * fx + fy * fy)
        spectrum = np.fft.rfft2(padded) * (f * np.exp(-((f / self.f0) ** 4)))
        white = np.fft.irfft2(spectrum, s=padded.shape)[ph : ph + h, pw : pw + w]
        return (white / (white.std() + self.eps)).astype(np.float32)
