"""Separable filtering in torch: a 1-D kernel down the columns or along the rows of every plane, fast on the CPU.

The result is ``F.conv2d``'s with the kernel as a ``(K, 1)`` or ``(1, K)`` filter (no padding), to float rounding
(``tests/test_torch_separable.py``), in the input's dtype under a caller's autocast too, computed by one of three
paths:

* on the CPU in float32 or float64 where no gradient is recorded: a sum of shifted views of the input, one fused
  multiply-add per tap (``addcmul_``, no copy of the input);
* on the CPU where a gradient is recorded, and for bfloat16: a depthwise convolution over :data:`GROUPS` channels
  that views the image without copying it (down the columns, adjacent columns are the channels of a channels-last
  tensor; along the rows, bands of rows are the channels of a contiguous one; a side that is not a multiple of
  :data:`GROUPS` is zero-padded for the pass and cropped after), which accumulates in float32;
* elsewhere -- on CUDA, for float16 on the CPU and in an ONNX export (:mod:`alcn_cv.train.export`; ``cv2.dnn`` runs
  it for any size) -- the plain convolution.

The measurements behind these choices are in ``docs/journal.md``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from alcn_cv.filters.torch_precision import autocast_enabled

__all__ = ["filter_columns", "filter_rows"]

#: The channels a plane is viewed as.
GROUPS = 16


def _grouped(x: torch.Tensor) -> bool:
    return x.device.type == "cpu" and x.dtype != torch.float16 and not torch.onnx.is_in_onnx_export()


def filter_columns(x: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """Correlate every column of ``x`` with ``kernel``, where it lies inside (no padding).

    Args:
        x: ``(B, C, H, W)`` float, ``H >= K``.
        kernel: ``(K,)``, ``x``'s dtype and device.

    Returns:
        ``(B, C, H - K + 1, W)``: ``F.conv2d`` of each plane with ``kernel.view(1, 1, K, 1)``.

    Example:
        >>> filter_columns(torch.ones(1, 1, 5, 20), torch.ones(3)).shape
        torch.Size([1, 1, 3, 20])
    """
    return _filter(x, kernel, down_columns=True)


def filter_rows(x: torch.Tensor, kernel: torch.Tensor) -> torch.Tensor:
    """Correlate every row of ``x`` with ``kernel``, where it lies inside (no padding).

    Args:
        x: ``(B, C, H, W)`` float, ``W >= K``.
        kernel: ``(K,)``, ``x``'s dtype and device.

    Returns:
        ``(B, C, H, W - K + 1)``: ``F.conv2d`` of each plane with ``kernel.view(1, 1, 1, K)``.

    Example:
        >>> filter_rows(torch.ones(1, 1, 20, 5), torch.ones(3)).shape
        torch.Size([1, 1, 20, 3])
    """
    return _filter(x, kernel, down_columns=False)


def _shifted_sum(x: torch.Tensor, kernel: torch.Tensor, dim: int) -> torch.Tensor:
    """``sum_i kernel[i] * x[i : i + n]`` along ``dim``, ``n`` the positions where the kernel lies inside."""
    n = x.shape[dim] - kernel.numel() + 1
    out = x.narrow(dim, 0, n) * kernel[0]
    for i in range(1, kernel.numel()):
        out.addcmul_(x.narrow(dim, i, n), kernel[i])
    return out


def _filter(x: torch.Tensor, kernel: torch.Tensor, down_columns: bool) -> torch.Tensor:
    if autocast_enabled(x):  # in x's dtype, as the path without a gradient: a bfloat16 Eq. 3 is 5e-2 off
        with torch.autocast(x.device.type, enabled=False):
            return _filter(x, kernel, down_columns)
    b, c, h, w = x.shape
    k = kernel.numel()
    taps = (k, 1) if down_columns else (1, k)
    out_h, out_w = (h - k + 1, w) if down_columns else (h, w - k + 1)
    if not _grouped(x):
        return F.conv2d(x.reshape(b * c, 1, h, w), kernel.view(1, 1, *taps)).view(b, c, out_h, out_w)
    recorded = torch.is_grad_enabled() and (x.requires_grad or kernel.requires_grad)
    if not recorded and x.dtype in (torch.float32, torch.float64):
        return _shifted_sum(x, kernel, -2 if down_columns else -1)
    weight = kernel.view(1, 1, *taps).expand(GROUPS, 1, *taps)
    planes = x.reshape(b * c, h, w)
    if down_columns:
        extra = -w % GROUPS
        if extra:
            planes = F.pad(planes, (0, extra))
        # (P, H, W / 16, 16) is the memory of a channels-last (P, 16, H, W / 16): adjacent columns as channels
        channels = planes.reshape(b * c, h, (w + extra) // GROUPS, GROUPS).permute(0, 3, 1, 2)
        out = F.conv2d(channels, weight.contiguous(memory_format=torch.channels_last), groups=GROUPS)
        out = out.permute(0, 2, 3, 1).reshape(b, c, out_h, w + extra)
        return out[..., :w] if extra else out
    extra = -h % GROUPS
    if extra:
        planes = F.pad(planes, (0, 0, 0, extra))
    # 16 bands of rows as the channels of a contiguous (P, 16, H / 16, W): a view
    bands = planes.reshape(b * c, GROUPS, (h + extra) // GROUPS, w)
    out = F.conv2d(bands, weight.contiguous(), groups=GROUPS).reshape(b, c, h + extra, out_w)
    return out[:, :, :h] if extra else out
