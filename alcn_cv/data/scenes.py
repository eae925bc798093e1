"""Registered multi-light scenes: one fixed view, many lights; the one loader of ``alcn bench
relight``, of the gain Normalizer's trainer (:mod:`alcn_cv.train.real_light`) and of the planar
targets of ``alcn pose``.

A *scene* is a set of frames of one fixed view under different light, registered (the camera
did not move), so a pixel is the same point of the scene in every frame. The data sets:

* ``webcam`` (``../shared/data/webcam``): 4 fixed outdoor cameras, one folder per scene,
  ``<root>/<scene>/*.jpg``. Terms: academic research use only; cite TILDE (Verdie et al., CVPR
  2015) and AMOS (Jacobs et al., CVPR 2007).
* ``psm`` (``../shared/data/psm``): 4 photometric-stereo objects, ``NAME.0.png`` ..
  ``NAME.11.png`` per object (one folder per object, or all in one folder), ``NAME.mask.png``
  (a mask, not a frame) skipped. Terms: research use, citing S. Seitz (U. Washington).
  :func:`load_photometric` reads such a set with its masks (one folder per object), as
  :class:`PhotometricObject`; :func:`mean_pairwise_ncc` is the agreement of an object's images.
* the rendered scenes of ``alcn data scenes`` (:mod:`alcn_cv.data.relief_scenes`):
  ``<root>/scene_NNN/frame_NN.png``.
* Phos-like folders: one folder per object holding its photographs under different light.

The split: the baselines are tuned on :data:`TRAIN_SCENES` (and the gain Normalizer, trained on
relit photographs that permit any use, is validated on them); :data:`TEST_SCENES` are never trained or tuned on.

A folder's images named ``NAME.<index>.<ext>`` form the scene ``NAME`` (ordered by index); its
other images form the scene named after the folder (ordered by name). Frames are read with
:func:`alcn_cv.io.read_image` as uint8 grayscale (16-bit images rounded to 8 bits, with a warning when a scene's
values, its brightest frame's maximum, use less than a sixteenth of the range: 12-bit data in 16-bit files keep a few
grey levels; the dark frames of a multi-light scene are not warned of). :func:`scene_names` names the scenes of a
folder as the loader does, from the file names alone.
A scene whose frames do not look registered (:func:`registration_score` below :data:`REGISTERED_SCORE`:
unrelated photographs of one size) is loaded with a warning: training on it learns nothing.

Example (with the shared data)::

    from alcn_cv.data.scenes import load_scenes, scene_dirs, select_scenes, shared_root

    train = load_scenes(scene_dirs())  # TRAIN_SCENES, as the trainer reads them
    test = select_scenes(load_scenes([shared_root("webcam"), shared_root("psm")]), ["mexico", "psm"])
    frames = test[0].unit_frames()  # (n, H, W) float32 in [0, 1]
"""

from __future__ import annotations

import itertools
import logging
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import IMAGE_SUFFIXES, eight_bits, list_images, read_image, read_mask
from alcn_cv.shared_data import missing_folder, shared_data_dir

__all__ = [
    "NARROW_16_BIT",
    "REGISTERED_SCORE",
    "TEST_SCENES",
    "WEBCAM_SCENES",
    "TRAIN_SCENES",
    "PhotometricObject",
    "Scene",
    "load_photometric",
    "load_scene_folder",
    "load_scenes",
    "mean_pairwise_ncc",
    "read_eight_bits",
    "registration_score",
    "scene_dirs",
    "scene_names",
    "select_scenes",
    "shared_root",
]

logger = logging.getLogger(__name__)

#: The ``webcam`` scenes the benchmark tunes parameters on and the gain Normalizer is validated on.
TRAIN_SCENES = ("courbevoie", "frankfurt", "panorama")
#: Scenes and data sets never trained or tuned on.
TEST_SCENES = ("mexico", "psm")
#: The scenes of the shared ``webcam`` data (academic research use only).
WEBCAM_SCENES = (*TRAIN_SCENES, "mexico")

