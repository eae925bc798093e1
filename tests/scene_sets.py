"""Small registered multi-light scenes on disk, in the layouts of :mod:`alcn_cv.data.scenes`."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from scipy import ndimage

__all__ = ["lit", "make_sets", "texture", "write_scene"]


def texture(h: int = 120, w: int = 160, seed: int = 0) -> np.ndarray:
    """A smooth random texture ``(h, w)`` in [0, 1]."""
    rng = np.random.default_rng(seed)
    t = ndimage.gaussian_filter(rng.random((h, w)), 1.5)
    return (t - t.min()) / np.ptp(t)


def lit(texture: np.ndarray) -> list[np.ndarray]:
    """The texture under three lights, uint8: a gain, another gain, a brightness gradient."""
    h, w = texture.shape
    ramp = np.linspace(0.3, 1.0, w)[None, :]
    lights = [0.9 * np.ones((h, w)), 0.35 * np.ones((h, w)), ramp * np.ones((h, w))]
    return [np.rint(np.clip((0.15 + 0.8 * texture) * light, 0, 1) * 255).astype(np.uint8) for light in lights]


def write_scene(
    folder: Path,
    frames: int = 3,
    h: int = 120,
    w: int = 136,
    seed: int = 0,
    *,
    gamma: tuple[float, float] | None = (0.6, 1.6),
    noise: float = 0.3,
) -> Path:
    """A registered scene in ``folder`` (made): one texture under a different uneven light in each frame
    (``00.png``...), raised to a gamma drawn in ``gamma`` (None: none drawn) and with multiplicative noise of
    standard deviation ``noise``."""
    rng = np.random.default_rng(seed)
    t = cv2.GaussianBlur(rng.random((h, w)).astype(np.float32), (0, 0), 1.5)
    t = (t - t.min()) / (t.max() - t.min())
    folder.mkdir(parents=True)
    yy, xx = np.mgrid[0:h, 0:w] / max(h, w)
    for i in range(frames):
        light = np.exp(rng.uniform(-1.5, 0.0) + rng.uniform(-1.5, 1.5) * xx + rng.uniform(-1.0, 1.0) * yy)
        frame = (0.3 + 0.4 * t) ** rng.uniform(*gamma) * light if gamma else (0.3 + 0.4 * t) * light
        frame = np.clip(frame * (1 + noise * rng.standard_normal((h, w))), 0, 1)
        cv2.imwrite(str(folder / f"{i:02d}.png"), np.rint(255 * frame).astype(np.uint8))
    return folder


def make_sets(root: Path) -> Path:
    """Under ``root``: a webcam-style folder of two scenes (``street``, ``square``; 3 frames of
    120x160) and a photometric-stereo folder (``psm/ball``: 4 frames of 100x130 and a mask, and a
    folder without frames)."""
    for name, seed in (("street", 0), ("square", 1)):
        folder = root / "webcam" / name
        folder.mkdir(parents=True)
        for i, frame in enumerate(lit(texture(seed=seed))):
            cv2.imwrite(str(folder / f"2013010{i}_1200.png"), frame)
    psm = root / "psm" / "ball"
    psm.mkdir(parents=True)
    frames = lit(texture(100, 130, seed=2))
    for i in (0, 1, 2, 10):  # NAME.10 sorts after NAME.2
        cv2.imwrite(str(psm / f"ball.{i}.png"), frames[i % 3])
    cv2.imwrite(str(psm / "ball.mask.png"), np.full((100, 130), 255, np.uint8))
    (root / "psm" / "notes").mkdir()  # a folder without frames is no scene
    return root
