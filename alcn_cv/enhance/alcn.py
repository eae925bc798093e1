"""ALCN as an OpenCV-style preprocessing step: ``alcn_cv.createALCN().apply(img)``.

The Normalizer runs fully-convolutionally at the *working scale* (the resolution at which its 48x48 window was
trained), giving per-pixel weight maps F_k; these are upsampled to the input resolution and the Gaussian mixture
of Eq. 3 is applied there with the sigmas scaled by ``1 / working_scale``, so the output keeps the input's size
and detail: ``ALCN(I) = sum_k G_{sigma_k / s} * (F_k(I) o I)``. The gain family then divides the response by its
local energy and equalizes it. :class:`ALCN` is the ``apply()`` front; the work is a model family's runtime
(:mod:`alcn_cv.runtime`, OpenCV; :mod:`alcn_cv.nn`, torch).

The default model, ``"gain"``, is trained on the webcam frames of Verdie et al. and AMOS, **for academic research
only** (see its model card); ``model="lite"`` (rendered data) has no such restriction.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

import numpy as np

from alcn_cv.checks import SUPPORTED_DTYPES, check_image, unit_windows
from alcn_cv.runtime import DEFAULT_MODEL, MODELS, TEACHERS, ModelSpec, Runtime, check_teacher, make_runtime
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import parse_spec, register
from alcn_cv.errors import InputError
from alcn_cv.extras import is_installed, require
from alcn_cv.filters.divisive import gaussian_energy
from alcn_cv.filters.gaussian_mixture import PYRAMID_MIN_SIGMA, alcn_filter, kernel_radius, pyramid_plan
from alcn_cv.nets.opencv_runtime import WINDOW
from alcn_cv.weight_file import load_normalizer_file

__all__ = ["ALCN", "DEFAULT_MODEL", "MODELS", "TEACHERS", "createALCN", "pin_default_model"]

logger = logging.getLogger(__name__)

BACKENDS = ("fast", "torch", "opencv")
MIXTURES = ("exact", "pyramid")
#: The divisive floor of the whole image while its strips are normalized (None: each call computes it from its
#: own image); a context variable, so threads do not share it.
_DIVISIVE_FLOOR: ContextVar[float | None] = ContextVar("alcn_divisive_floor", default=None)


@register
class ALCN(Normalization):
    """Adaptive Local Contrast Normalization (Rad, Roth & Lepetit, BMVC 2017).

    Args:
        weights: a Normalizer weight file (``.npz``, see :mod:`alcn_cv.weight_file`); default:
            the file shipped in the package for ``model``.
        model: which shipped Normalizer to use when ``weights`` is not given: ``"gain"``
            (default; the gain-adaptive Normalizer of :mod:`alcn_cv.nets.gain`, F_k = exp(g) w_k,
            the response divided by its local energy (per pixel, a Gaussian of sigma 2)
            (:func:`~alcn_cv.filters.divisive.divisive_normalization`), then a contrast
            equalization ``tanh(x / tau)``; trained on real photographs of outdoor scenes under
            changing daylight by ``alcn train-real-light``, first on real light changes;
            ``alcn_normalizer_gain.npz``, card ``alcn_normalizer_gain.md``; **its training
            photographs are for academic research only**, and so are its weights) or
            ``"gain-lite"`` (the same method with a smaller network distilled from it by ``alcn
            distill``, ``alcn_normalizer_gain_lite.npz``, card ``alcn_normalizer_gain_lite.md``;
            academic research only too) or ``"lite"`` (:class:`~alcn_cv.nets.lite.LiteNormalizer`
            distilled from the paper's, trained on rendered data only,
            ``alcn_cv/weights/alcn_normalizer_lite.npz``, a few hundred times cheaper than the
            paper's; see its model card) or ``"paper"`` (the paper's architecture, trained jointly
            with a detector, ``alcn_normalizer.npz``; see ``MODEL_CARD.md``).
        scale: working scale, the factor from the input resolution to the one the Normalizer
            sees (its 48x48 window and sigmas are in working-scale pixels). Default: the
            weight file's ``working_scale`` (1 for the gain Normalizers; 0.5 for the paper's
            and the lite one: a 640x480 frame is seen at 320x240, where a 48-pixel window
            spans 15% of the width).
        backend: ``None`` (default): ``"fast"`` when torch is installed, else ``"opencv"``;
            ``"fast"`` (Normalizer in torch on the CPU, Gaussian mixture in OpenCV),
            ``"torch"`` (everything in torch/kornia, on ``device``), or ``"opencv"`` (no torch at
            all: the Normalizer exported to ONNX -- the ``.onnx`` file beside the weight file, see
            ``alcn export`` -- run by ``cv2.dnn``, the mixture in OpenCV; ``grid_stride`` at the
            network's stride).
        device: torch device for ``backend="torch"`` (``"cpu"`` or ``"cuda"``).
        grid_stride: spacing, in working-scale pixels, of the windows the Normalizer is
            evaluated on (a multiple of the network's stride); the weight maps are interpolated
            bilinearly in between. Default: the network's own stride (4 for the paper's, 8 for
            the lite and gain ones). The paper's network at 8, 16, 32 is 4, 16, 64 times cheaper in its
            fully connected layer (not in its convolutions) and has smoother maps.
        mixture: ``"exact"``: Eq. 3 at the input resolution; ``"pyramid"`` (``fast`` and
            ``opencv`` backends): the blurs of sigma >= 2 pixels on a Gaussian pyramid and the
            maps sampled directly from the grid at each level
            (:func:`alcn_cv.filters.gaussian_mixture.pyramid_mixture`), 5 to 10 times cheaper.
            Default: ``"pyramid"``, except ``"exact"`` with ``backend="torch"`` and for the gain
            Normalizer: its Weber gain makes the pyramid's error large (0.24 of its [-1, 1]
            output on ``alcn bench speed``'s frame), and its exact Eq. 3 runs from its grid in
            OpenCV (:func:`~alcn_cv.filters.gaussian_mixture.alcn_filter_grid`, within 1e-5 of
            the torch model's output).
        threads: torch's intra-op threads while the Normalizer runs (restored after); default 1:
            the fastest for the light Normalizers and on a loaded machine, where the threads of
            small convolutions wait for each other, and it leaves no torch (OpenMP) threads
            spinning to slow the OpenCV calls that follow, the mixture's and the application's.
            None: torch's own setting.

    The default, ``model="gain"`` (exact Eq. 3, divisive normalization, equalization), is the
    method first on real light changes (``alcn bench relight``); ``model="lite"`` with
    ``mixture="pyramid"`` is the paper family's real-time configuration and ``model="paper",
    mixture="exact"`` its exact Eq. 3 with the paper's network.
    ``alcn bench speed`` measures every variant's time and its difference from the exact output.
    """

    name = "alcn"
    summary = "Adaptive Local Contrast Normalization: a CNN predicts per-pixel weights of Gaussian kernels (Eq. 3)"
    reference = "Rad, Roth & Lepetit, BMVC 2017"

    def __init__(
        self,
        weights: str | Path | None = None,
        scale: float | None = None,
        backend: str | None = None,
        device: str = "cpu",
        grid_stride: int | None = None,
        mixture: str | None = None,
        model: str = DEFAULT_MODEL,
        threads: int | None = 1,
    ) -> None:
        backend = ("fast" if is_installed("torch") else "opencv") if backend is None else backend
        if backend not in BACKENDS:
            raise InputError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        if model not in MODELS:
            raise InputError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
        if mixture is not None and mixture not in MIXTURES:
            raise InputError(f"unknown mixture {mixture!r}; choose one of {', '.join(MIXTURES)}")
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
            raise InputError(f"threads must be a positive integer or None, got {threads!r}")
        self.backend, self.device, self.threads = backend, device, threads
        self.weights_path = Path(weights) if weights is not None else MODELS[model]
        weight_file = load_normalizer_file(self.weights_path)
        meta = weight_file.meta
        if mixture is None:
            mixture = "exact" if backend == "torch" or meta.get("architecture") == "gain" else "pyramid"
        if mixture == "pyramid" and backend == "torch":
            raise InputError("mixture='pyramid' runs in OpenCV: use it with backend='fast' or 'opencv'")
        self.mixture = mixture
        self.spec = ModelSpec.from_meta(meta, scale)
        self.sigmas, self.scale, self.output_range = self.spec.sigmas, self.spec.scale, self.spec.output_range
        self.trained = bool(meta["trained"])
        if not self.trained:
            logger.warning("%s holds UNTRAINED Normalizer weights (%s)", self.weights_path.name, meta.get("description", ""))
        self.runtime: Runtime = self._runtime(weight_file, grid_stride)
        self.grid_stride = self.runtime.grid_stride

    def _runtime(self, weight_file: object, grid_stride: int | None) -> Runtime:
        if self.backend == "opencv":
            from alcn_cv.nets.opencv_runtime import OpenCVNormalizer

            self.net = OpenCVNormalizer(self.weights_path.with_suffix(".onnx"))
            if grid_stride not in (None, self.net.stride):
                raise InputError(f"backend='opencv' evaluates the Normalizer at its stride {self.net.stride}, got grid_stride={grid_stride}")
            if len(self.sigmas) != weight_file.meta["config"].get("num_kernels", len(self.sigmas)):
                raise InputError(f"weight file has {len(self.sigmas)} sigmas for {weight_file.meta['config']['num_kernels']} outputs")
            return make_runtime(self.spec, self.net, self.mixture)
        require("torch", "kornia", what=f"ALCN(backend={self.backend!r})")
        from alcn_cv.nets.device import torch_device  # deferred: importing alcn_cv must not need torch
        from alcn_cv.nn import ALCN2d, TorchNetwork, TorchRuntime

        module = ALCN2d(weights=self.weights_path, scale=self.scale, grid_stride=grid_stride)
        module.to(torch_device(self.device) if self.backend == "torch" else "cpu")
        self.net = module.net
        check_teacher(weight_file.meta, self.weights_path)
        if self.backend == "torch":
            return TorchRuntime(module, self.threads)
        return make_runtime(self.spec, TorchNetwork(module.net, module.grid_stride, self.threads), self.mixture)

    @property
    def equalization_tau(self) -> float | None:
        """``tau`` of the gain family's final ``tanh(x / tau)``; None for the others."""
        return self.spec.tau

    @property
    def min_size(self) -> int:  # type: ignore[override] -- the window's side depends on the scale
        """The Normalizer's 48-pixel window in input pixels, ``ceil(48 / scale)``; smaller images are mirrored."""
        return math.ceil(WINDOW / self.scale)

    @property
    def full_res_sigmas(self) -> tuple[float, ...]:
        """The mixture's sigmas in input pixels: ``sigma_k / scale``."""
        return self.spec.full_res_sigmas

    def weight_grid(self, gray: np.ndarray) -> np.ndarray:
        """``(H, W)`` float32 in [0, 1] -> ``(N, gh, gw)``: the Normalizer's output on its grid, point ``(i, j)``
        the prediction for the window centred on working-scale pixel ``(g*i, g*j)``, ``g = grid_stride``."""
        return self.runtime.weight_grid(gray)

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        """``(H, W)`` float32 in [0, 1] -> ``(N, H, W)``: the per-pixel mixture weights F_k."""
        return self.runtime.weight_maps(gray)

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        """Eq. 1's weights: ``(n, 48, 48)`` float32 windows at the working scale -> ``(n, N)``."""
        if not isinstance(windows, np.ndarray) or windows.ndim != 3 or windows.shape[1:] != (WINDOW, WINDOW):
            raise InputError(f"windows must be (n, {WINDOW}, {WINDOW}), got {getattr(windows, 'shape', type(windows))}")
        return self.runtime.window_weights(np.ascontiguousarray(windows, dtype=np.float32))

    def normalize_windows(self, windows: np.ndarray) -> np.ndarray:
        """Eq. 1 on every ``(n, S, S)`` window (``S >= 48`` at the working scale): one weight vector from its
        central 48x48, then the mixture over the whole window -> ``(n, S, S)`` float32. The gain family
        (per-pixel by design) normalizes each window as a small image instead."""
        if self.spec.per_pixel:
            return super().normalize_windows(windows)
        unit = unit_windows(windows)
        centre = np.stack([self.spec.working_image(w) for w in unit])
        if centre.shape[1] < WINDOW:
            raise InputError(f"windows must be at least {WINDOW} px at the working scale, got {centre.shape[1]}")
        o = (centre.shape[1] - WINDOW) // 2
        weights = self.window_weights(centre[:, o : o + WINDOW, o : o + WINDOW])
        return np.stack([alcn_filter(w, wt, self.full_res_sigmas) for w, wt in zip(unit, weights)])

    @contextmanager
    def _strip_context(self, img: np.ndarray, strips: list[tuple[int, int, int, int]]) -> Iterator[None]:
        # The divisive floor is a mean of the energy over the whole image: a first pass over the
        # strips sums it (Eq. 3 and the energy computed twice, the memory still a strip's).
        if self.spec.divisive is None:
            yield
            return
        sigma, c = self.spec.divisive
        total = 0.0
        for start, stop, lo, hi in strips:
            energy = gaussian_energy(self.runtime.mixture(self._intensity(img[lo:hi])), sigma)
            total += float(energy[start - lo : stop - lo].sum(dtype=np.float64))
        token = _DIVISIVE_FLOOR.set(c * total / (img.shape[0] * img.shape[1]))
        try:
            yield
        finally:
            _DIVISIVE_FLOOR.reset(token)

    def _tiling(self, shape: tuple[int, int]) -> tuple[int, int] | None:
        # A strip gives the whole image's output when it starts on a grid row (and so on a row
        # of every pyramid level) and its working image is the whole one's rows (an integer
        # zoom from the working scale); its halo covers the Normalizer's windows around the
        # grid points its maps interpolate, the mixture's blurs and pyramid filters and the energy's Gaussian.
        zoom = 1.0 / self.scale
        if abs(zoom - round(zoom)) > 1e-9 or abs(shape[0] * self.scale - round(shape[0] * self.scale)) > 1e-9:
            return None
        zoom = round(zoom)
        top = max(level for level, _ in pyramid_plan(self.full_res_sigmas, PYRAMID_MIN_SIGMA)) if self.mixture == "pyramid" else 0
        step = math.lcm(zoom * self.grid_stride, 2**top)
        reach = zoom * (self.spec.reach + self.grid_stride) + kernel_radius(max(self.full_res_sigmas)) + 2 ** (top + 2)
        if self.spec.divisive is not None:
            reach += kernel_radius(self.spec.divisive[0])
        return -(-reach // step) * step, step

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return self.runtime.normalize(gray, _DIVISIVE_FLOOR.get())

    def apply_batch(self, frames: np.ndarray, out_dtype: type | np.dtype | str | None = None, half: bool = False) -> np.ndarray:
        """:meth:`apply` on a batch of grayscale frames of one size in one pass on :attr:`device`
        (``backend="torch"``): the GPU path. The frames go to the device as they are (uint8: a quarter of the
        float traffic; from pinned memory on CUDA), are converted there, and the output is cast there. The
        working image is the frames averaged over blocks of ``1 / scale`` pixels (``cv2.INTER_AREA`` when the
        sides are multiples of ``1 / scale``; other sizes by torch's area interpolation).
        :func:`alcn_cv.nn.batches` groups a stream of frames.

        Args:
            frames: ``(B, H, W)`` uint8, uint16, or float32 intensities in [0, 1].
            out_dtype: as in :meth:`apply` (default: the frames' dtype).
            half: run the Normalizer in float16 under ``torch.autocast``; Eq. 3 stays in float32.

        Returns:
            ``(B, H, W)`` of ``out_dtype``.
        """
        if self.backend != "torch":
            raise InputError(f"apply_batch runs on backend='torch' (device 'cpu' or 'cuda'), not {self.backend!r}")
        if not isinstance(frames, np.ndarray) or frames.ndim != 3 or frames.size == 0:
            raise InputError(f"frames must be a non-empty (B, H, W) array, got {getattr(frames, 'shape', type(frames))}")
        check_image(frames[0])  # the dtype; a float batch's range is checked as a whole below
        if frames.dtype == np.float32:
            check_image(frames.reshape(-1, frames.shape[-1]))
        out_dtype = np.dtype(frames.dtype if out_dtype is None else out_dtype)
        if out_dtype not in SUPPORTED_DTYPES:
            raise InputError(f"unsupported out_dtype {out_dtype}; use uint8, uint16 or float32")
        return self.runtime.apply_batch(frames, out_dtype, half)

    def __repr__(self) -> str:
        return (
            f"ALCN(weights={self.weights_path.name!r}, scale={self.scale}, backend={self.backend!r}, "
            f"grid_stride={self.grid_stride}, mixture={self.mixture!r}, threads={self.threads}, trained={self.trained})"
        )


def pin_default_model(spec: str) -> str:
    """``spec`` (``NAME[:KEY=VALUE...]``) with ALCN's default model named: ``"alcn"`` ->
    ``"alcn:model=gain"``; other specs unchanged. For files that record the normalization they
    were made with (pose models, corner detectors): a later change of the default does not change
    what they mean (the default was ``"lite"`` until 2026-11-24)."""
    name, params = parse_spec(spec)
    if name != ALCN.name or "model" in params or "weights" in params:
        return spec
    return f"{spec}:model={DEFAULT_MODEL}"


def createALCN(**params: object) -> ALCN:  # noqa: N802 -- OpenCV naming, like cv2.createCLAHE
    """Create an :class:`ALCN` normalization; ``createALCN().apply(img)`` normalizes an image.

    Example:
        >>> import alcn_cv, numpy as np
        >>> frame = (np.random.rand(480, 640) * 255).astype(np.uint8)
        >>> alcn_cv.createALCN().apply(frame).shape
        (480, 640)
    """
    return ALCN(**params)