#: A 16-bit image whose maximum is below this uses less than a sixteenth of the range (12-bit data in a 16-bit
#: file, say): rounded to 8 bits (:func:`alcn_cv.io.eight_bits`, ``round(x / 257)``) it keeps 17 grey levels or fewer
#: (0 to 16: 4095 rounds to 16).
NARROW_16_BIT = 4096
#: Frames of a registered scene score at least this (:func:`registration_score`); unrelated photographs of one size
#: score about 0. Views of one fixed background with a moving object or camera are not caught.
REGISTERED_SCORE = 0.1

_INDEXED = re.compile(r"^(?P<name>.+)\.(?P<index>\d+)$")
_MASK = re.compile(r"\.mask$", re.IGNORECASE)


@dataclass(frozen=True, eq=False)
class Scene:
    """The frames of one fixed view under different light.

    Attributes:
        name: the scene's name (its folder, or ``NAME`` of ``NAME.<i>.png``).
        group: the data set it was read from (the name of its root folder: ``webcam``, ``psm``).
        frames: ``(n, H, W)`` uint8 grayscale frames, registered.
        files: the file name of each frame.
    """

    name: str
    group: str
    frames: np.ndarray
    files: tuple[str, ...]

    def unit_frames(self) -> np.ndarray:
        """The frames as ``(n, H, W)`` float32 in [0, 1] (``frames / 255``)."""
        return self.frames.astype(np.float32) / np.float32(255)


def shared_root(name: str) -> Path:
    """The folder of the shared data set ``name`` (``webcam``, ``psm``); it may not exist."""
    return shared_data_dir() / name


def scene_dirs(entries: Sequence[str | os.PathLike] = TRAIN_SCENES) -> list[Path]:
    """The folders of ``entries`` (default: the training scenes): each an existing folder (``~`` expanded, a
    relative path from the working folder), else the name of a scene of the shared ``webcam`` data.

    Raises:
        InputError: an entry is neither (the message lists the webcam scenes).
    """
    webcam = shared_root("webcam")
    dirs = []
    for entry in entries:
        path = Path(entry).expanduser()
        name = str(entry)
        if path.is_dir():
            dirs.append(path)
        elif Path(name).name == name and (name in WEBCAM_SCENES or (webcam / name).is_dir()):
            dirs.append(webcam / name)  # the shared data's absence is load_scene_folder's to report
        else:
            try:
                listed = [p.name for p in _visible_subfolders(webcam)]
            except OSError:  # the shared data missing or unreadable: the message names the known scenes alone
                listed = []
            names = sorted({*WEBCAM_SCENES, *listed})
            raise InputError(f"{name}: neither a folder nor a webcam scene ({', '.join(names)})")
    return dirs


def _visible_subfolders(folder: Path) -> list[Path]:
    """The subfolders of ``folder`` whose names do not start with a dot, sorted. Raises OSError as
    ``Path.iterdir``."""
    return sorted(p for p in folder.iterdir() if p.is_dir() and not p.name.startswith("."))


def _warn_if_narrow(what: str, maximum: int | None) -> None:
    """Warn when ``maximum``, that of a 16-bit image or scene (None: not 16-bit), uses less than a sixteenth of the
    range (:data:`NARROW_16_BIT`)."""
    if maximum is not None and maximum < NARROW_16_BIT:
        logger.warning(
            f"{what}: a 16-bit maximum of {maximum} uses less than 1/16 of the range (12-bit data in a 16-bit file?): "
            f"as 8 bits it keeps {round(maximum / 257) + 1} grey levels (0 to {round(maximum / 257)}); scale the "
            "values to 16 bits (x16 for 12-bit data)"
        )


def _warn_if_narrow_set(what: str, kind: str, paths: Sequence[Path], tops: Sequence[int | None]) -> None:
    """:func:`_warn_if_narrow` of a set's maximum over its 16-bit images (``tops``, None for the others, one per path),
    not each image's: a multi-light set has dark images by design. ``what`` and ``kind`` (of image) name them."""
    deep = [(top, path) for path, top in zip(paths, tops) if top is not None]
    if deep:
        top, brightest = max(deep)
        _warn_if_narrow(f"{what} (its brightest {kind} {brightest})", top)


