"""Filtering operations: the steps of ALCN and of the gain Normalizers, each in NumPy/OpenCV and in torch.

* :mod:`~alcn_cv.filters.gaussian_mixture` -- ALCN's Gaussian mixture (Eq. 1 and 3), exact, from a grid or on a
  pyramid; its differentiable twin :mod:`~alcn_cv.filters.kornia_mixture` (:func:`gaussian_mixture2d`,
  :class:`GaussianMixture2d`);
* :mod:`~alcn_cv.filters.divisive` and :mod:`~alcn_cv.filters.torch_divisive` -- the divisive normalization;
* :mod:`~alcn_cv.filters.wide_band` and :mod:`~alcn_cv.filters.torch_wide_band` -- the wide band;
* :mod:`~alcn_cv.filters.equalization` -- the contrast equalization's ``tanh`` through OpenCV's ``exp``;
* :mod:`~alcn_cv.filters.lab` and :mod:`~alcn_cv.filters.torch_lab` -- the CIE Lab of colour images;
* :mod:`~alcn_cv.filters.torch_resize`, :mod:`~alcn_cv.filters.torch_separable` and
  :mod:`~alcn_cv.filters.torch_pad` -- resizes, separable filters and reflect-101 borders in torch;
* :mod:`~alcn_cv.filters.torch_precision` -- float32 where float16 and bfloat16 cannot hold ALCN's values, and
  constants that a cast of a module leaves exact;
* :mod:`~alcn_cv.filters.standardize` -- per-window standardization.

The NumPy/OpenCV modules import no torch; :func:`gaussian_mixture2d` and :class:`GaussianMixture2d` load it on
first use.
"""

from alcn_cv.filters.gaussian_mixture import (
    alcn_filter,
    gaussian_blur_stack,
    gaussian_kernel1d,
    gaussian_sigmas,
    kernel_radius,
)
from alcn_cv.filters.standardize import standardize_windows

# GaussianMixture2d and gaussian_mixture2d (torch) are not star-imported: `from alcn_cv.filters import *` imports no
# torch, as a base install has none
__all__ = [
    "alcn_filter",
    "gaussian_blur_stack",
    "gaussian_kernel1d",
    "gaussian_sigmas",
    "kernel_radius",
    "standardize_windows",
]


def __getattr__(name: str) -> object:
    if name in ("GaussianMixture2d", "gaussian_mixture2d"):
        from alcn_cv.filters import kornia_mixture

        return getattr(kornia_mixture, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
