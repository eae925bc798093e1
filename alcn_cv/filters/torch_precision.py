"""Precision in torch: where float16 and bfloat16 cannot hold ALCN's values (a variance that is the difference of two
nearly equal moments, Eq. 3's difference of two blurs), the operations run in float32, and under a caller's autocast
as well."""

from __future__ import annotations

import torch

__all__ = ["at_least_float32", "autocast_enabled"]


def at_least_float32(x: torch.Tensor) -> torch.Tensor:
    """``x`` itself if it is float32 or float64, else ``x`` cast to float32 (differentiably).

    Example:
        >>> at_least_float32(torch.zeros(2, dtype=torch.float16)).dtype, at_least_float32(torch.zeros(2)).dtype
        (torch.float32, torch.float32)
    """
    return x if x.dtype in (torch.float32, torch.float64) else x.float()


def autocast_enabled(x: torch.Tensor) -> bool:
    """Whether autocast is on for ``x``'s device type (False for a device without autocast, ``meta``)."""
    device = x.device.type
    return torch.amp.is_autocast_available(device) and torch.is_autocast_enabled(device)
