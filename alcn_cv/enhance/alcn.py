"""ALCN as an OpenCV-style preprocessing step: ``alcn_cv.createALCN().apply(src)``.

The Normalizer runs fully-convolutionally at the *working scale* (the resolution at which its 48x48 window was
trained), giving per-pixel weight maps F_k; these are upsampled to the input resolution and the Gaussian mixture
of Eq. 3 is applied there with the sigmas scaled by ``1 / working_scale``, so the output keeps the input's size
and detail: ``ALCN(I) = sum_k G_{sigma_k / s} * (F_k(I) o I)``. The gain family then divides the response by its
local energy and equalizes it. :class:`ALCN` is the ``apply()`` front; the work is a model family's runtime
(:mod:`alcn_cv.runtime`, OpenCV; :mod:`alcn_cv.nn`, torch).

The default model, ``"gain"``, and ``"gain-lite"`` are trained on relit photographs in the public domain, under CC0
or Apache-2.0, or with no known copyright restrictions; ``"paper"`` and ``"lite"`` on rendered windows whose textures
included scikit-image images with no licence stated: they are not shown to be free of those images' terms (``NOTICE``
and each model card).
"""

from __future__ import annotations

import logging
import math
import numbers
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, cast

import numpy as np

from alcn_cv.checks import check_gray, unit_windows
from alcn_cv.enhance.base import Normalization, with_alpha
from alcn_cv.enhance.registry import format_spec, parse_spec, register
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.extras import is_installed, require
from alcn_cv.filters.divisive import gaussian_energy
from alcn_cv.filters.lab import bgr_with_lightness, lab_and_lightness
from alcn_cv.filters.wide_band import BLOCK, block_means, wide_band_floor
from alcn_cv.nets.opencv_runtime import GAIN_NEEDS, RUNS_GAIN, WINDOW
from alcn_cv.runtime import (
    DEFAULT_MODEL,
    MODELS,
    ModelSpec,
    Runtime,
    check_batch,
    check_teacher,
    eq1_windows,
    make_runtime,
    opencv_network,
    resolve_weights,
    strip_layout,
    weights_setting,
)
from alcn_cv.weight_file import NormalizerFile, load_normalizer_file

if TYPE_CHECKING:
    import torch

    from alcn_cv.nn import TorchRuntime

__all__ = ["ALCN", "createALCN", "default_mixture", "pin_default_model"]

logger = logging.getLogger(__name__)

BACKENDS = ("fast", "torch", "opencv")
MIXTURES = ("exact", "pyramid")
#: The attributes an :class:`ALCN` is built from, read-only once set (its runtime would not follow a change), and the
#: arguments of :func:`createALCN` that set each; ``model`` and ``weights``, arguments only, are refused as attributes.
_FIXED_SETTINGS = {
    "weights_path": "weights",
    "weights": "weights",
    "model": "model",
    "spec": "weights",
    "output_range": "weights",
    "sigmas": "scale",
    "scale": "scale",
    "backend": "backend",
    "device": "device",
    "grid_stride": "grid_stride",
    "mixture": "mixture",
    "threads": "threads",
}
#: The divisive floors of the whole image, the response's and the wide band's, while its strips are normalized
#: (None: each call computes them from its own image); a context variable, so threads do not share them.
_DIVISIVE_FLOORS: ContextVar[tuple[float | None, float | None]] = ContextVar(
    "alcn_divisive_floors", default=(None, None)
)


