"""Rendered registered scenes (``alcn data scenes``): one fixed view of a relief scene under many lights.

The real multi-light scenes that train the gain Normalizer (:mod:`alcn_cv.data.scenes`, the
``webcam`` layout: one folder per scene, frames of a fixed camera under other light) are
outdoor scenes under daylight. Directional light on relief (grazing sun, lamps, spots, cast
shadows: the paper's Phos and its objects, faces) is rare there, and no such real set can be
downloaded at run time, so the data engine renders it: a textured, uneven ground with relief
objects (:mod:`alcn_cv.data.objects`) seen from above. Every frame of a scene shows the same geometry
and albedo, so the frames are registered exactly, as the trainer's layout requires. The lightings
(``lighting``, :data:`LIGHTINGS`):

* ``families`` (:func:`render_scene`): ``frames`` lightings drawn from :data:`FAMILIES`;
* ``directional`` (:func:`render_directional_scene`): hard directional light, the rendered stand-in for
  faces under Yale-B-like light: a frontal light (the gallery), then :data:`AZIMUTHS` directional lights
  at random azimuths at each of :data:`ELEVATIONS` (the probes), with cast shadows, gain and sensor noise;
  :data:`DIRECTIONAL_FRAMES` frames in that order (identified by :mod:`alcn_cv.bench.directional`).

Output (``generate``): ``out/scene_000/frame_00.png`` ... (grayscale PNG) and ``manifest.json``
(kind ``relief_scenes``, the parameters and the light family of every frame); :func:`render_scenes`
gives the same frames in memory. Scene ``i`` draws from ``numpy.random.default_rng([seed, i])``: the
output does not depend on ``workers``, and the first scenes of a larger run equal those of a smaller one.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from alcn_cv.data.lighting import LIGHT_FAMILIES, Lighting, directional, sample_lighting
from alcn_cv.data.manifest import atomic_output_dir, make_manifest
from alcn_cv.data.objects import background_surface, make_object, paste, to_surface
from alcn_cv.data.parallel import parallel_map
from alcn_cv.data.relief_settings import AZIMUTHS, DIRECTIONAL_FRAMES, ELEVATIONS, FRAMES, LIGHTINGS, MAX_SIDE, MIN_SIDE
from alcn_cv.data.render import render_surfaces
from alcn_cv.data.textures import random_texture
from alcn_cv.errors import InputError
from alcn_cv.io import write_image, write_json

__all__ = [
    "KIND",
    "generate",
    "relief_surface",
    "render_directional_scene",
    "render_scene",
    "render_scenes",
]

logger = logging.getLogger(__name__)

#: The ``kind`` of the manifest.
KIND = "relief_scenes"
#: Light families of the frames: every family but ``colour`` (the frames are grayscale).
FAMILIES: tuple[str, ...] = tuple(f for f in LIGHT_FAMILIES if f != "colour")
_CANONICAL = 96


def render_scene(
    rng: np.random.Generator,
    size: int,
    frames: int,
    objects: tuple[int, int] = (3, 7),
    families: Sequence[str] = FAMILIES,
) -> tuple[np.ndarray, list[str]]:
    """One scene of ``size x size`` pixels under ``frames`` lightings.

    Args:
        rng: the scene's generator (geometry, albedo, lights, noise).
        size: side of the frames (pixels).
        frames: number of lightings (frames).
        objects: least and most relief objects on the ground.
        families: light families, drawn uniformly for each frame.

    Returns:
        ``(frames, size, size)`` uint8 grayscale frames and the family of each.
    """
    if frames < 2:
        raise InputError(f"need frames >= 2, got {frames}")
    albedo, height, material = relief_surface(rng, size, objects)
    names = [str(families[int(i)]) for i in rng.integers(len(families), size=frames)]
    relief = float(height.max())
    lightings = [sample_lighting(rng, name, size, size, relief=relief) for name in names]
    surface = to_surface([(albedo, height, material)] * frames)
    return render_surfaces(surface, lightings, rng, gray=True, shadow_steps=12, shadow_scale=2), names


def render_directional_scene(rng: np.random.Generator, size: int) -> tuple[np.ndarray, list[str]]:
    """One scene of ``size x size`` pixels under the ``directional`` lighting (see the module).

    Args:
        rng: the scene's generator (geometry, albedo, azimuths, gains, noise).
        size: side of the frames (pixels).

    Returns:
        ``(DIRECTIONAL_FRAMES, size, size)`` uint8 grayscale frames: the gallery (frontal light), then
        :data:`AZIMUTHS` probes at each of :data:`ELEVATIONS` in order; and the family of each (``ambient``
        for the gallery, ``side`` for the probes).
    """
    albedo, height, material = relief_surface(rng, size)
    lightings = [Lighting("ambient", [directional(0.0, 90.0)], np.full(3, 0.05), gain=0.9)]
    for elevation in ELEVATIONS:
        for _ in range(AZIMUTHS):
            light = directional(rng.uniform(0.0, 360.0), elevation)
            gain = rng.uniform(0.6, 1.4)
            lightings.append(Lighting("side", [light], np.full(3, 0.02), gain=gain, shot_noise=5e-4, read_noise=3e-3))
    surface = to_surface([(albedo, height, material)] * len(lightings))
    return render_surfaces(surface, lightings, rng, gray=True, shadow_steps=24), [x.family for x in lightings]


def relief_surface(
    rng: np.random.Generator, size: int, objects: tuple[int, int] = (3, 7)
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The surface of one scene: a textured, uneven ground of ``size x size`` pixels with relief objects.

    Args:
        rng: the scene's generator.
        size: side of the surface (pixels).
        objects: least and most relief objects on the ground.

    Returns:
        ``(albedo, height, material)`` as :func:`~alcn_cv.data.objects.background_surface` gives them, for
        :func:`~alcn_cv.data.objects.to_surface` and :func:`~alcn_cv.data.render.render_surfaces`.
    """
    if size < MIN_SIDE or not 1 <= objects[0] <= objects[1]:
        raise InputError(f"need size >= {MIN_SIDE} and 1 <= objects[0] <= objects[1]; got {size}, {objects}")
    albedo, height, material = background_surface(rng, size, size, random_texture(rng, size, p_photo=0.6))
    for _ in range(int(rng.integers(objects[0], objects[1] + 1))):
        extent = rng.uniform(0.15, 0.4) * size
        paste(
            albedo,
            height,
            material,
            make_object(rng, _CANONICAL),
            tuple(rng.uniform(0.1, 0.9, 2) * size),
            extent / (0.92 * _CANONICAL),
            rng.uniform(0, 360),
        )
    return albedo, height, material


