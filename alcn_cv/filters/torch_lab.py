"""CIE Lab in torch as :meth:`ALCN.apply <alcn_cv.enhance.alcn.ALCN.apply>` computes it (:mod:`alcn_cv.filters.lab`):
OpenCV's constants and its splines for the cube root and the sRGB encoding, differentiable, on any device.

kornia's :func:`~kornia.color.rgb_to_lab` uses the exact CIE formulas and another white point; through a
normalization that amplifies L, they put :class:`~alcn_cv.nn.ALCN2d` 1e-2 away from ``apply()`` in colour.

Example::

    >>> import torch
    >>> rgb = torch.rand(1, 3, 8, 8)
    >>> bool((lab_to_rgb(rgb_to_lab(rgb)) - rgb).abs().max() < 1e-3)
    True
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from alcn_cv.errors import InputError
from alcn_cv.filters.lab import (
    CUBE_ROOT_SCALE,
    GAMMA_SCALE,
    L_SLOPE,
    LINEAR_BELOW,
    SLOPE,
    SRGB_TO_XYZ,
    WHITE_POINT,
    XYZ_TO_SRGB,
    cube_root_table,
    inverse_gamma_table,
)
from alcn_cv.filters.torch_precision import ExactBuffers

__all__ = ["LabToRgb", "RgbToLab", "lab_to_rgb", "rgb_to_lab"]

_OFFSET = 16.0 / 116.0
#: Linear RGB -> XYZ relative to the white point (X and Z divided by its, as OpenCV folds it into the matrix), and
#: XYZ relative to the white point -> linear RGB.
_TO_XYZ = torch.from_numpy((SRGB_TO_XYZ / WHITE_POINT[:, None]).astype(np.float32))
_TO_RGB = torch.from_numpy((XYZ_TO_SRGB * WHITE_POINT[None, :]).astype(np.float32))
#: The splines' coefficients ``(1024, 4)``.
_CUBE_ROOT = torch.from_numpy(cube_root_table())
_INVERSE_GAMMA = torch.from_numpy(inverse_gamma_table())


def _spline(x: torch.Tensor, table: torch.Tensor) -> torch.Tensor:
    """The spline of :func:`~alcn_cv.filters.lab.spline_coefficients` ``table`` at ``x`` (in knots), as OpenCV
    evaluates it: the polynomial of interval ``clamp(floor(x), 0, n - 1)``, beyond the ends too."""
    index = x.detach().float().floor().clamp(0, len(table) - 1).long()  # float32: 1023 is not a bfloat16
    t = x - index.to(x.dtype)
    a, b, c, d = (table[:, k][index] for k in range(4))
    return ((d * t + c) * t + b) * t + a


def _check_colour(image: torch.Tensor) -> None:
    # einsum would broadcast one channel as three, or fail naming its subscripts
    if image.ndim != 4 or image.shape[1] != 3:
        raise InputError(f"a (B, 3, H, W) image, got shape {tuple(image.shape)}")


def _rgb_to_lab(image: torch.Tensor, to_xyz: torch.Tensor, cube_root: torch.Tensor) -> torch.Tensor:
    _check_colour(image)
    rgb = image.clamp(0.0, 1.0)
    linear = torch.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    xyz = torch.einsum("ij,bjhw->bihw", to_xyz, linear)
    fx, fy, fz = _spline(xyz * float(CUBE_ROOT_SCALE), cube_root).unbind(1)
    y = xyz[:, 1]
    lightness = torch.where(y > LINEAR_BELOW, 116.0 * fy - 16.0, L_SLOPE * y)
    return torch.stack([lightness, 500.0 * (fx - fy), 200.0 * (fy - fz)], dim=1)


def _lab_to_rgb(lab: torch.Tensor, to_rgb: torch.Tensor, inverse_gamma: torch.Tensor) -> torch.Tensor:
    _check_colour(lab)
    lightness, a, b = lab.unbind(1)
    dark = lightness <= 8.0  # (6 / 29)^3 * 903.3
    y_dark = lightness / L_SLOPE
    fy = torch.where(dark, SLOPE * y_dark + _OFFSET, (lightness + 16.0) / 116.0)
    y = torch.where(dark, y_dark, fy * fy * fy)
    fxz = torch.stack([a / 500.0 + fy, fy - b / 200.0], dim=1)
    x, z = torch.where(fxz <= 6.0 / 29.0, (fxz - _OFFSET) / SLOPE, fxz * fxz * fxz).unbind(1)
    linear = torch.einsum("ij,bjhw->bihw", to_rgb, torch.stack([x, y, z], dim=1)).clamp(0.0, 1.0)
    return _spline(linear * float(GAMMA_SCALE), inverse_gamma)


def rgb_to_lab(image: torch.Tensor) -> torch.Tensor:
    """RGB ``(B, 3, H, W)`` in [0, 1] (sRGB-encoded; clipped) -> CIE Lab ``(B, 3, H, W)``: L in [0, 100], a and b
    in about [-128, 127], as OpenCV's ``COLOR_LBGR2Lab`` of the decoded intensities. Its constants are copied to
    ``image``'s device at each call; :class:`RgbToLab` keeps them there."""
    return _rgb_to_lab(image, _TO_XYZ.to(image), _CUBE_ROOT.to(image))


def lab_to_rgb(lab: torch.Tensor) -> torch.Tensor:
    """CIE Lab ``(B, 3, H, W)`` -> RGB ``(B, 3, H, W)`` in [0, 1] (sRGB-encoded; linear RGB clipped to [0, 1] before
    the encoding), as OpenCV's float ``COLOR_Lab2BGR``; :class:`LabToRgb` keeps the constants on its device."""
    return _lab_to_rgb(lab, _TO_RGB.to(lab), _INVERSE_GAMMA.to(lab))


class _Conversion(ExactBuffers):
    """A conversion of this module with its matrix and spline as buffers (not saved), moved with the module but kept
    float32 (rounded to bfloat16, they move L by 0.25 of 100 and a and b by 2); it runs in the image's dtype, a
    caller's autocast switched off inside."""

    exact_buffers = ("matrix", "spline")

    matrix: torch.Tensor
    spline: torch.Tensor

    def __init__(
        self,
        convert: Callable[[torch.Tensor, torch.Tensor, torch.Tensor], torch.Tensor],
        matrix: torch.Tensor,
        spline: torch.Tensor,
    ) -> None:
        super().__init__()
        self.convert = convert
        self.register_buffer("matrix", matrix.clone(), persistent=False)
        self.register_buffer("spline", spline.clone(), persistent=False)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        # in the image's own dtype under a caller's autocast too: a bfloat16 einsum moves L by 1.6 (of 100), which a
        # normalization after it amplifies; the conversion costs little at any precision
        with torch.autocast(image.device.type, enabled=False):
            return self.convert(image, self.matrix.to(image.dtype), self.spline.to(image.dtype))


class RgbToLab(_Conversion):
    """:func:`rgb_to_lab` as a module: its constants move with it (``.to(device, dtype)``)."""

    def __init__(self) -> None:
        super().__init__(_rgb_to_lab, _TO_XYZ, _CUBE_ROOT)


class LabToRgb(_Conversion):
    """:func:`lab_to_rgb` as a module: its constants move with it (``.to(device, dtype)``)."""

    def __init__(self) -> None:
        super().__init__(_lab_to_rgb, _TO_RGB, _INVERSE_GAMMA)
