"""The torch device a network runs or trains on, checked before any work starts."""

from __future__ import annotations

import torch

from alcn_cv.errors import InputError

__all__ = ["torch_device"]


def torch_device(name: str | None = None, what: str = "device") -> torch.device:
    """``name`` (``"cpu"``, ``"cuda"``, ``"cuda:1"``, ...) as a :class:`torch.device`; ``None``:
    CUDA where torch sees a CUDA device, else the CPU.

    Raises:
        InputError: not a device's name, or a CUDA device asked for where torch sees none (``what`` names the
            setting).
    """
    if name is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        raise InputError(f"{what} is {name!r}, not a torch device (cpu, cuda, cuda:1, ...)") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"{what} is {name!r} but torch sees no CUDA device")
    return device
