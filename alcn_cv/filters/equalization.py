"""The contrast equalization's ``tanh`` on float32 arrays (Tan & Triggs, TIP 2010: ``tanh(x / tau)`` compresses the
responses larger than ``tau``), the last step of the gain Normalizers and of their wide band.

``tanh(x) = 2 / (1 + exp(-2x)) - 1``: OpenCV's vectorized ``exp`` and four NumPy passes take a quarter of the time
of NumPy's float32 ``tanh`` (0.2 against 0.8 ms for a 640x480 frame on one core of an AMD EPYC, NumPy 2.4). Within
:data:`TANH_TOLERANCE` of the exact value (the rounding of numbers near 1): far below an 8-bit level. Every runtime
of the gain models computes it so, torch's inference on the CPU included (:func:`alcn_cv.nets.cpu_inference.tanh_`).
"""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["TANH_TOLERANCE", "tanh"]

#: The largest difference of :func:`tanh` from the exact value, measured over float32 inputs of every magnitude
#: (``tests/test_filters_equalization.py``).
TANH_TOLERANCE = 3e-7

_ONE, _TWO, _MINUS_TWO = np.float32(1), np.float32(2), np.float32(-2)


def tanh(x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """``tanh(x)`` of a float32 array of any shape, in ``out`` when given (``x`` itself may be ``out``).

    Args:
        x: float32, C-contiguous, any shape; NaN stays NaN, infinities go to -1 and 1.
        out: float32, C-contiguous, ``x``'s shape.

    Returns:
        ``out`` (or a new array), in [-1, 1], within :data:`TANH_TOLERANCE` of the exact ``tanh``.

    Example:
        >>> tanh(np.array([-30.0, 0.0, 0.5, 30.0], np.float32)).astype(np.float64).round(4).tolist()
        [-1.0, 0.0, 0.4621, 1.0]
    """
    if x.dtype != np.float32 or not x.flags.c_contiguous:
        raise ValueError(f"tanh takes a C-contiguous float32 array, got {x.dtype} (contiguous: {x.flags.c_contiguous})")
    if out is None:
        out = np.empty_like(x)
    elif out.shape != x.shape or out.dtype != np.float32 or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float32 array of shape {x.shape}")
    flat = out.reshape(-1)  # a view: OpenCV's exp takes arrays of at most 2 dimensions
    with np.errstate(over="ignore"):  # beyond 1.7e38, -2x is -inf: exp 0, tanh 1, as it should
        np.multiply(x.reshape(-1), _MINUS_TWO, out=flat)
    cv2.exp(flat, dst=flat)
    np.add(flat, _ONE, out=flat)
    np.divide(_TWO, flat, out=flat)
    np.subtract(flat, _ONE, out=flat)
    return out
