"""The torch form of :mod:`alcn_cv.filters.divisive`, differentiable: the same divisive normalization, kornia style.

``divisive_normalization(r) = multiplier * r / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)``, ``e = sqrt(G_sigma * r^2)``
per pixel and ``f = scale * mean(e)`` over each image (Jarrett et al., ICCV 2009). The Gaussian is
:func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d`'s with reflect-101 borders for any image size, so
both forms agree to float rounding (``tests/test_filters_divisive.py``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.filters.divisive import ABSOLUTE_FLOOR
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d
from alcn_cv.filters.torch_separable import filter_columns, filter_rows

__all__ = [
    "DivisiveNormalization2d",
    "divisive_normalization",
    "gaussian_blur",
    "gaussian_energy",
    "inverse_divisor",
    "reflect101_pad",
]


def _reflect101_along(x: torch.Tensor, dim: int, before: int, after: int) -> torch.Tensor:
    """``x`` padded along ``dim`` by reflect-101 for any pad size: the reflection repeats, with period
    ``2 * (n - 1)``, where the pad is longer than the side ``n`` (a side of one pixel repeats it). A new tensor,
    exact whatever ``x``'s dtype."""
    # copies of x and of x reversed, not an index_select of computed indices: inductor fails on those (torch 2.13,
    # an image shorter than a pad under torch.compile)
    n = x.shape[dim]
    cycle = torch.cat([x, x.flip(dim).narrow(dim, 1, n - 2)], dim) if n > 1 else x  # x, then back without the ends
    period = cycle.shape[dim]
    start = -before % period
    total = before + n + after
    return torch.cat([cycle] * -(-(start + total) // period), dim).narrow(dim, start, total)


def reflect101_pad(x: torch.Tensor, top: int, bottom: int, left: int, right: int) -> torch.Tensor:
    """``(..., H, W)`` padded on the last two dims with reflect-101 (``cv2.BORDER_REFLECT_101``), for any pad size:
    unlike ``F.pad(mode="reflect")``, a pad longer than its side repeats the reflection, as OpenCV does (a side of
    one pixel repeats it).

    Example:
        >>> reflect101_pad(torch.arange(3.0).view(1, 3), 0, 0, 4, 0)[0].tolist()
        [0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0]
    """
    if x.ndim != 4:  # every plane as one of a batch, for F.pad's 2-D reflect
        padded = reflect101_pad(x.reshape(-1, 1, *x.shape[-2:]), top, bottom, left, right)
        return padded.reshape(*x.shape[:-2], *padded.shape[-2:])
    h, w = x.shape[-2:]
    if (max(top, bottom) < h and max(left, right) < w) or torch.onnx.is_in_onnx_export():
        # torch's reflect is reflect-101; one fast pass. Exported as an ONNX Pad, which cv2.dnn (the export's
        # consumer) reflects repeatedly where the pad exceeds the size, as the path below.
        return F.pad(x, (left, right, top, bottom), mode="reflect")
    return _reflect101_along(_reflect101_along(x, -2, top, bottom), -1, left, right)


def gaussian_blur(x: torch.Tensor, sigma: float, pad: bool = True) -> torch.Tensor:
    """Separable Gaussian blur of ``(B, 1, H, W)`` (:func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d`),
    reflect-101, for any size. ``pad=False``: only where the kernel lies inside, ``(B, 1, H - 2r, W - 2r)``."""
    kernel = torch.as_tensor(gaussian_kernel1d(sigma), dtype=x.dtype, device=x.device)
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
        ``(B, 1, H, W)``, the response's dtype and device.

    Example:
        >>> r = torch.randn(2, 1, 32, 32)
        >>> divisive_normalization(r, sigma=2.0, scale=1.0).shape
        torch.Size([2, 1, 32, 32])
    """
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
    """Module form of :func:`divisive_normalization`: ``(B, 1, H, W)`` -> ``(B, 1, H, W)``.

    Args:
        sigma: the energy's Gaussian (pixels).
        scale: ``c`` of the floor ``c * mean(e)``.
    """

    def __init__(self, sigma: float, scale: float = 1.0) -> None:
        super().__init__()
        self.sigma, self.scale = float(sigma), float(scale)

    def forward(self, response: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        return divisive_normalization(response, self.sigma, self.scale, floor)

    def extra_repr(self) -> str:
        return f"sigma={self.sigma}, scale={self.scale}"
