"""The Normalizer without torch: the exported ONNX model run by OpenCV's DNN module.

An OpenCV application can use ALCN with only OpenCV and NumPy installed: the Normalizer
exported by ``alcn export --weights FILE.npz`` (:mod:`alcn_cv.train.export`) runs through
``cv2.dnn.readNetFromONNX``, and Eq. 3's Gaussian mixture runs in OpenCV
(:mod:`alcn_cv.filters.gaussian_mixture`, through :mod:`alcn_cv.runtime`).
This module imports no torch, nor the torch Normalizers beside it in :mod:`alcn_cv.nets`.

:meth:`OpenCVNormalizer.dense_grid` and :meth:`OpenCVNormalizer.dense` return what
:meth:`alcn_cv.nets.Normalizer.dense_grid` and :meth:`~alcn_cv.nets.Normalizer.dense` return
for the same weights (to float rounding): the image is padded here by reflect-101
(``cv2.BORDER_REFLECT_101``) exactly as the torch network pads it, and the grid is upsampled
bilinearly with the grid points on the pixels ``s*i`` (``align_corners=True``), ``s`` the
network's output stride (4 for the paper's Normalizer, 8 for the lite and the gain ones), read
from the model by running it on probe images (the gain Normalizer's from its config). The gain
Normalizer's export takes its features on the grid (:class:`GainFeatures`, computed here, so that ``cv2.dnn``
runs only the grid's convolutions) and the lite Normalizer's the padded image cut into 4x4 blocks
(:func:`image_blocks`, :data:`LITE_BLOCK`: its first convolution, 4x4 with stride 4, becomes a 1x1 one, which
``cv2.dnn`` runs without spreading a one-channel full-resolution tensor over its blocked layout); the input's name
says which (:data:`IMAGE_INPUT`, :data:`BLOCKS_INPUT`, :data:`FEATURES_INPUT`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.checks import check_gray
from alcn_cv.errors import WeightFileError
from alcn_cv.extras import opencv_version
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d, upsample_grid
from alcn_cv.row_parts import row_parts, run_parts
from alcn_cv.weight_file import load_normalizer_file

__all__ = [
    "BLOCKS_INPUT",
    "GAIN_NEEDS",
    "FEATURES_INPUT",
    "IMAGE_INPUT",
    "LITE_BLOCK",
    "GainFeatures",
    "OpenCVNormalizer",
    "cell_moments",
    "grid_shape",
    "image_blocks",
]

#: The Normalizer's window in pixels (``Normalizer.window`` takes it from here: this module imports no torch).
WINDOW = 48
# Grid points of the probe run that measures the model's output stride.
_PROBE_POINTS = 3
#: The input of the paper's Normalizer's export: the padded image.
IMAGE_INPUT = "image"
_OPENCV = opencv_version()
#: Whether ``cv2.dnn`` runs the gain Normalizers' exports: from OpenCV 4.8 on (4.5 and 4.6 fail to import their
#: ReduceMean or Mul, 4.7 imports them and fails in the ReduceMean's shapes on the first forward).
RUNS_GAIN = _OPENCV >= (4, 8)
#: What to do where ``cv2.dnn`` cannot run the gain Normalizers (not :data:`RUNS_GAIN`).
GAIN_NEEDS = (
    f"OpenCV {cv2.__version__}'s cv2.dnn cannot run the gain Normalizers: use OpenCV 4.8 or newer, install torch "
    "(backend='fast') or model='lite'"
)
#: Whether ``cv2.dnn`` is OpenCV 4's, whose ONNX importer reads no pads the graph computes (:func:`computes_pads`) and
#: whose reflect ``Pad`` pads no side by more than its length (the gain Normalizers' graphs pad grids smaller than
#: their largest pad); OpenCV 5's does both.
OPENCV_4_DNN = _OPENCV < (5, 0)
#: The input of the lite Normalizer's export: :func:`image_blocks` of the padded image.
BLOCKS_INPUT = "blocks"
#: The side of those blocks: the lite Normalizer's first convolution (4x4, stride 4; a test checks they agree).
LITE_BLOCK = 4
#: The input of the gain Normalizer's export: :class:`GainFeatures`.
FEATURES_INPUT = "features"


def computes_pads(onnx_path: Path) -> bool:
    """Whether an ONNX export computes its pads in its graph, as torch writes ``F.pad`` (:mod:`alcn_cv.train.export`
    writes them as constants): a ``ConstantOfShape`` node, which OpenCV 4's ONNX importer cannot read there."""
    return b"ConstantOfShape" in onnx_path.read_bytes()


