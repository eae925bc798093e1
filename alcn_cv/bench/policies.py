"""The detector's input policies of the detection benchmark (:data:`~alcn_cv.bench.detect_settings.POLICIES`).

The same policy serves every method: ``raw`` (one fixed affine map), ``standardize`` (each
32x32 window alone) and ``local`` (every pixel by its 31x31 neighbourhood); see
:data:`~alcn_cv.bench.detect_settings.POLICY_DESCRIPTIONS`.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from alcn_cv.bench.detect_settings import CROP, POLICIES
from alcn_cv.errors import InputError
from alcn_cv.filters.standardize import standardize_windows

__all__ = ["BENCH_STANDARDIZE_EPS", "LOCAL_BOX", "InputPolicy", "centre_windows", "local_standardize"]

#: Side of the box of the ``local`` policy: the detector window's size made odd.
LOCAL_BOX = 31

#: Added to the standard deviation by the per-window standardizations of the benchmark (the ``standardize`` and
#: ``local`` input policies): smaller than training's :data:`~alcn_cv.filters.standardize.STANDARDIZE_EPS`, because
#: the benchmark standardizes the raw output of every method, some of them (a DoG of [0, 1] intensities) of a far
#: smaller amplitude than ALCN's.
BENCH_STANDARDIZE_EPS = 1e-6


def centre_windows(windows: np.ndarray, size: int = CROP) -> np.ndarray:
    """The ``size x size`` centres of ``(n, S, S)`` windows (``S >= size``)."""
    s = windows.shape[-1]
    o = (s - size) // 2
    return windows[:, o : o + size, o : o + size]


def local_standardize(image: np.ndarray, size: int = LOCAL_BOX, eps: float = BENCH_STANDARDIZE_EPS) -> np.ndarray:
    """Standardize every pixel by the mean and standard deviation of the ``size x size`` box around it.

    Box filters with reflect-101 borders. An image operation, so a detector runs densely on
    its output; close to per-window standardization at a window's centre.

    Args:
        image: ``(H, W)`` float32.
        size: odd box side in pixels (default 31, the detector window's size made odd).
        eps: added to the standard deviation.

    Returns:
        ``(H, W)`` float32.
    """
    box = (size, size)
    mean = cv2.boxFilter(image, cv2.CV_32F, box, borderType=cv2.BORDER_REFLECT_101)
    sq = cv2.boxFilter(image * image, cv2.CV_32F, box, borderType=cv2.BORDER_REFLECT_101)
    std = np.sqrt(np.maximum(sq - mean * mean, 0.0))
    return ((image - mean) / (std + np.float32(eps))).astype(np.float32)


class InputPolicy:
    """The detector's input policy (see the module docstring).

    Args:
        name: ``raw``, ``standardize`` or ``local``.
        train_windows: ``(n, S, S)`` normalized training windows (``raw`` fits its mean and
            standard deviation on their 32x32 centres).
    """

    def __init__(self, name: str, train_windows: np.ndarray) -> None:
        if name not in POLICIES:
            raise InputError(f"unknown input policy {name!r}; choose from {', '.join(POLICIES)}")
        self.name = name
        centres = centre_windows(train_windows, CROP)
        self.mean = float(centres.mean())
        self.std = float(centres.std()) or 1.0

    def windows(self, windows: np.ndarray, size: int = CROP) -> np.ndarray:
        """``(n, S, S)`` normalized windows -> ``(n, size, size)`` detector inputs (their centres;
        ``size`` larger than 32 only with the dense policies, for networks that take context)."""
        if self.name == "local":
            return centre_windows(np.stack([local_standardize(w) for w in windows]), size)
        if self.name == "standardize" and size != CROP:
            raise InputError("per-window standardization scores bare 32x32 windows; it takes no context")
        centres = centre_windows(windows, size)
        if self.name == "standardize":
            return standardize_windows(centres, eps=BENCH_STANDARDIZE_EPS)
        return ((centres - np.float32(self.mean)) / np.float32(self.std)).astype(np.float32)

    def image(self, image: np.ndarray) -> np.ndarray:
        """A whole normalized image -> the detector's dense input (``raw`` and ``local``)."""
        if self.name == "local":
            return local_standardize(image)
        if self.name == "raw":
            return ((image - np.float32(self.mean)) / np.float32(self.std)).astype(np.float32)
        raise InputError("per-window standardization has no whole-image form; score windows one by one")

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "mean": self.mean, "std": self.std} if self.name == "raw" else {"name": self.name}
