"""Training sequences of ``alcn pose build``: the images, their cameras and (when known) their poses.

A registered sequence (:func:`load_sequence`: a BOP scene, a COLMAP model or a Middlebury set)
has a world-to-camera pose per image; an unregistered one (:func:`video_sequence`: frames of a
video) has intrinsics only, and :mod:`pose.triangulate` reconstructs its poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv import io
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import make_folder, to_gray
from calib.conventions import ARBITRARY_UNITS, colmap_model_units, registration_units


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

    Attributes:
        image_dir: the folder of the views' images.
        views: the training images.
        units: ``"mm"``, ``"cm"`` or ``"m"``; ``""`` for an unregistered video (no world frame yet);
            :data:`calib.conventions.ARBITRARY_UNITS` for poses without a known scale (``alcn calib register
            --method sfm`` without ``--known-distance`` or ``--reference``, a COLMAP model without a ``# Units:``
            header), which no part model can be built in.
        size: ``(width, height)`` of the images (all the views'), set where the sequence is read
            (:func:`load_sequence`, :func:`video_sequence`): the frames the camera stored in a part model is for.
        info: where the sequence comes from (``format``, ``path``, ...).
    """

    image_dir: Path
    views: list[TrainingView]
    units: str
    size: tuple[int, int]
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def registered(self) -> bool:
        return all(v.R_w2c is not None for v in self.views)


def check_known_units(seq: TrainingSequence, what: str, alternative: str = "") -> None:
    """Refuse a registered sequence whose poses are in :data:`calib.conventions.ARBITRARY_UNITS` (``alcn calib
    register --method sfm`` without a known length, a COLMAP model without a ``# Units:`` header), for every command
    that reads lengths from its poses: ``alcn pose build``, ``alcn pose train-corners`` and ``alcn pose eval``.
    ``what``: what needs known units (``"a part model"``); ``alternative``: another way than registering again,
    appended to the message (``", or ..."``).

    Raises:
        InputError: the sequence's poses are in arbitrary units; the message says how to register it in mm.
    """
    if seq.registered and seq.units == ARBITRARY_UNITS:
        raise InputError(
            f"{seq.info.get('path')}: its poses are in arbitrary units (registered by SfM without a known length, or "
            f"a COLMAP model without a '# Units:' line), and {what} needs known units: register again with `alcn "
            f"calib register --method sfm --known-distance FRAME_A FRAME_B MM` (or --reference POSES), or add the "
            f"line '# Units: mm' (cm, m) to the images.txt of a COLMAP model whose scale you know{alternative}"
        )


