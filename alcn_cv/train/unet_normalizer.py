r"""A free-form learned normalizer: a small U-Net that outputs the normalized image.

The baseline a practitioner would try instead of ALCN's Eq. 3: no Gaussian mixture, no divisive step,
any function of the image that a U-Net (Ronneberger et al., MICCAI 2015) can represent; the "jointly
trained U-Net" of Jenicek & Chum, No Fear of the Dark, ICCV 2019. Trained by :mod:`alcn_cv.train.unet` and
benchmarked through :class:`alcn_cv.bench.unet.UNetNormalization`.

The network sees ``log(I + eps)``, the photometric representation the gain Normalizer's features use
(a change of light is mostly a gain), and outputs ``tanh`` of a 1x1 convolution: (-1, 1).

Shapes: input ``(B, 1, H, W)`` float intensities in [0, 1], any ``H, W >= 1`` (padded internally by
reflect-101 to a multiple of ``2 ** (levels - 1)`` on the bottom and right, the output cropped back);
output ``(B, 1, H, W)`` in (-1, 1).
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.checks import check_positive
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.nets.normalizer import Normalizer
from alcn_cv.weight_file import NormalizerFile

__all__ = ["ARCHITECTURE", "UNetNormalizer"]

#: The ``architecture`` field of a U-Net's weight file.
ARCHITECTURE = "unet"


class _DoubleConv(nn.Module):
    """Two 3x3 convolutions with reflect-101 borders, each followed by a ReLU."""

    def __init__(self, inputs: int, outputs: int) -> None:
        super().__init__()
        self.first = nn.Conv2d(inputs, outputs, 3)
        self.second = nn.Conv2d(outputs, outputs, 3)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.relu(self.first(reflect101_pad(x, 1, 1, 1, 1)))
        return F.relu(self.second(reflect101_pad(x, 1, 1, 1, 1)))


class UNetNormalizer(nn.Module):
    """A U-Net from an intensity image to a normalized image (see the module's docstring).

    Level ``l`` (``0..levels-1``) has ``channels * 2**l`` channels at ``1 / 2**l`` of the resolution: two
    3x3 convolutions on the way down (2x2 max pooling between levels), then, on the way up, bilinear
    upsampling, the skip connection concatenated and two 3x3 convolutions; a 1x1 convolution and ``tanh``.

    Args:
        channels: width of the first level.
        levels: resolutions, the first included (>= 1).
        eps: added to intensities before the log (intensity units).

    Shape:
        ``(B, 1, H, W)`` in [0, 1] -> ``(B, 1, H, W)`` in (-1, 1).

    Example:
        >>> import torch
        >>> net = UNetNormalizer(channels=8, levels=3)
        >>> net(torch.rand(2, 1, 37, 50)).shape
        torch.Size([2, 1, 37, 50])
    """

    def __init__(self, channels: int = 8, levels: int = 3, eps: float = 0.01) -> None:
        super().__init__()
        if isinstance(channels, bool) or not isinstance(channels, int) or channels < 1:
            raise InputError(f"channels must be a positive integer, got {channels!r}")
        if isinstance(levels, bool) or not isinstance(levels, int) or levels < 1:
            raise InputError(f"levels must be a positive integer, got {levels!r}")
        self.eps = check_positive("eps", eps)
        widths = [channels * 2**level for level in range(levels)]
        self.down = nn.ModuleList(_DoubleConv(a, b) for a, b in zip([1, *widths[:-1]], widths))
        self.up = nn.ModuleList(_DoubleConv(wide + narrow, narrow) for narrow, wide in zip(widths, widths[1:]))
        self.head = nn.Conv2d(widths[0], 1, 1)
        self.config: dict[str, Any] = {"channels": channels, "levels": levels, "eps": self.eps}

    @property
    def reach(self) -> int:
        """An upper bound of the receptive field's radius (pixels, Chebyshev): the output at a pixel does not
        depend on the input farther away, when the padded grids of the two inputs align (see :attr:`multiple`)."""
        half = self.multiple  # 2 ** (levels - 1), the bottom level's pixel in input pixels
        # Per level l above the bottom: 2 + 2 convolutions, the pooling and the upsampling; the bottom's 2 convolutions.
        return 7 * (half - 1) + 2 * half

    @property
    def multiple(self) -> int:
        """The side the input is padded to a multiple of: ``2 ** (levels - 1)``."""
        return 2 ** (len(self.down) - 1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        if image.ndim != 4 or image.shape[1] != 1:
            raise InputError(f"image must have shape (B, 1, H, W), got {tuple(image.shape)}")
        h, w = image.shape[-2:]
        m = self.multiple
        x = reflect101_pad((image + self.eps).log(), 0, -h % m, 0, -w % m)
        skips = []
        for level, block in enumerate(self.down):
            x = block(F.max_pool2d(x, 2) if level else x)
            skips.append(x)
        for block, skip in zip(reversed(self.up), reversed(skips[:-1])):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = block(torch.cat([x, skip], dim=1))
        return torch.tanh(self.head(x))[..., :h, :w]

    @classmethod
    def from_file(cls, weight_file: NormalizerFile) -> UNetNormalizer:
        """Build the network a weight file describes (``architecture: "unet"``) and load its arrays."""
        if weight_file.meta.get("architecture") != ARCHITECTURE:
            raise WeightFileError(
                f"a weight file of architecture {weight_file.meta.get('architecture')!r}, not {ARCHITECTURE!r}"
            )
        return Normalizer.from_file.__func__(cls, weight_file)

    #: The parameters as float32 arrays, for :func:`alcn_cv.weight_file.save_normalizer_file`.
    state_arrays = Normalizer.state_arrays

    def file_meta(
        self, trained: bool, output_range: tuple[float, float] = (-1.0, 1.0), **provenance: Any
    ) -> dict[str, Any]:
        """The weight file's header: ``architecture`` ``"unet"``, ``config``, no ``sigmas``, ``working_scale`` 1,
        ``output_range`` (the responses mapped to an image's range; default ``tanh``'s)."""
        return {
            "architecture": ARCHITECTURE,
            "config": self.config,
            "sigmas": [],
            "working_scale": 1.0,
            "output_range": [float(v) for v in output_range],
            "trained": bool(trained),
            **provenance,
        }

    def extra_repr(self) -> str:
        return f"channels={self.config['channels']}, levels={self.config['levels']}"
