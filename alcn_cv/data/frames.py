"""A reproducible textured frame under uneven light: the frames of ``alcn bench speed`` and of
the tests of the runtime (any size, gray or BGR, deterministic for a seed)."""

from __future__ import annotations

import cv2
import numpy as np

__all__ = ["synthetic_frame"]


def synthetic_frame(width: int, height: int, colour: bool, seed: int = 0, t: float = 0.0) -> np.ndarray:
    """A reproducible textured frame under uneven light: uint8 ``(H, W)`` or BGR ``(H, W, 3)``.

    Multi-scale noise texture and a few flat shapes (edges), lit by a light gradient and a soft
    shadow; ``t`` (seconds) moves the light and shifts the texture, for video.
    """
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float32)
    texture = np.zeros((height, width), np.float32)
    for octave in range(5):
        cell = 2 ** (octave + 1)
        small = rng.random((height // cell + 2, width // cell + 2), dtype=np.float32)
        smooth = cv2.resize(small, (width + cell, height + cell), interpolation=cv2.INTER_CUBIC)
        texture += smooth[:height, :width] / (octave + 1)
    texture = cv2.normalize(texture, None, 0.15, 0.85, cv2.NORM_MINMAX)
    for _ in range(6):
        cx, cy, r = rng.uniform(0, width), rng.uniform(0, height), rng.uniform(0.05, 0.2) * min(width, height)
        cv2.circle(texture, (int(cx), int(cy)), int(r), float(rng.uniform(0.1, 0.9)), -1)
    shift = np.float32([[1, 0, 8 * t], [0, 1, 4 * t]])
    texture = cv2.warpAffine(texture, shift, (width, height), borderMode=cv2.BORDER_REFLECT_101)
    light = 0.25 + 1.2 * np.exp(-(((x / width - 0.3 - 0.1 * np.sin(t)) ** 2) + (y / height - 0.4) ** 2) / 0.15)
    shadow = 1.0 - 0.6 / (1.0 + np.exp(-(x - 0.7 * width - 0.05 * width * np.cos(t)) / (0.01 * width + 1)))
    gray = np.clip(texture * light * shadow, 0, 1)
    if not colour:
        return np.rint(gray * 255).astype(np.uint8)
    bgr = np.dstack([gray, np.clip(0.8 * gray + 0.1, 0, 1), np.clip(gray * gray * 1.2, 0, 1)])
    return np.rint(bgr * 255).astype(np.uint8)