def _scene_job(job: tuple[int, int, int, int, str]) -> tuple[np.ndarray, list[str]]:
    seed, index, size, frames, lighting = job
    rng = np.random.default_rng([seed, index])
    return render_directional_scene(rng, size) if lighting == "directional" else render_scene(rng, size, frames)


def _frames(scenes: int, frames: int | None, side: int, lighting: str) -> int:
    """The frames per scene of ``lighting`` (``frames``, or its default), the arguments checked; render_scene and
    relief_surface check them too, but in the workers, after the progress bar has started."""
    if lighting not in LIGHTINGS:
        raise InputError(f"unknown --lighting {lighting!r}; choose from {', '.join(LIGHTINGS)}")
    if scenes < 1:
        raise InputError(f"need at least one scene (--scenes), got {scenes}")
    if not MIN_SIDE <= side <= MAX_SIDE:
        raise InputError(f"--side is the side of the frames in pixels, from {MIN_SIDE} to {MAX_SIDE}; got {side}")
    if lighting == "directional":
        if frames not in (None, DIRECTIONAL_FRAMES):
            raise InputError(
                f"--lighting directional renders {DIRECTIONAL_FRAMES} frames (the gallery and {AZIMUTHS} probes at "
                f"each of {len(ELEVATIONS)} elevations); got --frames {frames}"
            )
        return DIRECTIONAL_FRAMES
    frames = FRAMES if frames is None else frames
    if frames < 2:
        raise InputError(f"need at least 2 frames (lightings) per scene (--frames), got {frames}")
    return frames


def render_scenes(
    scenes: int,
    frames: int | None = None,
    side: int = 320,
    seed: int = 0,
    lighting: str = "families",
    *,
    workers: int = 1,
    progress: bool = True,
) -> Iterator[tuple[np.ndarray, list[str]]]:
    """The frames of :func:`generate`, scene by scene: ``(frames, side, side)`` uint8 frames and the light family of
    each (``frames``: default :data:`FRAMES`; ``directional``: :data:`DIRECTIONAL_FRAMES`, the only value it
    takes; ``side``: from :data:`MIN_SIDE` to :data:`MAX_SIDE`). The arguments are checked when called, the scenes
    rendered as they are taken."""
    frames = _frames(scenes, frames, side, lighting)
    jobs = [(int(seed), i, int(side), frames, lighting) for i in range(scenes)]
    return parallel_map(_scene_job, jobs, workers=workers, desc="relief scenes", unit="scene", progress=progress)


def generate(
    out_dir: str | os.PathLike,
    scenes: int = 24,
    frames: int | None = None,
    side: int = 320,
    seed: int = 0,
    *,
    lighting: str = "families",
    overwrite: bool = False,
    workers: int = 1,
    progress: bool = True,
) -> Path:
    """Render ``scenes`` registered scenes into ``out_dir`` (written atomically; see the module and
    :func:`render_scenes` for the arguments).

    Returns:
        The output folder: a folder of scenes, ``scene_NNN`` (:func:`alcn_cv.data.scenes.load_scene_folder`;
        ``alcn train-real-light --set 'rendered=["DIR"]'``).
    """
    frames = _frames(scenes, frames, side, lighting)
    # rendered inside the block: atomic_output_dir refuses an existing or unwritable output before the minutes of work
    with atomic_output_dir(out_dir, overwrite=overwrite) as tmp:
        rendered = render_scenes(scenes, frames, side, seed, lighting, workers=workers, progress=progress)
        lights = {}
        for i, (stack, names) in enumerate(rendered):
            folder = tmp / f"scene_{i:03d}"
            folder.mkdir()
            for j, frame in enumerate(stack):
                write_image(folder / f"frame_{j:02d}.png", frame)  # raises where cv2.imwrite returns False
            lights[folder.name] = names
        write_json(
            tmp / "manifest.json",
            make_manifest(
                KIND,
                seed,
                {
                    "scenes": scenes,
                    "frames": frames,
                    "side": side,
                    "lighting": lighting,
                    "families": list(FAMILIES) if lighting == "families" else ["ambient", "side"],
                },
                lights=lights,
            ),
        )
    logger.info("wrote %d scenes of %d frames (%dx%d) to %s", scenes, frames, side, side, out_dir)
    return Path(out_dir)
