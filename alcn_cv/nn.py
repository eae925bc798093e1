"""ALCN for PyTorch: :func:`alcn2d` and :class:`ALCN2d`, the torch runtime of every shipped model family.

``ALCN2d`` is what ``createALCN(backend="torch")`` runs, and a module a PyTorch model can put in front of
itself: ``(B, 1 | 3, H, W)`` float intensities in [0, 1] on any device and dtype in, the same shape in [0, 1]
out, equal to :meth:`ALCN.apply <alcn_cv.enhance.alcn.ALCN.apply>`'s float output (with ``mixture="exact"`` for the
``lite`` and ``paper`` models, whose default mixture in ``apply`` approximates it on a pyramid; 3 channels: RGB,
normalized on the L channel of CIE Lab, a and b kept), differentiable end to end. In float32 on the CPU, with or
without autograd (:func:`~alcn_cv.nets.cpu_inference.cpu_eager`), colour is converted to Lab by ``apply()``'s own
OpenCV passes (within 3e-6 of it), differentiated as :mod:`alcn_cv.filters.torch_lab`, OpenCV's arithmetic in torch,
which converts it elsewhere (within 1e-4). In CPU inference (under ``torch.no_grad()`` or
``torch.inference_mode()``; not traced, exported, compiled, transformed by ``torch.func`` or under autocast; a float16
or bfloat16 image is computed in float32, its module's network in its own dtype) the gain
models run ``apply()``'s own passes throughout for one image, or images of 2**18 pixels or more
(:class:`~alcn_cv.runtime.GainRuntime` with the module's network, called once per image, and ``apply()``'s colour
path), as fast as ``apply()``; their torch filters run everywhere else.
Importing this module imports torch and kornia; importing :mod:`alcn_cv` does not.

Example:
    >>> import torch
    >>> from alcn_cv.nn import ALCN2d
    >>> alcn = ALCN2d(model="lite").eval().requires_grad_(False)  # frozen in front of a classifier
    >>> alcn(torch.rand(2, 3, 64, 80)).shape
    torch.Size([2, 3, 64, 80])
"""

from __future__ import annotations

import dataclasses
import functools
import math
import numbers
import os
import sys
import threading
import warnings
from collections.abc import Callable, Iterable, Iterator
from contextlib import AbstractContextManager, contextmanager, nullcontext
from pathlib import Path
from typing import NoReturn

import cv2
import numpy as np

from alcn_cv.extras import missing_extra

try:  # the module PyTorch users import first: without torch or kornia, one line naming the extra
    import torch
    import torch.nn.functional as F
    from torch import nn

    from alcn_cv.filters.kornia_mixture import GaussianMixture2d
except ModuleNotFoundError as exc:
    error = missing_extra(exc, "alcn_cv.nn")
    if error is None:
        raise
    raise error from exc

from alcn_cv.checks import FLOAT_TOLERANCE, FULL_SCALE
from alcn_cv.errors import InputError
from alcn_cv.filters.lab import normalized_bgr, srgb_to_lab
from alcn_cv.filters.torch_divisive import divisive_normalization
from alcn_cv.filters.torch_lab import LabToRgb, RgbToLab
from alcn_cv.filters.torch_precision import at_least_float32, autocast_enabled
from alcn_cv.filters.torch_resize import area_downsample, interpolate_grid
from alcn_cv.filters.torch_wide_band import wide_band
from alcn_cv.nets.cpu_inference import cpu_eager, cpu_inference, transformed
from alcn_cv.nets.gain import GainNormalizer, contrast_equalization
from alcn_cv.nets.lite import normalizer_from_file
from alcn_cv.nets.normalizer import check_grid_stride
from alcn_cv.nets.opencv_runtime import WINDOW, GainFeatures
from alcn_cv.row_parts import MIN_PART_PIXELS
from alcn_cv.runtime import GainRuntime, ModelSpec, resolve_weights, weights_setting
from alcn_cv.weight_file import NormalizerFile, load_normalizer_file, save_normalizer_file

#: The runtime adapters of createALCN(backend="fast" | "torch"), TorchNetwork and TorchRuntime, are the library's, not
#: a PyTorch user's.
__all__ = ["ALCN2d", "alcn2d", "batches", "torch_threads"]

#: Windows per Normalizer call in :meth:`TorchNetwork.window_weights` (bounds the memory of a batch).
_WINDOW_BATCH = 512
_TORCH_DTYPES = {
    np.dtype(np.uint8): torch.uint8,
    np.dtype(np.uint16): torch.uint16,
    np.dtype(np.float32): torch.float32,
}


def _in_float32(method: Callable[..., torch.Tensor]) -> Callable[..., torch.Tensor]:
    """``method(self, image, ...)`` of a float16 or bfloat16 image run on the image and its other tensor arguments in
    float32, its result cast back to the image's dtype: the network's convolutions alone run in the module's dtype
    (:meth:`~alcn_cv.nets.gain.GainNormalizer.maps_from_features`), or a caller's autocast's. Eq. 3 in float16 (the
    difference of two blurs) moves the output by 1.2e-2, the divisive step by 8e-4; and under autocast, a float16
    image and a bfloat16 one would meet in the same operation, which torch refuses."""

    @functools.wraps(method)
    def run(self: ALCN2d, image: torch.Tensor, *args: object, **kwargs: object) -> torch.Tensor:
        if image.dtype not in (torch.float16, torch.bfloat16):
            return method(self, image, *args, **kwargs)
        args = tuple(at_least_float32(a) if isinstance(a, torch.Tensor) else a for a in args)
        kwargs = {k: at_least_float32(v) if isinstance(v, torch.Tensor) else v for k, v in kwargs.items()}
        return method(self, image.float(), *args, **kwargs).to(image.dtype)

    return run