def _read_eight_bits(path: str | os.PathLike, gray: bool = False) -> tuple[np.ndarray, int | None]:
    """The image as uint8 (:func:`alcn_cv.io.read_image`; 16 bits rounded to 8 by :func:`alcn_cv.io.eight_bits`),
    gray ``HxW`` when ``gray`` (BGR converted), else as read; and its maximum when it was a 16-bit image, else None
    (for :func:`_warn_if_narrow`: per file, or per scene)."""
    image = read_image(path)
    top = None
    if image.dtype == np.uint16:
        top = int(image.max())
        image = eight_bits(image)
    if gray and image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    return image, top


def read_eight_bits(path: str | os.PathLike) -> np.ndarray:
    """An image as uint8, gray ``HxW`` or BGR ``HxWx3`` (:func:`alcn_cv.io.read_image`; 16 bits rounded to 8 by
    :func:`alcn_cv.io.eight_bits`), with a warning naming the file and its maximum when its 16-bit values use less
    than a sixteenth of the range (:data:`NARROW_16_BIT`).

    Raises:
        InputError: as :func:`~alcn_cv.io.read_image`.
    """
    image, top = _read_eight_bits(path)
    _warn_if_narrow(str(path), top)
    return image


def registration_score(frames: np.ndarray) -> float:
    """How registered the frames ``(n, H, W)`` look: the median over pairs of frames of the normalized
    cross-correlation of their gradient magnitudes, on frames of about 128 x 128 pixels (area-resized, blurred by a
    Gaussian of sigma 1), each magnitude less its blur by a Gaussian of sigma 4 (so that the layout of a photograph,
    an object centred on a plain ground, does not count: where the edges are does). The edges of a fixed view stay
    in place whatever the light; unrelated photographs score about 0 (:data:`REGISTERED_SCORE`)."""
    n, h, w = frames.shape
    scale = min(1.0, 128 / np.sqrt(h * w))
    size = (max(8, round(w * scale)), max(8, round(h * scale)))
    rows = []
    for frame in frames:
        small = cv2.GaussianBlur(cv2.resize(frame.astype(np.float32), size, interpolation=cv2.INTER_AREA), (0, 0), 1.0)
        magnitude = cv2.magnitude(cv2.Sobel(small, cv2.CV_32F, 1, 0), cv2.Sobel(small, cv2.CV_32F, 0, 1))
        magnitude -= cv2.GaussianBlur(magnitude, (0, 0), 4.0)
        row = magnitude[2:-2, 2:-2].ravel().astype(np.float64)  # the borders' reflected gradients left out
        row -= row.mean()
        rows.append(row / max(float(np.linalg.norm(row)), 1e-12))
    stack = np.stack(rows)
    return float(np.median((stack @ stack.T)[np.triu_indices(n, 1)]))


def _evenly_spaced(n: int, max_frames: int | None) -> list[int]:
    """``max_frames`` indices spread over ``range(n)`` (all of them when there are fewer)."""
    if max_frames is None or n <= max_frames:
        return list(range(n))
    return sorted({int(round(v)) for v in np.linspace(0, n - 1, max_frames)})


def _folder_files(folder: Path) -> tuple[dict[str, list[Path]], list[Path], dict[str, Path]]:
    """The images of ``folder``: ``NAME.<i>.<ext>`` by ``NAME`` (ordered by index), the other images (by name) and
    the masks ``NAME.mask.<ext>`` by ``NAME``; none when ``folder`` cannot be listed as images."""
    try:
        files = list_images(folder)
    except InputError:
        return {}, [], {}
    indexed: dict[str, list[tuple[int, Path]]] = {}
    plain: list[Path] = []
    masks: dict[str, Path] = {}
    for path in files:
        if _MASK.search(path.stem):
            masks[path.stem[: -len(".mask")]] = path
            continue
        m = _INDEXED.match(path.stem)
        if m:
            indexed.setdefault(m.group("name"), []).append((int(m.group("index")), path))
        else:
            plain.append(path)
    return {name: [p for _, p in sorted(items)] for name, items in sorted(indexed.items())}, plain, masks


def _group_files(folder: Path) -> dict[str, list[Path]]:
    """The frames of ``folder`` by scene: ``NAME.<i>.<ext>`` by ``NAME`` (masks skipped), the rest by the folder."""
    groups, plain, _ = _folder_files(folder)
    if plain:
        groups.setdefault(folder.name, []).extend(plain)
    return groups


