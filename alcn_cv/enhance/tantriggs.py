"""Tan-Triggs illumination normalization: gamma, DoG, contrast equalization (``tantriggs``).

Tan & Triggs, "Enhanced local texture feature sets for face recognition under difficult
lighting conditions", IEEE Transactions on Image Processing 19(6), 2010, Sec. III: a chain of
gamma correction, difference-of-Gaussians filtering and a two-stage contrast equalization
ending in a ``tanh`` compression. The optional masking step of the paper (for faces) is left
out: it needs a mask the caller does not have.
"""

from __future__ import annotations

import numpy as np

from alcn_cv.checks import check_positive
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import gaussian_blur_stack

__all__ = ["TanTriggs", "contrast_equalize"]


def contrast_equalize(image: np.ndarray, alpha: float = 0.1, tau: float = 10.0, eps: float = 1e-6) -> np.ndarray:
    """Tan & Triggs' contrast equalization (TIP 2010, Eqs. 1-3).

    ``I <- I / mean(|I|^alpha)^(1/alpha)``, then ``I <- I / mean(min(tau, |I|)^alpha)^(1/alpha)``,
    then ``I <- tau * tanh(I / tau)``: a robust global rescaling (``alpha < 1`` keeps large
    values from dominating the scale, the truncation at ``tau`` removes their influence in the
    second stage) followed by a compression of the extreme values into ``(-tau, tau)``.

    Args:
        image: ``(H, W)`` float32, any range (typically a band-passed image).
        alpha: the exponent of the robust means. Default 0.1.
        tau: the truncation and compression threshold. Default 10.
        eps: the largest magnitude at or below which the image counts as flat and is returned
            as zeros (the float32 rounding noise of a band-passed flat image would otherwise be
            blown up to full contrast).

    Returns:
        ``(H, W)`` float32 in ``(-tau, tau)``; zeros for a flat image.
    """
    x = image.astype(np.float64)
    magnitude = np.abs(x)
    if not magnitude.max(initial=0.0) > eps:
        return np.zeros(image.shape, np.float32)
    x = x / np.mean(magnitude**alpha) ** (1.0 / alpha)
    x = x / np.mean(np.minimum(tau, np.abs(x)) ** alpha) ** (1.0 / alpha)
    return (tau * np.tanh(x / tau)).astype(np.float32)


@register
class TanTriggs(Normalization):
    """Tan-Triggs preprocessing chain (Tan & Triggs, IEEE TIP 2010, Sec. III).

    1. Gamma correction ``I^gamma`` (intensities in [0, 1]; ``gamma`` in (0, 1] lifts the
       dark regions, compressing the light's gain into a smaller range).
    2. Difference of Gaussians ``G_sigma0 * I - G_sigma1 * I`` (the kernels of
       :mod:`alcn_cv.filters.gaussian_mixture`, as in ``dog``), which removes the slow
       shading gradients and the aliasing/noise at the finest scale.
    3. Contrast equalization (:func:`contrast_equalize`): two robust global rescalings and a
       final ``tau * tanh(I / tau)``.

    The image-wide means of step 3 are part of the method (the paper's), so the output needs
    no per-frame min/max: :attr:`output_range` is ``(-tau, tau)``, the range of the final
    ``tanh``, fixed by the parameters. (With ``alpha = 0.1`` the robust scale is close to the
    geometric mean of ``|I|``, small on a band-passed image, so the equalized values spread
    over much of that range.)

    Args:
        gamma: exponent of the gamma correction. Default 0.2.
        sigma0: inner (centre) Gaussian of the DoG, pixels. Default 1.
        sigma1: outer (surround) Gaussian of the DoG, pixels, ``> sigma0``. Default 2. (The paper's names: the
            ``dog`` method's ``sigma1`` is its centre, this method's ``sigma0``.)
        alpha: exponent of the contrast equalization's robust means. Default 0.1.
        tau: truncation and ``tanh`` threshold of the contrast equalization. Default 10.
    """

    name = "tantriggs"
    summary = "gamma correction, difference of Gaussians, then contrast equalization with a final tanh"
    reference = "Tan & Triggs, IEEE TIP 2010"

    def __init__(
        self, gamma: float = 0.2, sigma0: float = 1.0, sigma1: float = 2.0, alpha: float = 0.1, tau: float = 10.0
    ) -> None:
        self.gamma = check_positive("gamma", gamma)
        self.sigma0 = check_positive("sigma0", sigma0)
        self.sigma1 = check_positive("sigma1", sigma1)
        if self.sigma1 <= self.sigma0:
            raise InputError(f"sigma1 must be larger than sigma0, got {self.sigma0} and {self.sigma1}")
        self.alpha = check_positive("alpha", alpha)
        self.tau = check_positive("tau", tau)
        self.output_range = (-self.tau, self.tau)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        corrected = np.power(np.maximum(gray, 0.0), np.float32(self.gamma))
        # The DoG ignores a constant; removing the mean first keeps the float32 rounding of the
        # blurs small beside the band-passed signal, which the equalization scales up.
        corrected -= np.float32(corrected.mean())
        centre, surround = gaussian_blur_stack(corrected, (self.sigma0, self.sigma1))
        return contrast_equalize(centre - surround, self.alpha, self.tau)
