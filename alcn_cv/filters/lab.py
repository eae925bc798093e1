"""CIE Lab as :meth:`Normalization.apply <alcn_cv.enhance.base.Normalization.apply>` computes it for a colour image:
the sRGB curve decoded, then OpenCV's float Lab of the linear intensities.

OpenCV's float ``COLOR_BGR2Lab`` reads its result from a 33x33x33 table of 16-bit values by trilinear interpolation,
its weights in sixteenths of a cell (its L is up to 0.19 off the CIE formula, which a normalization amplifies to a
hundredth of the output), where ``COLOR_LBGR2Lab``, on linear intensities, computes each pixel: the matrix, then the
cube root by a natural cubic spline through 1025 knots on [0, 1.5]. So the sRGB curve is decoded here (by a lookup
table for a uint8 image: the same float values) and the linear conversion follows. The way back, ``COLOR_Lab2BGR``,
computes each pixel as well, the sRGB curve by a spline. :mod:`alcn_cv.filters.torch_lab` does the same arithmetic
in torch, differentiably, with these constants (OpenCV's, not the CIE's exact ones: its D65 white point, 7.787 and
903.3) and the same splines (:func:`spline_coefficients`). :func:`normalized_bgr` is the colour path of ``apply()``
and of :class:`~alcn_cv.nn.ALCN2d`'s CPU inference: L normalized, a and b kept.

Example::

    >>> import numpy as np
    >>> [round(float(v), 4) for v in srgb_to_linear(np.array([0.0, 0.5, 1.0], np.float32))]
    [0.0, 0.214, 1.0]
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cache

import cv2
import numpy as np

from alcn_cv.checks import FULL_SCALE, UINT8_LEVELS, from_unit_float, to_unit_float
from alcn_cv.errors import InputError

__all__ = [
    "CUBE_ROOT_SCALE",
    "GAMMA_SCALE",
    "LINEAR_BELOW",
    "L_SLOPE",
    "SLOPE",
    "SRGB_TO_XYZ",
    "WHITE_POINT",
    "XYZ_TO_SRGB",
    "bgr_with_lightness",
    "cube_root_table",
    "inverse_gamma_table",
    "lab_and_lightness",
    "linear_to_lab",
    "normalized_bgr",
    "spline_coefficients",
    "srgb_to_lab",
    "srgb_to_linear",
]

#: Linear RGB -> XYZ (rows X, Y, Z) and back, and the D65 white point, as OpenCV's ``color_lab.cpp`` has them.
SRGB_TO_XYZ = np.array([[0.412453, 0.357580, 0.180423], [0.212671, 0.715160, 0.072169], [0.019334, 0.119193, 0.950227]])
XYZ_TO_SRGB = np.array(
    [[3.240479, -1.53715, -0.498535], [-0.969256, 1.875991, 0.041556], [0.055648, -0.204043, 1.057311]]
)
WHITE_POINT = np.array([0.950456, 1.0, 1.088754])
#: ``(6 / 29)^3``: below it, ``f(t) = SLOPE * t + 16 / 116`` and ``L = L_SLOPE * Y``.
LINEAR_BELOW = 0.008856
SLOPE = 7.787
L_SLOPE = 903.3
#: The knots per unit of the cube root's spline (1024 intervals over [0, 1.5]) and of the sRGB curve's (over [0, 1]).
CUBE_ROOT_SCALE = np.float32(2048.0 / 3.0)
GAMMA_SCALE = np.float32(1024.0)


def srgb_to_linear(unit: np.ndarray) -> np.ndarray:
    """The sRGB curve decoded, in place: float32 intensities in [0, 1] -> linear intensities in [0, 1]
    (``x / 12.92`` up to 0.04045, ``((x + 0.055) / 1.055)^2.4`` above), in OpenCV passes. Any layout: a strided
    view is computed in a contiguous copy and written back."""
    _check_float32(unit)
    # the reshape of a strided view would be a copy, and the result would never reach ``unit``
    work = unit if unit.flags.c_contiguous else np.ascontiguousarray(unit)
    plane = work.reshape(work.shape[0] if work.ndim > 1 else 1, -1)  # one channel: OpenCV's scalars reach every value
    high = cv2.pow(cv2.addWeighted(plane, 1.0 / 1.055, plane, 0.0, 0.055 / 1.055), 2.4)
    np.copyto(plane, np.where(plane <= np.float32(0.04045), cv2.multiply(plane, 1.0 / 12.92), high))
    if work is not unit:
        np.copyto(unit, work)
    return unit


def linear_to_lab(linear: np.ndarray) -> np.ndarray:
    """CIE Lab of a C-ordered float32 ``HxWx3`` image of linear BGR intensities in [0, 1] (:func:`srgb_to_linear`),
    in place: OpenCV's ``COLOR_LBGR2Lab``, which computes each pixel (its cube root by the spline of
    :func:`cube_root_table`), L in [0, 100]."""
    if not (_check_float32(linear).ndim == 3 and linear.shape[2] == 3 and linear.flags.c_contiguous):
        raise InputError(f"a C-ordered HxWx3 image, got shape {linear.shape}")
    return cv2.cvtColor(linear, cv2.COLOR_LBGR2Lab, dst=linear)


def _check_float32(image: np.ndarray) -> np.ndarray:
    # OpenCV's pow of a uint8 image corrupts its state (a crash, or a later call's failed assertion)
    if not isinstance(image, np.ndarray) or image.dtype != np.float32:
        raise InputError(
            f"float32 intensities in [0, 1] are converted in place, got {getattr(image, 'dtype', type(image))} "
            "(a uint8 image: image * np.float32(1 / 255) first, or Normalization.apply, which converts any image)"
        )
    return image


def srgb_to_lab(unit: np.ndarray) -> np.ndarray:
    """CIE Lab of a C-ordered float32 ``HxWx3`` image of BGR sRGB intensities in [0, 1], in place:
    :func:`linear_to_lab` of :func:`srgb_to_linear`, the conversion ``apply()`` makes of a colour image."""
    return linear_to_lab(srgb_to_linear(unit))


def spline_coefficients(values: np.ndarray) -> np.ndarray:
    """``(n + 1,)`` values at the knots ``0 .. n`` -> ``(n, 4)`` float32 ``(a, b, c, d)`` of the natural cubic spline
    through them, ``a + b t + c t^2 + d t^3`` on ``[i, i + 1]`` (OpenCV's ``splineBuild``)."""
    f = np.asarray(values, np.float64)
    n = len(f) - 1
    # c_i = s''(i) / 2, zero at both ends: c_{i-1} + 4 c_i + c_{i+1} = 3 (f_{i+1} - 2 f_i + f_{i-1}), solved by
    # elimination down the rows and substitution back up (a thousand rows, once per table)
    rhs = 3.0 * (f[2:] - 2.0 * f[1:-1] + f[:-2])
    pivot, carried = np.empty(n - 1), np.empty(n - 1)
    pivot[0], carried[0] = 4.0, rhs[0]
    for i in range(1, n - 1):
        pivot[i] = 4.0 - 1.0 / pivot[i - 1]
        carried[i] = rhs[i] - carried[i - 1] / pivot[i - 1]
    c = np.zeros(n + 1)
    c[n - 1] = carried[-1] / pivot[-1]
    for i in range(n - 3, -1, -1):
        c[i + 1] = (carried[i] - c[i + 2]) / pivot[i]
    b = f[1:] - f[:-1] - (c[1:] + 2.0 * c[:-1]) / 3.0
    d = (c[1:] - c[:-1]) / 3.0
    return np.stack([f[:-1], b, c[:-1], d], axis=1).astype(np.float32)


@cache
def cube_root_table() -> np.ndarray:
    """:func:`spline_coefficients` of Lab's ``f(t)`` (the cube root, linear below :data:`LINEAR_BELOW`) at
    ``t = i / CUBE_ROOT_SCALE``, ``i = 0 .. 1024``."""
    t = np.arange(1025) / float(CUBE_ROOT_SCALE)
    return spline_coefficients(np.where(t < LINEAR_BELOW, SLOPE * t + 16.0 / 116.0, np.cbrt(t)))


@cache
def inverse_gamma_table() -> np.ndarray:
    """:func:`spline_coefficients` of the sRGB curve encoding linear intensities at ``i / 1024``, ``i = 0 .. 1024``."""
    x = np.arange(1025) / float(GAMMA_SCALE)
    return spline_coefficients(np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1.0 / 2.4) - 0.055))