def load_sequence(path: str | Path, images: str | Path | None = None, obj_id: int | None = None) -> TrainingSequence:
    """Read a registered training sequence.

    Args:
        path: a BOP scene folder (``scene_camera.json``, ``scene_gt.json``, ``rgb/``), a COLMAP
            model folder (``cameras.txt``/``images.txt`` or ``.bin``), or a Middlebury set
            (``*_par.txt``).
        images: image folder of a COLMAP model (default: the first folder of ``<path>/../images``,
            ``<path>/images`` and ``<path>/../rgb``, the layout of ``alcn calib register``).
        obj_id: BOP object whose model frame becomes the world (default: the first annotated in
            ``scene_gt.json``); without annotations, ``scene_camera.json``'s ``cam_R_w2c`` is used.

    The units: a BOP scene's are millimetres, a COLMAP model's :func:`calib.conventions.colmap_model_units` (its
    ``# Units:`` header, else the ``registration.json`` of ``alcn calib register`` beside it, else arbitrary), a
    Middlebury set's metres; a BOP scene written by ``alcn calib register`` (with ``registration.json``) is in the
    units recorded there, :data:`calib.conventions.ARBITRARY_UNITS` when it had no known length.

    The sequence's ``size`` is that of its first image (BOP, Middlebury) or of its first view's COLMAP camera.

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
        size = _image_size(scene.frames[0].rgb_path)
        return TrainingSequence(scene.frames[0].rgb_path.parent, views, units, size, info=info)
    if any(path.glob("*_par.txt")):
        from alcn_cv.formats.middlebury import read_middlebury

        mv = read_middlebury(path)
        return TrainingSequence(
            path,
            [TrainingView(v.name, v.K, None, v.R_w2c, v.t_w2c) for v in mv],
            "m",
            _image_size(path / mv[0].name),
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
        images_sorted = sorted(cm.images.values(), key=lambda i: i.name)
        if not images_sorted:
            raise DatasetError(f"{path}: the COLMAP model has no registered image")
        views = []
        for im in images_sorted:
            K, dist = cm.cameras[im.camera_id].to_opencv()
            views.append(TrainingView(im.name, K, dist if np.any(dist) else None, im.R_w2c, im.t_w2c))
        camera = cm.cameras[images_sorted[0].camera_id]
        info = {"format": "colmap", "path": str(path)}
        return TrainingSequence(
            image_dir, views, colmap_model_units(cm, path), (camera.width, camera.height), info=info
        )
    raise DatasetError(
        f"{path}: not a BOP scene (scene_camera.json), a COLMAP model (cameras.txt/.bin) "
        "or a Middlebury set (*_par.txt)"
    )


def _image_size(path: Path) -> tuple[int, int]:
    """``(width, height)`` of the image ``path``."""
    height, width = io.read_image(path).shape[:2]
    return width, height


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
    undistorted: the reconstruction models it); its ``size`` is the frames'."""
    image_dir = Path(work_dir) / "images"
    make_folder(image_dir)
    views = []
    size = (0, 0)
    for name, frame in io.iter_frames(video, step=step, max_frames=max_frames):
        io.write_image(image_dir / f"{name}.png", frame)
        views.append(TrainingView(f"{name}.png", np.asarray(K, np.float64), dist))
        size = (frame.shape[1], frame.shape[0])
    if len(views) < 3:
        raise DatasetError(f"{video}: only {len(views)} frames read; at least 3 are needed")
    info = {"format": "video", "path": str(video), "step": step}
    return TrainingSequence(image_dir, views, "", size, info=info)


#: :func:`motion_masks`: what differs from the background by more than ``MOTION_THRESHOLD`` grey levels moves; its
#: regions smaller than ``MOTION_MIN_AREA`` of the image are dropped, and the mask is dilated by a disc
#: ``MOTION_DILATE`` pixels across.
MOTION_THRESHOLD = 25.0
MOTION_MIN_AREA = 0.005
MOTION_DILATE = 25


def motion_masks(frames: list[np.ndarray]) -> list[np.ndarray]:
    """Masks (uint8 0/255) of what moves in a video taken by a static camera.

    The background is the per-pixel median of ``frames``; the mask is the convex hull of the regions (larger than
    :data:`MOTION_MIN_AREA` of the image) that differ from it by more than :data:`MOTION_THRESHOLD` grey levels,
    dilated by a disc :data:`MOTION_DILATE` pixels across. Used for hand-held objects in front of a fixed camera
    (e.g. the cookie-box video), whose static background would otherwise dominate the reconstruction.
    """
    grays = np.stack([to_gray(f) for f in frames]).astype(np.int16)
    bg = np.median(grays, axis=0)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (MOTION_DILATE, MOTION_DILATE))
    masks = []
    for g in grays:
        m = (np.abs(g - bg) > MOTION_THRESHOLD).astype(np.uint8) * 255
        m = cv2.morphologyEx(m, cv2.MORPH_OPEN, np.ones((5, 5), np.uint8))
        contours, _ = cv2.findContours(m, cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
        big = [c for c in contours if cv2.contourArea(c) > MOTION_MIN_AREA * m.size]
        filled = np.zeros_like(m)
        if big:  # what moves, with the holes where it resembles the background: hull of the moving regions
            cv2.fillConvexPoly(filled, cv2.convexHull(np.concatenate(big)), 255)
        masks.append(cv2.dilate(filled, kernel))
    return masks
