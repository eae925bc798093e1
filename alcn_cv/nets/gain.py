r"""The gain-adaptive Normalizer for ALCN's Eq. 3, run on a coarse grid.

ALCN normalizes an image with per-pixel weights F_k predicted by a network (Rad, Roth & Lepetit, BMVC 2017,
Eq. 3)::

    ALCN(I) = sum_k G_{sigma_k} * (F_k o I)

:class:`GainNormalizer` predicts a per-pixel log-gain ``g`` and kernel weights ``w_k`` summing to zero (a
band-pass, as the DoG it starts from) and forms ``F_k = exp(g) * w_k``. The network sees log intensities (of
each cell's mean, of a local mean, of a wider context mean and of the cell's standard deviation), all computed
on a grid of stride :attr:`~GainNormalizer.stride` (8 pixels), so it costs a small fraction of the
full-resolution mixture; the maps are interpolated bilinearly in between. Eq. 3's response is then divided by
its local energy (:mod:`alcn_cv.filters.torch_divisive`, Jarrett et al. 2009) and equalized by
``tanh(x / tau)`` (:func:`contrast_equalization`, Tan & Triggs, TIP 2010), in (-1, 1); the output adds ``band``
times the :mod:`~alcn_cv.filters.wide_band` (0.15 in the shipped files), so that ORB can orient its keypoints.

The constructor's defaults are the shipped files' (``alcn_normalizer_gain.npz``; ``channels=8`` for
``alcn_normalizer_gain_lite.npz``).

Shapes (``B`` images, ``N`` kernels, ``g`` the grid stride): input ``(B, 1, H, W)`` float intensities in
[0, 1]; :meth:`~GainNormalizer.dense_grid` ``(B, N, ceil((H-1)/g)+1, ceil((W-1)/g)+1)``, grid point
``(i, j)`` at pixel ``(g*i, g*j)``; :meth:`~GainNormalizer.dense` ``(B, N, H, W)``;
:meth:`~GainNormalizer.response` ``(B, 1, H, W)``; :meth:`~GainNormalizer.forward` ``(B, 1, H, W)`` in
``(-1 - band, 1 + band)``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from contextlib import nullcontext
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.errors import InputError
from alcn_cv.filters.equalization import tanh
from alcn_cv.filters.gaussian_mixture import gaussian_sigmas
from alcn_cv.filters.kornia_mixture import GaussianMixture2d
from alcn_cv.filters.torch_divisive import (
    divisive_normalization,
    gaussian_blur,
)
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.filters.torch_precision import ExactBuffers, at_least_float32, autocast_enabled
from alcn_cv.filters.torch_resize import interpolate_grid
from alcn_cv.filters.torch_wide_band import wide_band
from alcn_cv.filters.wide_band import band_meta
from alcn_cv.nets.cpu_inference import cpu_inference, tanh_
from alcn_cv.nets.normalizer import Normalizer, check_grid_stride
from alcn_cv.nets.opencv_runtime import grid_shape
from alcn_cv.weight_file import NormalizerFile

__all__ = ["ARCHITECTURE", "GainNormalizer", "contrast_equalization", "dog_weights"]

#: The ``architecture`` field of a gain Normalizer's weight file.
ARCHITECTURE = "gain"
#: The untrained model's band-pass: ``G_1 - G_2`` (pixels at the working scale).
DOG_SIGMAS = (1.0, 2.0)
_INPUT_FEATURES = 4


def dog_weights(sigmas: Sequence[float], sigma1: float = DOG_SIGMAS[0], sigma2: float = DOG_SIGMAS[1]) -> list[float]:
    """The mixture weights of ``G_sigma1 - G_sigma2`` over the basis ``sigmas`` (both must be in it, to float
    rounding: ``3 * 0.1`` is the basis's 0.3)."""
    sigmas = [float(s) for s in sigmas]
    positions = [[i for i, b in enumerate(sigmas) if math.isclose(b, s, rel_tol=1e-9)] for s in (sigma1, sigma2)]
    if not all(positions):
        raise InputError(f"the DoG sigmas {sigma1} and {sigma2} must be in the basis {sigmas}")
    weights = [0.0] * len(sigmas)
    weights[positions[0][0]] += 1.0
    weights[positions[1][0]] -= 1.0
    return weights


def contrast_equalization(response: np.ndarray | torch.Tensor, tau: float | torch.Tensor) -> np.ndarray | torch.Tensor:
    """``tanh(response / tau)``: compresses responses larger than ``tau`` (Tan & Triggs, TIP 2010).

    Args:
        response: the mixture's response, any shape, numpy float32 or a torch tensor.
        tau: the scale above which responses saturate (> 0).

    Returns:
        The same type and shape, in (-1, 1).
    """
    if isinstance(response, torch.Tensor):
        scaled = response / tau
        return tanh_(scaled) if cpu_inference(scaled) else torch.tanh(scaled)
    scaled = np.asarray(response / np.float32(tau), np.float32, order="C")  # the quotient's own array, C order
    return tanh(scaled, out=scaled)


class GainNormalizer(ExactBuffers):
    """Predicts F_k = exp(g) * w_k on a coarse grid (see the module's docstring).

    Args:
        num_kernels: N, the Gaussian kernels of the mixture (sigmas 1 and 2 by default, the DoG's own).
        sigma_step: the mixture's sigmas are ``k * sigma_step``, ``k = 1..N`` (working pixels).
        stride: the grid's spacing in working pixels (the network's own resolution).
        channels: width of the hidden convolutions.
        dilations: one 3x3 convolution per entry, with that dilation (on the grid).
        mean_sigma: sigma of the local mean fed to the network (working pixels).
        context_sigma: sigma of the wider mean fed to the network (working pixels).
        eps: added to intensities before every log (intensity units).
        tau: scale of the final :func:`contrast_equalization`.
        init_weights: the N weights of the untrained model; default :func:`dog_weights`.
        floor_scale: ``c`` of the divisive floor ``c * mean(e)``.
        learn_scales: learn ``tau`` and ``c`` (otherwise they keep their initial values).
        divisive_sigma: the divisive normalization's energy ``e = sqrt(G_sigma * r^2)`` (working pixels).
        band: the weight of the :mod:`~alcn_cv.filters.wide_band` added to the output (0: none), so that ORB
            orients its keypoints; it has no parameters, and training (on crops too small for it) leaves it out.

    A fixed ``tau`` and ``c`` (buffers) stay float32 through a cast of the module: bfloat16 would round the file's
    ``tau`` of 3 to 3.016.
    """

    exact_buffers = ("log_tau", "log_floor_scale")

    def __init__(
        self,
        num_kernels: int = 2,
        sigma_step: float = 1.0,
        stride: int = 8,
        channels: int = 16,
        dilations: Sequence[int] = (1, 2, 4),
        mean_sigma: float = 8.0,
        context_sigma: float = 32.0,
        eps: float = 0.01,
        tau: float = 3.0,
        init_weights: Sequence[float] | None = None,
        floor_scale: float = 1.0,
        learn_scales: bool = False,
        divisive_sigma: float = 2.0,
        band: float = 0.15,
    ) -> None:
        super().__init__()
        if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
            raise InputError(f"stride must be a positive integer, got {stride!r}")
        if not (
            eps > 0 and tau > 0 and mean_sigma > 0 and context_sigma > 0 and floor_scale > 0 and divisive_sigma > 0
        ):
            raise InputError("eps, tau, mean_sigma, context_sigma, floor_scale and divisive_sigma must be positive")
        if not 0 <= band < 1:
            raise InputError(f"band must be in [0, 1), got {band}")
        self.sigmas = gaussian_sigmas(num_kernels, sigma_step)
        init_weights = dog_weights(self.sigmas) if init_weights is None else [float(w) for w in init_weights]
        if len(init_weights) != num_kernels:
            raise InputError(f"init_weights has {len(init_weights)} values for {num_kernels} kernels")
        self.stride = stride
        self.eps = float(eps)
        self.mean_sigma = float(mean_sigma)
        self.context_sigma = float(context_sigma)
        self.dilations = tuple(int(d) for d in dilations)
        layers: list[nn.Module] = []
        width = _INPUT_FEATURES
        for dilation in self.dilations:
            layers.append(nn.Conv2d(width, channels, 3, dilation=dilation))
            width = channels
        self.convs = nn.ModuleList(layers)
        # Output 0 is the log-gain, outputs 1..N the kernel weights w_k.
        self.head = nn.Conv2d(width, 1 + num_kernels, 1)
        with torch.no_grad():
            self.head.weight.zero_()
            self.head.bias.copy_(torch.tensor([0.0] + init_weights))
        for name, value in (("log_tau", tau), ("log_floor_scale", floor_scale)):
            initial = torch.tensor(math.log(value))
            # fixed values are buffers, so that a caller's requires_grad_(True) leaves them fixed
            if learn_scales:
                self.register_parameter(name, nn.Parameter(initial))
            else:
                self.register_buffer(name, initial)
        #: The divisive normalization's energy sigma (working pixels).
        self.divisive_sigma = float(divisive_sigma)
        self.mixture = GaussianMixture2d(self.sigmas)
        #: The weight of the wide band added to the output.
        self.band = float(band)
        self.config: dict[str, Any] = {
            "num_kernels": num_kernels,
            "sigma_step": float(sigma_step),
            "stride": stride,
            "channels": channels,
            "dilations": list(self.dilations),
            "mean_sigma": self.mean_sigma,
            "context_sigma": self.context_sigma,
            "eps": self.eps,
            "tau": float(tau),
            "init_weights": init_weights,
            "floor_scale": float(floor_scale),
            "learn_scales": bool(learn_scales),
            "divisive_sigma": self.divisive_sigma,
            "band": self.band,
        }

    @property
    def num_kernels(self) -> int:
        return len(self.sigmas)

    @property
    def tau(self) -> torch.Tensor:
        """The equalization's scale ``tau`` (a 0-d tensor)."""
        return self.log_tau.exp()

    def tau_value(self) -> float:
        """``tau`` as a float (for headers and logs)."""
        return float(self.log_tau.detach().exp())

    @property
    def floor_scale(self) -> torch.Tensor:
        """``c`` of the divisive floor (a 0-d tensor)."""
        return self.log_floor_scale.exp()

    def cell_moments(self, image: torch.Tensor) -> torch.Tensor:
        """The only full-resolution part of the network: ``(B, 2, gh, gw)``, the mean of each cell of side
        :attr:`stride` centred on a grid point, of the image ``(B, 1, H, W)`` and of its square."""
        if image.ndim != 4 or image.shape[1] != 1:
            raise InputError(f"image must have shape (B, 1, H, W), got {tuple(image.shape)}")
        s = self.stride
        before = s // 2
        # H + 2s - 2 pixels hold exactly ceil((H-1)/s)+1 cells (the pooling drops the rest), so
        # the pads do not depend on the size and the ONNX export keeps the size dynamic.
        after = 2 * s - 2 - before
        padded = reflect101_pad(image, before, after, before, after)  # the square of the pad is the pad of the square
        return torch.cat([F.avg_pool2d(padded, s), F.avg_pool2d(padded * padded, s)], dim=1)

    def features(self, image: torch.Tensor) -> torch.Tensor:
        """The network's input ``(B, 4, gh, gw)`` on the grid of :attr:`stride`: :meth:`features_from_moments`
        of :meth:`cell_moments`, both in float32 at least (see :meth:`features_from_moments`)."""
        return self.features_from_moments(self.cell_moments(at_least_float32(image)))

    def features_from_moments(self, moments: torch.Tensor) -> torch.Tensor:
        """``(B, 4, gh, gw)``: the log of each cell's mean, of the local mean, of the context mean and of the
        cell's standard deviation, from :meth:`cell_moments` ``(B, 2, gh, gw)``; in float32 at least: the variance
        is the difference of two nearly equal moments, which float16 rounds to a log-deviation 1.3 off."""
        mean, square = at_least_float32(moments).split(1, dim=1)
        # The blurs of the grid stand for blurs of the image: sigma in cells = sigma / stride.
        local = gaussian_blur(mean, self.mean_sigma / self.stride)
        context = gaussian_blur(mean, self.context_sigma / self.stride)
        variance = (square - mean * mean).clamp_min(0.0)
        # sqrt's gradient at 0 is infinite: a flat cell (black borders, padding) would give the input NaN gradients
        positive = variance > 0
        std = torch.where(positive, torch.where(positive, variance, 1.0).sqrt(), 0.0)
        return (torch.cat([mean, local, context, std], dim=1) + self.eps).log()

    def maps_from_features(self, features: torch.Tensor) -> torch.Tensor:
        """F_k = exp(g) * w_k ``(B, N, gh, gw)`` from :meth:`features` ``(B, 4, gh, gw)``: the dilated
        convolutions (reflect-101 borders, ReLU) in the parameters' dtype (or a caller's autocast), then the head,
        the weights made to sum to zero, in float32 at least (the maps' dtype): their rounding in float16 moves
        ALCN's output by 2.6e-3 where the convolutions' moves it by 3e-4."""
        # oneDNN's channels-last convolutions are faster on the CPU; in inference only, so that training (and the
        # preset's rebuild of the shipped file) keeps its own sums
        inference = cpu_inference(features)
        x = features.contiguous(memory_format=torch.channels_last) if inference else features
        if not autocast_enabled(x):
            x = x.to(self.head.weight.dtype)
        for conv, d in zip(self.convs, self.dilations):
            x = F.relu(conv(reflect101_pad(x, d, d, d, d)))
        with torch.autocast(x.device.type, enabled=False) if autocast_enabled(x) else nullcontext():
            x = at_least_float32(x)
            if inference:  # the 1x1 head on channels-last maps and the operations on its 1-channel slices cost
                return self._head_by_cells(x)  # more than their work on the CPU
            head = F.conv2d(x, at_least_float32(self.head.weight), at_least_float32(self.head.bias))
        # A band-pass, as the DoG: weights summing to zero, so the response does not follow the
        # local mean (which the division would turn into structure in flat regions).
        weights = head[:, 1:]
        return head[:, :1].exp() * (weights - weights.mean(dim=1, keepdim=True))

    def _head_by_cells(self, x: torch.Tensor) -> torch.Tensor:
        """:meth:`maps_from_features`' head and its weights' centring on the channels-last ``x`` ``(B, C, gh, gw)`` of
        the last convolution, as one matrix product over the cells and operations on whole rows: ``(B, N, gh, gw)``,
        torch's values to float rounding."""
        b, c, gh, gw = x.shape
        cells = x.permute(0, 2, 3, 1).reshape(-1, c)  # a row per cell: the layout of x in memory
        bias = self.head.bias
        assert bias is not None  # the head is built with one
        weight = at_least_float32(self.head.weight[:, :, 0, 0])
        head = torch.addmm(at_least_float32(bias)[:, None], weight, cells.T)  # (1 + N, cells)
        weights = head[1:]
        maps = head[0].exp() * (weights - weights.mean(dim=0))
        return maps.reshape(len(maps), b, gh, gw).transpose(0, 1)

    def dense_grid(self, image: torch.Tensor, grid_stride: int | None = None) -> torch.Tensor:
        """The maps F_k on a grid of stride ``grid_stride`` (a multiple of :attr:`stride`).

        Args:
            image: ``(B, 1, H, W)`` float intensities in [0, 1].
            grid_stride: default :attr:`stride`; a multiple keeps every ``grid_stride / stride``-th
                point of the network's grid (the network always runs at its own stride).

        Returns:
            ``(B, N, ceil((H-1)/g)+1, ceil((W-1)/g)+1)``, point ``(i, j)`` at pixel ``(g*i, g*j)``.
        """
        grid_stride = check_grid_stride(grid_stride, self.stride)
        step = grid_stride // self.stride
        if step > 1:  # extend the image so the network's grid reaches the last point of the coarser one
            h, w = image.shape[-2:]
            gh, gw = grid_shape((h, w), grid_stride)
            image = reflect101_pad(image, 0, grid_stride * (gh - 1) + 1 - h, 0, grid_stride * (gw - 1) + 1 - w)
        maps = self.maps_from_features(self.features(image))
        return maps[..., ::step, ::step] if step > 1 else maps

    def dense(self, image: torch.Tensor, grid_stride: int | None = None) -> torch.Tensor:
        """Per-pixel maps F_k ``(B, N, H, W)``: :meth:`dense_grid` interpolated bilinearly (exact on the grid)."""
        grid_stride = self.stride if grid_stride is None else grid_stride
        return interpolate_grid(self.dense_grid(image, grid_stride), grid_stride, image.shape[-2:])

    def response(self, image: torch.Tensor, maps: torch.Tensor | None = None) -> torch.Tensor:
        """Eq. 3, ``sum_k G_{sigma_k} * (F_k o I)`` ``(B, 1, H, W)``, unbounded, the image's dtype (maps: default
        :meth:`dense`)."""
        return self.mixture(image, (self.dense(image) if maps is None else maps).to(image.dtype))

    def divide(self, response: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        """:func:`~alcn_cv.filters.torch_divisive.divisive_normalization` of the response ``(B, 1, H, W)`` with
        :attr:`divisive_sigma` and the floor scale ``c``; ``floor`` ``(B, 1, 1, 1)`` overrides ``c * mean(e)``
        over each image (training estimates the whole frame's mean from crops)."""
        return divisive_normalization(response, self.divisive_sigma, self.floor_scale, floor)

    def equalize(self, response: torch.Tensor) -> torch.Tensor:
        """The final :func:`contrast_equalization` with ``tau``: into (-1, 1)."""
        return contrast_equalization(response, self.tau)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """The whole normalization, ``tanh(divide(ALCN(I)) / tau)`` plus the weighted wide band: ``(B, 1, H, W)`` ->
        ``(B, 1, H, W)`` in ``(-1 - band, 1 + band)``."""
        out = self.equalize(self.divide(self.response(image)))
        if self.band:
            out = out + self.band * wide_band(image, self.tau, self.floor_scale)
        return out

    @classmethod
    def from_file(cls, weight_file: NormalizerFile) -> GainNormalizer:
        """Build the network a weight file describes (``architecture: "gain"``) and load its arrays.

        Raises:
            WeightFileError: a ``config`` the network refuses (a key it does not have, say), or arrays that do not
                fit it.
        """
        return Normalizer.from_file.__func__(cls, weight_file)

    #: The parameters as float32 arrays, for :func:`alcn_cv.weight_file.save_normalizer_file`.
    state_arrays = Normalizer.state_arrays

    def file_meta(self, trained: bool, **provenance: Any) -> dict[str, Any]:
        """The weight file's header: ``architecture``, ``config`` (the constructor's arguments: ``tau`` and
        ``floor_scale`` their initial values), ``sigmas``, ``working_scale`` 1, ``output_range`` ``[-1 - band, 1 +
        band]`` (the equalized output and the band), the equalization's ``tau`` and the divisive normalization's
        ``scale`` ``c`` (restating the arrays ``log_tau`` and ``log_floor_scale``, the parameters) and ``sigma``, and
        the wide band's (:func:`band_meta`) when it has one."""
        divisive = {"scale": float(self.floor_scale.detach()), "sigma": self.divisive_sigma}
        band = {"band": band_meta(self.band)} if self.band else {}
        return {
            "architecture": ARCHITECTURE,
            "config": self.config,
            "sigmas": list(self.sigmas),
            "working_scale": 1.0,
            "output_range": [-1.0 - self.band, 1.0 + self.band],
            "trained": bool(trained),
            "equalization": {"tau": self.tau_value()},
            "divisive": divisive,
            **band,
            **provenance,
        }

    def extra_repr(self) -> str:
        # a module on the meta device (shape propagation, deferred initialization) has no value to read
        tau = "?" if self.log_tau.is_meta else f"{self.tau_value():.3g}"
        return f"stride={self.stride}, dilations={self.dilations}, tau={tau}"
