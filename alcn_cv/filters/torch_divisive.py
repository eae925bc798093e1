"""The torch form of :mod:`alcn_cv.filters.divisive`, differentiable: the same divisive normalization, kornia style.

``divisive_normalization(r) = multiplier * r / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)``, ``e = sqrt(G_sigma * r^2)``
per pixel and ``f = scale * mean(e)`` over each image (Jarrett et al., ICCV 2009). The Gaussian is
:func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d`'s with reflect-101 borders for any image size, so
both forms agree to float rounding (``tests/test_filters_divisive.py``).
"""

from __future__ import annotations

from functools import lru_cache

import torch
from torch import nn

from alcn_cv.filters.divisive import ABSOLUTE_FLOOR
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.filters.torch_separable import filter_columns, filter_rows

__all__ = [
    "DivisiveNormalization2d",
    "divisive_normalization",
    "gaussian_blur",
    "gaussian_energy",
    "inverse_divisor",
]


def _kernel(sigma: float, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    return torch.as_tensor(gaussian_kernel1d(sigma), dtype=dtype, device=device)


@lru_cache(maxsize=64)
def _kernel_on(sigma: float, device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """:func:`gaussian_kernel1d` on ``device``, copied there once, not at every call: on CUDA each copy of a NumPy
    array waits for the work queued before it."""
    with torch.inference_mode(False):  # made in an inference call, the cached tensor would refuse a backward later
        return _kernel(sigma, device, dtype)


def gaussian_blur(x: torch.Tensor, sigma: float, pad: bool = True) -> torch.Tensor:
    """Separable Gaussian blur of ``(B, 1, H, W)`` (:func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d`),
    reflect-101, for any size. ``pad=False``: only where the kernel lies inside, ``(B, 1, H - 2r, W - 2r)``."""
    traced = torch.compiler.is_compiling() or torch.jit.is_tracing()  # a constant of the graph, as it is recorded
    kernel = (_kernel if traced else _kernel_on)(float(sigma), x.device, x.dtype)
    if pad:
        r = kernel.numel() // 2
        x = reflect101_pad(x, r, r, r, r)
    return filter_rows(filter_columns(x, kernel), kernel)


def _blurred_square(response: torch.Tensor, sigma: float, pad: bool = True) -> torch.Tensor:
    """``G_sigma * response^2``, kept positive: its square root and inverse square root stay differentiable where the
    response is exactly flat."""
    return gaussian_blur(response * response, sigma, pad).clamp_min(1e-12)


def gaussian_energy(response: torch.Tensor, sigma: float, pad: bool = True) -> torch.Tensor:
    """``sqrt(G_sigma * response^2)`` of ``(B, 1, H, W)``, per pixel (:func:`alcn_cv.filters.divisive.gaussian_energy`);
    ``pad`` as :func:`gaussian_blur`."""
    return _blurred_square(response, sigma, pad).sqrt()


def inverse_divisor(energy: torch.Tensor, floor: torch.Tensor) -> torch.Tensor:
    """``1 / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)`` for the energy ``e`` ``(B, 1, H, W)`` and the floor ``f``
    (broadcast, e.g. ``(B, 1, 1, 1)``)."""
    return (energy * energy + floor * floor + ABSOLUTE_FLOOR**2).rsqrt()


def divisive_normalization(
    response: torch.Tensor,
    sigma: float,
    scale: float | torch.Tensor,
    floor: torch.Tensor | None = None,
    multiplier: float = 1.0,
) -> torch.Tensor:
    """:func:`alcn_cv.filters.divisive.divisive_normalization` in torch.

    Args:
        response: ``(B, 1, H, W)`` float, unbounded.
        sigma: the energy's Gaussian (pixels).
        scale: ``c`` in ``f = c * mean(e)`` over each image (a float or a 0-d tensor, learnable).
        floor: ``f`` itself, ``(B, 1, 1, 1)``, overriding ``c * mean(e)``.
        multiplier: a factor of the result.

    Returns:
        ``(B, 1, H, W)``, the response's dtype and device. A float16 response is divided in float32 (under autocast
        too, whose float16 the blurs do not take: :mod:`~alcn_cv.filters.torch_separable`): float16's smallest values
        (6e-8) hold neither the floor's ``ABSOLUTE_FLOOR^2`` nor a flat region's energy, whose inverse square root
        would be infinite, and neither does its range hold that inverse square root's gradient.

    Example:
        >>> r = torch.randn(2, 1, 32, 32)
        >>> divisive_normalization(r, sigma=2.0, scale=1.0).shape
        torch.Size([2, 1, 32, 32])
    """
    if response.dtype == torch.float16:
        wide = None if floor is None else floor.float()
        return divisive_normalization(response.float(), sigma, scale, wide, multiplier).to(response.dtype)
    squared = _blurred_square(response, sigma)  # e^2 itself: no square root squared again
    if floor is None:
        floor = scale * squared.sqrt().mean(dim=(-2, -1), keepdim=True)
    offset = floor * floor + ABSOLUTE_FLOOR**2
    if torch.is_grad_enabled() and any(isinstance(v, torch.Tensor) and v.requires_grad for v in (response, offset)):
        result = (squared + offset).rsqrt() * response
        return result if multiplier == 1.0 else result * multiplier
    # no gradient asked for: the same operations in place, fewer full-size arrays
    result = squared.add_(offset).rsqrt_().mul_(response)
    return result if multiplier == 1.0 else result.mul_(multiplier)


class DivisiveNormalization2d(nn.Module):
    """Module form of :func:`divisive_normalization`: ``(B, 1, H, W)`` float -> ``(B, 1, H, W)``, the same dtype,
    unbounded (a response of unit local energy maps to about unit magnitude).

    Args:
        sigma: the energy's Gaussian (pixels).
        scale: ``c`` of the floor ``c * mean(e)``.

    Example:
        >>> DivisiveNormalization2d(sigma=2.0)(torch.randn(2, 1, 32, 32)).shape
        torch.Size([2, 1, 32, 32])
    """

    def __init__(self, sigma: float, scale: float = 1.0) -> None:
        super().__init__()
        self.sigma, self.scale = float(sigma), float(scale)

    def forward(self, response: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        return divisive_normalization(response, self.sigma, self.scale, floor)

    def extra_repr(self) -> str:
        return f"sigma={self.sigma}, scale={self.scale}"
