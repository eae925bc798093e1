"""ALCN's runtimes behind :class:`~alcn_cv.enhance.alcn.ALCN`: one per model family, a network adapter per backend.

A weight file's header says which method it is (:class:`ModelSpec`). :class:`WindowRuntime` runs the paper's
family (the paper's and the lite Normalizer: maps at the working scale, Eq. 3 exact or on a pyramid) and
:class:`GainRuntime` the gain family (maps on the network's grid, Eq. 3 from the grid, divisive normalization,
``tanh``), both with Eq. 3 in OpenCV and the network behind :class:`Network`: the ONNX export run by
``cv2.dnn`` (:class:`~alcn_cv.nets.opencv_runtime.OpenCVNormalizer`, ``backend="opencv"``) or the torch network
on the CPU (:class:`alcn_cv.nn.TorchNetwork`, ``backend="fast"``). ``backend="torch"`` runs everything in torch:
:class:`alcn_cv.nn.ALCN2d`, behind the same :class:`Runtime` protocol. This module imports no torch.
"""

from __future__ import annotations

import hashlib
import logging
import math
import numbers
import os
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from alcn_cv.checks import check_image, check_out_dtype
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.divisive import blurred_square, divide_by_energy, divisive_floor, divisive_normalization
from alcn_cv.filters.equalization import tanh
from alcn_cv.filters.gaussian_mixture import (
    PYRAMID_MIN_SIGMA,
    alcn_filter,
    alcn_filter_grid,
    kernel_radius,
    proportional_scales,
    pyramid_mixture,
    pyramid_plan,
    upsample_grid,
)
from alcn_cv.filters.wide_band import BLOCK, band_reach, check_band_meta, wide_band
from alcn_cv.nets.opencv_runtime import WINDOW, OpenCVNormalizer
from alcn_cv.row_parts import row_parts, run_parts, submit
from alcn_cv.weight_file import WEIGHTS_DIR, NormalizerFile, gain_scale

__all__ = [
    "DEFAULT_MODEL",
    "MODELS",
    "GainRuntime",
    "ModelSpec",
    "Network",
    "TEACHERS",
    "Runtime",
    "WindowRuntime",
    "make_runtime",
    "opencv_network",
    "resolve_weights",
    "weights_setting",
]

logger = logging.getLogger(__name__)

#: The weight files shipped in the package, by ``model`` name.
MODELS = {
    "paper": WEIGHTS_DIR / "alcn_normalizer.npz",
    "lite": WEIGHTS_DIR / "alcn_normalizer_lite.npz",
    "gain": WEIGHTS_DIR / "alcn_normalizer_gain.npz",
    "gain-lite": WEIGHTS_DIR / "alcn_normalizer_gain_lite.npz",
}
#: The shipped Normalizer when neither ``model`` nor ``weights`` is given.
DEFAULT_MODEL = "gain"
#: The distilled models and the model each was distilled from (a warning when that file changed).
TEACHERS = {"lite": "paper", "gain-lite": "gain"}

#: ``mixture="pyramid"`` samples the maps exactly this many times per grid cell (at least).
MAP_STEP_PER_CELL = 4


