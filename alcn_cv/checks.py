"""The input contract: validation of images, intensity images, batches of windows and run seeds.

Every normalization's :meth:`~alcn_cv.enhance.base.Normalization.apply` and the Normalizer
runtimes check their input here, so a bad array ends in one :class:`~alcn_cv.errors.InputError`
that names the problem.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable

import numpy as np

from alcn_cv.errors import InputError

__all__ = [
    "FLOAT_TOLERANCE",
    "FULL_SCALE",
    "SUPPORTED_DTYPES",
    "check_gray",
    "check_image",
    "check_positive",
    "check_seeds",
    "unit_windows",
]

SUPPORTED_DTYPES = (np.uint8, np.uint16, np.float32)
FULL_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}
#: How far outside [0, 1] float32 intensities may lie (rounding) before they are refused.
FLOAT_TOLERANCE = 1e-3


def check_positive(name: str, value: float) -> float:
    """``value`` as a float, checked positive and finite (a method's parameter called ``name``).

    Raises:
        InputError: ``value`` is zero, negative, infinite or NaN.
    """
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be positive and finite, got {value}")
    return value


def check_seeds(seeds: Iterable[int]) -> list[int]:
    """``seeds``, the seeds a command repeats its runs with, as a list of ints: at least one, each a non-negative
    integer (NumPy's generators take no negative seed), none twice (a repeated seed would count its run twice in the
    spread over seeds).

    Example:
        >>> check_seeds((0, 1, 2))
        [0, 1, 2]

    Raises:
        InputError: no seed, a seed that is no non-negative integer, or a repeated one; the message names them.
    """
    given = list(seeds)
    good = [isinstance(s, numbers.Integral) and not isinstance(s, bool) and s >= 0 for s in given]
    bad = [s for s, ok in zip(given, good) if not ok]
    valid = [int(s) for s, ok in zip(given, good) if ok]
    repeated = sorted({s for i, s in enumerate(valid) if s in valid[:i]})
    if not given or bad or repeated:
        problems = ([f"not a non-negative integer: {bad}"] if bad else []) + (
            [f"repeated: {repeated}"] if repeated else []
        )
        raise InputError(
            f"seeds must be distinct non-negative integers, at least one; got {given}"
            + (f" ({'; '.join(problems)})" if problems else "")
        )
    return valid


def check_image(img: object) -> np.ndarray:
    """Validate an image for :meth:`Normalization.apply` and return it as an ndarray.

    Accepts ``HxW``, ``HxWx1``, ``HxWx2`` (grayscale and alpha), BGR ``HxWx3`` and BGRA ``HxWx4``
    of a supported dtype in any byte order; a non-native byte order (e.g. big-endian ``>u2``)
    is returned converted to the native one.

    Raises:
        InputError: not an array, empty, wrong number of dimensions or channels, unsupported
            dtype, NaN/inf or out-of-range values in a float image.
    """
    if not isinstance(img, np.ndarray):
        raise InputError(f"image must be a numpy array, got {type(img).__name__}")
    if img.size == 0:
        raise InputError(f"image is empty (shape {img.shape})")
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 2, 3, 4)):
        stacked = img.ndim == 4 or (img.ndim == 3 and img.shape[0] < min(img.shape[1:]) and img.shape[2] > 4)
        frames = " (frames stacked? apply each one, or createALCN(backend='torch').apply_batch)" if stacked else ""
        raise InputError(
            f"image must be HxW, HxWx1, HxWx2 (gray, alpha), HxWx3 (BGR) or HxWx4 (BGRA), got shape {img.shape}{frames}"
        )
    native = img.dtype.newbyteorder("=")
    if native not in SUPPORTED_DTYPES:
        hint = " (image.astype(np.float32))" if native.kind == "f" else ""
        raise InputError(f"unsupported dtype {img.dtype}; use uint8, uint16 or float32 (intensities in [0, 1]){hint}")
    if img.dtype != native:  # byte order is a storage detail, not a pixel type
        img = img.astype(native)
    if img.dtype == np.float32:
        # min and max see NaN (it propagates) and inf (out of range) without a boolean copy
        lo, hi = float(img.min()), float(img.max())
        if not (lo >= -FLOAT_TOLERANCE and hi <= 1 + FLOAT_TOLERANCE):
            if not np.isfinite(img).all():
                raise InputError("float32 image contains NaN or inf")
            raise InputError(
                f"float32 intensities must be in [0, 1], got [{lo:.4g}, {hi:.4g}]"
                + (" (divide by 255 first)" if lo >= 0 and 1.5 < hi <= 255 else "")
            )
    return img


def check_gray(gray: object) -> np.ndarray:
    """Validate a float32 ``HxW`` intensity image (the input of :meth:`Normalization.normalize`
    and of the Normalizer runtimes)."""
    if not isinstance(gray, np.ndarray) or gray.ndim != 2 or gray.size == 0:
        raise InputError(f"image must be a non-empty HxW array, got shape {getattr(gray, 'shape', None)}")
    if gray.dtype != np.float32:
        raise InputError(f"image must be float32 intensities in [0, 1], got {gray.dtype}")
    if not np.isfinite(gray).all():
        raise InputError("image contains NaN or inf")
    return gray


def unit_windows(windows: np.ndarray) -> np.ndarray:
    """``(n, S, S)`` uint8 or float32 windows as float32 intensities in [0, 1]."""
    if not isinstance(windows, np.ndarray) or windows.ndim != 3 or windows.size == 0:
        raise InputError(f"windows must be a non-empty (n, S, S) array, got {getattr(windows, 'shape', type(windows))}")
    if windows.dtype == np.uint8:
        return windows.astype(np.float32) * np.float32(1 / 255)
    if windows.dtype != np.float32:
        raise InputError(f"windows must be uint8 or float32, got {windows.dtype}")
    return windows
