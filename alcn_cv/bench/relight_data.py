"""Registered multi-illumination sets for ``alcn bench relight``: a fixed camera, many lights.

A *scene* is a set of frames of one fixed view under different light, registered (the camera
did not move), so a pixel is the same point of the scene in every frame. Layouts read by
:func:`load_scenes`, from a root folder:

* the webcam layout (``../shared/data/webcam``): one folder per scene, ``<root>/<scene>/*.jpg``;
* the Phos layout: one folder per object holding its photographs under different light;
* the photometric-stereo layout (``../shared/data/psm``): ``NAME.0.png`` .. ``NAME.11.png`` per
  object, in one folder per object or all in one folder; files are grouped by ``NAME`` and
  ``NAME.mask.png`` (a mask, not a frame) is skipped.

A folder's images named ``NAME.<index>.<ext>`` form the scene ``NAME`` (ordered by index); its
other images form the scene named after the folder (ordered by name). Images directly in the
root count as a folder's. Frames are read with :func:`alcn_cv.io.read_image` as uint8 grayscale.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import IMAGE_SUFFIXES, list_images, read_image

__all__ = ["Scene", "load_scene_folder", "load_scenes", "select_scenes"]

logger = logging.getLogger(__name__)

_INDEXED = re.compile(r"^(?P<name>.+)\.(?P<index>\d+)$")
_MASK = re.compile(r"\.mask$", re.IGNORECASE)


@dataclass(frozen=True, eq=False)
class Scene:
    """The frames of one fixed view under different light.

    Attributes:
        name: the scene's name (its folder, or ``NAME`` of ``NAME.<i>.png``).
        group: the name of the root folder it was read from (``webcam``, ``psm``).
        frames: ``(n, H, W)`` uint8 grayscale frames, registered.
        files: the file name of each frame.
    """

    name: str
    group: str
    frames: np.ndarray
    files: tuple[str, ...]


def _gray_u8(path: Path) -> np.ndarray:
    img = read_image(path)
    if img.dtype == np.uint16:
        img = np.rint(img / np.float32(257.0)).astype(np.uint8)
    return img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)


def _evenly_spaced(n: int, max_frames: int | None) -> list[int]:
    """``max_frames`` indices spread over ``range(n)`` (all of them when there are fewer)."""
    if max_frames is None or n <= max_frames:
        return list(range(n))
    return sorted({int(round(v)) for v in np.linspace(0, n - 1, max_frames)})


def _group_files(folder: Path) -> dict[str, list[Path]]:
    """The frames of ``folder`` by scene: ``NAME.<i>.<ext>`` by ``NAME`` (masks skipped), the rest by the folder."""
    try:
        files = list_images(folder)
    except InputError:
        return {}
    indexed: dict[str, list[tuple[int, Path]]] = {}
    plain: list[Path] = []
    for path in files:
        if _MASK.search(path.stem):
            continue
        m = _INDEXED.match(path.stem)
        if m:
            indexed.setdefault(m.group("name"), []).append((int(m.group("index")), path))
        else:
            plain.append(path)
    groups = {name: [p for _, p in sorted(items)] for name, items in sorted(indexed.items())}
    if plain:
        groups.setdefault(folder.name, []).extend(plain)
    return groups


def load_scene_folder(root: str | os.PathLike, max_frames: int | None = None) -> list[Scene]:
    """Every scene under ``root`` (see the module docstring), each with at most ``max_frames``
    frames, evenly spaced over its ordered files.

    Raises:
        DatasetError: ``root`` is not a folder, holds no scene of at least two frames, or a
            scene's frames differ in size.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder")
    if max_frames is not None and max_frames < 2:
        raise InputError(f"max_frames must be at least 2, got {max_frames}")
    folders = [root] + sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith("."))
    scenes = []
    for folder in folders:
        for name, paths in _group_files(folder).items():
            if len(paths) < 2:
                logger.debug("skipping %s/%s: fewer than two frames", folder, name)
                continue
            paths = [paths[i] for i in _evenly_spaced(len(paths), max_frames)]
            frames = [_gray_u8(p) for p in paths]
            if any(f.shape != frames[0].shape for f in frames):
                raise DatasetError(f"{folder}: the frames of scene {name!r} differ in size (not registered)")
            scenes.append(Scene(name, root.name, np.stack(frames), tuple(p.name for p in paths)))
    if not scenes:
        raise DatasetError(
            f"{root}: no scene (a folder of at least two frames, or NAME.<i>{'|'.join(sorted(IMAGE_SUFFIXES))})"
        )
    return scenes


def load_scenes(roots: Sequence[str | os.PathLike], max_frames: int | None = None) -> list[Scene]:
    """The scenes of several roots (:func:`load_scene_folder`); scene names must be unique.

    Raises:
        DatasetError: as :func:`load_scene_folder`, or two scenes with the same name.
    """
    scenes = [s for root in roots for s in load_scene_folder(root, max_frames)]
    seen: set[str] = set()
    for scene in scenes:
        if scene.name in seen:
            raise DatasetError(f"two scenes named {scene.name!r}; give roots whose scene names differ")
        seen.add(scene.name)
    return scenes


def select_scenes(scenes: Sequence[Scene], tokens: Sequence[str]) -> list[Scene]:
    """The scenes named by ``tokens``, each a scene name or a root's name (all its scenes), in order.

    Raises:
        InputError: a token names no scene and no root.
    """
    chosen: list[Scene] = []
    for token in tokens:
        hits = [s for s in scenes if token in (s.name, s.group)]
        if not hits:
            names = ", ".join(sorted({s.name for s in scenes} | {s.group for s in scenes}))
            raise InputError(f"no scene or data set {token!r}; available: {names}")
        chosen += [s for s in hits if all(s is not c for c in chosen)]
    return chosen
