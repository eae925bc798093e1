"""The deep baselines of the detection benchmark (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3.1): window
classifiers trained on the raw images, without normalization (:mod:`alcn_cv.bench.detect`).

**Plain CNN** (:class:`PlainCNN`), the "best plain CNN" baseline, of configurable depth and width:
two stages of ``depth`` 3x3 convolutions without padding + ReLU, each followed by 2x2
max-pooling (widths ``width`` and ``2 * width``), a fully connected layer stored as a
convolution over the remaining feature map, and the class scores. Without padding, the
network runs fully-convolutionally over a whole image exactly as on each 32x32 window
(:meth:`PlainCNN.dense`, stride 4), like :class:`~alcn_cv.nets.Detector`.

**CIFAR-style residual networks** (:class:`CifarResNet`; He, Zhang, Ren & Sun, "Deep residual learning for image
recognition", CVPR 2016, Sec. 4.2): the ResNet-20 and ResNet-56 baselines, on 32x32 grayscale windows.

``6n + 2`` layers: a 3x3 convolution (16 channels), three stages of ``n`` basic blocks (two 3x3
convolutions with batch normalization) with 16, 32 and 64 channels, the last two starting with
stride 2 (shortcut: 1x1 convolution with stride 2 and batch normalization, option B), global
average pooling and a linear layer. ResNet-20: ``n = 3``; ResNet-56: ``n = 9``.

:meth:`CifarResNet.dense` runs it over a whole image: the convolutions over the image, then an
8x8 average pooling with stride 1 of the final (1/4-resolution) feature map, which is the
global average of each 32x32 window at stride 4. Run on a bare 32x32 window, the padded
convolutions see zeros around it where the dense run sees the image, so a network trained on
bare windows scores whole images badly. With ``context=c`` the network is trained on windows
with ``c`` pixels of their surroundings (``32 + 2c`` square) and classifies from the feature
cells of the central 32x32 only, exactly what :meth:`~CifarResNet.dense` pools: training and
dense scoring then differ only where a cell's receptive field reaches more than ``c`` pixels
beyond the window.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from alcn_cv.errors import InputError
from alcn_cv.nets.detector import INPUT, WindowClassifier

__all__ = ["PLAIN_HIDDEN", "CifarResNet", "PlainCNN", "resnet20", "resnet56"]


#: Width of :class:`PlainCNN`'s fully connected layer.
PLAIN_HIDDEN = 256


def _feature_size(depth: int) -> int:
    size = INPUT
    for _ in range(2):
        size = (size - 2 * depth) // 2
    return size


class PlainCNN(WindowClassifier):
    """Plain convolutional window classifier.

    Args:
        num_classes: background + objects (>= 2).
        depth: 3x3 convolutions per stage (1 to 4; 2 stages, so 2 to 8 convolutions in all).
        width: channels of the first stage (the second has twice as many); the fully connected layer has
            :data:`PLAIN_HIDDEN` channels.

    Shape:
        - :meth:`forward`: ``(B, 1, 32, 32)`` -> ``(B, num_classes)`` logits
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, num_classes, (H-32)//4+1, (W-32)//4+1)``
    """

    def __init__(self, num_classes: int, depth: int = 2, width: int = 32) -> None:
        super().__init__()
        if num_classes < 2:
            raise InputError(f"a classifier needs background and at least one object, got {num_classes} classes")
        if not 1 <= depth <= 4 or width < 1:
            raise InputError(f"need 1 <= depth <= 4 and width >= 1, got {depth} and {width}")
        self.config = {"num_classes": num_classes, "depth": depth, "width": width, "hidden": PLAIN_HIDDEN}
        layers: list[nn.Module] = []
        channels = 1
        for stage in range(2):
            out = width * 2**stage
            for _ in range(depth):
                layers += [nn.Conv2d(channels, out, 3), nn.ReLU(inplace=True)]
                channels = out
            layers.append(nn.MaxPool2d(2))
        self.features = nn.Sequential(*layers)
        f = _feature_size(depth)
        self.classifier = nn.Sequential(
            nn.Conv2d(channels, PLAIN_HIDDEN, f), nn.ReLU(inplace=True), nn.Conv2d(PLAIN_HIDDEN, num_classes, 1)
        )


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
        context: pixels of surroundings on each side of the 32x32 window in the inputs of
            :meth:`forward` (a multiple of 4; 0: the plain CIFAR network), see the module's
            docstring.

    Shape:
        - :meth:`forward`: ``(B, 1, S, S)`` -> ``(B, num_classes)`` logits, ``S = 32 + 2 * context``
          (:attr:`input_size`)
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, num_classes, H//4-7, W//4-7)`` for H, W
          multiples of 4 (entry ``(i, j)`` scores the window with top-left corner ``(4i, 4j)``).
    """

    stride = 4

    def __init__(self, num_classes: int, blocks: int = 3, context: int = 0) -> None:
        super().__init__()
        if num_classes < 2 or blocks < 1:
            raise InputError(f"need num_classes >= 2 and blocks >= 1, got {num_classes} and {blocks}")
        if context < 0 or context % self.stride:
            raise InputError(f"context must be a non-negative multiple of {self.stride}, got {context}")
        self.context = context
        self.input_size = INPUT + 2 * context
        self.config = {"num_classes": num_classes, "blocks": blocks, "context": context}
        self.stem = nn.Sequential(nn.Conv2d(1, 16, 3, 1, 1, bias=False), nn.BatchNorm2d(16), nn.ReLU(inplace=True))
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
        size = self.input_size
        if windows.ndim != 4 or windows.shape[1:] != (1, size, size):
            raise InputError(f"windows must have shape (B, 1, {size}, {size}), got {tuple(windows.shape)}")
        c, cells = self.context // self.stride, INPUT // self.stride
        return self.fc(self.stages(self.stem(windows))[..., c : c + cells, c : c + cells].mean((2, 3)))

    def dense(self, image: torch.Tensor) -> torch.Tensor:
        if image.ndim != 4 or image.shape[1] != 1 or min(image.shape[-2:]) < INPUT:
            raise InputError(f"image must have shape (B, 1, H>={INPUT}, W>={INPUT}), got {tuple(image.shape)}")
        h, w = image.shape[-2:]
        image = image[..., : h - h % 4, : w - w % 4]
        features = F.avg_pool2d(self.stages(self.stem(image)), INPUT // 4, stride=1)
        return torch.einsum("bchw,kc->bkhw", features, self.fc.weight) + self.fc.bias[None, :, None, None]


def resnet20(num_classes: int, context: int = 0) -> CifarResNet:
    """ResNet-20 (CIFAR-style, 0.27M parameters)."""
    return CifarResNet(num_classes, blocks=3, context=context)


def resnet56(num_classes: int, context: int = 0) -> CifarResNet:
    """ResNet-56 (CIFAR-style, 0.85M parameters)."""
    return CifarResNet(num_classes, blocks=9, context=context)
