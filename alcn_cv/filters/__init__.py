"""Filtering operations: ALCN's Gaussian mixture and per-window standardization.

:mod:`~alcn_cv.filters.gaussian_mixture` (NumPy/OpenCV) imports no torch; the differentiable
:func:`gaussian_mixture2d` and :class:`GaussianMixture2d` (kornia) load torch on first use. Each
step has its NumPy/OpenCV module and its torch twin (``torch_*``): the divisive normalization, the
wide band, the CIE Lab of colour images (:mod:`~alcn_cv.filters.lab`, :mod:`~alcn_cv.filters.torch_lab`).
"""

from alcn_cv.filters.gaussian_mixture import (
    alcn_filter,
    gaussian_blur_stack,
    gaussian_kernel1d,
    gaussian_sigmas,
    kernel_radius,
)
from alcn_cv.filters.standardize import standardize_windows

__all__ = [
    "GaussianMixture2d",
    "alcn_filter",
    "gaussian_blur_stack",
    "gaussian_kernel1d",
    "gaussian_mixture2d",
    "gaussian_sigmas",
    "kernel_radius",
    "standardize_windows",
]


def __getattr__(name: str):
    if name in ("GaussianMixture2d", "gaussian_mixture2d"):
        from alcn_cv.filters import kornia_mixture

        return getattr(kornia_mixture, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
