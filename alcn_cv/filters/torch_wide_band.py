"""The wide band of :mod:`alcn_cv.filters.wide_band` in torch: differentiable, any device, ``(B, 1, H, W)``."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from alcn_cv.filters.torch_divisive import divisive_normalization, gaussian_blur
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.filters.torch_resize import upsample_blocks
from alcn_cv.filters.wide_band import BLOCK, ENERGY_SIGMA, SIGMAS

__all__ = ["block_means", "wide_band"]


def block_means(image: torch.Tensor) -> torch.Tensor:
    """``(B, 1, H, W)`` -> ``(B, 1, ceil(H / BLOCK), ceil(W / BLOCK))``, as
    :func:`alcn_cv.filters.wide_band.block_means`."""
    bottom, right = -image.shape[-2] % BLOCK, -image.shape[-1] % BLOCK
    if bottom or right:
        image = reflect101_pad(image, 0, bottom, 0, right)
    return F.avg_pool2d(image, BLOCK)


def _band_response(small: torch.Tensor) -> torch.Tensor:
    return gaussian_blur(small, SIGMAS[0] / BLOCK) - gaussian_blur(small, SIGMAS[1] / BLOCK)


def wide_band(
    image: torch.Tensor, tau: float | torch.Tensor, scale: float | torch.Tensor = 1.0, floor: torch.Tensor | None = None
) -> torch.Tensor:
    """:func:`alcn_cv.filters.wide_band.wide_band` of ``(B, 1, H, W)`` intensities in [0, 1] -> ``(B, 1, H, W)``
    in (-1, 1); ``floor`` ``(B, 1, 1, 1)`` overrides ``c * mean(e)``.

    Example:
        >>> wide_band(torch.rand(2, 1, 64, 80), tau=3.0).shape
        torch.Size([2, 1, 64, 80])
    """
    h, w = image.shape[-2:]
    small = divisive_normalization(_band_response(block_means(image)), ENERGY_SIGMA / BLOCK, scale, floor)
    return upsample_blocks(torch.tanh(small / tau), BLOCK, (h, w))
