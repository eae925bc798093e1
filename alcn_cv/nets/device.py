"""The torch device a network runs or trains on, checked before any work starts."""

from __future__ import annotations

import torch

from alcn_cv.errors import InputError

__all__ = ["torch_device"]


def torch_device(name: str | torch.device | None = None, what: str = "device") -> torch.device:
    """``name`` (``"cpu"``, ``"cuda"``, ``"cuda:1"``, ...) as a :class:`torch.device`; ``None``:
    CUDA where torch sees a CUDA device, else the CPU.

    Raises:
        InputError: not a device's name, a CUDA device asked for where torch sees none (or not that one), or a device
            of a type this torch cannot use here (mps, xpu, ...; ``what`` names the setting).
    """
    if name is None:
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    try:
        device = torch.device(name)
    except (RuntimeError, TypeError):
        raise InputError(f"{what} is {name!r}, not a torch device (cpu, cuda, cuda:1, ...)") from None
    if device.type == "cuda" and not torch.cuda.is_available():
        raise InputError(f"{what} is {name!r} but torch sees no CUDA device")
    if device.type == "cuda" and device.index is not None and device.index >= torch.cuda.device_count():
        raise InputError(f"{what} is {name!r} but torch sees {torch.cuda.device_count()} CUDA device(s), from cuda:0")
    if device.type not in ("cpu", "cuda"):
        try:  # mps, xpu, ...: a build without them says so only when a tensor goes there
            torch.empty(0, device=device)
        except RuntimeError:  # whose message lists every backend torch has
            raise InputError(f"{what} is {name!r}, but torch cannot use {device.type} devices here") from None
    return device
