r"""The Gaussian mixture at the heart of ALCN (Rad, Roth & Lepetit, BMVC 2017, Sec. 3.1 and 3.3).

The normalized image is a linear combination of Gaussian-filtered images:

* Eq. 1, one weight vector for the whole image (or window)::

      ALCN(I) = (sum_i w_i G_{sigma_i}) * I

* Eq. 3, per-pixel weight maps F_k predicted by the Normalizer run fully-convolutionally::

      ALCN(I) = sum_k G_{sigma_k} * (F_k o I)

with ``sigma_i = i / 2`` for ``i = 1..10`` by default (:func:`gaussian_sigmas`).

Kernel definition, identical in every implementation here: a sampled Gaussian
``exp(-x^2 / (2 sigma^2))`` on ``x = -r..r`` with ``r = int(truncate * sigma + 0.5)``
(``truncate = 3``), normalized to sum 1 -- the kernel of
``scipy.ndimage.gaussian_filter(..., truncate=3)``. Border rule: reflect-101
(``cv2.BORDER_REFLECT_101``, scipy's ``mode="mirror"``, torch's ``"reflect"``), OpenCV's default.

Two implementations that agree to 1e-5:

* :func:`alcn_filter` -- NumPy/OpenCV, for inference (``float32`` arrays in and out);
* :func:`~alcn_cv.filters.kornia_mixture.gaussian_mixture2d` and
  :class:`~alcn_cv.filters.kornia_mixture.GaussianMixture2d` -- differentiable, on kornia's
  Gaussian filtering, for training (gradients reach the weights and the image). They live in
  their own module so that this one, and the OpenCV runtime, never import torch.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from typing import Literal

import cv2
import numpy as np

from alcn_cv.checks import check_gray
from alcn_cv.errors import InputError

DEFAULT_NUM_KERNELS = 10
DEFAULT_SIGMA_STEP = 0.5
TRUNCATE = 3.0
#: Smallest residual sigma (in pixels of its level) :func:`pyramid_plan` blurs with: a sampled
#: Gaussian much narrower than a pixel is a poor Gaussian. At 0.7 the sigma-2 blur runs on the
#: half-resolution level; a larger value keeps more blurs on the finer levels (more accurate, slower).
#: The error of ALCN's pyramid path at this value is bounded in ``tests/test_fast_alcn.py``.
PYRAMID_MIN_SIGMA = 0.7

__all__ = [
    "PYRAMID_MIN_SIGMA",
    "alcn_filter",
    "alcn_filter_grid",
    "pyramid_mixture",
    "pyramid_plan",
    "check_sigmas",
    "gaussian_blur_stack",
    "gaussian_kernel1d",
    "gaussian_sigmas",
    "kernel_radius",
    "proportional_scales",
    "upsample_grid",
]


def gaussian_sigmas(num_kernels: int = DEFAULT_NUM_KERNELS, step: float = DEFAULT_SIGMA_STEP) -> tuple[float, ...]:
    """Standard deviations of the basis: ``sigma_i = i * step`` for ``i = 1..num_kernels`` (pixels)."""
    if num_kernels < 1 or step <= 0:
        raise InputError(f"need num_kernels >= 1 and step > 0, got {num_kernels} and {step}")
    return tuple(float(i * step) for i in range(1, num_kernels + 1))


def kernel_radius(sigma: float) -> int:
    """Half-width of the sampled kernel of ``sigma``: ``int(3 * sigma + 0.5)`` (at least 1)."""
    return max(1, int(TRUNCATE * sigma + 0.5))


def gaussian_kernel1d(sigma: float) -> np.ndarray:
    """The 1D kernel of ``sigma`` as a float64 array of length ``2 * kernel_radius(sigma) + 1``, sum 1."""
    r = kernel_radius(sigma)
    x = np.arange(-r, r + 1, dtype=np.float64)
    k = np.exp(-0.5 * (x / sigma) ** 2)
    return k / k.sum()


@functools.lru_cache(maxsize=256)
def _cached_kernel(sigma: float) -> np.ndarray:
    """:func:`gaussian_kernel1d`, computed once per sigma (read-only)."""
    kernel = gaussian_kernel1d(sigma)
    kernel.flags.writeable = False
    return kernel


def check_sigmas(sigmas: Sequence[float]) -> tuple[float, ...]:
    """``sigmas`` as a tuple of floats.

    Raises:
        InputError: ``sigmas`` is empty, or one is not positive and finite.
    """
    sigmas = tuple(float(s) for s in sigmas)
    if not sigmas or any(not np.isfinite(s) or s <= 0 for s in sigmas):
        raise InputError(f"sigmas must be positive and finite, got {sigmas}")
    return sigmas


def gaussian_blur_stack(image: np.ndarray, sigmas: Sequence[float]) -> np.ndarray:
    """Blur one image with every kernel of the basis (OpenCV, reflect-101).

    Args:
        image: ``(H, W)`` float32.
        sigmas: the basis' standard deviations, in pixels.

    Returns:
        ``(N, H, W)`` float32, ``out[i] = G_{sigma_i} * image``.
    """
    image = check_gray(image, finite=False)
    sigmas = check_sigmas(sigmas)
    out = np.empty((len(sigmas),) + image.shape, np.float32)
    for i, s in enumerate(sigmas):
        k = gaussian_kernel1d(s)
        cv2.sepFilter2D(image, cv2.CV_32F, k, k, dst=out[i], borderType=cv2.BORDER_REFLECT_101)
    return out


def _check_mixture(
    image: np.ndarray, weights: np.ndarray, sigmas: Sequence[float] | None
) -> tuple[np.ndarray, np.ndarray, tuple[float, ...]]:
    image = check_gray(image, finite=False)
    weights = np.asarray(weights)
    if weights.ndim not in (1, 3) or weights.shape[0] == 0:
        raise InputError(f"weights must have shape (N,) or (N, H, W), got {weights.shape}")
    if weights.ndim == 3 and weights.shape[1:] != image.shape:
        raise InputError(f"weight maps {weights.shape[1:]} do not match the image {image.shape}")
    if not np.isfinite(weights).all():
        raise InputError("weights contain NaN or inf")
    sigmas = gaussian_sigmas(weights.shape[0]) if sigmas is None else check_sigmas(sigmas)
    if len(sigmas) != weights.shape[0]:
        raise InputError(f"{weights.shape[0]} weights for {len(sigmas)} sigmas")
    return image, weights, sigmas


def alcn_filter(image: np.ndarray, weights: np.ndarray, sigmas: Sequence[float] | None = None) -> np.ndarray:
    """ALCN's Gaussian mixture on NumPy arrays (OpenCV filtering, reflect-101 borders).

    Args:
        image: ``(H, W)`` float32 image, intensities nominally in [0, 1].
        weights: ``(N,)`` -- one weight per kernel for the whole image (Eq. 1), or
            ``(N, H, W)`` -- per-pixel weight maps F_k (Eq. 3). float32 or float64.
        sigmas: ``N`` standard deviations in pixels; default :func:`gaussian_sigmas` of ``N``.

    Returns:
        ``(H, W)`` float32 normalized image (unbounded; DoG-like weights give values around 0).

    Example:
        >>> img = np.random.rand(64, 64).astype(np.float32)
        >>> dog = np.zeros(10); dog[0], dog[2] = 1.0, -1.0   # G_0.5 - G_1.5
        >>> alcn_filter(img, dog).shape
        (64, 64)
    """
    image, weights, sigmas = _check_mixture(image, weights, sigmas)
    out = np.zeros(image.shape, np.float32)
    blurred = np.empty(image.shape, np.float32)
    for i, s in enumerate(sigmas):
        k = _cached_kernel(s)
        if weights.ndim == 1:
            if weights[i] == 0:
                continue
            cv2.sepFilter2D(image, cv2.CV_32F, k, k, dst=blurred, borderType=cv2.BORDER_REFLECT_101)
            cv2.scaleAdd(blurred, float(weights[i]), out, dst=out)
        else:
            product = cv2.multiply(image, weights[i].astype(np.float32, copy=False))
            cv2.sepFilter2D(product, cv2.CV_32F, k, k, dst=blurred, borderType=cv2.BORDER_REFLECT_101)
            cv2.add(out, blurred, dst=out)
    return out


def upsample_grid(grid: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """A map given on a grid interpolated bilinearly onto every pixel.

    Grid point ``(i, j)`` lies on pixel ``(stride * i, stride * j)``, as on the grids of ALCN's
    Normalizers: the result is ``torch.nn.functional.interpolate(grid, size=stride * (g - 1) + 1,
    mode="bilinear", align_corners=True)`` cropped to ``shape`` (to float rounding). Along x on the
    grid's rows (small), then along y: one ``cv2.addWeighted`` per phase of the rows within a
    grid cell, each writing its rows in place, so the output is written once -- several times
    cheaper than ``cv2.warpAffine`` onto every pixel, and exact for every stride (``cv2.resize``
    puts its samples half a pixel off these points).

    Args:
        grid: ``(gh, gw)`` float32, ``stride * (gh - 1) >= h - 1`` and ``stride * (gw - 1) >= w - 1``.
        stride: the grid's spacing in pixels.
        shape: ``(h, w)`` of the output.

    Returns:
        ``(h, w)`` float32.

    Raises:
        InputError: the grid does not cover ``shape`` (as :func:`~alcn_cv.filters.torch_resize.interpolate_grid`).
    """
    h, w = shape
    gh, gw = grid.shape
    if stride * (gh - 1) < h - 1 or stride * (gw - 1) < w - 1:
        raise InputError(f"a grid of {gh}x{gw} points {stride} px apart does not cover {h}x{w} pixels")
    return _upsample_rows(_upsample_columns(grid.astype(np.float32, copy=False), stride, w), stride, h)


#: OpenCV's warps interpolate with weights in steps of ``1 / WARP_STEPS`` (``cv2.INTER_TAB_SIZE``) and coordinates
#: held as 16-bit integers: exact for a stride that divides it, on fewer than ``2**15`` columns.
WARP_STEPS = 32


def _upsample_columns(grid: np.ndarray, stride: int, n: int) -> np.ndarray:
    """``grid`` ``(g, m)`` interpolated linearly along its second axis onto ``n`` columns, column
    ``c`` at grid coordinate ``c / stride``: by OpenCV's bilinear warp where its weights are exact
    (:data:`WARP_STEPS`; a pass without the GIL, beside the other rows' parts), else by NumPy."""
    if WARP_STEPS % stride == 0 and n < 2**15:
        to_grid = np.array([[1.0 / stride, 0.0, 0.0], [0.0, 1.0, 0.0]])  # output pixel -> grid coordinate
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        return cv2.warpAffine(grid, to_grid, (n, len(grid)), flags=flags, borderMode=cv2.BORDER_REPLICATE)
    cells = min(grid.shape[1] - 1, -(-n // stride))
    out = np.empty((len(grid), cells * stride + 1), np.float32)
    body = out[:, :-1].reshape(len(grid), cells, stride)
    left = grid[:, :cells]
    step = grid[:, 1 : cells + 1] - left
    # one pass per phase over whole rows of cells: NumPy's loops over a last axis of `stride` values cost 3x more
    for phase in range(stride):
        column = body[:, :, phase]
        np.multiply(step, np.float32(phase) / np.float32(stride), out=column)
        np.add(column, left, out=column)
    out[:, -1] = grid[:, cells]
    return out[:, :n]


def _upsample_rows(grid: np.ndarray, stride: int, n: int) -> np.ndarray:
    """``grid`` ``(g, m)`` interpolated linearly along its first axis onto ``n`` rows, row ``r`` at
    grid coordinate ``r / stride``."""
    m = grid.shape[1]
    cells = min(len(grid) - 1, -(-n // stride))
    out = np.empty((cells * stride + 1, m), np.float32)
    # Row stride * i + p of the output is column block p of row i of this view.
    blocks = out[:-1].reshape(cells, stride * m)
    above, below = grid[:cells], grid[1 : cells + 1]
    for phase in range(stride if cells else 0):
        t = phase / stride
        cv2.addWeighted(above, 1.0 - t, below, t, 0.0, dst=blocks[:, phase * m : (phase + 1) * m])
    out[-1] = grid[cells]
    return out[:n]


def proportional_scales(grid: np.ndarray) -> np.ndarray | None:
    """``s`` with ``grid[k] = s_k * grid[0]`` for every map of an ``(N, gh, gw)`` grid (to float rounding), or
    None: the maps of a band-pass of two kernels (``F_2 = -F_1``, the gain Normalizer's) share one product in
    :func:`alcn_filter_grid`."""
    first = grid[0].astype(np.float64)
    norm = float((first * first).sum())
    if len(grid) < 2 or norm == 0.0:
        return None
    scales = np.array([float((m.astype(np.float64) * first).sum()) / norm for m in grid])
    tolerance = 1e-6 * float(np.abs(first).max())
    # the largest residual of each map, one pass each (np.allclose costs several per map and call)
    if any(float(np.abs(m - s * first).max()) > tolerance for m, s in zip(grid, scales)):
        return None
    return scales


def alcn_filter_grid(
    image: np.ndarray,
    grid: np.ndarray,
    stride: int,
    sigmas: Sequence[float],
    rows: tuple[int, int] | None = None,
    dst: np.ndarray | None = None,
    scales: np.ndarray | None | Literal["whole grid"] = "whole grid",
) -> np.ndarray:
    """Eq. 3 with maps given on a grid: :func:`alcn_filter` of the maps :func:`upsample_grid`
    interpolates, in fewer passes (one map at a time, multiplied by the image in place).

    Args:
        image: ``(H, W)`` float32.
        grid: ``(N, gh, gw)`` float32 maps, point ``(i, j)`` on pixel ``(stride * i, stride * j)``.
        stride: the grid's spacing in pixels.
        sigmas: the ``N`` standard deviations, in pixels.
        rows: ``(start, stop)``: only these rows of the output, computed from the rows within the widest
            kernel's reach around them (the whole output's values, bit for bit); default all.
        dst: a C-contiguous float32 array of the output's shape to write it into (OpenCV's ``dst``).
        scales: the whole grid's :func:`proportional_scales`, from a caller that filters its rows in parts and
            computes them once; default: computed here, of the whole ``grid``, so that every part takes one path.

    Returns:
        ``(H, W)`` float32, or ``(stop - start, W)`` (rows of a larger array): ``dst`` when given.
    """
    image = check_gray(image, finite=False)
    sigmas = check_sigmas(sigmas)
    if grid.ndim != 3 or len(grid) != len(sigmas):
        raise InputError(f"need one grid map per sigma, got {grid.shape} for {len(sigmas)} sigmas")
    start, stop = (0, len(image)) if rows is None else rows
    if not 0 <= start <= stop <= len(image):
        raise InputError(f"rows must be (start, stop) with 0 <= start <= stop <= {len(image)}, got {rows}")
    shape = (stop - start, image.shape[1])
    if dst is not None and (dst.shape != shape or dst.dtype != np.float32 or not dst.flags.c_contiguous):
        raise InputError(f"dst must be a C-contiguous float32 array of shape {shape}, got {dst.dtype} {dst.shape}")
    if isinstance(scales, str):
        scales = proportional_scales(grid)
    # From a grid row, so the part's maps are the whole one's rows; the blurs' reflected margins fall
    # outside the rows kept unless they are the image's own.
    reach = kernel_radius(max(sigmas))
    lo, hi = max(0, start - reach) // stride * stride, min(len(image), stop + reach)
    if (lo, hi) == (start, stop):
        return _alcn_filter_grid(image, grid, stride, sigmas, scales, dst)
    part = _alcn_filter_grid(image[lo:hi], grid[:, lo // stride :], stride, sigmas, scales, None)
    if dst is None:
        return part[start - lo : stop - lo]
    np.copyto(dst, part[start - lo : stop - lo])
    return dst


def _alcn_filter_grid(
    image: np.ndarray,
    grid: np.ndarray,
    stride: int,
    sigmas: tuple[float, ...],
    scales: np.ndarray | None,
    dst: np.ndarray | None,
) -> np.ndarray:
    """:func:`alcn_filter_grid` of the whole ``image``, into ``dst`` when given."""
    h, w = image.shape
    if dst is None:
        dst = np.empty((h, w), np.float32)
    blurred = np.empty((h, w), np.float32)
    maps = [grid[0]] if scales is not None else list(grid)
    for k, sigma in enumerate(sigmas):
        if k < len(maps):  # one product for every kernel when the maps are proportional
            product = upsample_grid(maps[k], stride, (h, w))
            cv2.multiply(image, product, dst=product)
        kernel = _cached_kernel(sigma)
        # with one product for every kernel (sum_k G_k * (s_k F o I)), s_k is folded into the blur's row kernel
        row_kernel = kernel if scales is None else kernel * scales[k]
        cv2.sepFilter2D(
            product, cv2.CV_32F, row_kernel, kernel, dst=dst if k == 0 else blurred, borderType=cv2.BORDER_REFLECT_101
        )
        if k:
            cv2.add(dst, blurred, dst=dst)
    return dst


# --- The pyramid approximation of Eq. 3 (fast path) ------------------------------------------
#
# A blur of sigma >= 2 does not need every pixel: G_sigma * P equals, up to the non-Gaussian
# shape of the pyramid kernels, pyrUp^L(G_sigma' * pyrDown^L(P)). cv2.pyrDown and cv2.pyrUp
# both filter with the 5-tap binomial (1, 4, 6, 4, 1) / 16, of variance 1 pixel^2 at the finer
# level, so L levels down and up add ``2 * (4**L - 1) / 3`` fine pixels^2 and the residual blur
# at level L is ``sigma'^2 = (sigma^2 - 2 * (4**L - 1) / 3) / 4**L``. Kernels on the same level
# are summed there and the levels are added coarse to fine (one pyrUp per level, Horner
# style), so the cost is that of the finest level's few small kernels plus a fraction for the
# rest. The product F_k o I is formed at each kernel's level from the level's image and the
# maps sampled at that level, which assumes the maps vary little within a pyramid footprint
# (Eq. 3's maps are interpolated from a grid of at least 4 working pixels).
# Level pixel x_L sits on pixel 2**L * x_L of the input (cv2.pyrDown's convention).


def _pyramid_variance(level: int) -> float:
    return 2.0 * (4.0**level - 1.0) / 3.0


def pyramid_plan(
    sigmas: Sequence[float], min_sigma: float = PYRAMID_MIN_SIGMA, max_level: int | None = None
) -> tuple[tuple[int, float], ...]:
    """Where :func:`pyramid_mixture` computes each blur.

    Args:
        sigmas: standard deviations in input pixels.
        min_sigma: smallest residual sigma allowed at a level (its pixels).
        max_level: coarsest level allowed (0 = input resolution); default: no limit.

    Returns:
        For each sigma, ``(level, residual sigma in that level's pixels)``: the coarsest level
        whose residual sigma is still at least ``min_sigma`` (level 0 with the sigma itself
        when none is).
    """
    sigmas = check_sigmas(sigmas)
    if not min_sigma > 0:
        raise InputError(f"min_sigma must be positive, got {min_sigma}")
    plan = []
    for sigma in sigmas:
        level = 0
        while max_level is None or level < max_level:
            nxt = level + 1
            residual2 = (sigma * sigma - _pyramid_variance(nxt)) / 4.0**nxt
            if residual2 < min_sigma * min_sigma:
                break
            level = nxt
        plan.append((level, math.sqrt((sigma * sigma - _pyramid_variance(level)) / 4.0**level)))
    return tuple(plan)


def _max_pyramid_level(shape: tuple[int, int], min_size: int = 8) -> int:
    """The coarsest pyramid level whose smaller side keeps at least ``min_size`` pixels."""
    return max(0, int(math.floor(math.log2(max(1, min(shape)) / min_size))))


#: ``weights_at(level, kernel indices, (h, w))`` -> the kernels' maps (or scalars) at that level.
WeightsAtLevel = Callable[[int, Sequence[int], tuple[int, int]], Sequence]


def pyramid_mixture(
    image: np.ndarray, sigmas: Sequence[float], weights_at: WeightsAtLevel, min_sigma: float = PYRAMID_MIN_SIGMA
) -> np.ndarray:
    """Eq. 3 with the wide blurs on a Gaussian pyramid (``cv2.pyrDown`` / ``cv2.pyrUp``): an approximation of
    :func:`alcn_filter`, exact in the limit of smooth maps and Gaussian pyramid kernels, its error largest near the
    image's bottom and right borders (where the pyramid's reflection is off by a pixel). ``ALCN(mixture="pyramid")``
    runs it on its grid's maps; its error against ``mixture="exact"`` is bounded in ``tests/test_fast_alcn.py``.

    Args:
        image: ``(H, W)`` float32.
        sigmas: the mixture's standard deviations, in input pixels.
        weights_at: ``weights_at(level, ks, (h, w))`` returns the weights of kernels ``ks`` at
            pyramid level ``level`` of size ``(h, w)``: a ``(len(ks), h, w)`` float32 array of
            maps sampled on that level's pixels (pixel ``x`` of level ``L`` is input pixel
            ``2**L * x``; the coarser levels extend beyond the input's bottom and right edges,
            where the maps are expected to continue smoothly), or ``len(ks)`` scalars.
        min_sigma: smallest residual sigma at a coarse level (:func:`pyramid_plan`); larger is more accurate
            and slower.

    Returns:
        ``(H, W)`` float32.
    """
    image = check_gray(image, finite=False)
    plan = pyramid_plan(sigmas, min_sigma, _max_pyramid_level(image.shape))
    top = max(level for level, _ in plan)
    height, width = image.shape
    levels = [_pad_to_pyramid(image, top, _pyramid_margin(sigmas, top))]
    for _ in range(top):
        levels.append(cv2.pyrDown(levels[-1], borderType=cv2.BORDER_REFLECT_101))
    # Level 0 is the largest: it runs only as far beyond the input as its own blurs reach (the
    # padded plane there, so the result is that of the whole level), and the coarser sum is
    # brought up only that far (pyrUp's output rows 2i and 2i+1 read input rows i-1 to i+1).
    if top > 0:
        reach = max((kernel_radius(residual) for level, residual in plan if level == 0), default=0)
        levels[0] = levels[0][: height + reach, : width + reach]
    acc: np.ndarray | None = None
    for level in range(top, -1, -1):
        img = levels[level]
        h, w = img.shape
        if acc is not None:
            if level == 0:
                acc = acc[: h // 2 + 2, : w // 2 + 2]
            up = (2 * acc.shape[1], 2 * acc.shape[0]) if level == 0 else (w, h)
            acc = cv2.pyrUp(acc, dstsize=up, borderType=cv2.BORDER_REFLECT_101)[:h, :w]
        ks = [k for k, (lv, _) in enumerate(plan) if lv == level]
        if not ks:
            continue
        product = np.empty((h, w), np.float32)
        blurred = np.empty((h, w), np.float32)
        for k, weight in zip(ks, weights_at(level, ks, (h, w))):
            kernel = _cached_kernel(plan[k][1])
            if np.ndim(weight) == 0:
                if weight == 0:
                    continue
                cv2.sepFilter2D(img, cv2.CV_32F, kernel, kernel, dst=blurred, borderType=cv2.BORDER_REFLECT_101)
                if acc is None:
                    acc = np.zeros((h, w), np.float32)
                cv2.scaleAdd(blurred, float(weight), acc, dst=acc)
            else:
                cv2.multiply(img, weight, dst=product)
                if acc is None:  # the first blur is the sum so far
                    acc = cv2.sepFilter2D(product, cv2.CV_32F, kernel, kernel, borderType=cv2.BORDER_REFLECT_101)
                    continue
                cv2.sepFilter2D(product, cv2.CV_32F, kernel, kernel, dst=blurred, borderType=cv2.BORDER_REFLECT_101)
                cv2.add(acc, blurred, dst=acc)
    if acc is None:  # every weight was zero
        return np.zeros((height, width), np.float32)
    return acc[:height, :width]


def _pyramid_margin(sigmas: Sequence[float], top: int) -> int:
    """Rows and columns added beyond the bottom and right edges (see :func:`_pad_to_pyramid`)."""
    return 0 if top == 0 else int(math.ceil(TRUNCATE * max(sigmas))) + 2**top


def _pad_to_pyramid(plane: np.ndarray, top: int, margin: int) -> np.ndarray:
    """Extend the bottom and right by reflect-101, by at least ``margin`` and up to a size
    ``2**top * m + 1``.

    The top and left edges need nothing: pixel 0 lies on every level, so the levels'
    reflect-101 borders mirror about the input's. At the far edges they would mirror about
    another pixel; the margin moves that border out of the blurs' reach, where the extension
    holds the input's own reflection, as the exact filter sees it.
    """
    if top == 0:
        return plane
    h, w = plane.shape
    step = 2**top
    bottom, right = margin + (-(h - 1 + margin) % step), margin + (-(w - 1 + margin) % step)
    return cv2.copyMakeBorder(plane, 0, bottom, 0, right, cv2.BORDER_REFLECT_101)
