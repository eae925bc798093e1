"""Precision in torch: where float16 and bfloat16 cannot hold ALCN's values (a variance that is the difference of two
nearly equal moments, Eq. 3's difference of two blurs), the operations run in float32, and under a caller's autocast
as well; constants that a cast of a module would round keep their precision."""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import torch
from torch import nn

__all__ = ["ExactBuffers", "at_least_float32", "autocast_enabled"]


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


class ExactBuffers(nn.Module):
    """A module whose buffers named in :attr:`exact_buffers` follow the module to a device but keep their dtype:
    ``.half()`` or ``.to(torch.bfloat16)`` would round them (a Gaussian kernel, the Lab matrix, a fixed ``tau``), a
    cast back to float32 would not restore them, and ``.double()`` would give float32 values in float64. The
    operations that read them cast them to their inputs' dtype (or make them again, for float64).

    Example:
        >>> class Scale(ExactBuffers):
        ...     exact_buffers = ("factor",)
        ...     def __init__(self):
        ...         super().__init__()
        ...         self.register_buffer("factor", torch.tensor(1 / 3))
        >>> Scale().half().float().factor.item() == torch.tensor(1 / 3).item()
        True
    """

    #: The names of the buffers that keep their dtype (a name that is not a buffer, a parameter say, is cast).
    exact_buffers: ClassVar[tuple[str, ...]] = ()

    def _apply(self, fn: Callable[[torch.Tensor], torch.Tensor], recurse: bool = True) -> ExactBuffers:
        kept = {name: self._buffers.get(name) for name in self.exact_buffers}
        super()._apply(fn, recurse)
        for name, before in kept.items():
            after = self._buffers.get(name)
            if before is not None and after is not None and after.dtype != before.dtype:
                self._buffers[name] = before.to(after.device)
        return self
