"""The rendered stand-in for faces under hard directional light (experiments/directional_light.py, and
relief_training.py's training scenes): relief scenes of the data engine, each an identity, under a frontal light
(the gallery) and under directional light at several elevations (the probes), identified by correlation."""

from __future__ import annotations

import _run  # noqa: F401  (puts the checkout's packages on the path, also when not installed)
import cv2
import numpy as np
from tqdm.auto import tqdm

#: Elevations of the probes' light above the ground (degrees); the gallery is lit from 90.
ELEVATIONS = (75, 55, 35, 20, 12)
AZIMUTHS = 4
#: Sides of the compared images (pixels).
SIZES = (32, 64)


def render_identity(index: int, size: int, seed: int) -> np.ndarray:
    """``(1 + len(ELEVATIONS) * AZIMUTHS, size, size)`` uint8: scene ``index`` under the gallery's light, then
    under the probes'."""
    from alcn_cv.data.lighting import Lighting, directional
    from alcn_cv.data.objects import to_surface
    from alcn_cv.data.relief_scenes import relief_surface
    from alcn_cv.data.render import render_surfaces

    rng = np.random.default_rng([seed, index])
    albedo, height, material = relief_surface(rng, size)
    lightings = [Lighting("ambient", [directional(0.0, 90.0)], np.full(3, 0.05), gain=0.9)]
    for elevation in ELEVATIONS:
        for _ in range(AZIMUTHS):
            light = directional(rng.uniform(0.0, 360.0), elevation)
            gain = rng.uniform(0.6, 1.4)
            lightings.append(Lighting("side", [light], np.full(3, 0.02), gain=gain, shot_noise=5e-4, read_noise=3e-3))
    surface = to_surface([(albedo, height, material)] * len(lightings))
    return render_surfaces(surface, lightings, rng, gray=True, shadow_steps=24)


def render_stand_in(identities: int = 80, size: int = 128, seed: int = 7) -> np.ndarray:
    """``(identities, 1 + len(ELEVATIONS) * AZIMUTHS, size, size)`` uint8: :func:`render_identity` of each."""
    return np.stack([render_identity(i, size, seed) for i in tqdm(range(identities), desc="render", unit="scene")])


def identify(spec: str, images: np.ndarray) -> dict[int, dict[str, float]]:
    """:func:`identification` of the images of :func:`render_stand_in` normalized by the method ``spec``'s
    ``apply()`` (float output), for each side of :data:`SIZES`."""
    from alcn_cv.enhance.registry import from_spec

    norm = from_spec(spec)
    normalized = np.stack([[norm.apply(im, out_dtype=np.float32) for im in scene] for scene in images])
    return {size: identification(normalized, size) for size in SIZES}


def descriptors(images: np.ndarray, size: int) -> np.ndarray:
    """``(..., H, W)`` float -> ``(..., size * size)``: area-resized, zero-mean, unit-norm."""
    flat = images.reshape(-1, *images.shape[-2:])
    small = np.stack([cv2.resize(im, (size, size), interpolation=cv2.INTER_AREA).ravel() for im in flat])
    small -= small.mean(axis=1, keepdims=True)
    small /= np.linalg.norm(small, axis=1, keepdims=True) + 1e-9
    return small.reshape(*images.shape[:-2], size * size)


def identification(normalized: np.ndarray, size: int) -> dict[str, float]:
    """Per elevation, the percentage of probes whose most correlated gallery image is their own scene's."""
    features = descriptors(normalized, size)
    gallery, identities = features[:, 0], np.arange(len(features))
    result = {}
    for j, elevation in enumerate(ELEVATIONS):
        probes = features[:, 1 + j * AZIMUTHS : 1 + (j + 1) * AZIMUTHS]
        nearest = np.argmax(probes @ gallery.T, axis=-1)
        result[f"elevation {elevation}"] = float(100 * np.mean(nearest == identities[:, None]))
    return result
