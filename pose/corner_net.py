"""The corner network (torch): a dense window classifier with a sub-stride offset head.

Same geometry as :class:`alcn_cv.nets.Detector` (two 5x5 convolutions with 2x2 max-pooling, then
the fully connected layer as a 5x5 convolution; no padding), so one output cell scores the 32x32
window whose top-left corner is 4 times its index: per cell, ``1 + n`` class logits (background,
the ``n`` parts of the box: :func:`pose.box.box_parts`) and, per part, its offset
``(dx, dy)`` from the window's centre in units of the stride (4 pixels of the downscaled frame).
The offsets place a part finer than the stride, as the offset head of CenterNet (Zhou et al.,
"Objects as Points", 2019) does.
"""

from __future__ import annotations

import torch
from torch import nn

from pose.corners import STRIDE, WINDOW

__all__ = ["CornerNet"]


class CornerNet(nn.Module):
    """``(B, 1, H, W)`` -> ``(B, 3 n + 1, (H - 32) // 4 + 1, (W - 32) // 4 + 1)``: ``1 + n`` logits
    then ``n`` offsets ``(dx, dy)``.

    Batch normalization after every convolution (Ioffe & Szegedy, ICML 2015) speeds up the short
    training; the widths are those of the ``box`` recipe (:class:`pose.corner_train.CornerRecipe`).

    Args:
        num_parts: ``n``, the parts found (8: the box corners; 26 with the edges' middles and the
            faces' centres).
        channels: widths of the two convolutions.
        hidden: width of the fully connected layer (a 5x5 convolution).
        mixing: fully connected layers of that width after it (1x1 convolutions: the window and
            the stride unchanged, little time at the output's resolution).
    """

    input_size = WINDOW
    stride = STRIDE

    def __init__(
        self, num_parts: int = 26, channels: tuple[int, int] = (16, 32), hidden: int = 128, mixing: int = 1
    ) -> None:
        super().__init__()
        c1, c2 = channels
        self.config = {"num_parts": num_parts, "channels": [c1, c2], "hidden": hidden, "mixing": mixing}
        layers = [
            nn.Conv2d(1, c1, 5),
            nn.BatchNorm2d(c1),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(c1, c2, 5),
            nn.BatchNorm2d(c2),
            nn.ReLU(inplace=True),
            nn.MaxPool2d(2),
            nn.Conv2d(c2, hidden, 5),
            nn.BatchNorm2d(hidden),
            nn.ReLU(inplace=True),
        ]
        for _ in range(mixing):
            layers += [nn.Conv2d(hidden, hidden, 1), nn.BatchNorm2d(hidden), nn.ReLU(inplace=True)]
        self.features = nn.Sequential(*layers)
        self.head = nn.Conv2d(hidden, 1 + 3 * num_parts, 1)

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.head(self.features(image))
