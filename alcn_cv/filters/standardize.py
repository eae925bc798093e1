"""Per-window standardization: zero mean and unit variance over each window.

The one implementation of the package, for NumPy arrays and torch tensors alike (the same
formula, so the trainer, the detector's second stage and the benchmarks agree): over the last
two axes, ``(x - mean) / (std + eps)`` with the population standard deviation.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, TypeVar

import numpy as np

if TYPE_CHECKING:
    import torch

__all__ = ["STANDARDIZE_EPS", "standardize_windows"]

ArrayT = TypeVar("ArrayT", np.ndarray, "torch.Tensor")

#: ``eps`` of the detector input's per-window standardization in training, both stages (the shipped Normalizers
#: were trained with it).
STANDARDIZE_EPS = 1e-4


def standardize_windows(windows: ArrayT, eps: float = STANDARDIZE_EPS) -> ArrayT:
    """Standardize every window over its last two axes.

    Args:
        windows: ``(..., H, W)`` NumPy float array or torch tensor (e.g. ``(n, H, W)`` or
            ``(B, 1, H, W)``), any value range.
        eps: added to the standard deviation, so constant windows map to zero.

    Returns:
        The same shape; float32 for NumPy input, the input's dtype and device for a tensor.
    """
    if isinstance(windows, np.ndarray):
        w = windows.astype(np.float32, copy=False)
        mean = w.mean(axis=(-2, -1), keepdims=True)
        std = w.std(axis=(-2, -1), keepdims=True)
        return ((w - mean) / (std + np.float32(eps))).astype(np.float32, copy=False)
    mean = windows.mean(dim=(-2, -1), keepdim=True)
    std = windows.std(dim=(-2, -1), keepdim=True, unbiased=False)
    return (windows - mean) / (std + eps)