@register
class ALCN(Normalization):
    """Adaptive Local Contrast Normalization (Rad, Roth & Lepetit, BMVC 2017).

    Args:
        weights: a Normalizer weight file (``.npz``, :mod:`alcn_cv.weight_file`); default: the shipped ``model``'s.
        model: instead of ``weights``, a shipped Normalizer (:data:`~alcn_cv.runtime.MODELS`; see each model
            card): ``"gain"`` (default: F_k = exp(g) w_k on a grid, the response divided by its local energy, then
            ``tanh(x / tau)``; trained on relit photographs that permit any use), ``"gain-lite"`` (distilled from
            it), ``"lite"`` (the paper's family distilled) or ``"paper"`` (these two not shown to be free of their
            textures' terms: the module's docstring).
        scale: working scale, input resolution -> the Normalizer's (its 48x48 window and sigmas are in working
            pixels). Default: the weight file's (1 for the gain family, 0.5 for the paper's).
        backend: ``"opencv"`` (no torch: the ONNX export beside the weight file run by ``cv2.dnn``, Eq. 3 in
            OpenCV), ``"fast"`` (the Normalizer in torch on the CPU, Eq. 3 in OpenCV; any grid stride, no ONNX
            file needed) or ``"torch"`` (:class:`alcn_cv.nn.ALCN2d` on ``device``). Default: ``"opencv"`` for a shipped
            ``model`` without a ``grid_stride`` on OpenCV 4.8 or newer (the same output as ``"fast"`` to 1e-5), else
            ``"fast"`` where torch is installed.
        device: torch device of ``backend="torch"`` (``"cpu"``, ``"cuda"``); another device than the CPU selects
            that backend when none is given, as ``threads`` other than ``"auto"`` select ``"fast"``.
        grid_stride: spacing of the Normalizer's grid in working pixels, a multiple of its stride (default: its
            stride); the maps are interpolated bilinearly in between.
        mixture: ``"exact"`` (Eq. 3 at the input resolution) or ``"pyramid"`` (the wide blurs on a Gaussian
            pyramid, :func:`~alcn_cv.filters.gaussian_mixture.pyramid_mixture`; ``fast`` and ``opencv`` only).
            Default: ``"exact"`` for the gain family and ``backend="torch"``, else ``"pyramid"``.
        threads: torch's intra-op threads while ALCN runs in torch (restored after; None: torch's setting).
            Default ``"auto"``: 1 with ``backend="fast"``, whose torch part (the network's layers on the grid) is
            small, so that no torch threads are left spinning against the OpenCV calls around it; torch's setting
            with ``backend="torch"``, which runs everything in torch. ``backend="opencv"`` runs no torch.

    Raises:
        InputError: both ``model`` and ``weights``, an unknown ``model``, ``backend`` or ``mixture``, ``scale`` not a
            number in (0, 4], or settings that do not go together (:class:`~alcn_cv.errors.WeightFileError`: a
            weight file that does not load).

    The settings are fixed when the ALCN is created (its runtime is built from them): setting one afterwards raises
    ``AttributeError``; create another ALCN instead.

    The gain family on ``backend="fast"`` and ``"opencv"`` also uses OpenCV's threads, as OpenCV's own parallel
    functions do: each image's rows are cut into one part per thread of ``cv2.getNumThreads()``
    (:mod:`alcn_cv.row_parts`; the same output whatever their number), and ``cv2.setNumThreads(1)`` makes
    :meth:`apply` sequential.
    """

    name = "alcn"
    summary = (
        "Adaptive Local Contrast Normalization: a CNN predicts per-pixel weights of Gaussian kernels (Eq. 3); "
        f"models {', '.join(f'{m} (default)' if m == DEFAULT_MODEL else m for m in MODELS)}"
    )
    reference = "Rad, Roth & Lepetit, BMVC 2017"

    @classmethod
    def resolved(cls, params: dict[str, object]) -> dict[str, object]:
        """The default model named where neither ``model`` nor ``weights`` is given (``model=None`` means it)."""
        if params.get("model") is None and params.get("weights") is None:
            return {**params, "model": DEFAULT_MODEL}
        return params

    def __init__(
        self,
        weights: str | Path | None = None,
        scale: float | None = None,
        backend: str | None = None,
        device: str = "cpu",  # or a torch.device: not in the hint, which the registry resolves without torch
        grid_stride: int | None = None,
        mixture: str | None = None,
        model: str | None = None,
        threads: int | None | Literal["auto"] = "auto",
    ) -> None:
        self.weights_path = resolve_weights(model, weights)
        if (
            threads != "auto"
            and threads is not None
            and (isinstance(threads, bool) or not isinstance(threads, numbers.Integral) or threads < 1)
        ):
            raise InputError(f"threads must be a positive integer, None or 'auto', got {threads!r}")
        if isinstance(threads, numbers.Integral):
            threads = int(threads)  # NumPy's integers too, which torch's set_num_threads refuses
        if not isinstance(device, str) and not hasattr(device, "type"):  # a torch.device has one; None is no device
            raise InputError(f"device must be a torch device's name ('cpu', 'cuda', 'cuda:1', ...), got {device!r}")
        on_cpu = str(device).split(":")[0] == "cpu"
        chosen_by = None  # the setting that chose a torch backend, which a missing torch's error names
        if backend is None and not on_cpu:
            backend, chosen_by = "torch", f"device={device!r}"  # the one backend that runs on a device
        elif backend is None and threads != "auto":
            backend, chosen_by = "fast", f"threads={threads!r}, torch's threads"
        elif backend is None:  # a user's weight file may sit beside an older export: its own network in torch
            shipped = weights is None and grid_stride is None and RUNS_GAIN
            backend = "opencv" if shipped or not is_installed("torch") else "fast"
        if backend not in BACKENDS:
            raise InputError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        if backend != "torch" and not on_cpu:
            raise InputError(f"device={device!r} runs backend='torch'; backend={backend!r} runs on the CPU")
        if backend == "opencv" and threads != "auto":
            raise InputError(
                "threads sets torch's threads, and backend='opencv' runs no torch (cv2.setNumThreads sets OpenCV's)"
            )
        if threads == "auto":
            threads = None if backend == "torch" else 1
        if mixture is not None and mixture not in MIXTURES:
            raise InputError(f"unknown mixture {mixture!r}; choose one of {', '.join(MIXTURES)}")
        self.backend, self.device, self.threads = backend, device, threads
        weight_file = load_normalizer_file(self.weights_path)
        meta = weight_file.meta
        #: The weight file's header (:attr:`~alcn_cv.weight_file.NormalizerFile.meta`), kept so that what reads its
        #: provenance (the benchmarks' check of the scenes it was trained on) does not read the file again.
        self.weights_meta = meta
        if mixture is None:
            mixture = default_mixture(meta, backend)
        if mixture == "pyramid" and backend == "torch":
            raise InputError("mixture='pyramid' runs in OpenCV: use it with backend='fast' or 'opencv'")
        self.mixture = mixture
        self.spec = ModelSpec.from_file(weight_file, scale)
        self.sigmas, self.scale, self.output_range = self.spec.sigmas, self.spec.scale, self.spec.output_range
        self.trained = bool(meta["trained"])
        if not self.trained:
            logger.warning(
                "%s holds UNTRAINED Normalizer weights (%s)", self.weights_path.name, meta.get("description", "")
            )
        self.runtime: Runtime
        self.runtime, self.net = _build_runtime(
            self.spec, weight_file, self.weights_path, backend, device, grid_stride, mixture, threads, chosen_by
        )
        self.grid_stride = self.runtime.grid_stride

    def __setattr__(self, name: str, value: object) -> None:
        # the runtime is built from the settings once: a setting changed afterwards would not take effect
        if name in _FIXED_SETTINGS and (name in self.__dict__ or name in ("model", "weights")):
            raise self._fixed(name)
        super().__setattr__(name, value)

    def __delattr__(self, name: str) -> None:
        if name in _FIXED_SETTINGS:
            raise self._fixed(name)
        super().__delattr__(name)

    @staticmethod
    def _fixed(name: str) -> AttributeError:
        return AttributeError(
            f"ALCN.{name} is fixed when the ALCN is created: createALCN({_FIXED_SETTINGS[name]}=...) makes one with "
            "another"
        )

    @property
    def equalization_tau(self) -> float | None:
        """``tau`` of the gain family's final ``tanh(x / tau)``; None for the others."""
        return self.spec.tau

    @property
    def min_size(self) -> int:  # type: ignore[override]  # the window's side depends on the scale
        """The Normalizer's 48-pixel window in input pixels, ``ceil(48 / scale)``; smaller images are mirrored."""
        return math.ceil(WINDOW / self.scale)

    @property
    def full_res_sigmas(self) -> tuple[float, ...]:
        """The mixture's sigmas in input pixels: ``sigma_k / scale``."""
        return self.spec.full_res_sigmas

    def weight_grid(self, gray: np.ndarray) -> np.ndarray:
        """``(H, W)`` float32 in [0, 1] -> ``(N, gh, gw)``: the Normalizer's output on its grid, point ``(i, j)``
        the prediction for the window centred on working-scale pixel ``(g*i, g*j)``, ``g = grid_stride``."""
        return self.runtime.weight_grid(check_gray(gray))

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        """``(H, W)`` float32 in [0, 1] -> ``(N, H, W)``: the per-pixel mixture weights F_k."""
        return self.runtime.weight_maps(check_gray(gray))

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        """Eq. 1's weights: ``(n, 48, 48)`` windows at the working scale, uint8 or float32 intensities in [0, 1]
        (as :meth:`normalize_windows` takes them) -> ``(n, N)``."""
        if not isinstance(windows, np.ndarray) or windows.ndim != 3 or windows.shape[1:] != (WINDOW, WINDOW):
            raise InputError(f"windows must be (n, {WINDOW}, {WINDOW}), got {getattr(windows, 'shape', type(windows))}")
        return self.runtime.window_weights(np.ascontiguousarray(unit_windows(windows)))

    def normalize_windows(self, windows: np.ndarray) -> np.ndarray:
        """Eq. 1 on every ``(n, S, S)`` window (``S >= 48`` at the working scale): one weight vector from its
        central 48x48, then the mixture over the whole window -> ``(n, S, S)`` float32. The gain family
        (per-pixel by design) normalizes each window as a small image instead."""
        if self.spec.per_pixel:
            return super().normalize_windows(windows)
        return eq1_windows(self.runtime, unit_windows(windows))

    @contextmanager
    def _strip_context(self, img: np.ndarray, strips: list[tuple[int, int, int, int]]) -> Iterator[None]:
        # The divisive floor is a mean of the energy over the whole image: a first pass over the
        # strips sums it (Eq. 3 and the energy computed twice, the memory still a strip's). The wide
        # band's is the mean over the whole image's blocks, which the strips' own blocks make up.
        if self.spec.divisive is None:
            yield
            return
        sigma, c = self.spec.divisive
        total = 0.0
        blocks = []
        for start, stop, lo, hi in strips:
            intensity = self._intensity(img[lo:hi])
            energy = gaussian_energy(self.runtime.mixture(intensity), sigma)
            total += float(energy[start - lo : stop - lo].sum(dtype=np.float64))
            if self.spec.band:  # its blocks; the last strip's bottom reflected from rows above it, as the whole's
                if stop == img.shape[0]:
                    blocks.append(block_means(intensity)[(start - lo) // BLOCK :])
                else:
                    blocks.append(block_means(intensity[start - lo : stop - lo]))
        band_floor = wide_band_floor(np.concatenate(blocks), c) if blocks else None
        token = _DIVISIVE_FLOORS.set((c * total / (img.shape[0] * img.shape[1]), band_floor))
        try:
            yield
        finally:
            _DIVISIVE_FLOORS.reset(token)

    def _tiling(self, shape: tuple[int, int]) -> tuple[int, int] | None:
        return strip_layout(self.spec, self.grid_stride, self.mixture, shape)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return self.runtime.normalize(gray, *_DIVISIVE_FLOORS.get())

    def apply_batch(
        self, frames: np.ndarray, out_dtype: type | np.dtype | str | None = None, half: bool = False
    ) -> np.ndarray:
        """:meth:`apply` on a batch of frames of one size and layout in one pass on :attr:`device`
        (``backend="torch"``): the GPU path. Colour frames are normalized on their CIE L (the Lab
        conversions on the CPU, as :meth:`apply`), an alpha channel is passed through. The frames go to the
        device as they are (uint8: a quarter of the float traffic; from pinned memory on CUDA), are converted
        there, and the output is cast there. The
        working image is the frames averaged over blocks of ``1 / scale`` pixels (``cv2.INTER_AREA`` when the
        sides are multiples of ``1 / scale``; other sizes by torch's area interpolation).
        :func:`alcn_cv.nn.batches` groups a stream of frames.

        Args:
            frames: ``(B, H, W)`` or ``(B, H, W, C)`` (gray, gray + alpha, BGR, BGRA) uint8, uint16, or float32
                intensities in [0, 1], in any byte order.
            out_dtype: as in :meth:`apply` (default: the frames' dtype).
            half: run the Normalizer's convolutions in float16 under ``torch.autocast`` (its input features and head,
                Eq. 3 and the steps after it stay in float32).

        Returns:
            The frames' shape, of ``out_dtype``.
        """
        if self.backend != "torch":
            raise InputError(f"apply_batch runs on backend='torch' (device 'cpu' or 'cuda'), not {self.backend!r}")
        frames, dtype = check_batch(frames, out_dtype)
        run = cast("TorchRuntime", self.runtime).apply_batch
        channels = 1 if frames.ndim == 3 else frames.shape[3]
        body = frames[..., :-1] if channels in (2, 4) else frames
        if channels in (3, 4):
            labs, planes = zip(*(lab_and_lightness(image) for image in body))
            units = run(np.stack(planes), np.dtype(np.float32), half)
            out = np.stack([bgr_with_lightness(lab, unit * np.float32(100), dtype) for lab, unit in zip(labs, units)])
        else:
            out = run(np.ascontiguousarray(body.reshape(body.shape[:3])), dtype, half).reshape(body.shape)
        if channels not in (2, 4):
            return out
        return np.stack([with_alpha(image, alpha, dtype) for image, alpha in zip(out, frames[..., -1])])

    def __repr__(self) -> str:
        return (
            f"ALCN({weights_setting(self.weights_path)}, scale={self.scale}, backend={self.backend!r}, "
            f"grid_stride={self.grid_stride}, mixture={self.mixture!r}, threads={self.threads}, trained={self.trained})"
        )


def _build_runtime(
    spec: ModelSpec,
    weight_file: NormalizerFile,
    weights: Path,
    backend: str,
    device: str | torch.device,
    grid_stride: int | None,
    mixture: str,
    threads: int | None,
    chosen_by: str | None,
) -> tuple[Runtime, object]:
    """The runtime of ``backend`` for the weight file ``weights``, read once by the caller (``weight_file``, which the
    runtime is built from: the file is not read again), and its network; ``chosen_by``: the setting that chose
    ``backend`` when the caller gave none, which the error of a missing torch names."""
    check_teacher(weight_file.meta, weights)
    if backend == "opencv" and spec.per_pixel and not RUNS_GAIN:
        # before cv2.dnn tries: its ONNX importer logs errors of its own and fails with several lines of C++ context
        hint = "" if is_installed("torch") else ' (torch: pip install "alcn-cv[train]")'
        raise WeightFileError(f"{weights.name}: {GAIN_NEEDS}{hint}")
    if backend == "opencv":
        net = opencv_network(weight_file, grid_stride, spec)
        return make_runtime(spec, net, mixture), net
    what = f"ALCN(backend={backend!r})" if chosen_by is None else f"ALCN({chosen_by}, runs backend={backend!r})"
    require("torch", "kornia", what=what)
    # deferred: importing alcn_cv must not need torch
    from alcn_cv.nets.device import torch_device
    from alcn_cv.nn import ALCN2d, TorchNetwork, TorchRuntime

    module = ALCN2d(weights=weight_file, scale=spec.scale, grid_stride=grid_stride)
    module.to(torch_device(device) if backend == "torch" else "cpu")
    if backend == "torch":
        return TorchRuntime(module, threads), module.net
    return make_runtime(spec, TorchNetwork(module.net, module.grid_stride, threads), mixture), module.net


def default_mixture(meta: dict[str, Any], backend: str) -> str:
    """The mixture :class:`ALCN` runs by default for a weight file's header ``meta`` on ``backend``: Eq. 3 exactly
    for the gain models and in torch, its ``pyramid`` approximation (OpenCV only) for the paper family."""
    return "exact" if backend == "torch" or meta.get("architecture") == "gain" else "pyramid"


def pin_default_model(spec: str) -> str:
    """``spec`` (``NAME[:KEY=VALUE...]``) with ALCN's default model named: ``"alcn"`` ->
    ``"alcn:model=gain"``; other specs unchanged. For files that record the normalization they
    were made with (pose models, corner detectors): a later change of the default does not change
    what they mean."""
    name, params = parse_spec(spec)
    resolved = ALCN.resolved(params) if name == ALCN.name else params
    # rebuilt, not appended to: "alcn:model=None" names the model once (no weights here: no path's ":" to keep)
    return spec if resolved is params else format_spec(name, resolved)


def createALCN(  # noqa: N802 -- OpenCV naming, like cv2.createCLAHE
    weights: str | Path | None = None,
    scale: float | None = None,
    backend: str | None = None,
    device: str = "cpu",
    grid_stride: int | None = None,
    mixture: str | None = None,
    model: str | None = None,
    threads: int | None | Literal["auto"] = "auto",
) -> ALCN:
    """Create an :class:`ALCN` normalization; ``createALCN().apply(src)`` normalizes an image.

    The parameters are :class:`ALCN`'s, with its defaults (``help(alcn_cv.ALCN)`` details each):

    - ``model`` or ``weights``: the Normalizer, a shipped model by name (``"gain"``, the default; ``"gain-lite"``,
      ``"lite"``, ``"paper"``) or a weight file (``.npz``);
    - ``scale``: the working scale (default: the weight file's);
    - ``backend``, ``device``, ``threads``: where it runs (``"opencv"``, no torch needed; ``"fast"``; ``"torch"`` on
      ``device``, ``"cuda"`` say) and torch's threads;
    - ``grid_stride``, ``mixture``: coarser and faster approximations.

    Example:
        >>> import alcn_cv, numpy as np
        >>> frame = (np.random.rand(480, 640) * 255).astype(np.uint8)
        >>> alcn_cv.createALCN().apply(frame).shape
        (480, 640)
    """
    return ALCN(
        weights=weights,
        scale=scale,
        backend=backend,
        device=device,
        grid_stride=grid_stride,
        mixture=mixture,
        model=model,
        threads=threads,
    )
