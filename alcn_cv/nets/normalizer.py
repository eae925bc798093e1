"""The Normalizer network of ALCN (Rad, Roth & Lepetit, BMVC 2017, Sec. 3.1, 3.3 and 4.2).

It looks at a 48x48 window and predicts the N weights of the Gaussian mixture
(:mod:`alcn_cv.filters.gaussian_mixture`). Architecture of Sec. 4.2: 20 convolutions 5x5 +
2x2 max-pooling, 50 convolutions 5x5 + 2x2 max-pooling, a fully connected layer of 1024, and
N outputs, with tanh activations. The fully connected layer is stored as a 9x9 convolution so
the same parameters run fully-convolutionally over a whole image (Sec. 3.3): the
convolutions are shared between overlapping windows and the output has a stride of 4 pixels.
"""

from __future__ import annotations

import numbers
from collections.abc import Sequence
from contextlib import nullcontext

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.filters.torch_precision import at_least_float32, autocast_enabled
from alcn_cv.filters.torch_resize import interpolate_grid
from alcn_cv.nets.opencv_runtime import WINDOW, grid_shape
from alcn_cv.weight_file import NormalizerFile

__all__ = ["Normalizer", "check_grid_stride"]

STRIDE = 4
ACTIVATIONS = {"tanh": nn.Tanh, "relu": nn.ReLU}


def check_grid_stride(grid_stride: int | None, stride: int) -> int:
    """``grid_stride``, or the network's ``stride`` for ``None``, checked to be a positive multiple of ``stride``.

    Raises:
        InputError: anything else (a bool, a float, a smaller or unaligned stride).
    """
    grid_stride = stride if grid_stride is None else grid_stride
    if (
        isinstance(grid_stride, bool)
        or not isinstance(grid_stride, numbers.Integral)
        or grid_stride < stride
        or grid_stride % stride
    ):
        raise InputError(f"grid_stride must be a positive multiple of {stride}, got {grid_stride!r}")
    return int(grid_stride)  # NumPy's integers too


def _check_fit(needed: dict[str, torch.Tensor], arrays: dict[str, np.ndarray], name: object) -> None:
    """One line on the first array of a weight file that its header's network (``needed``, its ``state_dict``) lacks,
    does not have, or has in another shape, rather than torch's lines on all of them."""
    mixed_up = "its arrays do not fit its header (edited or mixed up?)"
    for key, tensor in needed.items():
        if key not in arrays:
            raise WeightFileError(f"{name}: array {key!r} missing, the header's network needs it: {mixed_up}")
        if tuple(np.shape(arrays[key])) != tuple(tensor.shape):
            raise WeightFileError(
                f"{name}: array {key!r} has shape {tuple(np.shape(arrays[key]))}, the header's network needs "
                f"{tuple(tensor.shape)}: {mixed_up}"
            )
    extra = next((key for key in arrays if key not in needed), None)
    if extra is not None:
        raise WeightFileError(f"{name}: array {extra!r} is not in the header's network: {mixed_up}")


