"""A plain CNN window classifier of configurable depth and width: the "best plain CNN" baseline
of Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3.1 (deep networks trained on the raw images).

Two stages of ``depth`` 3x3 convolutions without padding + ReLU, each followed by 2x2
max-pooling (widths ``width`` and ``2 * width``), a fully connected layer stored as a
convolution over the remaining feature map, and the class scores. Without padding, the
network runs fully-convolutionally over a whole image exactly as on each 32x32 window
(:meth:`PlainCNN.dense`, stride 4), like :class:`~alcn_cv.nets.Detector`.
"""

from __future__ import annotations

from torch import nn

from alcn_cv.errors import InputError
from alcn_cv.nets.detector import INPUT, WindowClassifier

__all__ = ["PlainCNN"]


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
        width: channels of the first stage (the second has twice as many).
        hidden: width of the fully connected layer.

    Shape:
        - :meth:`forward`: ``(B, 1, 32, 32)`` -> ``(B, num_classes)`` logits
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, num_classes, (H-32)//4+1, (W-32)//4+1)``
    """

    def __init__(self, num_classes: int, depth: int = 2, width: int = 32, hidden: int = 256) -> None:
        super().__init__()
        if num_classes < 2:
            raise InputError(f"a classifier needs background and at least one object, got {num_classes} classes")
        if not 1 <= depth <= 4 or width < 1 or hidden < 1:
            raise InputError(f"need 1 <= depth <= 4, width >= 1 and hidden >= 1, got {depth}, {width}, {hidden}")
        self.config = {"num_classes": num_classes, "depth": depth, "width": width, "hidden": hidden}
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
            nn.Conv2d(channels, hidden, f), nn.ReLU(inplace=True), nn.Conv2d(hidden, num_classes, 1)
        )
