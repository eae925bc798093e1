"""Real photographs that permit any use, for training on relit copies (:mod:`alcn_cv.data.light_changes`).

Two sources, each photograph with its licence:

* the photographs that ship inside the scikit-image wheel
  (:data:`alcn_cv.data.textures.SKIMAGE_PHOTOGRAPHS`, the photographs the data engine's textures
  are cut from): only those whose ``skimage.data`` docstring states public domain, CC0 or no known
  copyright restrictions, and that load without a download (``pooch``); the phrase of each
  docstring is kept and checked when it is read;
* OpenCV's samples under ``../shared/data`` (Apache-2.0, :data:`SHARED_PHOTOGRAPHS`): the
  chessboard views, the cookie box's still and frames of its video.

The ``webcam`` frames (academic research only) and the other shared sets are not listed: they
are validation data, not training data of a default that anyone may use.

Your own photographs (:func:`folder_photographs`, ``alcn train-real-light --set photos=[...]``) are relit the
same way; their terms are yours.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.data.light_changes import LIGHTS, relit_frames
from alcn_cv.data.scenes import Scene, read_eight_bits
from alcn_cv.data.textures import SKIMAGE_PHOTOGRAPHS, skimage_photograph
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import IMAGE_SUFFIXES, VideoReader, list_images, read_image, to_gray
from alcn_cv.report import listed

logger = logging.getLogger(__name__)

#: Photographs' formats that OpenCV does not read (phones' HEIF, cameras' raw files, animations): such files in a
#: ``photos`` folder are named in a warning, as skipped (other files, notes for instance, are skipped without a word).
UNREAD_PHOTO_SUFFIXES = frozenset(
    {".heic", ".heif", ".avif", ".jxl", ".gif", ".dng", ".cr2", ".cr3", ".nef", ".arw", ".orf", ".rw2", ".raf", ".raw"}
    - IMAGE_SUFFIXES
)

__all__ = [
    "PERMISSIVE_LICENCES",
    "SHARED_PHOTOGRAPHS",
    "USER_LICENCE",
    "Photograph",
    "folder_photographs",
    "permissive_photographs",
    "photo_files",
    "relit_scenes",
    "shared_photographs",
    "skimage_photographs",
    "training_photographs",
]

#: The licences a training photograph of the default may carry.
PERMISSIVE_LICENCES = ("public domain", "CC0", "no known copyright restrictions", "Apache-2.0", "rendered by alcn-cv")

#: The licence recorded for the photographs of :func:`folder_photographs`: the user's own terms.
USER_LICENCE = "the user's"

#: Files under the shared data (glob patterns) -> licence: OpenCV's samples.
SHARED_PHOTOGRAPHS: dict[str, str] = {
    "chessboard/left*.jpg": "Apache-2.0",
    "cookie_box/resized_IMG_3875.JPG": "Apache-2.0",
    "cookie_box/box.mp4": "Apache-2.0",
}


@dataclass(frozen=True)
class Photograph:
    """A training photograph: ``image`` uint8 grayscale ``HxW`` or BGR ``HxWx3``, its licence
    (one of :data:`PERMISSIVE_LICENCES`, or :data:`USER_LICENCE` for the user's) and where it comes from."""

    name: str
    image: np.ndarray
    licence: str
    source: str


def _fit(image: np.ndarray, max_side: int | None) -> np.ndarray:
    side = max(image.shape[:2])
    if max_side is None or side <= max_side:
        return image
    scale = max_side / side
    size = (round(image.shape[1] * scale), round(image.shape[0] * scale))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def skimage_photographs(max_side: int | None = 640) -> list[Photograph]:
    """The photographs of :data:`~alcn_cv.data.textures.SKIMAGE_PHOTOGRAPHS`, BGR or gray uint8, the
    longer side at most ``max_side``.

    Raises:
        DatasetError: as :func:`~alcn_cv.data.textures.skimage_photograph` (scikit-image is missing,
            or a docstring no longer states the recorded licence).
    """
    photos = []
    for name, (licence, _) in SKIMAGE_PHOTOGRAPHS.items():
        image = skimage_photograph(name)
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
        photos.append(Photograph(name, _fit(image, max_side), licence, f"skimage.data.{name}"))
    return photos


def _video_frames(path: Path, count: int) -> list[np.ndarray]:
    """``count`` frames evenly spaced over the video's header count (fewer if it ends before)."""
    with VideoReader(path) as video:
        wanted = set(np.linspace(0, max(len(video) - 1, 0), count).round().astype(int).tolist())
        return [frame for index, frame in zip(range(len(video)), video) if index in wanted]


def shared_photographs(root: str | Path, video_frames: int = 8, max_side: int | None = 640) -> list[Photograph]:
    """The photographs of :data:`SHARED_PHOTOGRAPHS` under ``root`` (the shared data folder):
    every still, and ``video_frames`` evenly spaced frames of each video.

    Raises:
        DatasetError: none of them is there.
    """
    root = Path(root)
    photos = []
    for pattern, licence in SHARED_PHOTOGRAPHS.items():
        for path in sorted(root.glob(pattern)):
            rel = path.relative_to(root).as_posix()
            if path.suffix.lower() == ".mp4":
                for k, frame in enumerate(_video_frames(path, video_frames)):
                    photos.append(Photograph(f"{rel}#{k}", _fit(frame, max_side), licence, rel))
            else:
                photos.append(Photograph(rel, _fit(read_image(path), max_side), licence, rel))
    if not photos:
        raise DatasetError(f"{root}: none of {', '.join(SHARED_PHOTOGRAPHS)} found")
    return photos


def photo_files(folders: Sequence[str | os.PathLike]) -> list[Path]:
    """The images directly in each of ``folders`` (:data:`~alcn_cv.io.IMAGE_SUFFIXES`, hidden files skipped), folder
    by folder in name order; ``~`` is expanded and a relative folder is taken from the working folder. Lists the
    folders only (what a configuration's check can afford).

    Raises:
        InputError: a folder is missing, a file (``photos`` lists folders: the run's checkpoint records each folder's
            files, for a resumed run to find them again), or holds no image (one line naming it).
    """
    files = []
    for given in folders:
        folder = Path(given).expanduser()
        if folder.is_file():
            raise InputError(
                f"photos: {given}: a file, not a folder: photos lists folders, and every image directly in each is "
                f"trained on; give its folder (photos=['{folder.parent}']) or put the photographs meant in one of "
                "their own"
            )
        if not folder.is_dir():
            raise InputError(f"photos: {given}: folder not found")
        try:
            files += list_images(folder)
        except InputError:
            kinds = ", ".join(sorted(IMAGE_SUFFIXES))
            unread = _unread_photos(folder)
            hint = f"; {listed(unread, 5)}: not read here (convert them to JPEG or PNG)" if unread else ""
            raise InputError(f"photos: {given}: no image ({kinds}) in this folder{hint}") from None
    return files


def _unread_photos(folder: Path) -> list[str]:
    """The names of the files of ``folder`` in a photograph's format that OpenCV does not read
    (:data:`UNREAD_PHOTO_SUFFIXES`), sorted."""
    return sorted(p.name for p in folder.iterdir() if p.suffix.lower() in UNREAD_PHOTO_SUFFIXES)


def folder_photographs(
    folders: Sequence[str | os.PathLike], min_side: int = 0, max_side: int | None = 640
) -> list[Photograph]:
    """The user's photographs: every image of :func:`photo_files` ``(folders)``, gray or colour, 8 or 16 bits
    (:func:`~alcn_cv.data.scenes.read_eight_bits`: rounded to 8 bits, with a warning when their values use less than
    a sixteenth of the range), the longer side brought to at most ``max_side`` as the shipped photographs', licence
    :data:`USER_LICENCE`, named ``FOLDER/FILE`` (the folder's own name).

    Raises:
        InputError: as :func:`photo_files`, an unreadable image, or one whose shorter side (once fitted) is below
            ``min_side`` (the training crop), the file and the minimum named.
    """
    photos = []
    paths = photo_files(folders)
    # said: a phone's HEIC or a camera's raw files would leave the run with fewer photographs without a word
    for given in folders:
        others = _unread_photos(Path(given).expanduser())
        if others:
            logger.warning("photos: %s: %s skipped: not an image OpenCV reads here", given, listed(others, 5))
    for path in paths:
        image = read_eight_bits(path)
        fitted = _fit(image, max_side)
        h, w = fitted.shape[:2]
        if min(h, w) < min_side:
            size = f"{image.shape[1]}x{image.shape[0]} pixels"
            if fitted is not image:
                size += f" ({w}x{h} once its longer side is brought to {max_side}, as the shipped photographs')"
            raise InputError(
                f"photos: {path}: {size}, smaller than the training crop: photographs need at least "
                f"{min_side}x{min_side} pixels (crop={min_side})"
            )
        photos.append(Photograph(f"{path.parent.name}/{path.name}", fitted, USER_LICENCE, str(path)))
    return photos


def permissive_photographs(shared: str | Path) -> list[Photograph]:
    """Every photograph of scikit-image's and of the shared OpenCV samples under ``shared``, the longer side at most
    640 pixels."""
    return skimage_photographs() + shared_photographs(shared)


def training_photographs(shared: str | Path) -> list[Photograph]:
    """:func:`permissive_photographs` with a third of the near-identical chessboard views and half of the
    cookie box's video frames, so that no view weighs much more than the others in training."""
    photos = permissive_photographs(shared)
    chessboards = [p for p in photos if p.name.startswith("chessboard/")]
    video = [p for p in photos if "#" in p.name]
    # by name: a Photograph's == would compare its pixels (a dataclass compares every field)
    thinned = {p.name for p in chessboards + video}
    return [p for p in photos if p.name not in thinned] + chessboards[::3] + video[::2]


def relit_scenes(
    photos: list[Photograph], frames: int, seed: int = 0, light: str = "relief", jitter: float = 0.0
) -> list[Scene]:
    """Each photograph relit ``frames`` times (:func:`~alcn_cv.data.light_changes.relit_frames` with
    :data:`~alcn_cv.data.light_changes.LIGHTS` ``[light]``, generator ``[seed, i]`` for the ``i``-th): registered
    grayscale scenes (group ``relit``) for the real-light trainer, made in memory.

    Raises:
        InputError: ``frames < 2`` or an unknown ``light``.
    """
    if frames < 2:
        raise InputError(f"a relit scene needs at least 2 frames (relit >= 2), got {frames}")
    if light not in LIGHTS:
        raise InputError(f"unknown light {light!r}; known: {', '.join(LIGHTS)}")
    scenes = []
    for i, photo in enumerate(photos):
        relit = relit_frames(photo.image, frames, np.random.default_rng([seed, i]), LIGHTS[light], jitter)
        gray = np.stack([to_gray(f) if f.ndim == 3 else f for f in relit])
        name = f"{i:02d}_{photo.name.replace('/', '_').replace('#', '_').replace('.', '_')}"
        scenes.append(Scene(name, "relit", gray, tuple(f"frame_{k:02d}.png" for k in range(frames))))
    return scenes
