"""CIFAR-style residual networks (He, Zhang, Ren & Sun, "Deep residual learning for image
recognition", CVPR 2016, Sec. 4.2): the ResNet-20 and ResNet-56 baselines of Rad, Roth & Lepetit,
BMVC 2017, Sec. 4.3.1, on 32x32 grayscale windows.

``6n + 2`` layers: a 3x3 convolution (16 channels), three stages of ``n`` basic blocks (two 3x3
convolutions with batch normalization) with 16, 32 and 64 channels, the last two starting with
stride 2 (shortcut: 1x1 convolution with stride 2 and batch normalization, option B), global
average pooling and a linear layer. ResNet-20: ``n = 3``; ResNet-56: ``n = 9``.

:meth:`CifarResNet.dense` runs it over a whole image: the convolutions over the image, then an
8x8 average pooling with stride 1 of the final (1/4-resolution) feature map, which is the
global average of each 32x32 window at stride 4. It differs from running every window alone
near the window borders: there the padded convolutions see the image around the window instead
of zeros.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.errors import InputError

__all__ = ["CifarResNet", "resnet20", "resnet56"]

INPUT = 32


class _BasicBlock(nn.Module):
    def __init__(self, cin: int, cout: int, stride: int) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(cin, cout, 3, stride, 1, bias=False)
        self.bn1 = nn.BatchNorm2d(cout)
        self.conv2 = nn.Conv2d(cout, cout, 3, 1, 1, bias=False)
        self.bn2 = nn.BatchNorm2d(cout)
        self.shortcut: nn.Module = nn.Identity()
        if stride != 1 or cin != cout:
            self.shortcut = nn.Sequential(nn.Conv2d(cin, cout, 1, stride, bias=False), nn.BatchNorm2d(cout))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = F.relu(self.bn1(self.conv1(x)))
        out = self.bn2(self.conv2(out))
        return F.relu(out + self.shortcut(x))


class CifarResNet(nn.Module):
    """ResNet for 32x32 inputs with ``6 * blocks + 2`` layers.

    Args:
        num_classes: background + objects (>= 2).
        blocks: basic blocks per stage (``n``; 3 gives ResNet-20, 9 ResNet-56).
        in_channels: input channels (1 for grayscale).

    Shape:
        - :meth:`forward`: ``(B, 1, 32, 32)`` -> ``(B, num_classes)`` logits
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, num_classes, H//4-7, W//4-7)`` for H, W
          multiples of 4 (entry ``(i, j)`` scores the window with top-left corner ``(4i, 4j)``).
    """

    input_size = INPUT
    stride = 4

    def __init__(self, num_classes: int, blocks: int = 3, in_channels: int = 1) -> None:
        super().__init__()
        if num_classes < 2 or blocks < 1:
            raise InputError(f"need num_classes >= 2 and blocks >= 1, got {num_classes} and {blocks}")
        self.config = {"num_classes": num_classes, "blocks": blocks, "in_channels": in_channels}
        self.stem = nn.Sequential(nn.Conv2d(in_channels, 16, 3, 1, 1, bias=False), nn.BatchNorm2d(16), nn.ReLU(inplace=True))
        layers: list[nn.Module] = []
        cin = 16
        for stage, cout in enumerate((16, 32, 64)):
            for b in range(blocks):
                layers.append(_BasicBlock(cin, cout, 2 if stage > 0 and b == 0 else 1))
                cin = cout
        self.stages = nn.Sequential(*layers)
        self.fc = nn.Linear(64, num_classes)
        for m in self.modules():
            if isinstance(m, nn.Conv2d):
                nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")

    @property
    def num_classes(self) -> int:
        return self.fc.out_features

    def forward(self, windows: torch.Tensor) -> torch.Tensor:
        if windows.ndim != 4 or windows.shape[1:] != (1, INPUT, INPUT):
            raise InputError(f"windows must have shape (B, 1, {INPUT}, {INPUT}), got {tuple(windows.shape)}")
        return self.fc(self.stages(self.stem(windows)).mean((2, 3)))

    def dense(self, image: torch.Tensor) -> torch.Tensor:
        if image.ndim != 4 or image.shape[1] != 1 or min(image.shape[-2:]) < INPUT:
            raise InputError(f"image must have shape (B, 1, H>={INPUT}, W>={INPUT}), got {tuple(image.shape)}")
        h, w = image.shape[-2:]
        image = image[..., : h - h % 4, : w - w % 4]
        features = F.avg_pool2d(self.stages(self.stem(image)), INPUT // 4, stride=1)
        return torch.einsum("bchw,kc->bkhw", features, self.fc.weight) + self.fc.bias[None, :, None, None]


def resnet20(num_classes: int) -> CifarResNet:
    """ResNet-20 (CIFAR-style, 0.27M parameters)."""
    return CifarResNet(num_classes, blocks=3)


def resnet56(num_classes: int) -> CifarResNet:
    """ResNet-56 (CIFAR-style, 0.85M parameters)."""
    return CifarResNet(num_classes, blocks=9)