class Normalizer(nn.Module):
    """Predicts the Gaussian-mixture weights of ALCN from an image window.

    Args:
        num_kernels: N, the number of Gaussian kernels (weights predicted per window).
        channels: widths of the two convolution layers (paper: 20 and 50).
        hidden: width of the fully connected layer (paper: 1024).
        output_scale: fixed factor on the outputs. tanh features and small initial weights
            give outputs near 0; the mixture needs weights of order 1-10 to reach a useful
            output range, which a fixed scale gives without slowing training.
        init_weights: optional N weights the untrained network predicts for every window
            (the bias of the last layer, with its weights at zero), e.g. a DoG.
        activation: ``"tanh"`` (the paper's) or ``"relu"``.

    Shape:
        - :meth:`forward`: ``(B, 1, 48, 48)`` -> ``(B, N)``
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, N, H, W)``

    Inputs are grayscale intensities in [0, 1], float32.
    """

    window = WINDOW
    stride = STRIDE

    def __init__(
        self,
        num_kernels: int = 10,
        channels: tuple[int, int] = (20, 50),
        hidden: int = 1024,
        output_scale: float = 1.0,
        init_weights: Sequence[float] | None = None,
        activation: str = "tanh",
    ) -> None:
        super().__init__()
        if activation not in ACTIVATIONS:
            raise InputError(f"activation must be one of {', '.join(ACTIVATIONS)}, got {activation!r}")
        c1, c2 = channels
        act = ACTIVATIONS[activation]
        self.features = nn.Sequential(
            nn.Conv2d(1, c1, 5),
            act(),
            nn.MaxPool2d(2),
            nn.Conv2d(c1, c2, 5),
            act(),
            nn.MaxPool2d(2),
        )
        self.activation = act()
        # The fully connected layer over the 9x9x50 features, as a convolution (Sec. 3.3).
        self.fc = nn.Conv2d(c2, hidden, 9)
        self.head = nn.Conv2d(hidden, num_kernels, 1)
        self.output_scale = float(output_scale)
        self.config = {
            "num_kernels": num_kernels,
            "channels": [c1, c2],
            "hidden": hidden,
            "output_scale": self.output_scale,
            "init_weights": None if init_weights is None else [float(w) for w in init_weights],
            "activation": activation,
        }
        if init_weights is not None:
            if len(init_weights) != num_kernels:
                raise InputError(f"init_weights has {len(init_weights)} values for {num_kernels} kernels")
            with torch.no_grad():
                self.head.weight.zero_()
                self.head.bias.copy_(torch.as_tensor(init_weights, dtype=torch.float32) / self.output_scale)

    @property
    def num_kernels(self) -> int:
        return self.head.out_channels

    def _weights(self, x: torch.Tensor, fc_stride: int = 1) -> torch.Tensor:
        # fc_stride > 1 evaluates the fully connected layer (a 9x9 convolution over the pooled
        # features) only on every fc_stride-th window: the output grid is coarser and the
        # layer's cost, which dominates, drops by fc_stride**2.
        hidden = F.conv2d(self.features(x), self.fc.weight, self.fc.bias, stride=fc_stride)
        return self.output_scale * self._head(self.activation(hidden))

    def _head(self, hidden: torch.Tensor) -> torch.Tensor:
        """The 1x1 head, in float32 at least (outside a caller's autocast too): Eq. 3 sums its outputs' products, where
        float16's rounding of them would show."""
        with torch.autocast(hidden.device.type, enabled=False) if autocast_enabled(hidden) else nullcontext():
            return F.conv2d(
                at_least_float32(hidden), at_least_float32(self.head.weight), at_least_float32(self.head.bias)
            )

    def forward(self, windows: torch.Tensor) -> torch.Tensor:
        """Weights for each ``(B, 1, 48, 48)`` window -> ``(B, N)``, float32 at least (see :meth:`dense_grid`)."""
        if windows.ndim != 4 or windows.shape[1:] != (1, WINDOW, WINDOW):
            raise InputError(f"windows must have shape (B, 1, {WINDOW}, {WINDOW}), got {tuple(windows.shape)}")
        return self._weights(windows).flatten(1)

    def dense(self, image: torch.Tensor, grid_stride: int | None = None) -> torch.Tensor:
        """Per-pixel weight maps F_k over a whole image (Eq. 3).

        The map at pixel ``(y, x)`` is the output for the 48x48 window covering rows
        ``y-24 .. y+23`` and columns ``x-24 .. x+23`` (reflect-101 outside the image). The
        network is evaluated on a grid of stride ``grid_stride`` (default: the network's own
        output stride, :attr:`stride`, 4) and bilinearly interpolated in between; on the grid
        (``y`` and ``x`` multiples of ``grid_stride``) it equals :meth:`forward` exactly.

        Args:
            image: ``(B, 1, H, W)`` float tensor, any H, W >= 1.
            grid_stride: spacing of the evaluated windows in pixels, a multiple of
                :attr:`stride`. A coarser grid costs ``(stride / grid_stride) ** 2`` of the fully
                connected layer (the convolutions before it are shared by overlapping windows
                and cost the same) and interpolates the maps over longer distances.

        Returns:
            ``(B, N, H, W)`` weight maps.
        """
        if image.ndim != 4 or image.shape[1] != 1:
            raise InputError(f"image must have shape (B, 1, H, W), got {tuple(image.shape)}")
        grid_stride = self.stride if grid_stride is None else grid_stride
        return interpolate_grid(self.dense_grid(image, grid_stride), grid_stride, image.shape[-2:])

    def dense_grid(self, image: torch.Tensor, grid_stride: int | None = None) -> torch.Tensor:
        """The network's output on a grid of stride ``grid_stride`` (a multiple of :attr:`stride`,
        default :attr:`stride`): ``(B, N, gh, gw)``, :func:`~alcn_cv.nets.opencv_runtime.grid_shape` of
        ``(H, W)`` at ``g = grid_stride``; grid point ``(i, j)`` is the window centred on pixel ``(g*i, g*j)``. The
        layers run in the parameters' dtype (or a caller's autocast), the head in float32 at least (the output's
        dtype)."""
        grid_stride = check_grid_stride(grid_stride, self.stride)
        h, w = image.shape[-2:]
        gh, gw = grid_shape((h, w), grid_stride)
        half = WINDOW // 2
        padded = reflect101_pad(image, half, grid_stride * (gh - 1) + half - h, half, grid_stride * (gw - 1) + half - w)
        if not autocast_enabled(padded):  # a float32 image of a float16 module's (ALCN2d's): the module's dtype
            padded = padded.to(self.head.weight.dtype)
        return self._weights(padded, grid_stride // self.stride)

    @classmethod
    def from_file(cls, weight_file: NormalizerFile) -> Normalizer:
        """Build the network described by a weight file and load its arrays.

        Raises:
            WeightFileError: a ``config`` the network refuses, or arrays that do not fit it (the first array missing,
                unknown or of another shape named).
        """
        name = weight_file.path or "weights"
        try:
            net = cls(**weight_file.meta["config"])
        except (TypeError, ValueError) as exc:  # ValueError: the constructor's InputError among them
            raise WeightFileError(f"{name}: its weights do not fit the Normalizer they describe: {exc}") from None
        _check_fit(net.state_dict(), weight_file.arrays, name)
        net.load_state_dict({k: torch.from_numpy(np.array(v)) for k, v in weight_file.arrays.items()})
        return net.eval()

    def state_arrays(self: nn.Module) -> dict[str, np.ndarray]:
        """The parameters as float32 arrays, for :func:`alcn_cv.weight_file.save_normalizer_file` (typed on any
        module: the other Normalizers borrow it)."""
        return {k: v.detach().float().cpu().numpy() for k, v in self.state_dict().items()}  # bfloat16: no NumPy dtype

    def extra_repr(self) -> str:
        return f"output_scale={self.output_scale}, activation={self.config['activation']!r}"
