"""Training sequences of ``alcn pose build``: the images, their cameras and (when known) their poses.

A registered sequence (:func:`load_sequence`: a BOP scene, a COLMAP model or a Middlebury set)
has a world-to-camera pose per image; an unregistered one (:func:`video_sequence`: frames of a
video) has intrinsics only, and :mod:`pose.triangulate` reconstructs its poses.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv import io
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import make_folder, to_gray


@dataclass
class TrainingView:
    """One training image.

    Attributes:
        name: file name relative to ``image_dir``.
        K: (3, 3) OpenCV intrinsics; ``dist`` OpenCV distortion or ``None``.
        R_w2c, t_w2c: world-to-camera pose (``None`` for an unregistered image).
        mask: the file of the object's visible pixels (a BOP ``mask_visib``), or ``None``.
    """

    name: str
    K: np.ndarray
    dist: np.ndarray | None = None
    R_w2c: np.ndarray | None = None
    t_w2c: np.ndarray | None = None
    mask: Path | None = None


@dataclass
class TrainingSequence:
    """Training images in one folder, their cameras, and the unit of the world frame.

    ``units``: ``"mm"``, ``"cm"`` or ``"m"``; ``""`` for an unregistered video (no world frame yet);
    :data:`ARBITRARY_UNITS` for poses registered without a known length (``alcn calib register --method sfm``
    without ``--known-distance`` or ``--reference``), which no part model can be built in.
    """

    image_dir: Path
    views: list[TrainingView]
    units: str
    size: tuple[int, int] = (0, 0)
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def registered(self) -> bool:
        return all(v.R_w2c is not None for v in self.views)


#: The ``units`` of ``registration.json`` (``alcn calib register``) whose poses have no known scale.
ARBITRARY_UNITS = "arbitrary"


def registration_units(folder: str | Path) -> str | None:
    """The units ``alcn calib register`` recorded in ``folder/registration.json`` (``"mm"``, or
    :data:`ARBITRARY_UNITS` for an SfM registration without a known length); ``None`` without that file.

    Raises:
        DatasetError: the file is not JSON, or its ``units`` is not a string.
    """
    path = Path(folder) / "registration.json"
    if not path.is_file():
        return None
    try:
        units = json.loads(path.read_text(encoding="utf-8")).get("units")
    except (OSError, ValueError, AttributeError) as exc:
        raise DatasetError(f"{path}: not the JSON of `alcn calib register` ({exc})") from exc
    if not isinstance(units, str):
        raise DatasetError(f"{path}: field 'units': expected a string such as 'mm', got {units!r}")
    return units


def check_known_units(seq: TrainingSequence, what: str, alternative: str = "") -> None:
    """Refuse a registered sequence whose poses are in :data:`ARBITRARY_UNITS` (``alcn calib register --method sfm``
    without a known length), for every command that reads lengths from its poses: ``alcn pose build``,
    ``alcn pose train-corners`` and ``alcn pose eval``. ``what``: what needs known units (``"a part model"``);
    ``alternative``: another way than registering again, appended to the message (``", or ..."``).

    Raises:
        InputError: the sequence's poses are in arbitrary units; the message says how to register it in mm.
    """
    if seq.registered and seq.units == ARBITRARY_UNITS:
        raise InputError(
            f"{seq.info.get('path')}: its poses are in arbitrary units (registration.json: registered by SfM without "
            f"a known length), and {what} needs known units: register again with `alcn calib register --method sfm "
            f"--known-distance FRAME_A FRAME_B MM` (or --reference POSES){alternative}"
        )


def load_sequence(path: str | Path, images: str | Path | None = None, obj_id: int | None = None) -> TrainingSequence:
    """Read a registered training sequence.

    Args:
        path: a BOP scene folder (``scene_camera.json``, ``scene_gt.json``, ``rgb/``), a COLMAP
            model folder (``cameras.txt``/``images.txt`` or ``.bin``), or a Middlebury set
            (``*_par.txt``).
        images: image folder of a COLMAP model (default: ``<path>/../images`` then ``<path>/images``).
        obj_id: BOP object whose model frame becomes the world (default: the first annotated in
            ``scene_gt.json``); without annotations, ``scene_camera.json``'s ``cam_R_w2c`` is used.

    The units: a BOP scene's are millimetres, a COLMAP model's its ``# Units:`` header's, else metres, a
    Middlebury set's metres; the output of ``alcn calib register`` (``registration.json`` in the scene's folder,
    beside its ``colmap/``) is in the units recorded there, :data:`ARBITRARY_UNITS` when it had no known length.

    Raises:
        DatasetError: no such folder, the folder is none of these, or an image has no pose.
    """
    path = Path(path)
    if not path.exists():
        raise DatasetError(f"{path}: no such file or folder")
    if (path / "scene_camera.json").is_file():
        from alcn_cv.formats import bop

        scene = bop.load_scene(path)
        views = []
        for fr in scene.frames:
            mask = None
            if fr.objects:  # world = the object's model frame (the object is static in a training sequence)
                index = 0 if obj_id is None else fr.object_index(obj_id)
                if index is None:
                    raise DatasetError(f"{path / 'scene_gt.json'}: image {fr.im_id} has no object {obj_id}")
                R, t = fr.objects[index].R, fr.objects[index].t
                mask = path / "mask_visib" / f"{fr.im_id:06d}_{index:06d}.png"
            elif fr.R_w2c is not None:
                R, t = fr.R_w2c, fr.t_w2c
            else:
                raise DatasetError(f"{path / 'scene_gt.json'}: image {fr.im_id} has no pose (field 'cam_R_m2c')")
            views.append(TrainingView(fr.rgb_path.name, fr.K, None, R, np.ravel(t), mask))
        units = registration_units(path) or "mm"  # `alcn calib register` without a known length: arbitrary
        info = {"format": "bop", "path": str(path)}
        return TrainingSequence(scene.frames[0].rgb_path.parent, views, units, info=info)
    if any(path.glob("*_par.txt")):
        from alcn_cv.formats.middlebury import read_middlebury

        mv = read_middlebury(path)
        return TrainingSequence(
            path,
            [TrainingView(v.name, v.K, None, v.R_w2c, v.t_w2c) for v in mv],
            "m",
            info={"format": "middlebury", "path": str(path)},
        )
    if (path / "cameras.txt").is_file() or (path / "cameras.bin").is_file():
        from alcn_cv.formats.colmap import read_model

        cm = read_model(path)
        image_dir = (
            Path(images)
            if images
            else next((p for p in (path.parent / "images", path / "images", path.parent / "rgb") if p.is_dir()), None)
        )
        if image_dir is None:
            raise DatasetError(f"{path}: no image folder found beside the COLMAP model; pass --images")
        views = []
        for im in sorted(cm.images.values(), key=lambda i: i.name):
            K, dist = cm.cameras[im.camera_id].to_opencv()
            views.append(TrainingView(im.name, K, dist if np.any(dist) else None, im.R_w2c, im.t_w2c))
        # A model without a "# Units:" line is in the units of the registration it is part of (`alcn calib register`
        # writes none when they are arbitrary), else (e.g. written by COLMAP itself) taken as metres.
        units = cm.units or registration_units(path.parent) or "m"
        return TrainingSequence(image_dir, views, units, info={"format": "colmap", "path": str(path)})
    raise DatasetError(
        f"{path}: not a BOP scene (scene_camera.json), a COLMAP model (cameras.txt/.bin) "
        "or a Middlebury set (*_par.txt)"
    )


#: The frames of a video :func:`video_sequence` keeps by default: every ``VIDEO_STEP``-th, at most ``VIDEO_MAX_FRAMES``.
VIDEO_STEP = 5
VIDEO_MAX_FRAMES = 80


def video_sequence(
    video: str | Path,
    K: np.ndarray,
    work_dir: str | Path,
    *,
    step: int = VIDEO_STEP,
    max_frames: int = VIDEO_MAX_FRAMES,
    dist: np.ndarray | None = None,
) -> TrainingSequence:
    """An unregistered sequence: every ``step``-th frame of ``video`` (at most ``max_frames``)
    written as PNG into ``work_dir/images``, each view with the intrinsics ``K`` ``(3, 3)`` (OpenCV pixel convention)
    and the lens distortion ``dist`` (OpenCV order; ``None``: none), the camera of every frame (the frames are not
    undistorted: the reconstruction models it)."""
    image_dir = Path(work_dir) / "images"
    make_folder(image_dir)
    views = []
    for name, frame in io.iter_frames(video, step=step, max_frames=max_frames):
        io.write_image(image_dir / f"{name}.png", frame)
        views.append(TrainingView(f"{name}.png", np.asarray(K, np.float64), dist))
    if len(views) < 3:
        raise DatasetError(f"{video}: only {len(views)} frames read; at least 3 are needed")
    return TrainingSequence(image_dir, views, "", info={"format": "video", "path": str(video), "step": step})


def motion_masks(
    frames: list[np.ndarray], threshold: float = 25.0, dilate: int = 25, min_area: float = 0.005
) -> list[np.ndarray]:
    """Masks (uint8 0/255) of what moves in a video taken by a static camera.

    The background is the per-pixel median of ``frames``; the mask is the convex hull of the
    regions (larger than ``min_area`` of the image) that differ from it by more than
    ``threshold`` grey levels, dilated by a disc ``dilate`` pixels across. Used for hand-held objects in front
    of a fixed camera (e.g. the cookie-box video), whose static background would otherwise
    dominate the reconstruction.
    """
    grays = np.stack([to_gray(f) for f in frames]).astype(np.int16)
    bg = np.median(grays, axis=0)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (dilate, dilate))
    masks = []
    for g in grays:
        m = (np.abs(g - bg) > threshold).astype(np.uint8) * 255
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        big = [c for c in contours if cv2.contourArea(c) > min_area * m.size]
        filled = np.zeros_like(m)
        if big:  # what moves, with the holes where it resembles the background: hull of the moving regions
            cv2.fillConvexPoly(filled, cv2.convexHull(np.concatenate(big)), 255)
        masks.append(cv2.dilate(filled, kernel))
    return masks
