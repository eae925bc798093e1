"""The input contract: validation of images, intensity images, batches of windows and run seeds,
and the conversions between the supported dtypes and float32 intensities in [0, 1].

Every normalization's :meth:`~alcn_cv.enhance.base.Normalization.apply` and the Normalizer
runtimes check their input here, so a bad array ends in one :class:`~alcn_cv.errors.InputError`
that names the problem.
"""

from __future__ import annotations

import numbers
from collections.abc import Iterable

import cv2
import numpy as np

from alcn_cv.errors import InputError

__all__ = [
    "FLOAT_TOLERANCE",
    "FULL_SCALE",
    "SUPPORTED_DTYPES",
    "UINT8_LEVELS",
    "check_array",
    "check_gray",
    "check_image",
    "check_out_dtype",
    "check_positive",
    "check_seeds",
    "check_unit_range",
    "from_unit_float",
    "to_unit_float",
    "unit_windows",
]

SUPPORTED_DTYPES = (np.uint8, np.uint16, np.float32)
FULL_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}
#: How far outside [0, 1] float32 intensities may lie (rounding) before they are refused.
FLOAT_TOLERANCE = 1e-3
#: The 256 intensities of a uint8 image as :func:`to_unit_float` gives them: ``(1, 256)`` float32.
UINT8_LEVELS = np.arange(256, dtype=np.uint8).astype(np.float32).reshape(1, 256) * np.float32(
    1.0 / FULL_SCALE[np.dtype(np.uint8)]
)


def check_positive(name: str, value: float) -> float:
    """``value`` as a float, checked positive and finite (a method's parameter called ``name``).

    Raises:
        InputError: ``value`` is zero, negative, infinite or NaN.
    """
    value = float(value)
    if not np.isfinite(value) or value <= 0:
        raise InputError(f"{name} must be positive and finite, got {value}")
    return value


def check_out_dtype(out_dtype: type | np.dtype | str | None, default: np.dtype) -> np.dtype:
    """The output dtype a caller asked for (``None``: ``default``, the input's) as a supported ``np.dtype``.

    Raises:
        InputError: ``out_dtype`` is no dtype, or not uint8, uint16 or float32.
    """
    try:
        dtype = np.dtype(default if out_dtype is None else out_dtype)
    except TypeError:
        raise InputError(f"unknown out_dtype {out_dtype!r}; use uint8, uint16 or float32") from None
    if dtype not in SUPPORTED_DTYPES:
        raise InputError(f"unsupported out_dtype {dtype}; use uint8, uint16 or float32")
    return dtype


def to_unit_float(img: np.ndarray) -> np.ndarray:
    """A valid image of a supported dtype (native byte order, any shape and layout) as float32 intensities:
    ``img / full scale`` for the integer types (:data:`FULL_SCALE`, rounded once in float32), clipped to [0, 1]
    for float32. Always a new C-ordered array, which the caller may write into."""
    if img.dtype == np.float32:
        return np.clip(img, 0.0, 1.0, out=np.empty(img.shape, np.float32))
    if img.dtype == np.uint8 and (img.ndim == 2 or img.shape[2] <= 4):
        # one table lookup: the values of the two passes below, in one
        return cv2.LUT(img, UINT8_LEVELS).reshape(img.shape)
    unit = img.astype(np.float32, order="C")
    unit *= np.float32(1.0 / FULL_SCALE[img.dtype])
    return unit


