"""A light Normalizer for real-time ALCN, distilled from the paper's.

The paper's Normalizer (:class:`~alcn_cv.nets.Normalizer`) spends about 13 M multiply-adds per
48x48 window; run densely over a 640x400 working image (a 1280x800 frame) that is several
GMACs, hundreds of times the cost of a difference of Gaussians. :class:`LiteNormalizer` has the
same contract -- a 48x48 window in, the N mixture weights out, fully convolutional with valid
convolutions so that its dense output on a grid equals its output on each window -- at about
15 k multiply-adds per window on a grid of stride 8:

==========================  =========  ==================
layer                       output     on a 48x48 window
==========================  =========  ==================
conv 4x4 stride 4, c1       12x12      patch features
conv 3x3, c1                10x10
conv 2x2 stride 2, c2       5x5
conv 3x3, c2                3x3
conv 3x3, c2 (stride s)     1x1        receptive field 48
conv 1x1, N                 1x1        the weights
==========================  =========  ==================

with tanh activations. It is trained by :mod:`alcn_cv.train.distill` to reproduce a teacher's
weights on the data engine's windows; its weight file says so (``architecture: "lite"`` and
the teacher's checksum in the header).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.nets.cpu_inference import cpu_inference, tanh_
from alcn_cv.nets.normalizer import ACTIVATIONS, Normalizer
from alcn_cv.weight_file import NormalizerFile

__all__ = ["ARCHITECTURES", "LiteNormalizer", "normalizer_from_file"]

LITE_STRIDE = 8


class LiteNormalizer(Normalizer):
    """A light Normalizer with the paper's contract (see the module's docstring).

    Args:
        num_kernels: N, the number of Gaussian kernels.
        channels: ``(c1, c2)``, the widths of the convolutions (default 8 and 16).
        output_scale: fixed factor on the outputs (as :class:`~alcn_cv.nets.Normalizer`).
        activation: ``"tanh"`` or ``"relu"``.

    Shape:
        - :meth:`forward`: ``(B, 1, 48, 48)`` -> ``(B, N)``
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, N, H, W)``; :meth:`dense_grid` on a grid of
          stride 8 (or a multiple of 8).
    """

    stride = LITE_STRIDE

    def __init__(
        self,
        num_kernels: int = 10,
        channels: tuple[int, int] = (8, 16),
        output_scale: float = 1.0,
        activation: str = "tanh",
    ) -> None:
        nn.Module.__init__(self)
        if activation not in ACTIVATIONS:
            raise InputError(f"activation must be one of {', '.join(ACTIVATIONS)}, got {activation!r}")
        c1, c2 = channels
        act = ACTIVATIONS[activation]
        self.features = nn.Sequential(
            nn.Conv2d(1, c1, 4, stride=4),
            act(),
            nn.Conv2d(c1, c1, 3),
            act(),
            nn.Conv2d(c1, c2, 2, stride=2),
            act(),
            nn.Conv2d(c2, c2, 3),
            act(),
        )
        self.activation = act()
        self.fc = nn.Conv2d(c2, c2, 3)  # the last 3x3: its stride sets the grid's
        self.head = nn.Conv2d(c2, num_kernels, 1)
        self.output_scale = float(output_scale)
        self.config = {
            "num_kernels": num_kernels,
            "channels": [c1, c2],
            "output_scale": self.output_scale,
            "activation": activation,
        }

    def _weights(self, x: torch.Tensor, fc_stride: int = 1) -> torch.Tensor:
        if not cpu_inference(x) or self.config["activation"] != "tanh":
            hidden = F.conv2d(self.features(x), self.fc.weight, self.fc.bias, stride=fc_stride)
            return self.output_scale * self._head(self.activation(hidden))
        # Inference on the CPU: the same layers with the tanh computed in place by NumPy (cpu_inference.tanh_).
        for layer in self.features:
            x = layer(x) if isinstance(layer, nn.Conv2d) else tanh_(x)
        hidden = tanh_(F.conv2d(x, self.fc.weight, self.fc.bias, stride=fc_stride))
        out = self._head(hidden)
        return out if self.output_scale == 1 else out.mul_(self.output_scale)


#: Network classes by the ``architecture`` field of a weight file's header; ``"gain"`` is
#: :class:`~alcn_cv.nets.gain.GainNormalizer`, imported when a file asks for it (it needs kornia).
ARCHITECTURES: dict[str, type[Normalizer]] = {"paper": Normalizer, "lite": LiteNormalizer}


def normalizer_from_file(weight_file: NormalizerFile) -> Normalizer:
    """The network a weight file describes: its header's ``architecture`` (``"paper"`` when
    absent, :class:`~alcn_cv.nets.Normalizer`; ``"lite"``, :class:`LiteNormalizer`; ``"gain"``,
    :class:`~alcn_cv.nets.gain.GainNormalizer`), loaded.

    Raises:
        WeightFileError: unknown architecture, or arrays that do not fit it.
    """
    name = weight_file.meta.get("architecture", "paper")
    if name == "gain":
        from alcn_cv.nets.gain import GainNormalizer

        return GainNormalizer.from_file(weight_file)
    if name == "unet":  # the lab's free-form baseline, which `alcn bench relight` runs
        raise WeightFileError(
            f"{weight_file.path or 'the weight file'}: the U-Net baseline of `alcn train-unet`, not an ALCN "
            "Normalizer; the benchmark runs it: `alcn bench relight --methods unet:weights=FILE`"
        )
    if name not in ARCHITECTURES:
        raise WeightFileError(f"unknown Normalizer architecture {name!r} (known: {', '.join(ARCHITECTURES)}, gain)")
    return ARCHITECTURES[name].from_file(weight_file)
