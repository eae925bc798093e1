"""Reflect-101 padding in torch (``cv2.BORDER_REFLECT_101``) for any pad size, differentiable: the border of every
torch filter of the package, so that each agrees with its OpenCV twin at the edges."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from alcn_cv.errors import InputError

__all__ = ["reflect101_pad"]


def _reflect101_along(x: torch.Tensor, dim: int, before: int, after: int) -> torch.Tensor:
    """``x`` padded along ``dim`` by reflect-101 for any pad size: the reflection repeats, with period
    ``2 * (n - 1)``, where the pad is longer than the side ``n`` (a side of one pixel repeats it). A new tensor,
    exact whatever ``x``'s dtype."""
    # copies of x and of x reversed, not an index_select of computed indices: inductor fails on those (torch 2.13,
    # an image shorter than a pad under torch.compile)
    n = x.shape[dim]
    cycle = torch.cat([x, x.flip(dim).narrow(dim, 1, n - 2)], dim) if n > 1 else x  # x, then back without the ends
    period = cycle.shape[dim]
    start = -before % period
    total = before + n + after
    return torch.cat([cycle] * -(-(start + total) // period), dim).narrow(dim, start, total)


def reflect101_pad(x: torch.Tensor, top: int, bottom: int, left: int, right: int) -> torch.Tensor:
    """``(..., H, W)`` padded on the last two dims with reflect-101 (``cv2.BORDER_REFLECT_101``), for any pad size:
    unlike ``F.pad(mode="reflect")``, a pad longer than its side repeats the reflection, as OpenCV does (a side of
    one pixel repeats it).

    Example:
        >>> reflect101_pad(torch.arange(3.0).view(1, 3), 0, 0, 4, 0)[0].tolist()
        [0.0, 1.0, 2.0, 1.0, 0.0, 1.0, 2.0]
    """
    if x.ndim != 4:  # every plane as one of a batch, for F.pad's 2-D reflect
        padded = reflect101_pad(x.reshape(-1, 1, *x.shape[-2:]), top, bottom, left, right)
        return padded.reshape(*x.shape[:-2], *padded.shape[-2:])
    h, w = x.shape[-2:]
    if max(top, bottom) < h and max(left, right) < w:
        # torch's reflect is reflect-101; one fast pass. Exported as an ONNX Pad, which cv2.dnn (the export's
        # consumer) reflects repeatedly where the pad exceeds the size, as the path below: the graph takes any size
        return F.pad(x, (left, right, top, bottom), mode="reflect")
    if torch.onnx.is_in_onnx_export():  # torch traces no such pad: its own error names neither the image nor a fix
        raise InputError(
            f"an ONNX export traces a reflect pad of {max(top, bottom, left, right)} px on a {h}x{w} plane, longer "
            "than its side, which torch cannot export: export with a larger example image (120x160 exports every "
            "shipped model)"
        )
    return _reflect101_along(_reflect101_along(x, -2, top, bottom), -1, left, right)