@dataclass(frozen=True)
class ModelSpec:
    """The method a weight file describes, at the input resolution.

    Attributes:
        sigmas: Eq. 3's sigmas in working pixels; :attr:`full_res_sigmas` in input pixels.
        scale: the working scale (input -> the Normalizer's resolution).
        output_range: the raw responses mapped onto [0, 1].
        tau: the gain family's final ``tanh(x / tau)`` (``exp`` of its array ``log_tau``), or None.
        divisive: the gain family's divisive normalization ``(sigma in input pixels, scale c)`` (``c``: ``exp`` of
            its array ``log_floor_scale``), or None.
        per_pixel: the gain family (maps on a grid of its own, windows normalized as small images).
        reach: how far from a grid point the network looks (working pixels).
        band: the weight of the :mod:`~alcn_cv.filters.wide_band` added to the gain family's output (0: none).
    """

    sigmas: tuple[float, ...]
    scale: float
    output_range: tuple[float, float]
    tau: float | None
    divisive: tuple[float, float] | None
    per_pixel: bool
    reach: int
    band: float = 0.0

    @classmethod
    def from_file(cls, weight_file: NormalizerFile, scale: float | None = None) -> ModelSpec:
        """The method of a weight file read by :func:`~alcn_cv.weight_file.load_normalizer_file` (which checked the
        header fields read here) at ``scale`` (default: the file's working scale); the gain family's ``tau`` and
        ``c`` from its arrays (:func:`~alcn_cv.weight_file.gain_scale`), as its network has them.

        Raises:
            InputError: ``scale`` not a number in (0, 4].
        """
        meta = weight_file.meta
        scale = meta["working_scale"] if scale is None else scale
        number = isinstance(scale, numbers.Real) and not isinstance(scale, bool)
        if not (number and 0 < scale <= 4):
            raise InputError(f"scale must be a number in (0, 4], got {scale!r}")
        scale = float(scale)
        per_pixel = meta.get("architecture") == "gain"
        reach = WINDOW // 2
        tau: float | None = None
        divisive: tuple[float, float] | None = None
        if per_pixel:  # the cells, the reach of the context blur on them and of the dilated convolutions
            config = meta["config"]
            stride = int(config["stride"])
            blur = max(float(config["mean_sigma"]), float(config["context_sigma"])) / stride
            reach = stride * (1 + kernel_radius(blur) + sum(int(d) for d in config["dilations"]))
            tau = gain_scale(weight_file.arrays, "log_tau")
            divisive = (float(meta["divisive"]["sigma"]) / scale, gain_scale(weight_file.arrays, "log_floor_scale"))
        return cls(
            sigmas=tuple(float(s) for s in meta["sigmas"]),
            scale=scale,
            output_range=(float(meta["output_range"][0]), float(meta["output_range"][1])),
            tau=tau,
            divisive=divisive,
            per_pixel=per_pixel,
            reach=reach,
            band=check_band_meta(meta["band"]) if "band" in meta else 0.0,
        )

    @property
    def full_res_sigmas(self) -> tuple[float, ...]:
        """Eq. 3's sigmas in input pixels: ``sigma_k / scale``."""
        return tuple(s / self.scale for s in self.sigmas)

    def working_shape(self, shape: tuple[int, int]) -> tuple[int, int]:
        """``(H, W)`` at the working scale: each side times :attr:`scale`, rounded half to even (Python's ``round``:
        101 x 0.5 is 50), at least 1; the same for every backend."""
        h, w = shape
        if self.scale == 1:
            return h, w
        return max(1, round(h * self.scale)), max(1, round(w * self.scale))

    def working_image(self, gray: np.ndarray) -> np.ndarray:
        """``(H, W)`` float32 at the working scale (``cv2.INTER_AREA`` down, bilinear up)."""
        if self.scale == 1:
            return gray
        h, w = self.working_shape(gray.shape)
        return cv2.resize(gray, (w, h), interpolation=cv2.INTER_AREA if self.scale < 1 else cv2.INTER_LINEAR)


class Network(Protocol):
    """A Normalizer as the OpenCV runtimes use it: NumPy in and out, on a grid of :attr:`stride` pixels."""

    stride: int

    def dense_grid(self, image: np.ndarray, alongside: Callable[[], object] | None = None) -> np.ndarray:
        """``(h, w)`` working-scale float32 -> ``(N, ceil((h-1)/s)+1, ceil((w-1)/s)+1)``, point ``(i, j)`` at
        pixel ``(s*i, s*j)``; ``alongside()`` is called once the full-resolution work is done (the gain
        Normalizer's cell moments, on OpenCV's threads), before the layers on the grid (one thread)."""

    def dense(self, image: np.ndarray) -> np.ndarray:
        """``(h, w)`` -> ``(N, h, w)``: :meth:`dense_grid` interpolated bilinearly (``align_corners``)."""

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        """``(n, 48, 48)`` float32 -> ``(n, N)``: the prediction for each window (Eq. 1)."""