def from_unit_float(unit: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """float32 intensities, any shape, clipped to [0, 1] and converted to the supported ``dtype``
    (``rint(unit * full scale)`` for the integer types), with ``unit`` as scratch space: it is overwritten (pass a
    copy to keep it). A row, a plane or an image of up to four channels takes OpenCV passes: for uint8 the lower
    clip, then ``cv2.convertScaleAbs``, which rounds half to even and saturates as ``np.rint`` after the clip
    does, bit for bit. Another layout (a strided view, a read-only or non-float32 array) is copied first."""
    if unit.dtype != np.float32 or not (unit.flags.c_contiguous and unit.flags.writeable):
        unit = np.array(unit, np.float32, order="C")  # the scratch space OpenCV writes into
    if not (unit.ndim in (1, 2) or (unit.ndim == 3 and unit.shape[2] <= 4)):  # what OpenCV cannot take as a Mat
        np.clip(unit, 0.0, 1.0, out=unit)
    else:  # cv2.threshold: no scalar that OpenCV could take for an array
        cv2.threshold(unit, 0.0, 0.0, cv2.THRESH_TOZERO, dst=unit)
        if dtype == np.uint8:
            return cv2.convertScaleAbs(unit, alpha=FULL_SCALE[dtype])
        cv2.threshold(unit, 1.0, 0.0, cv2.THRESH_TRUNC, dst=unit)
    if dtype == np.float32:
        return np.ascontiguousarray(unit)
    unit *= FULL_SCALE[dtype]
    np.rint(unit, out=unit)
    return unit.astype(dtype)


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


def check_array(img: object, what: str = "image") -> np.ndarray:
    """``img`` itself if it is a NumPy array.

    Raises:
        InputError: ``img`` is not one (``what`` names it), with a hint for the two mistakes of an OpenCV loop:
            ``None`` from a failed read, and a ``cv2.UMat``.
    """
    if isinstance(img, np.ndarray):
        return img
    hint = {
        "NoneType": " (cv2.imread could not read the file, or VideoCapture.read() reached the end?)",
        "UMat": " (a cv2.UMat: umat.get())",
    }.get(type(img).__name__, "")
    raise InputError(f"{what} must be a numpy array, got {type(img).__name__}{hint}")


def check_image(img: object) -> np.ndarray:
    """Validate an image for :meth:`Normalization.apply` and return it as an ndarray.

    Accepts ``HxW``, ``HxWx1``, ``HxWx2`` (grayscale and alpha), BGR ``HxWx3`` and BGRA ``HxWx4``
    of a supported dtype in any byte order; a non-native byte order (e.g. big-endian ``>u2``)
    is returned converted to the native one.

    Raises:
        InputError: not an array, empty, wrong number of dimensions or channels, unsupported
            dtype, NaN/inf or out-of-range values in a float image.
    """
    img = check_array(img)
    if img.size == 0:
        raise InputError(f"image is empty (shape {img.shape})")
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 2, 3, 4)):
        hints = []
        if img.ndim == 3 and img.shape[0] in (1, 3, 4) and img.shape[2] > 4:
            hints.append("channels first, as in torch? img.transpose(1, 2, 0)")
        if img.ndim == 4 or (img.ndim == 3 and img.shape[0] < min(img.shape[1:]) and img.shape[2] > 4):
            hints.append("frames stacked? apply each one, or createALCN(backend='torch').apply_batch")
        hint = f" ({'; '.join(hints)})" if hints else ""
        raise InputError(
            f"image must be HxW, HxWx1, HxWx2 (gray, alpha), HxWx3 (BGR) or HxWx4 (BGRA), got shape {img.shape}{hint}"
        )
    native = img.dtype.newbyteorder("=")
    if native not in SUPPORTED_DTYPES:
        hint = " (image.astype(np.float32))" if native.kind == "f" else ""
        raise InputError(f"unsupported dtype {img.dtype}; use uint8, uint16 or float32 (intensities in [0, 1]){hint}")
    if img.dtype != native:  # byte order is a storage detail, not a pixel type
        img = img.astype(native)
    if img.dtype == np.float32:
        check_unit_range(img, "float32 image")
    return img


def check_unit_range(img: np.ndarray, name: str) -> None:
    """Refuse a float image with values outside [0, 1] (:data:`FLOAT_TOLERANCE` of rounding allowed), NaN or inf;
    ``name`` is the image's in the message of NaN or inf ("float32 image contains NaN or inf")."""
    # min and max see NaN (it propagates) and inf (out of range) without a boolean copy
    lo, hi = float(img.min()), float(img.max())
    if not (lo >= -FLOAT_TOLERANCE and hi <= 1 + FLOAT_TOLERANCE):
        if not np.isfinite(img).all():
            raise InputError(f"{name} contains NaN or inf")
        hint = " (divide by 255 first)" if lo >= 0 and 5 < hi <= 255 else ""
        if lo > -0.5 and hi < 1.5:  # a resize's or a blur's overshoot
            hint = " (an interpolation's overshoot? np.clip(img, 0, 1))"
        raise InputError(f"float32 intensities must be in [0, 1], got [{lo:.4g}, {hi:.4g}]{hint}")


def check_gray(gray: object, finite: bool = True) -> np.ndarray:
    """Validate a float32 ``HxW`` intensity image (the input of :meth:`Normalization.normalize`,
    of the Normalizer runtimes and of the OpenCV filters) and return it.

    Args:
        gray: the image.
        finite: also refuse NaN, inf and values outside [0, 1] (:func:`check_unit_range`; the filters, whose
            callers have checked the image, pass False).

    Raises:
        InputError: not a non-empty ``HxW`` array, not float32, or (``finite``) NaN, inf or a value out of range.
    """
    if not isinstance(gray, np.ndarray) or gray.ndim != 2 or gray.size == 0:
        raise InputError(f"image must be a non-empty HxW array, got shape {getattr(gray, 'shape', None)}")
    if gray.dtype != np.float32:
        raise InputError(f"image must be float32 intensities in [0, 1], got {gray.dtype}")
    if finite:
        check_unit_range(gray, "image")
    return gray


def unit_windows(windows: np.ndarray) -> np.ndarray:
    """``(n, S, S)`` uint8 or float32 windows as float32 intensities in [0, 1]."""
    if not isinstance(windows, np.ndarray) or windows.ndim != 3 or windows.size == 0:
        raise InputError(f"windows must be a non-empty (n, S, S) array, got {getattr(windows, 'shape', type(windows))}")
    if windows.dtype == np.uint8:
        return to_unit_float(windows)
    if windows.dtype != np.float32:
        raise InputError(f"windows must be uint8 or float32, got {windows.dtype}")
    check_unit_range(windows, "windows")
    return windows
