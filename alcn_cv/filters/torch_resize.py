"""ALCN's resizes in torch: bilinear upsampling by an integer factor as ``torch.lerp`` over phases, and
``cv2.INTER_AREA``'s downsampling.

Between two samples ``factor`` pixels apart, each output pixel sits at a fixed fraction of the way, its phase: one
``torch.lerp`` over every pair of neighbours and every phase writes a whole axis at once, and the second axis is
written once, at full size. On the CPU this costs half of ``F.interpolate``'s bilinear mode; the values are its own
to float rounding (``tests/test_torch_resize.py``). Two placements of the samples, one function each:

* :func:`interpolate_grid`: the Normalizer's grid, point ``i`` on pixel ``stride * i`` (``align_corners=True``);
  its OpenCV form is :func:`alcn_cv.filters.gaussian_mixture.upsample_grid`.
* :func:`upsample_blocks`: one sample per block of ``block`` pixels, at the block's centre, the edges held
  (``align_corners=False``, ``cv2.resize``'s placement); the wide band's (:mod:`alcn_cv.filters.torch_wide_band`).

:func:`area_downsample` is ``cv2.resize(..., interpolation=cv2.INTER_AREA)`` to any smaller size, differentiable:
the working image of the ``lite`` and ``paper`` models (torch's own ``mode="area"`` averages other pixels when the
sides are not multiples of the factor).
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import torch

from alcn_cv.errors import InputError

__all__ = ["area_downsample", "interpolate_grid", "upsample_blocks"]


def _along(x: torch.Tensor, dim: int, phases: torch.Tensor, start: int, size: int) -> torch.Tensor:
    """``x`` interpolated along ``dim`` (-1 or -2) at ``len(phases)`` phases between each pair of neighbours, output
    ``start .. start + size - 1`` of that sequence (the first sample is output 0 at phase 0; the last sample alone
    ends it when the phases start at 0)."""
    factor = len(phases)
    n = x.shape[dim]
    # the pairs that hold the outputs asked for: a ceiling without a negative operand (traced for an ONNX export,
    # sizes are tensors and ONNX's Div truncates where // floors)
    pairs = min(n - 1, (start + size + factor - 1) // factor)
    lo, hi = x.narrow(dim, 0, pairs), x.narrow(dim, 1, pairs)
    if dim == -1:
        out = torch.lerp(lo[..., None], hi[..., None], phases).flatten(-2)
    else:
        out = torch.lerp(lo[..., None, :], hi[..., None, :], phases[:, None]).flatten(-3, -2)
    if out.shape[dim] < start + size:  # the grid's last point, on the last pixel
        out = torch.cat([out, x.narrow(dim, pairs, 1)], dim)
    return out.narrow(dim, start, size)


def interpolate_grid(grid: torch.Tensor, stride: int, shape: tuple[int, int]) -> torch.Tensor:
    """Maps given on a grid interpolated bilinearly onto every pixel, grid point ``(i, j)`` on pixel
    ``(stride * i, stride * j)``: ``F.interpolate(grid, size=stride * (g - 1) + 1, mode="bilinear",
    align_corners=True)`` cropped to ``shape``, to float rounding.

    Args:
        grid: ``(B, N, gh, gw)`` float, ``stride * (gh - 1) >= H - 1`` and ``stride * (gw - 1) >= W - 1``.
        stride: the grid's spacing in pixels.
        shape: ``(H, W)`` of the output.

    Returns:
        ``(B, N, H, W)``, ``grid``'s dtype and device.

    Example:
        >>> interpolate_grid(torch.rand(1, 2, 5, 6), 8, (33, 40)).shape
        torch.Size([1, 2, 33, 40])
    """
    h, w = shape
    gh, gw = grid.shape[-2:]
    if stride * (gh - 1) < h - 1 or stride * (gw - 1) < w - 1:
        raise InputError(f"a grid of {gh}x{gw} points {stride} px apart does not cover {h}x{w} pixels")
    phases = torch.arange(stride, device=grid.device, dtype=grid.dtype) / stride
    # along the grid's rows (few), then down its columns: the full-size output written once
    return _along(_along(grid, -1, phases, 0, w), -2, phases, 0, h)


def upsample_blocks(small: torch.Tensor, block: int, shape: tuple[int, int]) -> torch.Tensor:
    """One sample per block of ``block x block`` pixels, at its centre, interpolated bilinearly onto every pixel:
    ``F.interpolate(small, scale_factor=block, mode="bilinear", align_corners=False)`` cropped to ``shape``, to
    float rounding (``cv2.resize`` to ``block`` times the size places its samples the same way).

    Args:
        small: ``(B, C, h, w)`` float, ``block * h >= H`` and ``block * w >= W``.
        block: the blocks' side in pixels (even: the block's centre falls between pixels).
        shape: ``(H, W)`` of the output.

    Returns:
        ``(B, C, H, W)``, ``small``'s dtype and device.

    Example:
        >>> band = upsample_blocks(torch.tensor([[[[0.0, 1.0]]]]), 4, (4, 8))  # two blocks of 4x4
        >>> band[0, 0, 0].tolist()  # the centres on pixels 1.5 and 5.5: a ramp between, held beyond
        [0.0, 0.0, 0.125, 0.375, 0.625, 0.875, 1.0, 1.0]
    """
    h, w = shape
    if block % 2 or block * small.shape[-2] < h or block * small.shape[-1] < w:
        raise InputError(f"{tuple(small.shape[-2:])} blocks of {block} px do not cover {h}x{w} pixels (block even)")
    # Sample j of the edge-padded blocks sits on pixel block * j - (block + 1) / 2; pixel x = block * j + q - block / 2
    # is at phase (q + 1/2) / block between samples j and j + 1.
    phases = (torch.arange(block, device=small.device, dtype=small.dtype) + 0.5) / block
    # the edges held by copies, not F.pad's replicate mode: inductor fails on that after a concatenation (torch 2.13,
    # the reflect-101 border of a small image before it)
    padded = torch.cat([small[..., :1, :], small, small[..., -1:, :]], -2)
    padded = torch.cat([padded[..., :1], padded, padded[..., -1:]], -1)
    return _along(_along(padded, -1, phases, block // 2, w), -2, phases, block // 2, h)


def _area_taps(src: int, dst: int) -> tuple[np.ndarray, np.ndarray]:
    """``(taps, dst)`` source indices and float32 weights of ``cv2.INTER_AREA`` from ``src`` to ``dst <= src``
    samples: output ``d`` averages the source interval ``[d s, (d + 1) s)``, ``s = src / dst``, each pixel weighed
    by its overlap (OpenCV's own table, ``computeResizeAreaTab``; unused taps: index 0, weight 0)."""
    scale = src / dst
    rows: list[list[tuple[int, float]]] = []
    for d in range(dst):
        start, stop = d * scale, (d + 1) * scale
        cell = min(scale, src - start)
        first, last = math.ceil(start), min(math.floor(stop), src - 1)
        first = min(first, last)
        row = [(first - 1, (first - start) / cell)] if first - start > 1e-3 else []
        row += [(i, 1.0 / cell) for i in range(first, last)]
        if stop - last > 1e-3:
            row.append((last, min(stop - last, 1.0, cell) / cell))
        rows.append(row)
    taps = max(len(row) for row in rows)
    index, weight = np.zeros((taps, dst), np.int64), np.zeros((taps, dst), np.float32)
    for d, row in enumerate(rows):
        for k, (i, a) in enumerate(row):
            index[k, d], weight[k, d] = i, a
    return index, weight


@lru_cache(maxsize=64)
def _area_taps_on(src: int, dst: int, device: torch.device, dtype: torch.dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`_area_taps` as tensors on ``device``, the weights of ``dtype``: copied once, not at every call."""
    index, weight = _area_taps(src, dst)
    with torch.inference_mode(False):  # made in an inference call, the cached tensors would refuse a backward later
        return torch.from_numpy(index).to(device), torch.from_numpy(weight).to(device, dtype)


def area_downsample(x: torch.Tensor, size: tuple[int, int]) -> torch.Tensor:
    """``cv2.resize(x, size[::-1], interpolation=cv2.INTER_AREA)`` for a smaller ``size``, to float rounding
    (``tests/test_torch_resize.py``), differentiable.

    Args:
        x: ``(B, C, H, W)`` float.
        size: ``(h, w)`` with ``1 <= h <= H`` and ``1 <= w <= W``.

    Returns:
        ``(B, C, h, w)``, ``x``'s dtype and device.

    Example:
        >>> area_downsample(torch.arange(4.0).reshape(1, 1, 1, 4), (1, 3)).tolist()  # 4/3 pixels an output
        [[[[0.25, 1.5, 2.75]]]]
    """
    h, w = size
    if not (1 <= h <= x.shape[-2] and 1 <= w <= x.shape[-1]):
        raise InputError(f"area_downsample makes images smaller: {tuple(x.shape[-2:])} to {(h, w)}")
    for dim, dst in ((-2, h), (-1, w)):
        index, weight = _area_taps_on(x.shape[dim], dst, x.device, x.dtype)
        shape = (-1, 1) if dim == -2 else (-1,)
        x = sum(x.index_select(dim, i) * a.reshape(shape) for i, a in zip(index, weight))
    return x
