"""The rendered stand-in for faces under hard directional light (experiments/directional_light.py and
relief_training.py's faces): ``alcn data scenes --lighting directional``'s scenes, each an identity, rendered in
memory at the stand-in's number, side and seed."""

from __future__ import annotations

import _run  # noqa: F401  (puts the checkout's packages on the path, also when not installed)
import numpy as np

from alcn_cv.data.relief_scenes import render_scenes

#: The stand-in: its identities (scenes), the side of its images (pixels) and its rendering seed.
IDENTITIES, SIZE, SEED = 80, 128, 7


def render_stand_in(identities: int = IDENTITIES, size: int = SIZE, seed: int = SEED) -> np.ndarray:
    """``(identities, DIRECTIONAL_FRAMES, size, size)`` uint8: each scene's gallery, then its probes."""
    return np.stack([frames for frames, _ in render_scenes(identities, side=size, seed=seed, lighting="directional")])