class ALCN2d(nn.Module):
    """Adaptive Local Contrast Normalization (Rad, Roth & Lepetit, BMVC 2017) as a module.

    Args:
        model: a shipped model (:data:`alcn_cv.runtime.MODELS`): ``"gain"`` (the default), ``"gain-lite"``,
            ``"lite"`` or ``"paper"``.
        weights: a weight file instead of ``model``, or its contents already loaded
            (:func:`~alcn_cv.weight_file.load_normalizer_file`: the file is not read again).
        scale: the working scale (default: the weight file's).
        grid_stride: spacing of the Normalizer's grid, a multiple of its stride (default: its stride).
        allow_tf32: let CUDA convolutions use TF32 (faster, about 1e-3 off); default exact, by torch's legacy switch
            (``torch.backends.cudnn.flags``): a program that sets torch's ``fp32_precision`` settings, which may not be
            mixed with it, passes True and sets the precision itself.

    Shape:
        - image: ``(B, 1, H, W)`` or ``(B, 3, H, W)`` (RGB) float in [0, 1], any device and float dtype
          (move the module with ``.to(device, dtype)``), any size (``B = 0`` too: an empty output): a side shorter
          than a kernel's reach is mirrored as ``apply()`` mirrors it (OpenCV's reflect-101, repeated).
        - output: the same shape, dtype and device, in [0, 1] (the raw response mapped through
          the weight file's fixed ``output_range``, clipped).

    Raises:
        InputError: building, an unknown ``model``, both ``model`` and ``weights``, or a ``grid_stride`` that is not
            a multiple of the network's stride (:class:`~alcn_cv.errors.WeightFileError`: a weight file that does
            not load); calling, see :meth:`forward`.

    Range: the image is checked only where reading it costs no device sync: on the CPU, run eagerly (not under
    ``torch.jit.trace``, ``torch.compile``, an ONNX export or a ``torch.func`` transform), a value outside [0, 1] (1e-3
    of rounding allowed, as ``apply()``), NaN or inf raises. Elsewhere (CUDA, say) it is not checked and the output is
    undefined: a negative gray value makes the whole image NaN through the log of its cell means, colour is clipped to
    [0, 1] before Lab, and a NaN or inf pixel makes its whole image NaN (the divisive floor is the image's mean energy).

    Agreement with ``apply()``: the module's 1e-5 holds for integers converted as ``apply()`` converts them,
    ``image * (1 / 255)`` (uint16: ``1 / 65535``): ``image / 255`` differs by a float rounding, which the divisive step
    amplifies to 6e-5 on a photograph. The gain models at another ``scale`` than 1 are 6e-5 from it too: their working
    image is resized in torch, ``apply()``'s by ``cv2.resize``. Colour on CUDA, traced or compiled goes through the
    torch Lab conversion: 1e-4 from ``apply()`` on most photographs, up to 5e-4 on some.

    Precision: a float16 or bfloat16 module runs its network's convolutions in its dtype and the rest in float32 (the
    network's input features and head, Eq. 3, the divisive step, the Lab conversions), where float16 cannot hold the
    values (a cell's variance, the difference of two nearly equal moments; Eq. 3's difference of two blurs): against
    the float32 module on the same image, float16 was 9e-4 off at most on eight photographs, gray or colour (1e-4 on
    average; the lite model 1.6e-3 on one), bfloat16 8e-3. A float32 image cast to float16 is itself up to 3e-3 off in
    the output (the float32 module on the cast image), which no computation after it takes back. Under a caller's
    autocast an image of another float dtype than the module's is let through: the network's convolutions run at
    autocast's precision, the rest as outside autocast (in float32 for a float16 or bfloat16 image), and the output is
    the image's dtype (bfloat16 autocast: 1e-3 from float32 on a photograph, float16 1e-4).

    Tracing, compiling, exporting: ``torch.jit.trace`` records the sizes of the traced image: on another size the
    traced module fails or, without an error, returns wrong values (use ``torch.compile`` for several sizes, which
    compiles again for each new size: slow on a CPU, so compile for the few sizes a program runs, with
    ``dynamic=False``: by default the second size compiles the whole graph again for symbolic sizes, about 5 times as
    long as the first, 8 minutes on 2 cores); ``torch.jit.script`` is not supported (trace the module, or
    ``torch.compile`` it). ``torch.onnx.export`` (``dynamo=False``) writes it from an example image of 120x160 or
    larger (a smaller one may be refused: the network's pads would be longer than its grid); as a trace, the graph is
    for the example's size (with dynamic axes, other sizes give wrong values or fail). On the ``meta`` device a gray
    image propagates its shape; colour raises (torch has no autocast there, which the Lab conversions switch off).

    Workers: in a ``DataLoader``'s workers (or any process forked after this one ran torch's threads, which a fork
    leaves behind), the module runs on one thread: the outputs are one thread's, to float rounding.

    Fine-tuning: the network's parameters train (``requires_grad_(True)``, the default of a new module); the gain
    models' ``tau`` and ``floor_scale`` are buffers, fixed. ``train()`` and ``eval()`` give the same output (no
    dropout, no batch normalization). The gradients reaching the gain networks are small
    (about 1e-6 of a mean squared error, against weights of about 5e-2): use Adam rather than plain SGD, on a float32
    module (under autocast for speed): their squares underflow float16, where Adam's steps on a float16 module
    divide by zero.

    Example:
        >>> import torch
        >>> ALCN2d()(torch.rand(1, 1, 64, 64)).shape
        torch.Size([1, 1, 64, 64])
    """

    def __init__(
        self,
        model: str | None = None,
        weights: str | Path | NormalizerFile | None = None,
        scale: float | None = None,
        grid_stride: int | None = None,
        allow_tf32: bool = False,
    ) -> None:
        super().__init__()
        if isinstance(weights, NormalizerFile):
            if model is not None:
                raise InputError(f"give a model or a weight file, not both (model={model!r}, weights=its contents)")
            weight_file = weights
        else:
            weight_file = load_normalizer_file(resolve_weights(model, weights))
        self.spec = ModelSpec.from_file(weight_file, scale)
        self.net = normalizer_from_file(weight_file)
        self._built_from = weight_file.meta, weight_file.path  # the header and file that save() writes from
        if len(self.spec.sigmas) != self.net.num_kernels:
            raise InputError(f"weight file has {len(self.spec.sigmas)} sigmas for {self.net.num_kernels} outputs")
        self.grid_stride = check_grid_stride(grid_stride, self.net.stride)
        self.mixture = GaussianMixture2d(self.spec.full_res_sigmas)
        self.to_lab, self.from_lab = RgbToLab(), LabToRgb()  # colour images: the CIE Lab of apply()
        if not isinstance(allow_tf32, bool):
            raise InputError(f"allow_tf32 must be True or False, got {allow_tf32!r}")
        self.allow_tf32 = allow_tf32
        self._runtime: tuple[tuple, GainRuntime] | None = None  # _opencv_runtime's, with what it was built from

    def save(self, path: str | Path, description: str | None = None) -> Path:
        """Write the module's Normalizer, fine-tuned or not, as a weight file (``.npz``) that
        ``createALCN(weights=path)`` and ``ALCN2d(weights=path)`` load: a Normalizer fine-tuned in a training loop, into
        an OpenCV app.

        The header is that of the file the module was built from (its architecture, sigmas and working scale: a
        ``scale`` given to the module is not recorded), with ``description`` (default: "fine-tuned from" that file)
        and ``fine_tuned_from``, that file's path (None when it was given loaded) and description. ``createALCN`` runs
        it on the ``"fast"`` backend; ``alcn export`` makes the ONNX export ``backend="opencv"`` would run.

        Raises:
            InputError: ``path`` does not end in ``.npz``.
            WeightFileError: parameters that no longer fit the header (a gain model's fixed ``tau`` or
                ``floor_scale`` changed).

        Example:
            >>> import pathlib, tempfile
            >>> import alcn_cv
            >>> alcn = ALCN2d()  # ... fine-tuned in a training loop ...
            >>> path = alcn.save(pathlib.Path(tempfile.mkdtemp()) / "tuned.npz")
            >>> alcn_cv.createALCN(weights=path).apply(np.zeros((48, 64), np.uint8)).shape
            (48, 64)
        """
        meta, source = self._built_from
        start = {"file": None if source is None else str(source), "description": meta.get("description")}
        header = {**meta, "fine_tuned_from": start}
        header["description"] = description or f"fine-tuned from {start['file'] or start['description']}"
        return save_normalizer_file(path, self.net.state_arrays(), header)

    def working(self, gray: torch.Tensor) -> torch.Tensor:
        """``(B, 1, H, W)`` at the working scale, resized as :meth:`ALCN.apply` does: ``cv2.INTER_AREA`` down
        (blocks of ``1 / scale`` pixels averaged when the sides are multiples of it), bilinear up."""
        if self.spec.scale == 1:
            return gray
        h, w = map(int, gray.shape[-2:])  # 0-d tensors under torch.jit.trace, which round() refuses
        size = self.spec.working_shape((h, w))
        zoom = 1.0 / self.spec.scale
        if zoom == round(zoom) and gray.shape[-2] % round(zoom) == 0 and gray.shape[-1] % round(zoom) == 0:
            return F.avg_pool2d(gray, round(zoom))
        if self.spec.scale < 1:
            return area_downsample(gray, size)
        return F.interpolate(gray, size=size, mode="bilinear", align_corners=False)

    @_in_float32
    def weight_maps(self, gray: torch.Tensor, small: torch.Tensor | None = None) -> torch.Tensor:
        """Eq. 3's maps F_k ``(B, N, H, W)`` at the input resolution (``small``: the working image, default
        :meth:`working`)."""
        with self._tf32(gray):
            return self._maps(gray, small, first_only=False)

    @_in_float32
    def eq3(self, gray: torch.Tensor, small: torch.Tensor | None = None, half: bool = False) -> torch.Tensor:
        """Eq. 3's raw response ``(B, 1, H, W)`` (``small`` as in :meth:`weight_maps`; ``half``: the network under
        float16 autocast, Eq. 3 itself in ``gray``'s dtype).

        The gain Normalizer's two maps are ``F`` and ``-F`` (its kernel weights sum to zero), so there Eq. 3 is
        :meth:`GaussianMixture2d.difference <alcn_cv.filters.kornia_mixture.GaussianMixture2d.difference>` of the
        one product ``F o I``: one map interpolated and multiplied instead of two.
        """
        if small is None and not half and self._runs_opencv(gray):
            return self._opencv_planes(gray, lambda runtime, plane, _: runtime.mixture(plane))
        two_maps = isinstance(self.net, GainNormalizer) and self.net.num_kernels == 2
        with self._tf32(gray):
            # autocast's enabled=False would also switch off a caller's own autocast (bfloat16, say) inside
            with torch.autocast(gray.device.type, torch.float16) if half else nullcontext():
                maps = self._maps(gray, small, first_only=two_maps).to(gray.dtype)
            return self.mixture.difference(gray * maps) if two_maps else self.mixture(gray, maps)

    def _maps(self, gray: torch.Tensor, small: torch.Tensor | None, first_only: bool) -> torch.Tensor:
        working = self.working(gray) if small is None else small
        if first_only:
            grid = self.net.dense_grid(working, self.grid_stride)[:, :1]
            maps = interpolate_grid(grid, self.grid_stride, working.shape[-2:])
        else:
            maps = self.net.dense(working, self.grid_stride)
        if maps.shape[-2:] != gray.shape[-2:]:
            maps = F.interpolate(maps, size=gray.shape[-2:], mode="bilinear", align_corners=False)
        return maps

    @_in_float32
    def finish(self, response: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        """The gain family's steps after Eq. 3 (the divisive normalization, ``tanh(x / tau)``, ``c`` and ``tau`` the
        network's, the values :class:`~alcn_cv.runtime.ModelSpec` reads from its arrays); the response itself for the
        other families. ``floor``: ``(B, 1, 1, 1)``, the divisive floor (default: ``c`` times each image's mean
        energy)."""
        if self.spec.divisive is None or not isinstance(self.net, GainNormalizer):
            return response
        response = divisive_normalization(response, self.spec.divisive[0], self.net.floor_scale, floor)
        return contrast_equalization(response, self.net.tau)

    @_in_float32
    def with_band(self, response: torch.Tensor, gray: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        """:meth:`finish`'s ``response`` plus the model's weighted :mod:`~alcn_cv.filters.torch_wide_band` of
        ``gray`` (``floor``: the band's divisive floor ``(B, 1, 1, 1)``); the response itself for a model without."""
        if not self.spec.band or not isinstance(self.net, GainNormalizer):
            return response
        return response + self.spec.band * wide_band(gray, self.net.tau, self.net.floor_scale, floor)

    @_in_float32
    def response(
        self,
        gray: torch.Tensor,
        floor: torch.Tensor | None = None,
        small: torch.Tensor | None = None,
        band_floor: torch.Tensor | None = None,
        half: bool = False,
    ) -> torch.Tensor:
        """The raw normalized response ``(B, 1, H, W)`` (unbounded; :meth:`forward` maps it to [0, 1]); ``floor``
        as in :meth:`finish`, ``small`` and ``half`` as in :meth:`eq3`, ``band_floor`` as in :meth:`with_band`."""
        if gray.ndim != 4 or gray.shape[1] != 1:
            raise InputError(f"gray must have shape (B, 1, H, W), got {tuple(gray.shape)}")
        if small is None and not half and self._runs_opencv(gray):
            return self._opencv_response(gray, floor, band_floor)
        with self._tf32(gray):
            return self.with_band(self.finish(self.eq3(gray, small, half), floor), gray, band_floor)

    def _runs_opencv(self, image: torch.Tensor) -> bool:
        """Whether :meth:`forward`, :meth:`response` and :meth:`eq3` run ``apply()``'s own passes, with this module's
        network and its current ``tau`` and floor: the gain family at scale 1 in CPU inference of a float32 image
        (:func:`~alcn_cv.nets.cpu_inference.cpu_inference`: under ``torch.no_grad()`` or ``torch.inference_mode()``,
        not traced, exported, compiled or transformed by ``torch.func``), not under a caller's autocast (whose
        precision the network takes), for one image or images of :data:`~alcn_cv.row_parts.MIN_PART_PIXELS` or more:
        the OpenCV runtime (:class:`~alcn_cv.runtime.GainRuntime`) runs by parts of the rows, in cache, where torch's
        filters pass over the whole batch once per operation, which pays for small images only. The same values to
        float rounding."""
        return (
            isinstance(self.net, GainNormalizer)
            and self.spec.scale == 1
            and (image.shape[0] == 1 or image.shape[-2] * image.shape[-1] >= MIN_PART_PIXELS)
            and cpu_inference(image)
            and not torch.is_autocast_enabled("cpu")
        )

    def _opencv_response(
        self, gray: torch.Tensor, floor: torch.Tensor | None, band_floor: torch.Tensor | None
    ) -> torch.Tensor:
        """:meth:`response` by :class:`~alcn_cv.runtime.GainRuntime` (``floor`` and ``band_floor`` broadcast to the
        batch, as the torch filters take them)."""
        floors = [
            None if f is None else torch.broadcast_to(f, (len(gray), 1, 1, 1)).reshape(-1) for f in (floor, band_floor)
        ]
        return self._opencv_planes(
            gray,
            lambda runtime, plane, i: runtime.normalize(plane, *(None if f is None else float(f[i]) for f in floors)),
        )

    def _opencv_planes(
        self, gray: torch.Tensor, run: Callable[[GainRuntime, np.ndarray, int], np.ndarray]
    ) -> torch.Tensor:
        """``(B, 1, H, W)`` of ``run(runtime, plane, i)`` on each image of the batch (:meth:`_opencv_runtime`)."""
        runtime = self._opencv_runtime()
        planes = [run(runtime, np.ascontiguousarray(plane), i) for i, plane in enumerate(gray[:, 0].numpy())]
        # np.stack, not torch's copy: a torch operation would wake torch's threads (see _opencv_runtime)
        if len(planes) == 1:
            return torch.from_numpy(planes[0][None, None])
        return torch.from_numpy(np.stack(planes)[:, None]) if planes else torch.empty_like(gray)

    def _opencv_forward(self, image: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` by ``apply()``'s own passes (the colour path :func:`~alcn_cv.filters.lab.normalized_bgr`),
        one image of the batch at a time, in NumPy and OpenCV throughout (:meth:`_opencv_runtime`)."""
        normalize = self._opencv_runtime().normalize
        lo, hi = self.spec.output_range
        out = np.empty(image.shape, np.float32)
        for x, y in zip(image.numpy(), out):
            if len(x) == 3:  # RGB planes to a BGR image and back by OpenCV (NumPy's transposes are slower)
                bgr = normalized_bgr(cv2.merge(x[::-1]), normalize, (lo, hi), np.dtype(np.float32))
                cv2.split(bgr, mv=[y[2], y[1], y[0]])
            else:  # to_unit's operations
                unit = normalize(np.ascontiguousarray(x[0]))
                np.subtract(unit, np.float32(lo), out=unit)
                np.multiply(unit, np.float32(1.0 / (hi - lo)), out=unit)
                np.clip(unit, 0, 1, out=y[0])
        return torch.from_numpy(out)

    def _opencv_runtime(self) -> GainRuntime:
        """``apply()``'s runtime of the module's spec with its network as it is now (``tau`` and the floor of a
        ``learn_scales`` model after a step, or of a loaded ``state_dict``), on one torch thread (its small part;
        torch's threads, left spinning after a parallel operation, would slow the OpenCV calls around it), and on as
        many parts of the rows as torch has threads, at most OpenCV's (one in a ``DataLoader`` worker, as the torch
        filters)."""
        assert self.spec.divisive is not None  # a gain model's
        parts = 1 if _FORKED else min(torch.get_num_threads(), cv2.getNumThreads())
        # the runtime holds no state of a call: kept while what it is built from stays (0.3 ms a build, 2% of a call)
        key = (self.net, self.spec, self.grid_stride, self.net.tau_value(), float(self.net.floor_scale.detach()), parts)
        if self._runtime is None or self._runtime[0] != key:
            spec = dataclasses.replace(self.spec, tau=key[3], divisive=(self.spec.divisive[0], key[4]))
            self._runtime = key, GainRuntime(spec, TorchNetwork(self.net, self.grid_stride, 1), "exact", parts)
        return self._runtime[1]

    def to_unit(self, response: torch.Tensor) -> torch.Tensor:
        """The fixed map of raw responses to [0, 1]: ``output_range`` -> [0, 1], clipped."""
        lo, hi = self.spec.output_range
        unit = (response - lo) * (1.0 / (hi - lo))
        return unit.clamp(0, 1) if torch.is_grad_enabled() and unit.requires_grad else unit.clamp_(0, 1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """Normalize a batch of images, differentiably (to the image and, unless frozen, to the network).

        Args:
            image: ``(B, 1, H, W)`` gray or ``(B, 3, H, W)`` RGB float intensities in [0, 1], of the module's device
                and dtype (another float dtype under autocast); ``B`` may be 0, ``H`` and ``W`` may not.

        Returns:
            ``(B, 1 | 3, H, W)``, the image's dtype (float32 possibly, under autocast) and device, in [0, 1]:
            gray normalized, RGB normalized on the L channel of CIE Lab with a and b kept.

        Raises:
            InputError: not a tensor, not ``(B, 1 | 3, H, W)``, not float, on another device or of another dtype
                than the module, colour on the ``meta`` device; on the CPU run eagerly, values outside [0, 1], NaN or
                inf (not checked elsewhere: see the class).

        Example:
            >>> import torch
            >>> alcn = ALCN2d(model="lite").eval()
            >>> with torch.no_grad():
            ...     out = alcn(torch.rand(2, 3, 48, 64))
            >>> out.shape, bool(out.min() >= 0) and bool(out.max() <= 1)
            (torch.Size([2, 3, 48, 64]), True)
        """
        self._check_input(image)
        return self._normalize(image)

    @_in_float32
    def _normalize(self, image: torch.Tensor) -> torch.Tensor:
        """:meth:`forward` of an image already checked (:meth:`_check_input`)."""
        # The filters take in-place paths where no gradient is recorded, and torch.jit.trace's check traces again
        # under no_grad: while tracing, requires_grad alone decides, so that both traces record the same graph.
        with torch.enable_grad() if torch.jit.is_tracing() else nullcontext():
            if self._runs_opencv(image):
                return self._opencv_forward(image)
            if image.shape[1] == 1:
                return self.to_unit(self.response(image))
            lab = _OpenCVLab.apply(image, self.to_lab) if cpu_eager(image) else self.to_lab(image)
            lightness = self.to_unit(self.response(lab[:, :1] * 0.01)) * 100.0
            # contiguous, as the input is: the Lab conversion back leaves its channels strided
            return self.from_lab(torch.cat([lightness, lab[:, 1:]], dim=1)).contiguous()

    def _check_input(self, image: torch.Tensor) -> None:
        """:func:`_check_image`, and an :class:`InputError` for an image on another device or dtype than the module
        (another dtype is let through under autocast)."""
        _check_image(image)
        weight = next(self.net.parameters())
        if image.device != weight.device or (image.dtype != weight.dtype and not autocast_enabled(image)):
            raise InputError(
                f"image is {image.dtype} on {image.device}, the module {weight.dtype} on {weight.device}: "
                "move the module with .to(image.device, image.dtype)"
            )

    def _tf32(self, x: torch.Tensor) -> AbstractContextManager:
        """cuDNN without TF32 for a CUDA tensor unless :attr:`allow_tf32` (TF32 moves the output by about 1e-3); under
        ``torch.compile``, which cannot trace the switch, the caller's setting (``torch.backends.cudnn.flags``)."""
        if self.allow_tf32 or not x.is_cuda or torch.compiler.is_compiling():
            return nullcontext()
        return torch.backends.cudnn.flags(
            enabled=torch.backends.cudnn.enabled,
            benchmark=torch.backends.cudnn.benchmark,
            deterministic=torch.backends.cudnn.deterministic,
            allow_tf32=False,
        )

    def extra_repr(self) -> str:
        source = weights_setting(self._built_from[1])
        return f"{source}, scale={self.spec.scale}, grid_stride={self.grid_stride}, allow_tf32={self.allow_tf32}"

    def __prepare_scriptable__(self) -> NoReturn:
        """``torch.jit.script`` asks this first: the module is not scriptable (its error would be TorchScript's
        "Unknown type annotation")."""
        raise InputError("ALCN2d cannot be scripted: use torch.jit.trace (one image size) or torch.compile")


def _check_image(image: torch.Tensor) -> None:
    """An :class:`InputError` naming what is wrong with an image for :class:`ALCN2d`, and how to fix it: not a
    tensor, not ``(B, 1 | 3, H, W)`` (``B`` may be 0), not float, colour on a device without autocast (meta); its
    range where reading it costs no device sync (:func:`_check_range`)."""
    if not isinstance(image, torch.Tensor):
        raise InputError(f"image must be a torch.Tensor, got {type(image).__name__} (a NumPy array: torch.from_numpy)")
    if image.ndim != 4 or image.shape[1] not in (1, 3) or 0 in image.shape[2:]:
        hint = ""
        if image.ndim == 4 and image.shape[1] == 4:
            hint = " (RGBA: image[:, :3])"
        elif image.ndim == 4 and image.shape[1] == 2:
            hint = " (gray and alpha: image[:, :1])"
        elif image.ndim == 5:
            hint = " (frames of several clips: image.flatten(0, 1))"
        elif image.ndim == 4 and image.shape[-1] in (1, 3):
            hint = " (channels last: image.permute(0, 3, 1, 2))"
        elif image.ndim == 3 and image.shape[0] in (1, 3):
            hint = " (one image: image[None])"
        elif image.ndim == 3 and image.shape[-1] in (1, 3):
            hint = " (one image, channels last: image.permute(2, 0, 1)[None])"
        elif image.ndim == 3:
            hint = " (a batch of gray images: image[:, None])"
        elif image.ndim == 2:
            hint = " (one gray image: image[None, None])"
        raise InputError(f"image must have shape (B, 1 | 3, H, W), H and W not 0, got {tuple(image.shape)}{hint}")
    if not image.is_floating_point():
        # a multiplication, as apply() converts integers: a division differs by a rounding, which the divisive step
        # amplifies (6e-5 on a photograph)
        scale = {torch.uint8: " (a uint8 image: image * (1 / 255))", torch.uint16: " (image * (1 / 65535))"}
        raise InputError(f"image must be float in [0, 1], got {image.dtype}{scale.get(image.dtype, '')}")
    if image.shape[1] == 3 and not torch.amp.is_autocast_available(image.device.type):
        # the Lab conversions switch a caller's autocast off, which torch refuses on such a device
        raise InputError(
            f"colour is not supported on the {image.device.type} device (the Lab conversions switch autocast off, "
            "which torch has not there); a gray (B, 1, H, W) image is"
        )
    _check_range(image)


def _check_range(image: torch.Tensor) -> None:
    """An :class:`InputError` for values outside [0, 1] (``apply()``'s 1e-3 of rounding allowed), NaN or inf, with
    the likely fix, for an image on the CPU run eagerly: elsewhere reading the values would wait for the device
    (CUDA), see nothing (meta, a trace, a compilation, an export) or fail (``torch.func.vmap``)."""
    if (
        image.device.type != "cpu"
        or image.numel() == 0
        or torch.jit.is_tracing()
        or ("torch.onnx" in sys.modules and torch.onnx.is_in_onnx_export())  # no export without it (its import: 70 ms)
        or torch.compiler.is_compiling()  # before transformed(), which Dynamo cannot trace
    ):
        return
    if transformed(image):
        return
    # NaN propagates to both; on one thread: torch's threads, left spinning after a parallel reduction, would slow
    # the OpenCV calls of the CPU runtime that follow (ALCN2d._opencv_runtime)
    with torch_threads(1):
        lo, hi = (float(v) for v in image.detach().aminmax())
    if lo >= -FLOAT_TOLERANCE and hi <= 1 + FLOAT_TOLERANCE:
        return
    if not (math.isfinite(lo) and math.isfinite(hi)):
        hint = " (one such pixel would make its whole image NaN)"
    elif lo < -0.5:  # transforms.Normalize's ImageNet statistics put black at -2.1
        hint = " (standardized? undo transforms.Normalize, image * std + mean; standardize after ALCN2d)"
    elif hi > 2:
        scale = "255" if hi <= 255 else "65535"  # 0..255 from uint8.float(), 0..65535 from uint16
        hint = f" (0..{scale} intensities: image * (1 / {scale}))"
    else:  # a bicubic resize overshoots the range a little
        hint = " (an overshoot, of a bicubic resize say: image.clamp(0, 1))"
    raise InputError(f"image must be float in [0, 1], got values in [{lo:.4g}, {hi:.4g}]{hint}")


class _OpenCVLab(torch.autograd.Function):
    """:class:`~alcn_cv.filters.torch_lab.RgbToLab` of ``(B, 3, H, W)`` float32 CPU RGB by OpenCV's passes, the very
    ones of :meth:`ALCN.apply <alcn_cv.enhance.alcn.ALCN.apply>` (:func:`~alcn_cv.filters.lab.srgb_to_lab`), with
    the torch conversion's gradient: L rounded otherwise in float32, which the divisive step amplifies several hundred
    times in flat regions, puts the output 1e-4 from ``apply()``'s (2.7e-6 with these passes)."""

    @staticmethod
    def forward(image: torch.Tensor, to_lab: RgbToLab) -> torch.Tensor:
        lab = torch.empty_like(image)
        for rgb, out in zip(image.detach(), lab):
            bgr = np.clip(np.ascontiguousarray(rgb.flip(0).permute(1, 2, 0).numpy()), 0.0, 1.0)
            out.copy_(torch.from_numpy(srgb_to_lab(bgr)).permute(2, 0, 1))
        return lab

    @staticmethod
    def setup_context(ctx: torch.autograd.function.FunctionCtx, inputs: tuple, output: torch.Tensor) -> None:
        image, ctx.to_lab = inputs
        ctx.save_for_backward(image)

    @staticmethod
    def backward(ctx: torch.autograd.function.FunctionCtx, grad: torch.Tensor) -> tuple[torch.Tensor, None]:
        (image,) = ctx.saved_tensors
        vjp = torch.func.vjp(ctx.to_lab, image)[1]
        return vjp(grad)[0], None

    @staticmethod
    def vmap(info: object, in_dims: tuple, image: torch.Tensor, to_lab: RgbToLab) -> tuple[torch.Tensor, int]:
        # torch.func.vmap: the mapped dimension joins the batch
        frames = image.movedim(in_dims[0], 0)
        return _OpenCVLab.apply(frames.flatten(0, 1), to_lab).unflatten(0, frames.shape[:2]), 0


def alcn2d(
    image: torch.Tensor, model: str | None = None, weights: str | Path | None = None, scale: float | None = None
) -> torch.Tensor:
    """Functional :class:`ALCN2d`: the module built once per weight file (as it is on disk: a file saved again is
    read again), device and dtype, then reused, and frozen (``eval()``, ``requires_grad_(False)``): gradients reach
    the image only (fine-tune an :class:`ALCN2d` instead).

    Args:
        image: ``(B, 1 | 3, H, W)`` float in [0, 1] (3 channels: RGB), any device and float dtype.
        model: a shipped model: ``"gain"`` (the default), ``"gain-lite"``, ``"lite"`` or ``"paper"``.
        weights: a weight file instead of ``model``.
        scale: the working scale (default: the weight file's), as :class:`ALCN2d`'s.

    Returns:
        The same shape, dtype and device, in [0, 1].

    Raises:
        InputError: an image :meth:`ALCN2d.forward` refuses (its range checked on the CPU only, as there), an
            unknown ``model``, or both ``model`` and ``weights``.

    Example:
        >>> import torch
        >>> alcn2d(torch.rand(1, 1, 48, 48), model="lite").shape
        torch.Size([1, 1, 48, 48])
    """
    _check_image(image)  # before a module is built for the image's dtype, which must be a float one
    key = (model, None if weights is None else str(weights), scale, image.device, image.dtype)
    built = _MODULES.get(key)
    # the file as it is now (one saved again after more fine-tuning, or another under the same relative name), read
    # outside a compiled graph only: a file system call is no graph's to trace, and a compiled call keeps its module
    version = None if torch.compiler.is_compiling() else _file_version(resolve_weights(model, weights))
    if built is None or (version is not None and built[0] != version):
        # frozen: a backward through it must not accumulate gradients in a module the caller never sees; and of normal
        # tensors, whatever mode the first call runs in (inference tensors cannot be saved for a later backward)
        with torch.inference_mode(False):
            module = ALCN2d(model, weights, scale).to(image.device, image.dtype).eval().requires_grad_(False)
        built = _MODULES[key] = version, module
    return built[1]._normalize(image)  # checked above, and the module is of the image's device and dtype


def _file_version(path: Path) -> tuple[int, int, int, int] | None:
    """What tells a weight file from the one read before under its name (one saved again, or another file of that
    relative name): its device, inode, time and size, in one system call (None: no such file, which ALCN2d names)."""
    try:
        stat = os.stat(path)
    except OSError:
        return None
    return stat.st_dev, stat.st_ino, stat.st_mtime_ns, stat.st_size


#: The modules of :func:`alcn2d` by model or weight file as given, scale, device and dtype, each with the version of
#: the file it was built from (:func:`_file_version`).
_MODULES: dict[tuple, tuple[tuple[int, int, int, int] | None, ALCN2d]] = {}


class _ThreadScopes:
    """The open :func:`torch_threads` blocks of the process, counted: the count of before the first block (of any
    thread) is restored when the last one ends. Never waits but for the lock, held only around torch's get and set."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.open = 0  # the blocks open in the process, all threads'
        self.original = 0  # the count of before the first of them
        self.mine = threading.local()  # .open: this thread's open blocks (what a forked child keeps)

    @contextmanager
    def scope(self, threads: int) -> Iterator[None]:
        with self.lock:
            before = torch.get_num_threads()
            _set_threads(threads)  # registered only once set: a count torch refuses leaves nothing behind
            if self.open == 0:
                self.original = before
            self.open += 1
            self.mine.open = getattr(self.mine, "open", 0) + 1
        try:
            yield
        finally:
            with self.lock:
                self.open -= 1
                self.mine.open -= 1
                if self.open == 0:
                    torch.set_num_threads(self.original)  # also the count a new thread starts with (OpenMP)
                else:
                    _set_threads(before)


def _set_threads(threads: int) -> None:
    if torch.get_num_threads() != threads:
        torch.set_num_threads(threads)


def _thread_count(threads: object) -> int:
    """``threads`` as a count torch takes, checked before anything is set or counted."""
    if isinstance(threads, bool) or not isinstance(threads, numbers.Integral) or threads < 1:
        raise InputError(f"threads must be a whole number >= 1 or None, got {threads!r}")
    return int(threads)


_SCOPES = _ThreadScopes()
#: Whether this process is a fork of one that may have run torch's threads (:func:`_forked_child`).
_FORKED = False


def _forked_child() -> None:
    # torch's intra-op threads (OpenMP) do not survive a fork: the first parallel operation of a child forked after
    # the parent used them hangs (a multiprocessing pool's worker, say). ALCN's calls in the child run on one thread
    # instead (torch_threads), their outputs those of one thread (to float rounding: one grey level of a uint8
    # output at most); the rest of the child's torch is left as it is.
    global _FORKED
    _FORKED = True
    # only the forking thread came along: the others' blocks stay behind, and so does the lock should one hold it
    _SCOPES.lock = threading.Lock()
    _SCOPES.open = getattr(_SCOPES.mine, "open", 0)


if hasattr(os, "register_at_fork"):  # not on Windows, which has no fork
    os.register_at_fork(after_in_child=_forked_child)


@contextmanager
def torch_threads(threads: int | None) -> Iterator[None]:
    """Run the block with ``threads`` torch intra-op threads (a whole number >= 1, else an :class:`InputError`), the
    count of before restored after it; no change for None; one in a forked child, where torch's threads hang.

    Never waits for another thread's block. With OpenMP (the parallel backend of torch's Linux wheels) the count is
    each thread's own, so blocks of different counts in different Python threads run together, each with its count;
    a block of None runs with whatever count its thread has. A thread's nested blocks restore the inner block's, then
    the outer's, count of before. A new thread starts with the count last set in the process, so the last block to end
    (of any thread) restores the count of before the first block (of any thread): after overlapping blocks a new thread
    starts as it did before them. Where the count is the whole process's (torch's native thread pool; MKL's count,
    which torch sets along), overlapping blocks of different counts set it in turn: each runs at whichever count is
    in effect, and none waits.
    """
    count = None if threads is None else _thread_count(threads)  # checked before anything is set or counted
    if _FORKED:
        count = 1
    if count is None:
        yield
        return
    with _SCOPES.scope(count):
        yield


class TorchNetwork:
    """A torch Normalizer as the OpenCV runtimes use it (:class:`~alcn_cv.runtime.Network`):
    NumPy in and out on a grid of ``grid_stride``, ``threads`` torch threads while it runs.

    On the CPU the gain Normalizer's fixed features (its cell moments, the only full-resolution part, and their
    blurs and logs) are the OpenCV runtime's (:class:`~alcn_cv.nets.opencv_runtime.GainFeatures`, the same numbers
    as :meth:`GainNormalizer.features <alcn_cv.nets.gain.GainNormalizer.features>` to float rounding).
    """

    def __init__(self, net: nn.Module, grid_stride: int, threads: int | None) -> None:
        self.net, self.stride, self.threads = net, grid_stride, threads
        self.device = next(net.parameters()).device
        gain_on_cpu = isinstance(net, GainNormalizer) and grid_stride == net.stride and self.device.type == "cpu"
        self.features = GainFeatures(net.config) if gain_on_cpu else None

    def dense_grid(self, image: np.ndarray, alongside: Callable[[], object] | None = None) -> np.ndarray:
        with torch.inference_mode(), torch_threads(self.threads):
            if self.features is not None:
                features = torch.from_numpy(self.features(image))
                if alongside is not None:
                    alongside()
                # C order for the OpenCV runtime's passes over each map (the layers ran channels-last)
                return self.net.maps_from_features(features)[0].contiguous().numpy()
            if alongside is not None:
                alongside()
            x = read_only_tensor(image).to(self.device)[None, None]
            return self.net.dense_grid(x, self.stride)[0].cpu().numpy()

    def dense(self, image: np.ndarray) -> np.ndarray:
        with torch.inference_mode(), torch_threads(self.threads):
            return self.net.dense(read_only_tensor(image).to(self.device)[None, None], self.stride)[0].cpu().numpy()

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        x = torch.from_numpy(windows)[:, None]
        c = (WINDOW // 2) // self.net.stride  # the grid point at the window's centre sees exactly the window
        with torch.inference_mode(), torch_threads(self.threads):
            return torch.cat(
                [
                    self.net.dense_grid(x[i : i + _WINDOW_BATCH].to(self.device))[:, :, c, c].cpu()
                    for i in range(0, len(x), _WINDOW_BATCH)
                ]
            ).numpy()


class TorchRuntime:
    """The :class:`~alcn_cv.runtime.Runtime` of ``backend="torch"``: :class:`ALCN2d` on its device,
    NumPy in and out."""

    def __init__(self, module: ALCN2d, threads: int | None) -> None:
        self.module, self.threads, self.spec, self.grid_stride = module.eval(), threads, module.spec, module.grid_stride
        self.network = TorchNetwork(module.net, module.grid_stride, threads)
        self.device = self.network.device

    def _run(self, method: Callable[..., torch.Tensor], gray: np.ndarray, **kwargs: object) -> np.ndarray:
        # The working image resized by OpenCV, as :meth:`ALCN.apply` does for every size.
        with torch.inference_mode(), torch_threads(self.threads):
            small = None if self.spec.scale == 1 else _batch_of_one(self.spec.working_image(gray), self.device)
            return method(_batch_of_one(gray, self.device), small=small, **kwargs)[0].cpu().numpy()

    def weight_grid(self, gray: np.ndarray) -> np.ndarray:
        return self.network.dense_grid(self.spec.working_image(gray))

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        return self._run(self.module.weight_maps, gray)

    def window_weights(self, windows: np.ndarray) -> np.ndarray:
        return self.network.window_weights(windows)

    def mixture(self, gray: np.ndarray) -> np.ndarray:
        return self._run(self.module.eq3, gray)[0]

    def normalize(self, gray: np.ndarray, floor: float | None = None, band_floor: float | None = None) -> np.ndarray:
        floor_tensor, band_floor_tensor = (
            None if f is None else torch.full((1, 1, 1, 1), f, device=self.device) for f in (floor, band_floor)
        )
        return self._run(self.module.response, gray, floor=floor_tensor, band_floor=band_floor_tensor)[0]

    def apply_batch(self, frames: np.ndarray, out_dtype: np.dtype, half: bool = False) -> np.ndarray:
        """``(B, H, W)`` uint8, uint16 or float32 frames, C-contiguous in native byte order (as
        :meth:`ALCN.apply_batch <alcn_cv.enhance.alcn.ALCN.apply_batch>` passes them, checked by
        :func:`~alcn_cv.runtime.check_batch`) -> ``(B, H, W)`` of ``out_dtype``: uploaded as they are, converted on the
        device, the output cast there. On CUDA by chunks of :data:`CUDA_CHUNK` frames in a pipeline: a chunk is staged
        in pinned memory and uploaded on a stream of its own while the one before is computed, and downloaded on a
        third while the next is (each image is normalized on its own, so the chunks give the whole batch's values)."""
        cuda = self.device.type == "cuda"
        with torch.inference_mode(), torch_threads(self.threads):
            if cuda:
                compute = torch.cuda.current_stream(self.device)
                upload, download = _pipeline_streams(self.device)
            # the CPU takes the same chunks, without streams (nothing to overlap there)
            on = (lambda stream: torch.cuda.stream(stream)) if cuda else (lambda stream: nullcontext())
            out = torch.empty(frames.shape, dtype=_TORCH_DTYPES[np.dtype(out_dtype)], pin_memory=cuda)
            for start in range(0, len(frames), CUDA_CHUNK):
                chunk = slice(start, start + CUDA_CHUNK)
                host = torch.from_numpy(frames[chunk])
                with on(upload if cuda else None):
                    # staged in pinned memory on the CPU while the device computes the chunk before
                    x = host.pin_memory().to(self.device, non_blocking=True) if cuda else host
                if cuda:
                    compute.wait_stream(upload)
                    x.record_stream(compute)  # made on the upload stream, read on this one
                unit = self._frames_out(x, frames.dtype, out_dtype, half)
                if cuda:
                    download.wait_stream(compute)
                    unit.record_stream(download)
                with on(download if cuda else None):
                    out[chunk].copy_(unit, non_blocking=cuda)
            if cuda:
                download.synchronize()
            return out.numpy()

    def _frames_out(self, frames: torch.Tensor, dtype: np.dtype, out_dtype: np.dtype, half: bool) -> torch.Tensor:
        """``(B, H, W)`` frames of ``dtype`` on the device -> the normalized ``(B, H, W)`` of ``out_dtype`` there."""
        x = frames[:, None]
        x = x.clamp(0, 1) if dtype == np.float32 else x.float() * (1.0 / FULL_SCALE[dtype])
        # the network in float16 when half, Eq. 3 in float32
        unit = self.module.to_unit(self.module.response(x, half=half))[:, 0]
        if out_dtype != np.float32:
            unit = torch.round(unit * FULL_SCALE[out_dtype]).to(_TORCH_DTYPES[out_dtype])
        return unit


@functools.cache
def _pipeline_streams(device: torch.device) -> tuple[torch.cuda.Stream, torch.cuda.Stream]:
    """The upload and download streams of :meth:`TorchRuntime.apply_batch` on a CUDA ``device``: the same ones at
    every call, since the caching allocator reuses a freed block only on the stream that allocated it (new streams
    would allocate each chunk anew)."""
    return torch.cuda.Stream(device), torch.cuda.Stream(device)


#: The frames of a chunk of :meth:`TorchRuntime.apply_batch`'s pipeline on CUDA: 16 frames of 1280x800 are 16 MB of
#: uint8 to upload, small enough that the first upload and the last download leave the device idle briefly.
CUDA_CHUNK = 16


def read_only_tensor(array: np.ndarray) -> torch.Tensor:
    """``torch.from_numpy(array)`` for an array the tensor only reads (a method's image, which
    :meth:`~alcn_cv.enhance.base.Normalization.normalize` hands over read-only), without torch's warning that it does
    not support read-only tensors."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "The given NumPy array is not writable", UserWarning)
        return torch.from_numpy(array)


def _batch_of_one(plane: np.ndarray, device: torch.device) -> torch.Tensor:
    return read_only_tensor(plane).to(device)[None, None]


def batches(frames: Iterable[np.ndarray], size: int) -> Iterator[np.ndarray]:
    """Group an iterable of ``(H, W)`` frames of one size into ``(B, H, W)`` arrays of ``size`` (the last one
    shorter), for :meth:`ALCN.apply_batch <alcn_cv.enhance.alcn.ALCN.apply_batch>`: ``for out in
    map(alcn.apply_batch, batches(frames, 64))``."""
    if isinstance(size, bool) or not isinstance(size, numbers.Integral) or size < 1:
        raise InputError(f"size must be a positive integer, got {size!r}")
    batch: list[np.ndarray] = []
    first: tuple[int, ...] | None = None
    for index, frame in enumerate(frames):
        first = frame.shape if first is None else first
        if frame.shape != first:
            raise InputError(f"frame {index} is of shape {frame.shape}, the first {first}: a batch is of one size")
        batch.append(frame)
        if len(batch) == size:
            yield np.stack(batch)
            batch = []
    if batch:
        yield np.stack(batch)