def _scene_files(root: Path, subfolders: bool = True, say_skipped: bool = False) -> list[tuple[str, Path, list[Path]]]:
    """``(name, folder, ordered frame files)`` of every scene of at least two frames in ``root`` and (``subfolders``)
    its subfolders, hidden ones skipped; from the file names alone. ``say_skipped``: warn of each one-frame scene
    skipped (a scene a user made for a benchmark would vanish from it without a word). Raises OSError as
    ``Path.iterdir``."""
    folders = [root]
    if subfolders:
        folders += _visible_subfolders(root)
    scenes = []
    for folder in folders:
        for name, paths in _group_files(folder).items():
            if len(paths) >= 2:
                scenes.append((name, folder, paths))
            elif say_skipped:
                logger.warning(
                    "%s: %s is scene %r's only frame, skipped: a scene needs two", folder, paths[0].name, name
                )
    return scenes


def scene_names(root: str | os.PathLike, subfolders: bool = True) -> list[str]:
    """The names of the scenes :func:`load_scene_folder` finds under ``root`` (its own images and, with
    ``subfolders``, those of its subfolders; hidden files and folders, masks and scenes of fewer than two frames
    skipped), in its order, from the file names alone (no image is read); none when ``root`` is not a folder.

    Raises:
        OSError: a folder could not be listed.
    """
    root = Path(root)
    return [name for name, _, _ in _scene_files(root, subfolders)] if root.is_dir() else []


