r"""A gain-adaptive Normalizer for ALCN's Eq. 3, run on a coarse grid.

ALCN normalizes an image with per-pixel weights F_k predicted by a network (Rad, Roth &
Lepetit, BMVC 2017, Eq. 3)::

    ALCN(I) = sum_k G_{sigma_k} * (F_k o I)

:class:`GainNormalizer` separates what the light changes from what it does not: it predicts a
per-pixel log-gain ``g`` and kernel weights ``w_k`` and forms ``F_k = exp(g) * w_k``, so a gain
over two orders of magnitude is one additive step in ``g``. The network sees log intensities
(the log of a pixel, of a local mean, of a wider context mean and of the local contrast), all
computed on a grid of stride :attr:`~GainNormalizer.stride` (8 pixels by default), so it costs
a small fraction of the full-resolution mixture; the maps are interpolated bilinearly in
between, as ALCN does with the paper's network (:meth:`~alcn_cv.nets.Normalizer.dense`).

The log-gain is the network's output minus ``log(m + eps)``, ``m`` the local mean
(``sigma = mean_sigma``), and the last layer starts at zero weights with the bias of a DoG:
the untrained model is the hand-made member of ALCN's family "Weber gain ``I / m``, then DoG
``G_1 - G_2``" (the best of the hand-made gains on real light), so training starts from it.

With ``gain="divisive"`` the log-gain's fixed part is not the Weber ``-log(m + eps)`` but the
divisive normalization of the band-passed image (Jarrett et al., ICCV 2009: DLCN; here of the
mixture's own response): the response ``r`` is divided by ``sqrt(e^2 + (c * mean(e))^2)``, ``e``
the root-mean-square of ``r`` over the grid's cells and ``mean(e)`` its mean over the image
(:func:`alcn_cv.filters.divisive.divisive_normalization`; ``c`` learned with ``learn_scales``).
It is applied to the response of Eq. 3 rather than inside it (the per-window form of the paper's Eq. 1, weights outside the blurs): the divisor
follows the response it divides, it is smooth at the scale of the grid (8 pixels) where the
kernels are 1 to 2 pixels wide, and it makes the output invariant to the light's strength exactly,
while flat regions stay flat (the floor is relative to the whole image's contrast). The network's
own log-gain correction stays inside Eq. 3. Untrained, this is "DoG ``G_1 - G_2``, then divisive
normalization on the grid", the best hand-made member of the family on real light. With
``divisive_sigma`` the energy is per pixel, ``e = sqrt(G_sigma * r^2)`` (DLCN's own Gaussian-weighted
local standard deviation): the divisor follows the response's edges at the scale of its kernels.

The response is then equalized by ``tanh(x / tau)`` (:func:`contrast_equalization`, the last
step of Tan & Triggs, "Enhanced local texture feature sets for face recognition under difficult
lighting conditions", TIP 2010), with ``tau`` learned: large responses at strong shadow and
specular edges are compressed so they do not dominate a window. It is part of the method, so
``ALCN.apply`` alone delivers the invariance; the output lies in (-1, 1).

Shapes and ranges (``B`` images, ``N`` kernels, ``g`` the grid stride):

* input: ``(B, 1, H, W)`` float32 intensities in [0, 1] at the working scale;
* :meth:`~GainNormalizer.dense_grid`: ``(B, N, ceil((H-1)/g)+1, ceil((W-1)/g)+1)`` float32 maps
  F_k, grid point ``(i, j)`` at pixel ``(g*i, g*j)`` (ALCN's grid convention);
* :meth:`~GainNormalizer.dense`: ``(B, N, H, W)``; :meth:`~GainNormalizer.response`:
  ``(B, 1, H, W)`` (Eq. 3, unbounded); :meth:`~GainNormalizer.forward`: ``(B, 1, H, W)`` in (-1, 1).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.errors import InputError
from alcn_cv.filters.divisive import ABSOLUTE_FLOOR
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d, gaussian_sigmas
from alcn_cv.filters.kornia_mixture import GaussianMixture2d
from alcn_cv.nets.normalizer import Normalizer, reflect101_pad

__all__ = ["GainNormalizer", "GAINS", "cell_rms", "contrast_equalization", "dog_weights", "gaussian_energy", "ARCHITECTURE"]

#: The ``architecture`` field of a gain Normalizer's weight file.
ARCHITECTURE = "gain"
#: The untrained model's band-pass: ``G_1 - G_2`` (pixels at the working scale).
DOG_SIGMAS = (1.0, 2.0)
_INPUT_FEATURES = 4
#: The fixed part of the log-gain: the Weber gain ``1 / (m + eps)`` or the divisive normalization.
GAINS = ("weber", "divisive")


def dog_weights(sigmas: Sequence[float], sigma1: float = DOG_SIGMAS[0], sigma2: float = DOG_SIGMAS[1]) -> list[float]:
    """The mixture weights of ``G_sigma1 - G_sigma2`` over the basis ``sigmas`` (both must be in it)."""
    sigmas = [float(s) for s in sigmas]
    if sigma1 not in sigmas or sigma2 not in sigmas:
        raise InputError(f"the DoG sigmas {sigma1} and {sigma2} must be in the basis {sigmas}")
    weights = [0.0] * len(sigmas)
    weights[sigmas.index(sigma1)] = 1.0
    weights[sigmas.index(sigma2)] = -1.0
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
        return torch.tanh(response / tau)
    return np.tanh(response / np.float32(tau)).astype(np.float32, copy=False)


def cell_rms(response: torch.Tensor, stride: int, pad: bool = True) -> torch.Tensor:
    """Root-mean-square of a ``(B, 1, H, W)`` response over the cells of side ``stride``
    centred on the grid points (:func:`alcn_cv.filters.divisive.cell_rms` in torch).
    ``pad=False``: the response already spans whole cells (half a cell around the grid points),
    ``(B, 1, H / stride, W / stride)``."""
    squared = response * response
    if pad:
        before = stride // 2
        after = 2 * stride - 2 - before
        squared = reflect101_pad(squared, before, after, before, after)
    # The floor keeps the square root differentiable where a cell is exactly flat.
    return F.avg_pool2d(squared, stride).clamp_min(1e-12).sqrt()


def _reflect101_index(x: torch.Tensor, dim: int, before: int, after: int) -> torch.Tensor:
    """Indices of dim ``dim`` (-2 or -1) of ``x`` padded by reflect-101, for any pad size (the
    reflection repeats, as :func:`~alcn_cv.nets.normalizer.reflect101_pad`).

    The size is read from the data, in float32, so that the ONNX export
    (:mod:`alcn_cv.train.export`) computes the indices for every input size with ops ``cv2.dnn``
    runs (it has no integer arithmetic); float32 is exact for these small integers.
    """
    line = x[0, 0, :, 0] if dim == -2 else x[0, 0, 0, :]
    positions = (line * 0 + 1).cumsum(0) - 1  # 0..n-1; the inputs are finite
    last = positions[-1:]  # n - 1
    i = torch.cat([torch.arange(-before, 0, dtype=x.dtype, device=x.device), positions,
                   last + 1 + torch.arange(0, after, dtype=x.dtype, device=x.device)])
    period = torch.clamp(2 * last, min=1)
    i = i - torch.floor(i / period) * period
    return (last - (last - i).abs()).long()


def _reflect101_pad(x: torch.Tensor, pad: int) -> torch.Tensor:
    """Pad the last two dims of ``(B, C, H, W)`` by ``pad`` with reflect-101, for any size (see
    :func:`_reflect101_index`; the grids padded here are small)."""
    x = x.index_select(-2, _reflect101_index(x, -2, pad, pad))
    return x.index_select(-1, _reflect101_index(x, -1, pad, pad))


def _blur(x: torch.Tensor, sigma: float, pad: bool = True) -> torch.Tensor:
    """Separable Gaussian blur of a ``(B, 1, H, W)`` map (the kernels of
    :mod:`alcn_cv.filters.gaussian_mixture`), reflect-101, for any image size (the reflection
    repeats on images smaller than the kernel). ``pad=False``: only where the kernel lies inside,
    ``(B, 1, H - 2r, W - 2r)`` with ``r`` the kernel's radius."""
    kernel = torch.as_tensor(gaussian_kernel1d(sigma), dtype=x.dtype, device=x.device)
    if pad:
        x = _reflect101_pad(x, kernel.numel() // 2)
    return F.conv2d(F.conv2d(x, kernel.view(1, 1, -1, 1)), kernel.view(1, 1, 1, -1))


def gaussian_energy(response: torch.Tensor, sigma: float, pad: bool = True) -> torch.Tensor:
    """``sqrt(G_sigma * response^2)`` of a ``(B, 1, H, W)`` response, per pixel
    (:func:`alcn_cv.filters.divisive.gaussian_energy` in torch); ``pad`` as :func:`_blur`."""
    # The floor keeps the square root differentiable where the response is exactly flat.
    return _blur(response * response, sigma, pad).clamp_min(1e-12).sqrt()


class GainNormalizer(nn.Module):
    """Predicts F_k = exp(g) * w_k on a coarse grid (see the module's docstring).

    Args:
        num_kernels: N, the Gaussian kernels of the mixture. Default 2 (sigmas 1 and 2, the DoG's
            own): on unseen real scenes it identified better than the paper's 10 (``k / 2``) after
            the same training, and its mixture costs a third.
        sigma_step: the mixture's sigmas are ``k * sigma_step``, ``k = 1..N`` (working pixels).
        stride: the grid's spacing in working pixels (the network's own resolution).
        channels: width of the hidden convolutions.
        dilations: one 3x3 convolution per entry, with that dilation (on the grid).
        mean_sigma: sigma of the local mean ``m`` of the Weber gain (working pixels).
        context_sigma: sigma of the wider mean fed to the network (working pixels).
        eps: added to intensities before every log (intensity units).
        tau: initial scale of the final :func:`contrast_equalization` (learned).
        init_weights: the N weights of the untrained model; default :func:`dog_weights`.
        sharpness: also feed the log of each cell's root-mean-square pixel difference (its
            finest-scale energy; against the cell's standard deviation it tells sharp texture
            from blur and noise, which decides the best band).
        learn_floor: learn the Weber gain's floor, ``1 / (m + floor)``, starting at ``eps``
            (otherwise the floor is ``eps``): how dark a region may be before the gain stops
            following it and would amplify mostly noise.
        gain: the log-gain's fixed part (:data:`GAINS`): ``"weber"``, ``-log(m + eps)`` inside
            Eq. 3, or ``"divisive"``, the divisive normalization of Eq. 3's response on the
            grid of :attr:`stride` (the network's log-gain then only corrects it, inside Eq. 3,
            and the kernel weights sum to zero: a band-pass).
        floor_scale: initial ``c`` of the divisive floor ``c * mean(e)`` (``gain="divisive"``).
        divisive_sigma: the divisive normalization's energy per pixel, ``e = sqrt(G_sigma * r^2)``
            with this sigma (working pixels), instead of the root-mean-square over the grid's cells
            (``gain="divisive"``; None: the cells).
        learn_scales: learn ``tau`` and ``c`` (otherwise they keep their initial values).
    """

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
        tau: float = 0.5,
        init_weights: Sequence[float] | None = None,
        sharpness: bool = False,
        learn_floor: bool = False,
        gain: str = "weber",
        floor_scale: float = 1.0,
        learn_scales: bool = True,
        divisive_sigma: float | None = None,
    ) -> None:
        super().__init__()
        if isinstance(stride, bool) or not isinstance(stride, int) or stride < 1:
            raise InputError(f"stride must be a positive integer, got {stride!r}")
        if not (eps > 0 and tau > 0 and mean_sigma > 0 and context_sigma > 0 and floor_scale > 0):
            raise InputError("eps, tau, mean_sigma, context_sigma and floor_scale must be positive")
        if gain not in GAINS:
            raise InputError(f"unknown gain {gain!r}; choose one of {', '.join(GAINS)}")
        if divisive_sigma is not None and (gain != "divisive" or not divisive_sigma > 0):
            raise InputError(f"divisive_sigma must be positive and needs gain='divisive', got {divisive_sigma!r} with {gain!r}")
        self.sigmas = gaussian_sigmas(num_kernels, sigma_step)
        init_weights = dog_weights(self.sigmas) if init_weights is None else [float(w) for w in init_weights]
        if len(init_weights) != num_kernels:
            raise InputError(f"init_weights has {len(init_weights)} values for {num_kernels} kernels")
        self.stride = stride
        self.eps = float(eps)
        self.mean_sigma = float(mean_sigma)
        self.context_sigma = float(context_sigma)
        self.dilations = tuple(int(d) for d in dilations)
        self.sharpness = bool(sharpness)
        layers: list[nn.Module] = []
        width = _INPUT_FEATURES + self.sharpness
        for dilation in self.dilations:
            layers.append(nn.Conv2d(width, channels, 3, dilation=dilation))
            width = channels
        self.convs = nn.ModuleList(layers)
        # Output 0 is the log-gain's correction, outputs 1..N the kernel weights w_k.
        self.head = nn.Conv2d(width, 1 + num_kernels, 1)
        with torch.no_grad():
            self.head.weight.zero_()
            self.head.bias.copy_(torch.tensor([0.0] + init_weights))
        self.log_tau = nn.Parameter(torch.tensor(math.log(tau)), requires_grad=learn_scales)
        self.learn_floor = bool(learn_floor)
        if self.learn_floor:
            self.log_floor = nn.Parameter(torch.tensor(math.log(eps)))
        self.gain = gain
        #: The per-pixel energy's sigma of the divisive normalization (working pixels), or None (the cells).
        self.divisive_sigma = None if divisive_sigma is None else float(divisive_sigma)
        if gain == "divisive":
            self.log_floor_scale = nn.Parameter(torch.tensor(math.log(floor_scale)), requires_grad=learn_scales)
        self.mixture = GaussianMixture2d(self.sigmas)
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
            "sharpness": self.sharpness,
            "learn_floor": self.learn_floor,
            "gain": gain,
            "floor_scale": float(floor_scale),
            "learn_scales": bool(learn_scales),
        }
        if self.divisive_sigma is not None:  # absent by default: the earlier files' headers stay as they were
            self.config["divisive_sigma"] = self.divisive_sigma

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
    def floor_scale(self) -> torch.Tensor | None:
        """``c`` of the divisive floor (a 0-d tensor), None for the Weber gain."""
        return self.log_floor_scale.exp() if self.gain == "divisive" else None

    def _grid_shape(self, h: int, w: int, grid_stride: int) -> tuple[int, int]:
        return math.ceil((h - 1) / grid_stride) + 1, math.ceil((w - 1) / grid_stride) + 1

    def _cells(self, image: torch.Tensor) -> torch.Tensor:
        """``(B, C, gh, gw)`` means of each cell of side :attr:`stride` centred on a grid point."""
        s = self.stride
        before = s // 2
        # H + 2s - 2 pixels hold exactly ceil((H-1)/s)+1 cells (the pooling drops the rest), so
        # the pads do not depend on the size and the ONNX export keeps the size dynamic.
        after = 2 * s - 2 - before
        return F.avg_pool2d(reflect101_pad(image, before, after, before, after), s)

    def features(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The network's input on the grid of :attr:`stride` and the Weber mean.

        Returns:
            ``(B, 4, gh, gw)`` features (log of the cell's mean, of the local mean ``m``, of the
            context mean, and of the cell's standard deviation; a fifth with ``sharpness``) and
            ``(B, 1, gh, gw)`` ``m``.
        """
        if image.ndim != 4 or image.shape[1] != 1:
            raise InputError(f"image must have shape (B, 1, H, W), got {tuple(image.shape)}")
        # One padding and one pooling for both statistics (the full-resolution passes dominate).
        mean, square = self._cells(torch.cat([image, image * image], dim=1)).split(1, dim=1)
        # The blurs of the grid stand for blurs of the image: sigma in cells = sigma / stride.
        local = _blur(mean, self.mean_sigma / self.stride)
        context = _blur(mean, self.context_sigma / self.stride)
        std = (square - mean * mean).clamp_min(0.0).sqrt()
        eps = self.eps
        feats = [(mean + eps).log(), (local + eps).log(), (context + eps).log(), (std + eps).log()]
        if self.sharpness:
            dx = F.pad(image[..., :, 1:] - image[..., :, :-1], (0, 1))
            dy = F.pad(image[..., 1:, :] - image[..., :-1, :], (0, 0, 0, 1))
            feats.append((self._cells(0.5 * (dx * dx + dy * dy)).sqrt() + eps).log())
        return torch.cat(feats, dim=1), local

    def log_gain_and_weights(self, image: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """``g`` ``(B, 1, gh, gw)`` and ``w_k`` ``(B, N, gh, gw)`` on the grid of :attr:`stride`."""
        x, local = self.features(image)
        return self.gain_and_weights(self.head(self.trunk(x)), local)

    def trunk(self, features: torch.Tensor) -> torch.Tensor:
        """The hidden dilated convolutions (reflect-101 borders, ReLU) on the grid's
        :meth:`features` ``(B, 4, gh, gw)`` -> ``(B, channels, gh, gw)``: the input of the head."""
        x = features
        for conv, d in zip(self.convs, self.dilations):
            x = F.relu(conv(_reflect101_pad(x, d)))
        return x

    def gain_and_weights(self, head: torch.Tensor, local: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The head's output ``(B, 1 + N, gh, gw)`` as ``g`` ``(B, 1, gh, gw)`` and ``w_k``
        ``(B, N, gh, gw)``, given the local mean ``m`` ``(B, 1, gh, gw)`` of the Weber gain (the
        step shared with the OpenCV runtime of :class:`~alcn_cv.enhance.alcn.ALCN`)."""
        if self.gain == "divisive":  # the fixed part divides the response (:meth:`divide`)
            weights = head[:, 1:]
            # A band-pass, as the DoG: weights summing to zero, so the response does not follow
            # the local mean (which the division would turn into structure in flat regions).
            return head[:, :1], weights - weights.mean(dim=1, keepdim=True)
        floor = self.log_floor.exp() if self.learn_floor else self.eps
        return head[:, :1] - (local + floor).log(), head[:, 1:]

    def dense_grid(self, image: torch.Tensor, grid_stride: int | None = None) -> torch.Tensor:
        """The maps F_k on a grid of stride ``grid_stride`` (a multiple of :attr:`stride`).

        Args:
            image: ``(B, 1, H, W)`` float32 intensities in [0, 1].
            grid_stride: default :attr:`stride`; a multiple keeps every ``grid_stride / stride``-th
                point of the network's grid (the network always runs at its own stride).

        Returns:
            ``(B, N, ceil((H-1)/g)+1, ceil((W-1)/g)+1)``, point ``(i, j)`` at pixel ``(g*i, g*j)``.
        """
        grid_stride = self.stride if grid_stride is None else grid_stride
        if isinstance(grid_stride, bool) or not isinstance(grid_stride, int) or grid_stride < self.stride or grid_stride % self.stride:
            raise InputError(f"grid_stride must be a positive multiple of {self.stride}, got {grid_stride!r}")
        step = grid_stride // self.stride
        if step > 1:  # extend the image so the network's grid reaches the last point of the coarser one
            h, w = image.shape[-2:]
            gh, gw = self._grid_shape(h, w, grid_stride)
            image = reflect101_pad(image, 0, grid_stride * (gh - 1) + 1 - h, 0, grid_stride * (gw - 1) + 1 - w)
        log_gain, weights = self.log_gain_and_weights(image)
        maps = log_gain.exp() * weights
        return maps[..., ::step, ::step] if step > 1 else maps

    def dense(self, image: torch.Tensor, grid_stride: int | None = None) -> torch.Tensor:
        """Per-pixel maps F_k ``(B, N, H, W)``: :meth:`dense_grid` interpolated bilinearly (exact on the grid)."""
        grid_stride = self.stride if grid_stride is None else grid_stride
        grid = self.dense_grid(image, grid_stride)
        h, w = image.shape[-2:]
        size = (grid_stride * (grid.shape[-2] - 1) + 1, grid_stride * (grid.shape[-1] - 1) + 1)
        return F.interpolate(grid, size=size, mode="bilinear", align_corners=True)[..., :h, :w]

    def response(self, image: torch.Tensor, maps: torch.Tensor | None = None) -> torch.Tensor:
        """Eq. 3, ``sum_k G_{sigma_k} * (F_k o I)`` ``(B, 1, H, W)``, unbounded (maps: default :meth:`dense`)."""
        return self.mixture(image, self.dense(image) if maps is None else maps)

    def divide(self, response: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        """:func:`~alcn_cv.filters.divisive.divisive_normalization` (in torch) of the response
        ``(B, 1, H, W)`` on the grid of :attr:`stride` (per pixel with :attr:`divisive_sigma`) with
        the learned ``c`` (``gain="divisive"``; the response unchanged otherwise). ``floor``:
        ``(B, 1, 1, 1)``, overrides ``c * mean(e)`` over each image (training estimates the whole
        frame's mean from crops)."""
        if self.gain != "divisive":
            return response
        if self.divisive_sigma is not None:
            return response * self.inverse_divisor(gaussian_energy(response, self.divisive_sigma), floor)
        inverse = self.inverse_divisor(cell_rms(response, self.stride), floor)
        h, w = response.shape[-2:]
        size = (self.stride * (inverse.shape[-2] - 1) + 1, self.stride * (inverse.shape[-1] - 1) + 1)
        return response * F.interpolate(inverse, size=size, mode="bilinear", align_corners=True)[..., :h, :w]

    def inverse_divisor(self, energy: torch.Tensor, floor: torch.Tensor | None = None) -> torch.Tensor:
        """``1 / sqrt(e^2 + f^2 + ABSOLUTE_FLOOR^2)`` from the energy ``e`` ``(B, 1, h, w)`` (the
        cells' on the grid, or per pixel); ``f = c * mean(e)`` over each image unless ``floor``
        ``(B, 1, 1, 1)`` is given (``gain="divisive"``)."""
        if floor is None:
            floor = self.floor_scale * energy.mean(dim=(-2, -1), keepdim=True)
        return (energy * energy + floor * floor + ABSOLUTE_FLOOR**2).rsqrt()

    def equalize(self, response: torch.Tensor) -> torch.Tensor:
        """The final :func:`contrast_equalization` with the learned ``tau``: into (-1, 1)."""
        return contrast_equalization(response, self.tau)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """The whole normalization, ``tanh(ALCN(I) / tau)`` (divided first with ``gain="divisive"``):
        ``(B, 1, H, W)`` -> ``(B, 1, H, W)`` in (-1, 1)."""
        return self.equalize(self.divide(self.response(image)))

    #: Build the network a weight file describes (``architecture: "gain"``) and load its arrays.
    from_file = classmethod(Normalizer.from_file.__func__)
    #: The parameters as float32 arrays, for :func:`alcn_cv.weight_file.save_normalizer_file`.
    state_arrays = Normalizer.state_arrays

    def file_meta(self, trained: bool, **provenance: Any) -> dict[str, Any]:
        """The weight file's header: ``architecture``, ``config``, ``sigmas``, ``working_scale`` 1,
        ``output_range`` ``[-1, 1]`` (the equalized output), the equalization's ``tau`` and, with
        ``gain="divisive"``, the divisive normalization's ``stride`` and ``scale`` (and ``sigma``,
        :attr:`divisive_sigma`, when set)."""
        divisive = {}
        if self.gain == "divisive":
            sigma = {} if self.divisive_sigma is None else {"sigma": self.divisive_sigma}
            divisive = {"divisive": {"stride": self.stride, "scale": float(self.floor_scale.detach()), **sigma}}
        return {
            "architecture": ARCHITECTURE,
            "config": self.config,
            "sigmas": list(self.sigmas),
            "working_scale": 1.0,
            "output_range": [-1.0, 1.0],
            "trained": bool(trained),
            "equalization": {"kind": "tanh", "tau": self.tau_value()},
            **divisive,
            **provenance,
        }

    def extra_repr(self) -> str:
        return f"stride={self.stride}, dilations={self.dilations}, tau={self.tau_value():.3g}"
