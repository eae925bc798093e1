"""The detector CNN trained jointly with the Normalizer (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.2).

It classifies the 32x32 centre of a normalized 48x48 window into background (class 0) or
one of the objects (classes 1..K). Architecture: 20 convolutions 5x5 + 2x2 max-pooling, 50
convolutions 5x5 + 2x2 max-pooling, a fully connected layer, and the class scores, with ReLU
activations. As in :class:`~alcn_cv.nets.Normalizer`, the fully connected layer is a
convolution so :meth:`Detector.dense` scores every window of an image at stride 4 in one pass.
"""

from __future__ import annotations

import torch
from torch import nn

from alcn_cv.errors import InputError

__all__ = ["Detector", "WindowClassifier"]

INPUT = 32


class WindowClassifier(nn.Module):
    """Base of the 32x32 window classifiers: ``features`` then ``classifier``, both convolutional
    without padding, so :meth:`dense` scores every window of an image at stride 4 exactly as
    :meth:`forward` scores one. Subclasses build the two ``nn.Sequential`` (the last layer of
    ``classifier`` a 1x1 convolution to the classes)."""

    input_size = INPUT
    stride = 4
    features: nn.Sequential
    classifier: nn.Sequential

    @property
    def num_classes(self) -> int:
        return self.classifier[-1].out_channels

    def forward(self, windows: torch.Tensor) -> torch.Tensor:
        if windows.ndim != 4 or windows.shape[1:] != (1, INPUT, INPUT):
            raise InputError(f"windows must have shape (B, 1, {INPUT}, {INPUT}), got {tuple(windows.shape)}")
        return self.classifier(self.features(windows)).flatten(1)

    def dense(self, image: torch.Tensor) -> torch.Tensor:
        if image.ndim != 4 or image.shape[1] != 1 or min(image.shape[-2:]) < INPUT:
            raise InputError(f"image must have shape (B, 1, H>={INPUT}, W>={INPUT}), got {tuple(image.shape)}")
        return self.classifier(self.features(image))


class Detector(WindowClassifier):
    """Window classifier: background vs. objects.

    Args:
        num_classes: number of classes, background included (>= 2).
        channels: widths of the two convolution layers.
        hidden: width of the fully connected layer.
        dropout: dropout before the last layer (training only).

    Shape:
        - :meth:`forward`: ``(B, 1, 32, 32)`` normalized windows -> ``(B, num_classes)`` logits
        - :meth:`dense`: ``(B, 1, H, W)`` -> ``(B, num_classes, (H-32)//4+1, (W-32)//4+1)`` logits,
          entry ``(i, j)`` scoring the 32x32 window with top-left corner ``(4i, 4j)``.
    """

    def __init__(
        self, num_classes: int, channels: tuple[int, int] = (20, 50), hidden: int = 1024, dropout: float = 0.0
    ) -> None:
        super().__init__()
        if num_classes < 2:
            raise InputError(f"a detector needs background and at least one object, got {num_classes} classes")
        c1, c2 = channels
        self.config = {"num_classes": num_classes, "channels": [c1, c2], "hidden": hidden, "dropout": dropout}
        self.features = nn.Sequential(
            nn.Conv2d(1, c1, 5),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(c1, c2, 5),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
        )
        self.classifier = nn.Sequential(
            nn.Conv2d(c2, hidden, 5),  # fully connected over the 5x5x50 features
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
            nn.Conv2d(hidden, num_classes, 1),
        )