def load_scene_folder(root: str | os.PathLike, max_frames: int | None = None) -> list[Scene]:
    """Every scene under ``root`` (its own images and those of its subfolders; see the module),
    each with at most ``max_frames`` frames, evenly spaced over its ordered files.

    Raises:
        DatasetError: ``root`` is not a folder, holds no scene of at least two frames, or a
            scene's frames differ in size.
        InputError: ``max_frames`` is less than 2.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(missing_folder(root))
    if max_frames is not None and max_frames < 2:
        raise InputError(f"max_frames must be at least 2, got {max_frames}")
    scenes = []
    for name, folder, paths in _scene_files(root, say_skipped=True):
        paths = [paths[i] for i in _evenly_spaced(len(paths), max_frames)]
        frames, tops = zip(*(_read_eight_bits(p, gray=True) for p in paths))
        odd = next((i for i, f in enumerate(frames) if f.shape != frames[0].shape), None)
        if odd is not None:
            size = "x".join(map(str, frames[0].shape[1::-1]))
            raise DatasetError(
                f"{folder}: the frames of scene {name!r} differ in size (not registered): {paths[0].name} is {size}, "
                f"{paths[odd].name} {'x'.join(map(str, frames[odd].shape[1::-1]))}"
            )
        _warn_if_narrow_set(f"scene {name!r}", "frame", paths, tops)
        stack = np.stack(frames)
        score = registration_score(stack)
        if score < REGISTERED_SCORE:
            logger.warning(
                "scene %r (%s) does not look registered: its frames' gradients correlate %.2f (registered scenes "
                "%.1f or more); a scene is one fixed view under several lights: unrelated photographs score at "
                "chance in a benchmark, and train at chance (give those as photos=[...] to alcn train-real-light)",
                name,
                folder,
                score,
                REGISTERED_SCORE,
            )
        scenes.append(Scene(name, root.name, stack, tuple(p.name for p in paths)))
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
    """The scenes named by ``tokens``, each a scene name or a data set's name (all its scenes), in order.

    Raises:
        InputError: a token names no scene and no data set.
    """
    chosen: list[Scene] = []
    for token in tokens:
        hits = [s for s in scenes if token in (s.name, s.group)]
        if not hits:
            known = {s.name for s in scenes} | {s.group for s in scenes}
            parts = [part.strip() for part in token.split(",")]
            # --methods takes a comma list, the scene options a list of words
            hint = f" (scenes are given apart: {' '.join(parts)})" if len(parts) > 1 and set(parts) <= known else ""
            raise InputError(f"no scene or data set {token!r}{hint}; available: {', '.join(sorted(known))}")
        chosen += [s for s in hits if all(s is not c for c in chosen)]
    return chosen


@dataclass(frozen=True)
class PhotometricObject:
    """One object of a photometric-stereo set: one view under several lights, with the object's mask.

    Attributes:
        name: the object's name (its folder).
        images: ``(k, H, W)`` float32 grayscale intensities in [0, 1], one per light, in the order of their index.
        mask: ``(H, W)`` bool, the object's pixels.
    """

    name: str
    images: np.ndarray
    mask: np.ndarray


def load_photometric(root: str | os.PathLike, scale: float = 1.0) -> list[PhotometricObject]:
    """Every object of a photometric-stereo folder (the ``psm`` layout): one subfolder ``NAME/`` per object holding
    ``NAME.0.png`` ... ``NAME.{k-1}.png`` (any image type) and its mask ``NAME.mask.png`` (> 127 inside); subfolders
    without such images or without a mask are skipped. Images are read as 8-bit gray (the codec's conversion).

    Args:
        root: the folder holding one subfolder per object.
        scale: resize factor applied to images (``cv2.INTER_AREA``) and masks (nearest), in (0, 1].

    Raises:
        DatasetError: ``root`` is not a folder, holds no object, an object has one image only (an agreement
            compares two lights or more), an image is unreadable or differs in size from its mask, a mask marks no
            pixel (white, above 127, on the object). An object folder without a mask is skipped with a warning.
        InputError: ``scale`` out of range.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(f"{missing_folder(root)}; a photometric-stereo set: a folder of images per object")
    if not 0 < scale <= 1:
        raise InputError(f"scale must be in (0, 1], got {scale}")
    objects = []
    for folder in _visible_subfolders(root):
        indexed, _, masks = _folder_files(folder)
        shots, mask_path = indexed.get(folder.name), masks.get(folder.name)
        if not shots:
            logger.debug("skipping %s: no %s.<i> images", folder, folder.name)
            continue
        if mask_path is None:
            logger.warning("skipping %s: its images have no mask %s.mask.png", folder, folder.name)
            continue
        if len(shots) < 2:
            raise DatasetError(f"{folder}: one photograph ({shots[0].name}); an object needs 2 lights or more")
        try:
            images, tops = zip(*(_read_eight_bits(p, gray=True) for p in shots))
            mask = read_mask(mask_path)
        except InputError as exc:  # a file of the data set, not the caller's input
            raise DatasetError(str(exc)) from None
        _warn_if_narrow_set(f"object {folder.name!r}", "photograph", shots, tops)
        if any(img.shape != mask.shape for img in images):
            raise DatasetError(f"{folder}: images and mask {mask_path.name} differ in size")
        if scale != 1:
            size = (max(1, round(mask.shape[1] * scale)), max(1, round(mask.shape[0] * scale)))
            images = [cv2.resize(img, size, interpolation=cv2.INTER_AREA) for img in images]
            mask = cv2.resize(mask.astype(np.uint8), size, interpolation=cv2.INTER_NEAREST) > 0
        objects.append(PhotometricObject(folder.name, np.stack(images).astype(np.float32) / np.float32(255), mask))
    if not objects:
        raise DatasetError(f"{root}: no object folder with NAME/NAME.<i>.png and NAME/NAME.mask.png")
    return objects


def mean_pairwise_ncc(images: np.ndarray | Sequence[np.ndarray], mask: np.ndarray) -> float:
    """The mean, over every pair of ``images`` (``k >= 2`` of one view, ``(H, W)`` each), of their normalized
    cross-correlation inside the bool ``mask`` (in float64): in [-1, 1], 1 when the images agree up to a gain and an
    offset; a pair where either image is constant inside the mask counts as 0."""
    values = []
    for image in images:
        v = image[mask].astype(np.float64)
        values.append(v - v.mean())
    norms = [float(np.linalg.norm(v)) for v in values]
    scores = []
    for i, j in itertools.combinations(range(len(values)), 2):
        denom = norms[i] * norms[j]
        scores.append(float(values[i] @ values[j] / denom) if denom > 1e-12 else 0.0)
    return float(np.mean(scores))
