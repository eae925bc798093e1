"""ALCN as an OpenCV-style preprocessing step: ``alcn_cv.createALCN().apply(img)``.

The Normalizer runs fully-convolutionally at the *working scale* (the resolution at which its
48x48 window was trained), giving per-pixel weight maps F_k; these are upsampled to the input
resolution and the Gaussian mixture of Eq. 3 is applied there with the sigmas scaled by
``1 / working_scale``, so the output keeps the input's size and detail:
``ALCN(I) = sum_k G_{sigma_k / s} * (F_k(I) o I)``.

The default is the gain-adaptive Normalizer (:mod:`alcn_cv.nets.gain`, ``model="gain"``), trained on
real photographs under changing daylight: its exact Eq. 3 runs from its grid in OpenCV at the
input resolution, then the response is divided by its local energy and equalized. Its weights
are trained on the webcam frames of Verdie et al. and AMOS, **for academic research only** (see
its model card); ``model="lite"``, the paper's family trained on rendered data (the lite
Normalizer distilled from the paper's, the large blurs on a Gaussian pyramid), has no such
restriction. ``createALCN(model="paper", mixture="exact")`` is the paper's network with Eq. 3
computed exactly, hundreds of times slower; ``alcn bench speed`` measures them all,
``alcn bench relight`` and ``alcn bench detect`` their accuracy.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from alcn_cv.checks import FULL_SCALE, SUPPORTED_DTYPES, check_image, unit_windows
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import parse_spec, register
from alcn_cv.errors import InputError
from alcn_cv.extras import is_installed, require
from alcn_cv.filters.divisive import divisive_normalization, gaussian_energy
from alcn_cv.filters.gaussian_mixture import (
    PYRAMID_MIN_SIGMA,
    alcn_filter,
    alcn_filter_grid,
    gaussian_kernel1d,
    kernel_radius,
    pyramid_mixture,
    pyramid_plan,
    upsample_grid,
)
from alcn_cv.nets.opencv_runtime import WINDOW
from alcn_cv.weight_file import DEFAULT_WEIGHTS, load_normalizer_file

if TYPE_CHECKING:
    import torch

__all__ = ["ALCN", "createALCN", "pin_default_model"]

logger = logging.getLogger(__name__)

BACKENDS = ("fast", "torch", "opencv")
MIXTURES = ("exact", "pyramid")
#: ``mixture="pyramid"`` samples the maps exactly this many times per grid cell (at least).
MAP_STEP_PER_CELL = 4
#: Windows per Normalizer call in :meth:`ALCN.window_weights` (bounds the memory of a batch).
_WINDOW_BATCH = 512
#: The weight files shipped in the package, by ``model`` name.
MODELS = {
    "paper": DEFAULT_WEIGHTS,
    "lite": DEFAULT_WEIGHTS.with_name("alcn_normalizer_lite.npz"),
    "gain": DEFAULT_WEIGHTS.with_name("alcn_normalizer_gain.npz"),
    "gain-lite": DEFAULT_WEIGHTS.with_name("alcn_normalizer_gain_lite.npz"),
}
#: The shipped Normalizer of :func:`createALCN` when neither ``model`` nor ``weights`` is given.
DEFAULT_MODEL = "gain"
#: The distilled models and the model each was distilled from (ALCN warns when that file changed).
TEACHERS = {"lite": "paper", "gain-lite": "gain"}
#: The divisive floor ``f`` of the whole image while its strips are normalized (None: each
#: call computes it from its own image); a context variable, so threads do not share it.
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
        if backend is None:
            backend = "fast" if is_installed("torch") else "opencv"
        if backend not in BACKENDS:
            raise InputError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        if model not in MODELS:
            raise InputError(f"unknown model {model!r}; choose one of {', '.join(MODELS)}")
        if mixture is not None and mixture not in MIXTURES:
            raise InputError(f"unknown mixture {mixture!r}; choose one of {', '.join(MIXTURES)}")
        if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1):
            raise InputError(f"threads must be a positive integer or None, got {threads!r}")
        self.threads = threads
        self.weights_path = Path(weights) if weights is not None else MODELS[model]
        weight_file = load_normalizer_file(self.weights_path)
        meta = weight_file.meta
        if mixture is None:
            mixture = "exact" if backend == "torch" or meta.get("architecture") == "gain" else "pyramid"
        if mixture == "pyramid" and backend == "torch":
            raise InputError("mixture='pyramid' runs in OpenCV: use it with backend='fast' or 'opencv'")
        self.mixture = mixture
        self.sigmas = tuple(float(s) for s in meta["sigmas"])
        self.scale = float(meta["working_scale"] if scale is None else scale)
        if not 0 < self.scale <= 4:
            raise InputError(f"scale must be in (0, 4], got {self.scale}")
        self.output_range = tuple(float(v) for v in meta["output_range"])
        #: ``tau`` of the final contrast equalization ``tanh(x / tau)`` that is part of the
        #: gain Normalizer's method (:mod:`alcn_cv.nets.gain`); None for the others.
        self.equalization_tau = float(meta["equalization"]["tau"]) if "equalization" in meta else None
        #: The arguments ``stride``, ``scale`` and ``sigma`` of the gain Normalizer's divisive
        #: normalization of the response (:func:`alcn_cv.filters.divisive.divisive_normalization`,
        #: before the equalization; stride and sigma in input pixels), or None.
        self.divisive = _divisive_arguments(meta["divisive"], self.scale) if "divisive" in meta else None
        #: True for a Normalizer designed for Eq. 3 only (the gain Normalizer: per-pixel gain and
        #: weights on its own grid), whose windows are normalized as small images, not by Eq. 1.
        self.per_pixel = meta.get("architecture") == "gain"
        self.trained = bool(meta["trained"])
        self._network_reach = _network_reach(meta)
        if not self.trained:
            logger.warning("%s holds UNTRAINED Normalizer weights (%s)", self.weights_path.name, meta.get("description", ""))
        self.backend = backend
        self.device = device
        #: The gain Normalizer's maps interpolated from its grid in OpenCV as
        #: :meth:`GainNormalizer.dense <alcn_cv.nets.gain.GainNormalizer.dense>` does (:meth:`weight_maps`).
        self._grid_interpolated = self.per_pixel and self.scale == 1 and backend in ("fast", "opencv")
        #: Eq. 3 exact from that grid (:func:`alcn_filter_grid`), without the full-resolution maps.
        self._maps_on_grid = self._grid_interpolated and mixture == "exact"
        if backend == "opencv":
            self._init_opencv(meta, grid_stride)
            return

        require("torch", *(("kornia",) if backend == "torch" else ()), what=f"ALCN(backend={backend!r})")
        from alcn_cv.nets.device import torch_device  # deferred: importing alcn_cv must not need torch
        from alcn_cv.nets.lite import normalizer_from_file

        self.net = normalizer_from_file(weight_file).to(torch_device(device) if backend == "torch" else "cpu")
        if len(self.sigmas) != self.net.num_kernels:
            raise InputError(f"weight file has {len(self.sigmas)} sigmas for {self.net.num_kernels} outputs")
        stride = self.net.stride
        self.grid_stride = stride if grid_stride is None else grid_stride
        if isinstance(self.grid_stride, bool) or not isinstance(self.grid_stride, int) or self.grid_stride < stride or self.grid_stride % stride:
            raise InputError(f"grid_stride must be a positive multiple of {stride} for this network, got {grid_stride!r}")
        _check_teacher(meta, self.weights_path)
        #: The gain Normalizer's grid computed by :meth:`_gain_grid` (OpenCV at full resolution):
        #: on its network's own grid, without the finest-scale feature (``sharpness``).
        self._pooled_cells = self.per_pixel and self.grid_stride == stride and not meta["config"].get("sharpness", False)

    def _init_opencv(self, meta: dict, grid_stride: int | None) -> None:
        from alcn_cv.nets.opencv_runtime import OpenCVNormalizer

        self.net = OpenCVNormalizer(self.weights_path.with_suffix(".onnx"))
        self._pooled_cells = False
        self.grid_stride = self.net.stride if grid_stride is None else grid_stride
        if self.grid_stride != self.net.stride:
            raise InputError(f"backend='opencv' evaluates the Normalizer at its stride {self.net.stride}, got grid_stride={grid_stride}")
        if len(self.sigmas) != meta["config"].get("num_kernels", len(self.sigmas)):
            raise InputError(f"weight file has {len(self.sigmas)} sigmas for {meta['config']['num_kernels']} outputs")

    @property
    def min_size(self) -> int:  # type: ignore[override] -- the window's side depends on the scale
        """The Normalizer's 48-pixel window in input pixels: ``ceil(48 / scale)``; smaller images
        are mirrored at their borders to fill it (a one-time warning says so)."""
        return math.ceil(WINDOW / self.scale)

    @property
    def full_res_sigmas(self) -> tuple[float, ...]:
        """The mixture's sigmas in input pixels: ``sigma_k / scale``."""
        return tuple(s / self.scale for s in self.sigmas)

    def _working_shape(self, shape: tuple[int, int]) -> tuple[int, int]:
        h, w = shape
        if self.scale == 1:
            return h, w
        return max(1, round(h * self.scale)), max(1, round(w * self.scale))

    def _working_image(self, gray: np.ndarray) -> np.ndarray:
        if self.scale == 1:
            return gray
        h, w = self._working_shape(gray.shape)
        return cv2.resize(gray, (w, h), interpolation=cv2.INTER_AREA if self.scale < 1 else cv2.INTER_LINEAR)

    def _dense(self, gray: np.ndarray) -> torch.Tensor:
        import torch

        small = torch.from_numpy(self._working_image(gray)).to(next(self.net.parameters()).device)
        with torch.inference_mode(), _torch_threads(self.threads):
            return self.net.dense(small[None, None], self.grid_stride)[0]

    def weight_grid(self, gray: np.ndarray) -> np.ndarray:
        """The Normalizer's output on its grid: the network part of :meth:`normalize`.

        Args:
            gray: ``(H, W)`` float32 intensities in [0, 1].

        Returns:
            ``(N, gh, gw)`` float32; point ``(i, j)`` is the prediction for the 48x48 window
            centred on working-scale pixel ``(g*i, g*j)``, ``g = grid_stride``.
        """
        if self.backend == "opencv":
            return self.net.dense_grid(self._working_image(gray))
        if self._pooled_cells and self.backend == "fast":
            return self._gain_grid(self._working_image(gray))
        import torch

        small = torch.from_numpy(self._working_image(gray)).to(next(self.net.parameters()).device)
        with torch.inference_mode(), _torch_threads(self.threads):
            return self.net.dense_grid(small[None, None], self.grid_stride)[0].cpu().numpy()

    def _gain_grid(self, small: np.ndarray) -> np.ndarray:
        """:meth:`GainNormalizer.dense_grid <alcn_cv.nets.gain.GainNormalizer.dense_grid>` with
        the full-resolution work in OpenCV and only the convolutions in torch.

        The cells' means of the image and of its square are pooled by torch's ``avg_pool2d``
        (the network's own: the same numbers, which matters where a cell is flat and its
        deviation is rounding; ``cv2.resize`` with ``INTER_AREA`` sums in another order and moved
        the output by up to 0.07 on real frames with flat sky) from one reflect-101 border of
        OpenCV. The blurs, features and gain are computed on the grid in OpenCV and NumPy (the
        same kernels and borders, to float rounding), and the convolutions run on channels-last
        tensors that share memory with height x width x channels arrays: oneDNN's dilated
        convolutions are twice as fast on that layout, and OpenCV and NumPy do its borders and
        ReLUs (torch is slow on it).
        """
        import torch
        import torch.nn.functional as F

        net, s = self.net, self.net.stride
        h, w = small.shape
        gh, gw = -(-(h - 1) // s) + 1, -(-(w - 1) // s) + 1
        before = s // 2  # cell (i, j) spans pixels s*i - s/2 .. s*i + s/2 - 1, as in GainNormalizer._cells
        padded = cv2.copyMakeBorder(small, before, s * gh - h - before, before, s * gw - w - before, cv2.BORDER_REFLECT_101)
        with torch.inference_mode(), _torch_threads(self.threads):
            mean, square = (F.avg_pool2d(torch.from_numpy(plane)[None, None], s)[0, 0].numpy()
                            for plane in (padded, cv2.multiply(padded, padded)))
            local = _grid_blur(mean, net.mean_sigma / s)
            context = _grid_blur(mean, net.context_sigma / s)
            std = np.sqrt(np.maximum(square - mean * mean, np.float32(0)))
            x = np.log(np.stack([mean, local, context, std], axis=-1) + np.float32(net.eps))  # (gh, gw, 4)
            for conv, dilation in zip(net.convs, net.dilations):
                x = cv2.copyMakeBorder(x, dilation, dilation, dilation, dilation, cv2.BORDER_REFLECT_101)
                x = conv(_channels_last(x))[0].permute(1, 2, 0).numpy()
                np.maximum(x, np.float32(0), out=x)
            log_gain, weights = net.gain_and_weights(net.head(_channels_last(x)), torch.from_numpy(local)[None, None])
            return (log_gain.exp() * weights)[0].numpy()

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        """Eq. 1's weights: the Normalizer's prediction for each 48x48 window, one vector each.

        Args:
            windows: ``(n, 48, 48)`` float32 intensities in [0, 1], at the working scale.

        Returns:
            ``(n, N)`` float32, the weights of the N Gaussian kernels (sigmas :attr:`sigmas`,
            in working-scale pixels).
        """
        if not isinstance(windows, np.ndarray) or windows.ndim != 3 or windows.shape[1:] != (WINDOW, WINDOW):
            raise InputError(f"windows must be (n, {WINDOW}, {WINDOW}), got {getattr(windows, 'shape', type(windows))}")
        windows = np.ascontiguousarray(windows, dtype=np.float32)
        if self.backend == "opencv":
            # The grid point at the window's centre sees exactly the window (no padding reaches it).
            c = (WINDOW // 2) // self.net.stride
            return np.stack([self.net.dense_grid(w)[:, c, c] for w in windows])
        import torch

        device = next(self.net.parameters()).device
        x = torch.from_numpy(windows)[:, None]
        c = (WINDOW // 2) // self.net.stride  # the grid point at the window's centre, as above
        with torch.inference_mode(), _torch_threads(self.threads):
            return torch.cat(
                [self.net.dense_grid(x[i : i + _WINDOW_BATCH].to(device))[:, :, c, c].cpu() for i in range(0, len(x), _WINDOW_BATCH)]
            ).numpy()

    def normalize_windows(self, windows: np.ndarray) -> np.ndarray:
        """Eq. 1 on every window: one weight vector, predicted from the window's central 48x48
        (at the working scale), then the Gaussian mixture over the whole window.

        The paper's second stage trains its detector on windows normalized this way; whole
        images use Eq. 3 (per-pixel weights, :meth:`normalize`). A Normalizer made for Eq. 3
        only (:attr:`per_pixel`: the gain Normalizer, whose gain follows the local mean at every
        pixel) normalizes each window as a small image instead, as the other methods do: one
        weight vector for the whole window would give the detector other inputs in training
        than on whole images (measured: the correlation of a window's centre normalized alone
        with the same pixels of the whole normalized image rose from 0.69 to 0.84 on the
        detection benchmark's images).

        Args:
            windows: ``(n, S, S)`` uint8, or float32 intensities in [0, 1], ``S >= 48``, at the
                input resolution (the Normalizer sees them resized by :attr:`scale`; use
                ``scale=1`` for windows already at the working resolution).

        Returns:
            ``(n, S, S)`` float32.
        """
        if self.per_pixel:
            return super().normalize_windows(windows)
        unit = unit_windows(windows)
        centre = unit
        if self.scale != 1:
            side = max(1, round(unit.shape[1] * self.scale))
            centre = np.stack([cv2.resize(w, (side, side), interpolation=cv2.INTER_AREA if self.scale < 1 else cv2.INTER_LINEAR) for w in unit])
        if centre.shape[1] < WINDOW:
            raise InputError(f"windows must be at least {WINDOW} px at the working scale, got {centre.shape[1]}")
        o = (centre.shape[1] - WINDOW) // 2
        weights = self.window_weights(centre[:, o : o + WINDOW, o : o + WINDOW])
        return self._finish(np.stack([alcn_filter(w, wt, self.full_res_sigmas) for w, wt in zip(unit, weights)]))

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
        if along_y and along_x and grid.shape[1] * along_y[0] >= along_y[1] + h and grid.shape[2] * along_x[0] >= along_x[1] + w:
            # The level's pixels fall on a zoom of the grid by an integer factor: one cv2.resize,
            # the exact bilinear interpolation (at level 0 of a frame of even size, usually).
            (zy, oy), (zx, ox) = along_y, along_x
            return [cv2.resize(grid[k], None, fx=zx, fy=zy, interpolation=cv2.INTER_LINEAR)[oy : oy + h, ox : ox + w] for k in ks]
        f = 2 ** max(0, int(np.floor(np.log2(1.0 / (MAP_STEP_PER_CELL * max(ax, ay))))))
        to_grid = np.array([[ax * f, 0.0, ax * (f - 1) / 2 + bx], [0.0, ay * f, ay * (f - 1) / 2 + by]])
        coarse = (w, h) if f == 1 else (-(-w // f) + 1, -(-h // f) + 1)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        maps = []
        for k in ks:
            small = cv2.warpAffine(grid[k], to_grid, coarse, flags=flags, borderMode=cv2.BORDER_REPLICATE)
            maps.append(small if f == 1 else cv2.resize(small, None, fx=f, fy=f, interpolation=cv2.INTER_LINEAR)[:h, :w])
        return maps

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        """The per-pixel mixture weights F_k at the input resolution.

        Args:
            gray: ``(H, W)`` float32 intensities in [0, 1].

        Returns:
            ``(N, H, W)`` float32.
        """
        h, w = gray.shape
        if self._grid_interpolated:
            grid = self.weight_grid(gray)
            return np.stack([upsample_grid(m, self.grid_stride, (h, w)) for m in grid])
        if self.backend == "opencv":
            maps = self.net.dense(self._working_image(gray))
        else:
            maps = self._dense(gray).cpu().numpy()
        if maps.shape[1:] == (h, w):
            return maps
        return np.stack([cv2.resize(m, (w, h), interpolation=cv2.INTER_LINEAR) for m in maps])

    @contextmanager
    def _strip_context(self, img: np.ndarray, strips: list[tuple[int, int, int, int]]) -> Iterator[None]:
        # The divisive floor is a mean of the energy over the whole image: a first pass over the
        # strips sums it (Eq. 3 and the energy computed twice, the memory still a strip's).
        if self.divisive is None:
            yield
            return
        total = 0.0
        for start, stop, lo, hi in strips:
            energy = gaussian_energy(self._mixture(self._intensity(img[lo:hi])), self.divisive["sigma"])
            total += float(energy[start - lo : stop - lo].sum(dtype=np.float64))
        token = _DIVISIVE_FLOOR.set(self.divisive["scale"] * total / (img.shape[0] * img.shape[1]))
        try:
            yield
        finally:
            _DIVISIVE_FLOOR.reset(token)

    def _tiling(self, shape: tuple[int, int]) -> tuple[int, int] | None:
        if self.divisive is not None and self.divisive["sigma"] is None:
            return None  # the floor of a division on the grid is a mean over the whole image's cells
        # A strip gives the whole image's output when it starts on a grid row (and so on a row
        # of every pyramid level) and its working image is the whole one's rows (an integer
        # zoom from the working scale); its halo covers the Normalizer's windows around the
        # grid points its maps interpolate, and the mixture's blurs and pyramid filters.
        zoom = 1.0 / self.scale
        if abs(zoom - round(zoom)) > 1e-9 or abs(shape[0] * self.scale - round(shape[0] * self.scale)) > 1e-9:
            return None
        zoom = round(zoom)
        top = max(level for level, _ in pyramid_plan(self.full_res_sigmas, PYRAMID_MIN_SIGMA)) if self.mixture == "pyramid" else 0
        step = math.lcm(zoom * self.grid_stride, 2**top)
        reach = zoom * (self._network_reach + self.grid_stride) + kernel_radius(max(self.full_res_sigmas)) + 2 ** (top + 2)
        if self.divisive is not None:  # the energy's Gaussian
            reach += kernel_radius(self.divisive["sigma"])
        return -(-reach // step) * step, step

    def _finish(self, response: np.ndarray) -> np.ndarray:
        """The method's last steps after Eq. 3, when it has them (the gain Normalizer): the
        divisive normalization, then the contrast equalization (:mod:`alcn_cv.nets.gain`).
        ``response`` (float32, the caller's own) is overwritten by the equalization."""
        # 1 / tau folds into the division; without one, the multiplication is in place
        inverse_tau = 1.0 if self.equalization_tau is None else 1.0 / self.equalization_tau
        if self.divisive is not None:
            response = divisive_normalization(response, **self.divisive, floor=_DIVISIVE_FLOOR.get(), multiplier=inverse_tau)
        elif inverse_tau != 1.0:
            np.multiply(response, np.float32(inverse_tau), out=response)
        return response if self.equalization_tau is None else np.tanh(response, out=response)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        # Without a division (which would cancel it), 1 / tau folds into the grid's maps: Eq. 3 is
        # linear in them, and the tanh runs in place.
        if self._maps_on_grid and self.equalization_tau is not None and self.divisive is None:
            grid = self.weight_grid(gray) * np.float32(1.0 / self.equalization_tau)
            response = alcn_filter_grid(gray, grid, self.grid_stride, self.full_res_sigmas)
            return np.tanh(response, out=response)
        return self._finish(self._mixture(gray))

    def _mixture(self, gray: np.ndarray) -> np.ndarray:
        """Eq. 3 with the Normalizer's maps: the raw response before any equalization."""
        if self.mixture == "pyramid":
            grid = self.weight_grid(gray)
            h, w = gray.shape
            small_h, small_w = self._working_shape(gray.shape)
            ratios = (small_h / h, small_w / w)
            return pyramid_mixture(
                gray, self.full_res_sigmas, lambda *args: self._grid_maps_at(grid, ratios, *args), PYRAMID_MIN_SIGMA
            )
        if self._maps_on_grid:
            return alcn_filter_grid(gray, self.weight_grid(gray), self.grid_stride, self.full_res_sigmas)
        if self.backend in ("fast", "opencv"):
            return alcn_filter(gray, self.weight_maps(gray), self.full_res_sigmas)
        import torch
        import torch.nn.functional as F

        from alcn_cv.filters.kornia_mixture import gaussian_mixture2d

        maps = self._dense(gray)[None]
        with torch.inference_mode(), _torch_threads(self.threads):
            image = torch.from_numpy(gray).to(maps.device)[None, None]
            if maps.shape[-2:] != image.shape[-2:]:
                maps = F.interpolate(maps, size=image.shape[-2:], mode="bilinear", align_corners=False)
            return gaussian_mixture2d(image, maps, self.full_res_sigmas)[0, 0].cpu().numpy()

    def apply_batch(self, frames: np.ndarray, out_dtype: type | np.dtype | str | None = None, half: bool = False) -> np.ndarray:
        """:meth:`apply` on a batch of grayscale frames of one size, in one pass of the Normalizer
        and of the exact Eq. 3 on :attr:`device` (``backend="torch"``): the GPU path.

        The frames are sent to the device as they are (uint8: a quarter of the float traffic)
        and converted there. The working image is the frames averaged over blocks of
        ``1 / scale`` pixels, which is what ``cv2.INTER_AREA`` gives when the frame's sides
        are multiples of ``1 / scale`` (then the outputs equal :meth:`apply`'s to float
        rounding); other sizes are resized by torch's area interpolation.

        Args:
            frames: ``(B, H, W)`` uint8, uint16, or float32 intensities in [0, 1].
            out_dtype: as in :meth:`apply` (default: the frames' dtype).
            half: run the Normalizer in float16 under ``torch.autocast`` (for CUDA; on the CPU
                it is slow and only checks the path); Eq. 3 stays in float32.

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
        import torch

        from alcn_cv.filters.kornia_mixture import gaussian_mixture2d
        from alcn_cv.nets.gain import contrast_equalization

        device = next(self.net.parameters()).device
        lo, hi = self.output_range
        with torch.inference_mode(), _torch_threads(self.threads):
            x = torch.from_numpy(np.ascontiguousarray(frames).astype(frames.dtype.newbyteorder("="), copy=False)).to(device)
            x = x.clamp(0, 1) if frames.dtype == np.float32 else x.float() * (1.0 / FULL_SCALE[frames.dtype])
            x = x[:, None]
            with torch.autocast(device.type, torch.float16, enabled=half):  # the network; Eq. 3 in float32
                maps = self.net.dense(self._working_batch(x), self.grid_stride).float()
            maps = torch.nn.functional.interpolate(maps, size=x.shape[-2:], mode="bilinear", align_corners=False)
            response = gaussian_mixture2d(x, maps, self.full_res_sigmas)
            if self.divisive is not None:
                response = self.net.divide(response)
            if self.equalization_tau is not None:
                response = contrast_equalization(response, self.equalization_tau)
            unit = ((response[:, 0] - lo) * (1.0 / (hi - lo))).clamp(0, 1)
            if out_dtype != np.float32:
                unit = torch.round(unit * FULL_SCALE[out_dtype]).to(torch.int32)
            return unit.cpu().numpy().astype(out_dtype)

    def _working_batch(self, x: torch.Tensor) -> torch.Tensor:
        """A ``(B, 1, H, W)`` batch at the working scale (see :meth:`apply_batch`)."""
        import torch.nn.functional as F

        if self.scale == 1:
            return x
        size = self._working_shape(tuple(x.shape[-2:]))
        zoom = 1.0 / self.scale
        if zoom == round(zoom) and x.shape[-2] % round(zoom) == 0 and x.shape[-1] % round(zoom) == 0:
            return F.avg_pool2d(x, round(zoom))  # cv2.INTER_AREA's blocks
        if self.scale < 1:
            return F.interpolate(x, size=size, mode="area")
        return F.interpolate(x, size=size, mode="bilinear", align_corners=False)

    def __repr__(self) -> str:
        return (
            f"ALCN(weights={self.weights_path.name!r}, scale={self.scale}, backend={self.backend!r}, "
            f"grid_stride={self.grid_stride}, mixture={self.mixture!r}, threads={self.threads}, trained={self.trained})"
        )


def _divisive_arguments(divisive: dict, scale: float) -> dict[str, int | float | None]:
    """The keyword arguments of :func:`~alcn_cv.filters.divisive.divisive_normalization` at the
    input's resolution from a weight file's ``divisive`` header (its stride and sigma in working
    pixels; a file without ``sigma`` divides on the grid)."""
    sigma = divisive.get("sigma")
    return {
        "stride": max(1, round(divisive["stride"] / scale)),
        "scale": float(divisive["scale"]),
        "sigma": None if sigma is None else float(sigma) / scale,
    }


def _network_reach(meta: dict) -> int:
    """How far from a grid point, in working pixels, the Normalizer a weight file describes
    looks: half its 48-pixel window, or for the gain Normalizer (:mod:`alcn_cv.nets.gain`) its
    cells, the reach of its context blur on them and of its dilated convolutions."""
    if meta.get("architecture") != "gain":
        return WINDOW // 2
    config = meta["config"]
    stride = int(config["stride"])
    blur = max(float(config["mean_sigma"]), float(config["context_sigma"])) / stride
    return stride * (1 + kernel_radius(blur) + sum(int(d) for d in config["dilations"]))


def _channels_last(hwc: np.ndarray) -> torch.Tensor:
    """A ``(1, C, H, W)`` channels-last tensor sharing the memory of a C-ordered ``(H, W, C)`` array
    (the batch stride spelled out: torch takes a zero one for another layout)."""
    import torch

    return torch.from_numpy(hwc.reshape((1,) + hwc.shape)).permute(0, 3, 1, 2)


def _grid_blur(grid: np.ndarray, sigma: float) -> np.ndarray:
    """The Gaussian blur of the gain Normalizer on its grid (:func:`alcn_cv.nets.gain._blur`: the
    kernel of :func:`gaussian_kernel1d`, reflect-101, repeated on grids smaller than the kernel)."""
    kernel = gaussian_kernel1d(sigma)
    return cv2.sepFilter2D(grid, cv2.CV_32F, kernel, kernel, borderType=cv2.BORDER_REFLECT_101)


def _integer_zoom(step: float, offset: float) -> tuple[int, int] | None:
    """``(z, o)`` when pixel ``x`` at grid coordinate ``step * x + offset`` is pixel ``x + o``
    of the grid zoomed ``z`` times by ``cv2.resize`` (which puts pixel ``x`` at
    ``(x + 0.5) / z - 0.5``), ``z`` and ``o >= 0`` integers; else None."""
    zoom = 1.0 / step
    shift = (offset + 0.5 - 0.5 * step) * zoom
    if abs(zoom - round(zoom)) > 1e-9 or abs(shift - round(shift)) > 1e-6 or round(shift) < 0 or round(zoom) < 2:
        return None
    return round(zoom), round(shift)


@contextmanager
def _torch_threads(threads: int | None) -> Iterator[None]:
    """Run the block with ``threads`` torch intra-op threads (no change for None)."""
    import torch

    before = torch.get_num_threads()
    if threads is None or threads == before:
        yield
        return
    torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _check_teacher(meta: dict, path: Path) -> None:
    """Warn when a shipped distilled weight file's teacher (:data:`TEACHERS`) is not the file shipped now."""
    teacher = meta.get("teacher")
    model = next((name for name in TEACHERS if MODELS[name] == path), None)
    if not isinstance(teacher, dict) or model is None:
        return
    import hashlib

    teacher_path = MODELS[TEACHERS[model]]
    if hashlib.sha256(teacher_path.read_bytes()).hexdigest() != teacher.get("sha256"):
        logger.warning(
            "%s was distilled from another version of %s than the one installed: re-distil it "
            "(see its model card)", path.name, teacher_path.name,
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


def createALCN(  # noqa: N802 -- OpenCV naming, like cv2.createCLAHE
    weights: str | Path | None = None,
    scale: float | None = None,
    backend: str | None = None,
    device: str = "cpu",
    grid_stride: int | None = None,
    mixture: str | None = None,
    model: str = DEFAULT_MODEL,
    threads: int | None = 1,
) -> ALCN:
    """Create an :class:`ALCN` normalization; ``createALCN().apply(img)`` normalizes an image.

    The parameters are :class:`ALCN`'s, with its defaults.

    Example:
        >>> import alcn_cv, numpy as np
        >>> frame = (np.random.rand(480, 640) * 255).astype(np.uint8)
        >>> alcn_cv.createALCN().apply(frame).shape
        (480, 640)
    """
    return ALCN(
        weights=weights, scale=scale, backend=backend, device=device, grid_stride=grid_stride, mixture=mixture,
        model=model, threads=threads,
    )