class Runtime(Protocol):
    """What :class:`~alcn_cv.enhance.alcn.ALCN` asks of a model family's runtime (float32 ``(H, W)`` in [0, 1])."""

    spec: ModelSpec
    grid_stride: int

    def weight_grid(self, gray: np.ndarray) -> np.ndarray: ...

    def weight_maps(self, gray: np.ndarray) -> np.ndarray: ...

    def window_weights(self, windows: np.ndarray) -> np.ndarray: ...

    def mixture(self, gray: np.ndarray) -> np.ndarray:
        """Eq. 3's raw response ``(H, W)``."""

    def normalize(self, gray: np.ndarray, floor: float | None = None, band_floor: float | None = None) -> np.ndarray:
        """The method's raw response ``(H, W)``; ``floor`` and ``band_floor``: the divisive floors of the whole
        image (the response's and the wide band's)."""


class WindowRuntime:
    """The paper's family in OpenCV: the maps of :class:`Network` resized to the input, Eq. 3 exact
    (:func:`~alcn_cv.filters.gaussian_mixture.alcn_filter`) or on a pyramid
    (:func:`~alcn_cv.filters.gaussian_mixture.pyramid_mixture`); the gain family's last steps when the spec
    has them (:meth:`finish`)."""

    def __init__(self, spec: ModelSpec, network: Network, mixture: str) -> None:
        self.spec, self.network, self.mixture_kind = spec, network, mixture
        self.grid_stride = network.stride

    def weight_grid(self, gray: np.ndarray) -> np.ndarray:
        return self.network.dense_grid(self.spec.working_image(gray))

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        h, w = gray.shape
        maps = self.network.dense(self.spec.working_image(gray))
        if maps.shape[1:] == (h, w):
            return maps
        return np.stack([cv2.resize(m, (w, h), interpolation=cv2.INTER_LINEAR) for m in maps])

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        return self.network.window_weights(windows)

    def mixture(self, gray: np.ndarray) -> np.ndarray:
        if self.mixture_kind == "pyramid":
            grid = self.weight_grid(gray)
            h, w = gray.shape
            small_h, small_w = self.spec.working_shape(gray.shape)
            ratios = (small_h / h, small_w / w)
            return pyramid_mixture(
                gray,
                self.spec.full_res_sigmas,
                lambda *args: self._grid_maps_at(grid, ratios, *args),
                PYRAMID_MIN_SIGMA,
            )
        return alcn_filter(gray, self.weight_maps(gray), self.spec.full_res_sigmas)

    def finish(self, response: np.ndarray, floor: float | None = None) -> np.ndarray:
        """The gain family's steps after Eq. 3: the divisive normalization, then ``tanh(x / tau)``.
        ``response`` (float32, the caller's own) is overwritten."""
        tau, divisive = self.spec.tau, self.spec.divisive
        inverse_tau = 1.0 if tau is None else 1.0 / tau  # folds into the division
        if divisive is not None:
            response = divisive_normalization(response, *divisive, floor=floor, multiplier=inverse_tau)
        elif inverse_tau != 1.0:
            np.multiply(response, np.float32(inverse_tau), out=response)
        return response if tau is None else tanh(response, out=response)

    def normalize(self, gray: np.ndarray, floor: float | None = None, band_floor: float | None = None) -> np.ndarray:
        out = self.finish(self.mixture(gray), floor)
        if self.spec.band and self.spec.tau is not None and self.spec.divisive is not None:
            band = wide_band(gray, self.spec.tau, self.spec.divisive[1], band_floor)
            cv2.scaleAdd(band, self.spec.band, out, dst=out)
        return out

    def _grid_maps_at(
        self, grid: np.ndarray, ratios: tuple[float, float], level: int, ks: list[int], shape: tuple[int, int]
    ) -> list[np.ndarray]:
        # Pixel x of pyramid level L is input pixel 2**L * x (cv2.pyrDown), i.e. working pixel
        # (2**L * x + 0.5) * r - 0.5 with r = working / input size (cv2.resize), i.e. grid
        # coordinate that / grid_stride. The maps are interpolated bilinearly from the grid onto
        # every f-th pixel (cv2.warpAffine, small), then onto every pixel by cv2.resize
        # (x = f * u + (f - 1) / 2, its pixel-centre convention), several times cheaper than
        # warping every pixel. The two differ only between samples that straddle a grid point,
        # by a fraction of the maps' change there; f, a power of 2, is at most a quarter of the
        # grid's spacing at this level (covered by the error bounds in tests/test_fast_alcn.py).
        g = self.grid_stride
        (ry, rx), step = ratios, 2.0**level
        ax, bx = step * rx / g, (0.5 * rx - 0.5) / g
        ay, by = step * ry / g, (0.5 * ry - 0.5) / g
        h, w = shape
        along_y, along_x = _integer_zoom(ay, by), _integer_zoom(ax, bx)
        if (
            along_y
            and along_x
            and grid.shape[1] * along_y[0] >= along_y[1] + h
            and grid.shape[2] * along_x[0] >= along_x[1] + w
        ):
            # The level's pixels fall on a zoom of the grid by an integer factor: one cv2.resize,
            # the exact bilinear interpolation (at level 0 of a frame of even size, usually).
            (zy, oy), (zx, ox) = along_y, along_x
            return [
                cv2.resize(grid[k], None, fx=zx, fy=zy, interpolation=cv2.INTER_LINEAR)[oy : oy + h, ox : ox + w]
                for k in ks
            ]
        f = 2 ** max(0, int(np.floor(np.log2(1.0 / (MAP_STEP_PER_CELL * max(ax, ay))))))
        to_grid = np.array([[ax * f, 0.0, ax * (f - 1) / 2 + bx], [0.0, ay * f, ay * (f - 1) / 2 + by]])
        coarse = (w, h) if f == 1 else (-(-w // f) + 1, -(-h // f) + 1)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        maps = []
        for k in ks:
            small = cv2.warpAffine(grid[k], to_grid, coarse, flags=flags, borderMode=cv2.BORDER_REPLICATE)
            maps.append(
                small if f == 1 else cv2.resize(small, None, fx=f, fy=f, interpolation=cv2.INTER_LINEAR)[:h, :w]
            )
        return maps


class GainRuntime(WindowRuntime):
    """The gain family in OpenCV at scale 1: the maps interpolated from the network's grid as
    :meth:`GainNormalizer.dense <alcn_cv.nets.gain.GainNormalizer.dense>` does, and the exact Eq. 3 from the
    grid (:func:`~alcn_cv.filters.gaussian_mixture.alcn_filter_grid`, without the full-resolution maps), on
    OpenCV's threads (:mod:`alcn_cv.row_parts`)."""

    def __init__(self, spec: ModelSpec, network: Network, mixture: str, parts: int | None = None) -> None:
        super().__init__(spec, network, mixture)
        #: The most parts of the rows :meth:`normalize` cuts an image into (None: one per thread of
        #: ``cv2.getNumThreads()``).
        self.parts = parts

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        return np.stack([upsample_grid(m, self.grid_stride, gray.shape) for m in self.weight_grid(gray)])

    def mixture(self, gray: np.ndarray) -> np.ndarray:
        if self.mixture_kind == "pyramid":
            return super().mixture(gray)
        return alcn_filter_grid(gray, self.weight_grid(gray), self.grid_stride, self.spec.full_res_sigmas)

    def normalize(self, gray: np.ndarray, floor: float | None = None, band_floor: float | None = None) -> np.ndarray:
        """:meth:`WindowRuntime.normalize`'s values, bit for bit, on OpenCV's threads: the wide band beside the
        network's layers on the grid, then Eq. 3 and its energy ``e^2`` for each part of the rows
        (:func:`~alcn_cv.row_parts.row_parts`), the divisive floor from the whole image's energy, then each part's
        division, ``tanh`` and band."""
        spec = self.spec
        if self.mixture_kind == "pyramid" or spec.divisive is None or spec.tau is None:
            return super().normalize(gray, floor, band_floor)
        sigma, c = spec.divisive
        parts = row_parts(gray.shape, self.grid_stride, self.parts)
        band: list[Future[np.ndarray]] = []  # computed beside the network's layers on the grid

        def start_band() -> None:
            if spec.band and len(parts) > 1:  # an image too small for parts stays on one thread
                band.append(submit(wide_band, gray, spec.tau, c, band_floor))

        grid = self.network.dense_grid(gray, start_band)
        scales = proportional_scales(grid)  # once, not in each part (NumPy's small passes hold the GIL)
        response, squared = np.empty_like(gray), np.empty_like(gray)
        energy = np.empty_like(gray) if floor is None else None
        reach = kernel_radius(sigma)

        def eq3_and_energy(start: int, stop: int) -> None:
            # Eq. 3 over the rows the energy's blur reaches, then e^2 of this part's rows
            lo, hi = max(0, start - reach), min(len(gray), stop + reach)
            own = slice(start - lo, stop - lo)
            if (lo, hi) == (start, stop):
                eq3 = alcn_filter_grid(gray, grid, self.grid_stride, spec.full_res_sigmas, dst=response, scales=scales)
                blurred_square(eq3, sigma, squared)
            else:
                eq3 = alcn_filter_grid(gray, grid, self.grid_stride, spec.full_res_sigmas, (lo, hi), scales=scales)
                response[start:stop] = eq3[own]
                squared[start:stop] = blurred_square(eq3, sigma)[own]
            if energy is not None:
                cv2.sqrt(squared[start:stop], dst=energy[start:stop])

        run_parts(eq3_and_energy, parts)
        if floor is None:
            assert energy is not None  # computed by the parts when no floor is given
            floor = divisive_floor(energy, c)
        whole_floor = floor  # a name the closure below sees as a float
        inverse_tau = 1.0 / spec.tau
        band_image = band[0].result() if band else wide_band(gray, spec.tau, c, band_floor) if spec.band else None

        def divide(start: int, stop: int) -> None:  # in place in the rows of e^2
            rows = divide_by_energy(response[start:stop], squared[start:stop], whole_floor, inverse_tau)
            tanh(rows, out=rows)
            if band_image is not None:
                cv2.scaleAdd(band_image[start:stop], spec.band, rows, dst=rows)

        run_parts(divide, parts)
        return squared


def make_runtime(spec: ModelSpec, network: Network, mixture: str) -> WindowRuntime:
    """The OpenCV runtime of the spec's family with ``network``."""
    return (GainRuntime if spec.per_pixel and spec.scale == 1 else WindowRuntime)(spec, network, mixture)


def check_batch(frames: np.ndarray, out_dtype: type | np.dtype | str | None) -> tuple[np.ndarray, np.dtype]:
    """Check a ``(B, H, W)`` or ``(B, H, W, C)`` batch of :meth:`ALCN.apply_batch
    <alcn_cv.enhance.alcn.ALCN.apply_batch>`: the frames in native byte order (the array itself when it is) and the
    output dtype (default: the frames')."""
    if not isinstance(frames, np.ndarray) or frames.ndim not in (3, 4) or frames.size == 0:
        raise InputError(
            f"frames must be a non-empty (B, H, W) or (B, H, W, C) array, got {getattr(frames, 'shape', type(frames))}"
        )
    check_image(frames[0])  # the dtype and channels; a float batch's range is checked as a whole below
    frames = frames.astype(frames.dtype.newbyteorder("="), copy=False)  # as apply() takes any byte order
    if frames.dtype == np.float32:
        check_image(frames.reshape(-1, frames.shape[-1]))
    return frames, check_out_dtype(out_dtype, frames.dtype)


def opencv_network(weight_file: NormalizerFile, grid_stride: int | None, spec: ModelSpec) -> OpenCVNormalizer:
    """The ONNX export beside ``weight_file`` (its ``path``; the same name, ``.onnx``) run by ``cv2.dnn``, checked
    against the spec (it runs at its stride) and against the weight file: the export holds the arrays of its
    network, their float32 bytes as they are (the initializers' raw data), so an export that does not hold every
    one was made from other weights (a file copied beside another, or left over from an earlier run).

    Raises:
        WeightFileError: the export is missing, unreadable or not the export of these weights.
        InputError: ``grid_stride`` is not the export's stride; the export's kernels are not the spec's.
    """
    if weight_file.path is None:
        raise WeightFileError("backend='opencv' runs the ONNX export beside a weight file: save the weights to a file")
    onnx = weight_file.path.with_suffix(".onnx")
    # before the graph is read with the weight file's config: another model's export (a gain one beside a paper
    # model's weights) would need fields this config lacks
    if onnx.is_file():
        exported = onnx.read_bytes()
        missing = [
            name
            for name, array in weight_file.arrays.items()
            # the 0-d arrays (tau, the floor's scale) are not in the graph: the runtime reads them from the weight file
            if array.ndim and array.astype("<f4", copy=False).tobytes() not in exported
        ]
        if missing:
            raise WeightFileError(
                f"{onnx} is not the export of {weight_file.path.name} (it does not hold its {', '.join(missing)}): "
                f"export it again, `alcn export --weights {weight_file.path} --onnx {onnx} --overwrite`"
            )
    net = OpenCVNormalizer(onnx, weight_file.meta["config"])
    if grid_stride not in (None, net.stride):
        raise InputError(
            f"backend='opencv' evaluates the Normalizer at its stride {net.stride}, got grid_stride={grid_stride}; "
            "another grid stride runs the network in torch: backend='fast' (the [train] extra)"
        )
    kernels = net.dense_grid(np.zeros((WINDOW, WINDOW), np.float32)).shape[0]
    if len(spec.sigmas) != kernels:
        raise InputError(f"weight file has {len(spec.sigmas)} sigmas for {kernels} outputs")
    return net


def eq1_windows(runtime: Runtime, unit: np.ndarray) -> np.ndarray:
    """Eq. 1 on every ``(n, S, S)`` float32 window (``S >= 48`` at the working scale): one weight vector from its
    central 48x48, then the mixture over the whole window -> ``(n, S, S)``."""
    centre = np.stack([runtime.spec.working_image(w) for w in unit])
    if centre.shape[1] < WINDOW:
        raise InputError(f"windows must be at least {WINDOW} px at the working scale, got {centre.shape[1]}")
    o = (centre.shape[1] - WINDOW) // 2
    weights = runtime.window_weights(np.ascontiguousarray(centre[:, o : o + WINDOW, o : o + WINDOW]))
    return np.stack([alcn_filter(w, wt, runtime.spec.full_res_sigmas) for w, wt in zip(unit, weights)])


def strip_layout(spec: ModelSpec, grid_stride: int, mixture: str, shape: tuple[int, int]) -> tuple[int, int] | None:
    """``(halo, step)`` of the strips of a large image (:meth:`Normalization._tiling
    <alcn_cv.enhance.base.Normalization._tiling>`), or None where strips would change the output.

    A strip gives the whole image's output when it starts on a grid row (and so on a row of every pyramid level)
    and its working image is the whole one's rows (an integer zoom from the working scale); its halo covers the
    Normalizer's windows around the grid points its maps interpolate, the mixture's blurs and pyramid filters and
    the energy's Gaussian.
    """
    zoom = 1.0 / spec.scale
    if abs(zoom - round(zoom)) > 1e-9 or abs(shape[0] * spec.scale - round(shape[0] * spec.scale)) > 1e-9:
        return None
    zoom = round(zoom)
    sigmas = spec.full_res_sigmas
    top = max(level for level, _ in pyramid_plan(sigmas, PYRAMID_MIN_SIGMA)) if mixture == "pyramid" else 0
    step = math.lcm(zoom * grid_stride, 2**top)
    reach = zoom * (spec.reach + grid_stride) + kernel_radius(max(sigmas)) + 2 ** (top + 2)
    if spec.divisive is not None:
        reach += kernel_radius(spec.divisive[0])
    if spec.band:  # its blocks start on whole blocks of the image's; its reach is its own
        step = math.lcm(step, BLOCK)
        reach = max(reach, band_reach())
    return -(-reach // step) * step, step


def resolve_weights(model: str | None, weights: str | Path | None) -> Path:
    """The weight file of ``weights`` or of the shipped ``model`` (default :data:`DEFAULT_MODEL`), not both."""
    if weights is not None and not isinstance(weights, (str, os.PathLike)):  # createALCN(1.0), as cv2.createCLAHE(2.0)
        shown = f" {weights!r}" if isinstance(weights, numbers.Number) else ""  # not a state_dict's every tensor
        raise InputError(
            f"weights must be the path of a weight file (.npz), got {type(weights).__name__}{shown} (the other "
            "settings are keywords, as createALCN(scale=...); a module's state_dict loads by load_state_dict, and "
            "ALCN2d.save(path) writes a weight file)"
        )
    if model is not None and weights is not None:
        raise InputError(f"give a model or a weight file, not both (model={model!r}, weights={str(weights)!r})")
    if isinstance(weights, str) and weights in MODELS and not os.path.exists(weights):  # createALCN("lite")
        raise InputError(f"weights={weights!r} is no file; the shipped model of that name is model={weights!r}")
    model = DEFAULT_MODEL if model is None else model
    if model not in MODELS:
        # ALCN2d's first argument is the model, createALCN's the weights: ALCN2d("tuned.npz")
        path = isinstance(model, str | os.PathLike) and (str(model).endswith(".npz") or os.path.exists(model))
        hint = f" (a weight file: weights={str(model)!r})" if path else ""
        raise InputError(f"unknown model {str(model)!r}; choose one of {', '.join(MODELS)}{hint}")
    return Path(weights) if weights is not None else MODELS[model]


def weights_setting(path: str | Path | None) -> str:
    """How a repr names the Normalizer of the weight file ``path``: ``model='gain'`` for a shipped file, else
    ``weights='PATH'`` (``weights=<contents>`` for None: the file's contents given already loaded)."""
    if path is None:
        return "weights=<contents>"
    shipped = next((name for name, file in MODELS.items() if Path(path) == file), None)
    return f"model={shipped!r}" if shipped else f"weights={str(path)!r}"


def check_teacher(meta: dict, path: Path) -> None:
    """Warn when a shipped distilled weight file's teacher (:data:`TEACHERS`) is not the file shipped now."""
    teacher = meta.get("teacher")
    model = next((name for name in TEACHERS if MODELS[name] == path), None)
    if not isinstance(teacher, dict) or model is None:
        return
    teacher_path = MODELS[TEACHERS[model]]
    if hashlib.sha256(teacher_path.read_bytes()).hexdigest() != teacher.get("sha256"):
        logger.warning(
            "%s was distilled from another version of %s than the one installed: re-distil it (see its model card)",
            path.name,
            teacher_path.name,
        )


def _integer_zoom(step: float, offset: float) -> tuple[int, int] | None:
    """``(z, o)`` when pixel ``x`` at grid coordinate ``step * x + offset`` is pixel ``x + o``
    of the grid zoomed ``z`` times by ``cv2.resize`` (which puts pixel ``x`` at
    ``(x + 0.5) / z - 0.5``), ``z`` and ``o >= 0`` integers; else None."""
    zoom = 1.0 / step
    shift = (offset + 0.5 - 0.5 * step) * zoom
    if abs(zoom - round(zoom)) > 1e-9 or abs(shift - round(shift)) > 1e-6 or round(shift) < 0 or round(zoom) < 2:
        return None
    return round(zoom), round(shift)