def grid_shape(shape: tuple[int, int], stride: int) -> tuple[int, int]:
    """The grid of an image of ``shape`` ``(H, W)`` with points on the pixels ``(stride * i, stride * j)``:
    ``(ceil((H - 1) / stride) + 1, ceil((W - 1) / stride) + 1)``, the fewest points that reach its last pixels.

    Example:
        >>> grid_shape((480, 640), 8)
        (61, 81)
    """
    h, w = shape
    # no negative operand: traced for an ONNX export, sizes are tensors and ONNX's Div truncates where // floors
    return (h - 2 + stride) // stride + 1, (w - 2 + stride) // stride + 1


def image_blocks(padded: np.ndarray) -> np.ndarray:
    """``(H, W)`` float32, both multiples of :data:`LITE_BLOCK` -> ``(1, LITE_BLOCK**2, H / LITE_BLOCK,
    W / LITE_BLOCK)``: channel ``LITE_BLOCK * y + x`` holds pixel ``(y, x)`` of each block (space to depth)."""
    h, w = padded.shape
    b = LITE_BLOCK
    blocks = padded.reshape(h // b, b, w // b, b).transpose(1, 3, 0, 2)
    return np.ascontiguousarray(blocks).reshape(1, b * b, h // b, w // b)


def cell_parts(shape: tuple[int, int], stride: int) -> list[tuple[int, int]]:
    """The grid rows of an image of ``shape`` ``(H, W)`` (:func:`grid_shape`) cut into ``(first, stop)`` parts,
    one per part of its rows (:func:`~alcn_cv.row_parts.row_parts`)."""
    parts = [(start // stride, stop // stride) for start, stop in row_parts(shape, stride)]
    parts[-1] = (parts[-1][0], grid_shape(shape, stride)[0])
    return parts


def cells_padded(image: np.ndarray, stride: int, cells: tuple[int, int]) -> np.ndarray:
    """The grid rows ``cells = (first, stop)`` of an ``(H, W)`` float32 image mirrored (reflect-101) to whole
    ``stride``-pixel cells, each centred on a grid point ``stride * i``: float32 ``(stride * (stop - first),
    stride * gw)``, ``gw`` the grid's width (:func:`grid_shape`)."""
    h, w = image.shape
    width = stride * grid_shape(image.shape, stride)[1]
    before = stride // 2
    # the image rows of the part's first and last padded rows (beyond the image: mirrored)
    top, bottom = stride * cells[0] - before, stride * cells[1] - before
    return cv2.copyMakeBorder(
        image[max(top, 0) : min(bottom, h)],
        max(0, -top),
        max(0, bottom - h),
        before,
        width - w - before,
        cv2.BORDER_REFLECT_101,
    )


def cell_moments(image: np.ndarray, stride: int) -> np.ndarray:
    """:meth:`GainNormalizer.cell_moments <alcn_cv.nets.gain.GainNormalizer.cell_moments>` of an ``(H, W)``
    float32 image, bit for bit: ``(1, 2, gh, gw)`` float32, the mean of each ``stride``-pixel cell centred on a
    grid point, of the image and of its square; the grid's rows in parts on OpenCV's threads.

    The sums run in torch's order (row by row, left to right): where a cell is flat its standard deviation is
    the rounding of these sums, which the network's log amplifies.
    """

    def moments(first: int, stop: int) -> np.ndarray:
        padded = cells_padded(image, stride, (first, stop))
        gh, gw = padded.shape[0] // stride, padded.shape[1] // stride
        # each cell's pixels and their squares along the first axis, row by row: NumPy reduces an axis that is not
        # the array's fastest in order, pixel after pixel (pairwise summation runs along the fastest only), and the
        # two planes keep the fastest axis another one even for a single cell
        cells = np.empty((stride * stride, 2, gh, gw), np.float32)
        cells.reshape(stride, stride, 2, gh, gw)[:, :, 0] = padded.reshape(gh, stride, gw, stride).transpose(1, 3, 0, 2)
        np.multiply(cells[:, 0], cells[:, 0], out=cells[:, 1])
        sums = np.add.reduce(cells, axis=0)[None]
        return np.divide(sums, np.float32(stride * stride), out=sums)

    return np.concatenate(run_parts(moments, cell_parts(image.shape, stride)), axis=2)


class GainFeatures:
    """:meth:`GainNormalizer.features <alcn_cv.nets.gain.GainNormalizer.features>` in OpenCV and NumPy: an
    ``(H, W)`` float32 image -> ``(1, 4, gh, gw)`` float32, the log of each cell's mean, of the local and the
    context means (the grid's reflect-101 Gaussian blurs) and of the cell's standard deviation, plus ``eps``.

    Args:
        config: the gain Normalizer's ``config`` (its weight file's header): ``stride``, ``mean_sigma``,
            ``context_sigma``, ``eps``.
    """

    def __init__(self, config: dict) -> None:
        self.stride = int(config["stride"])
        self.eps = np.float32(config["eps"])
        # The blurs of the grid stand for blurs of the image: sigma in cells = sigma / stride.
        self.kernels = [
            gaussian_kernel1d(float(config[key]) / self.stride).astype(np.float32)
            for key in ("mean_sigma", "context_sigma")
        ]

    def __call__(self, image: np.ndarray) -> np.ndarray:
        return self.from_moments(cell_moments(image, self.stride))

    def from_moments(self, moments: np.ndarray) -> np.ndarray:
        """The features of :func:`cell_moments` ``(1, 2, gh, gw)``."""
        mean, square = moments[0]
        features = np.empty((1, 4, *mean.shape), np.float32)
        features[0, 0] = mean
        for plane, kernel in zip(features[0, 1:3], self.kernels):
            cv2.sepFilter2D(mean, -1, kernel, kernel, dst=plane, borderType=cv2.BORDER_REFLECT_101)
        np.sqrt(np.maximum(square - mean * mean, 0), out=features[0, 3])
        features += self.eps
        return np.log(features, out=features)


class OpenCVNormalizer:
    """The ALCN Normalizer run by ``cv2.dnn`` from its ONNX export.

    Args:
        onnx_path: the ``.onnx`` file written by :func:`alcn_cv.train.export.export_onnx` (a shipped model's: beside
            its weight file, :data:`alcn_cv.runtime.MODELS`).
        config: a gain Normalizer's ``config`` (:class:`GainFeatures`); default: read from the weight file
            beside ``onnx_path`` (the same name, ``.npz``) when the export is a gain Normalizer's.

    Raises:
        WeightFileError: the file is missing or OpenCV cannot read it; a gain export without its config.
    """

    window = WINDOW

    def __init__(self, onnx_path: str | Path, config: dict | None = None) -> None:
        self.path = Path(onnx_path)
        if not self.path.is_file():
            raise WeightFileError(
                f"ONNX model not found: {self.path} (backend='opencv' runs the export beside the weight file: "
                f"`alcn export --weights {self.path.with_suffix('.npz')} --onnx {self.path}`, with the [train] extra; "
                "or backend='fast', the network in torch)"
            )
        # a gain Normalizer's export from an older alcn-cv, before cv2.dnn tries: its ONNX importer logs an error of
        # its own and fails with lines of C++ context
        if RUNS_GAIN and OPENCV_4_DNN and computes_pads(self.path):
            raise WeightFileError(
                f"OpenCV {cv2.__version__} cannot read {self.path}, an older export (its graph computes its pads): "
                f"export it again, `alcn export --weights {self.path.with_suffix('.npz')} --onnx {self.path} "
                "--overwrite`"
            )
        # one inference at a time: setInput and forward share the network's state across threads
        self._lock = threading.Lock()
        try:
            self.net = cv2.dnn.readNetFromONNX(str(self.path))
        except cv2.error as exc:
            hint = "" if RUNS_GAIN else f"; {GAIN_NEEDS}"
            raise WeightFileError(f"OpenCV cannot read the ONNX model {self.path}{hint}: {exc.err}") from None
        #: The graph's input: :data:`IMAGE_INPUT`, :data:`BLOCKS_INPUT` or :data:`FEATURES_INPUT`.
        self.input = next((name for name in (FEATURES_INPUT, BLOCKS_INPUT) if self._has_input(name)), IMAGE_INPUT)
        gain_config = self._config(config) if self.input == FEATURES_INPUT else None
        #: The gain Normalizer's features (for :data:`FEATURES_INPUT`), or None.
        self.features = GainFeatures(gain_config) if gain_config is not None else None
        #: The graph's largest reflect pad, in grid points: the gain Normalizer's largest dilation (0 for the others,
        #: whose image is padded outside the graph).
        self.largest_pad = max(gain_config["dilations"]) if gain_config is not None else 0
        self.stride = self._output_stride() if self.features is None else self.features.stride

    def _has_input(self, name: str) -> bool:
        try:
            self.net.setInput(np.zeros((1, 2, 1, 1), np.float32), name)
        except cv2.error:
            return False
        return True

    def _config(self, config: dict | None) -> dict:
        if config is not None:
            return config
        header = self.path.with_suffix(".npz")
        if not header.is_file():
            raise WeightFileError(f"{self.path} is a gain Normalizer: give its config or put its weight file beside it")
        return load_normalizer_file(header).meta["config"]

    def __getstate__(self) -> dict:
        return {k: v for k, v in self.__dict__.items() if k not in ("net", "_lock")}

    def __setstate__(self, state: dict) -> None:  # the network read again from its file
        self.__dict__.update(state)
        self._lock = threading.Lock()
        self.net = cv2.dnn.readNetFromONNX(str(self.path))

    def _forward(self, blob: np.ndarray) -> np.ndarray:
        with self._lock:
            self.net.setInput(blob)
            return self.net.forward()

    def _grid_points(self, side: int) -> int:
        return self._forward(self._padded_input(np.zeros((side, side), np.float32))).shape[-1]

    def _padded_input(self, padded: np.ndarray) -> np.ndarray:
        return image_blocks(padded) if self.input == BLOCKS_INPUT else padded[None, None]

    def _output_stride(self) -> int:
        # A (48 + 8k)-pixel padded input gives 1 + 8k / stride grid points for the strides 1, 2, 4, 8.
        extent = 8 * (_PROBE_POINTS - 1)
        side = WINDOW + extent
        points = self._grid_points(side)
        if points < 2 or extent % (points - 1):
            raise WeightFileError(f"{self.path}: not a Normalizer export ({side}-pixel probe: {points} grid points)")
        return extent // (points - 1)

    def dense_grid(self, image: np.ndarray, alongside: Callable[[], object] | None = None) -> np.ndarray:
        """The Normalizer's output on its grid (stride :attr:`stride`).

        Args:
            image: ``(H, W)`` float32 intensities in [0, 1] (at the working scale).
            alongside: called once the full-resolution work is done (:class:`~alcn_cv.runtime.Network`).

        Returns:
            ``(N, gh, gw)`` float32, :func:`grid_shape` of the image at ``s = stride``; grid point
            ``(i, j)`` is the prediction for the 48x48 window centred on pixel ``(s*i, s*j)``.

        On OpenCV 4 (:data:`OPENCV_4_DNN`) an image whose grid has a side shorter than
        :attr:`largest_pad` (under 18 px at the gain models' stride 8) is first mirrored (reflect-101) at its bottom
        and right to the smallest size the graph pads, and the grid cut back: its window completed by mirroring, as
        :meth:`~alcn_cv.enhance.base.Normalization.apply` promises, where OpenCV 5 mirrors the grid instead.

        Raises:
            InputError: not an ``(H, W)`` float32 image.
        """
        h, w = check_gray(image, finite=False).shape  # its values checked by the callers (apply, weight_grid)
        s = self.stride
        gh, gw = grid_shape((h, w), s)
        if OPENCV_4_DNN and min(gh, gw) < self.largest_pad:
            # OpenCV 4's reflect Pad pads no side by more than its length: the first side whose grid it pads
            side = s * (self.largest_pad - 2) + 2
            mirrored = cv2.copyMakeBorder(image, 0, max(side - h, 0), 0, max(side - w, 0), cv2.BORDER_REFLECT_101)
            return self.dense_grid(mirrored, alongside)[:, :gh, :gw]
        if self.features is not None:
            blob = self.features.from_moments(cell_moments(image, s))
        else:
            half = WINDOW // 2
            padded = cv2.copyMakeBorder(
                image, half, s * (gh - 1) + half - h, half, s * (gw - 1) + half - w, cv2.BORDER_REFLECT_101
            )
            blob = self._padded_input(padded)
        if alongside is not None:
            alongside()
        return self._forward(blob)[0]

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        """``(n, 48, 48)`` float32 windows -> ``(n, N)``: the grid point at each window's centre, which sees
        exactly the window (no padding reaches it)."""
        c = (WINDOW // 2) // self.stride
        return np.stack([self.dense_grid(w)[:, c, c] for w in windows])

    def dense(self, image: np.ndarray) -> np.ndarray:
        """Per-pixel weight maps F_k (Eq. 3): :meth:`dense_grid` upsampled bilinearly to ``(N, H, W)`` float32
        (:func:`~alcn_cv.filters.gaussian_mixture.upsample_grid`)."""
        return np.stack([upsample_grid(m, self.stride, image.shape) for m in self.dense_grid(image)])

    def __repr__(self) -> str:
        return f"OpenCVNormalizer({self.path.name!r}, stride={self.stride}, input={self.input!r})"