#: ``cv2.transform`` matrix of the L channel of a float Lab image, divided by 100: intensities in [0, 1].
_LIGHTNESS_OF_LAB = np.array([[0.01, 0.0, 0.0]], np.float32)
#: :func:`srgb_to_linear` of :data:`~alcn_cv.checks.UINT8_LEVELS`.
_LINEAR_UINT8_LEVELS = srgb_to_linear(UINT8_LEVELS.copy())


def lab_and_lightness(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CIE Lab of a valid BGR image (uint8, uint16 or float32 in [0, 1]) as a new float32 array (L in [0, 100];
    :func:`~alcn_cv.filters.lab.srgb_to_lab`), and its L / 100 as a float32 ``HxW`` plane in [0, 1]: what
    :meth:`Normalization.apply <alcn_cv.enhance.base.Normalization.apply>` normalizes for a colour image."""
    # a uint8 image's decoded curve by one table lookup: the float path's values for its 256 levels
    lab = (
        linear_to_lab(cv2.LUT(img, _LINEAR_UINT8_LEVELS)) if img.dtype == np.uint8 else srgb_to_lab(to_unit_float(img))
    )
    return lab, cv2.transform(lab, _LIGHTNESS_OF_LAB)


def bgr_with_lightness(lab: np.ndarray, lightness: np.ndarray, out_dtype: np.dtype) -> np.ndarray:
    """The BGR image of ``out_dtype`` of the float32 Lab image ``lab`` (:func:`lab_and_lightness`; used as
    scratch space) with its L channel replaced by the float32 ``HxW`` plane ``lightness`` in [0, 100]."""
    cv2.insertChannel(lightness, lab, 0)
    bgr = cv2.cvtColor(lab, cv2.COLOR_Lab2BGR, dst=lab)
    if out_dtype == np.uint8:
        return cv2.convertScaleAbs(bgr, alpha=FULL_SCALE[out_dtype])
    return from_unit_float(bgr, out_dtype)


def normalized_bgr(
    img: np.ndarray,
    normalize: Callable[[np.ndarray], np.ndarray],
    output_range: tuple[float, float],
    out_dtype: np.dtype,
) -> np.ndarray:
    """A valid BGR image (uint8, uint16 or float32 in [0, 1]) with the L channel of its CIE Lab normalized, a and b
    kept, as ``out_dtype``: ``normalize`` maps L / 100 (float32 ``HxW``) to raw responses, and ``output_range`` of
    these maps linearly onto [0, 100], clipped.

    OpenCV passes throughout: the Lab image of :func:`lab_and_lightness` (its L / 100 in one ``cv2.transform``), the
    response mapped to [0, 100] by ``cv2.addWeighted`` and two thresholds and put back by ``cv2.insertChannel``
    (:func:`bgr_with_lightness`); ``cv2.COLOR_Lab2BGR`` clips linear RGB to [0, 1] before its sRGB curve, so a uint8
    output is one ``cv2.convertScaleAbs``. The two float conversions are most of the cost (``alcn bench speed``
    measures the BGR / gray ratio); OpenCV's 8-bit conversions quantize L to 100/255 and a, b to units, many levels
    off the float path."""
    lab, lightness = lab_and_lightness(img)
    response = normalize(lightness)
    lo, hi = output_range
    scale = 100.0 / (hi - lo)
    lightness = cv2.addWeighted(response, scale, response, 0.0, -lo * scale)
    cv2.threshold(lightness, 0.0, 0.0, cv2.THRESH_TOZERO, dst=lightness)
    cv2.threshold(lightness, 100.0, 0.0, cv2.THRESH_TRUNC, dst=lightness)
    return bgr_with_lightness(lab, lightness, out_dtype)
