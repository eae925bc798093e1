"""Camera conventions of OpenCV, COLMAP and BOP, and conversions between them.

All three use the same camera frame (x right, y down, z forward) and world-to-camera poses
``x_cam = R_w2c @ x_world + t_w2c``. They differ in:

- pixel convention: OpenCV and BOP put the centre of the top-left pixel at (0, 0), COLMAP at
  (0.5, 0.5); so ``cx_colmap = cx_opencv + 0.5`` and a COLMAP keypoint ``(u, v)`` is the OpenCV
  point ``(u - 0.5, v - 0.5)``;
- pose storage: OpenCV rvec/tvec or R, t; COLMAP a quaternion ``(qw, qx, qy, qz)`` and t in
  ``images.txt``; BOP row-major ``cam_R_w2c`` and ``cam_t_w2c`` in ``scene_camera.json``;
- units: BOP is in millimetres; COLMAP's are arbitrary (the models written here are in mm);
- distortion: COLMAP models carry it (``OPENCV``, ``FULL_OPENCV``); BOP images have none.

Camera conversions between OpenCV and COLMAP live in :mod:`alcn_cv.formats.colmap`
(:func:`camera_from_opencv`, :meth:`ColmapCamera.to_opencv`) and BOP I/O in
:mod:`alcn_cv.formats.bop`; this module converts whole registrations between COLMAP and BOP.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from alcn_cv.errors import InputError
from alcn_cv.formats.bop import BopFrame
from alcn_cv.formats.colmap import ColmapCamera, ColmapImage, ColmapModel, camera_from_opencv

__all__ = [
    "camera_from_opencv",
    "points_opencv_to_colmap",
    "points_colmap_to_opencv",
    "colmap_from_bop_frames",
    "bop_frames_from_colmap",
    "colmap_unit_to_mm",
    "MM_PER_UNIT",
]


def points_opencv_to_colmap(uv: np.ndarray) -> np.ndarray:
    """Pixel coordinates (..., 2) from OpenCV's convention to COLMAP's (+0.5)."""
    return np.asarray(uv, np.float64) + 0.5


def points_colmap_to_opencv(uv: np.ndarray) -> np.ndarray:
    """Pixel coordinates (..., 2) from COLMAP's convention to OpenCV's (-0.5)."""
    return np.asarray(uv, np.float64) - 0.5


def colmap_from_bop_frames(
    frames: Sequence[BopFrame], image_size: tuple[int, int]
) -> tuple[list[ColmapCamera], list[ColmapImage]]:
    """COLMAP cameras and images (poses in mm) of BOP frames that have camera poses.

    One ``PINHOLE`` camera per distinct ``K``; image ``im_id`` becomes COLMAP image
    ``im_id + 1`` (COLMAP ids start at 1) named like its file in ``rgb/``.

    Args:
        frames: frames with ``R_w2c``/``t_w2c``.
        image_size: (width, height) of the images.
    """
    cameras: list[ColmapCamera] = []
    images = []
    for f in frames:
        if f.R_w2c is None:
            raise InputError(f"BOP image {f.im_id} has no camera pose (cam_R_w2c/cam_t_w2c)")
        cam = next((c for c in cameras if np.allclose(c.to_opencv()[0], f.K, rtol=0, atol=1e-9)), None)
        if cam is None:
            cam = camera_from_opencv(f.K, None, *image_size, camera_id=len(cameras) + 1)
            cameras.append(cam)
        images.append(ColmapImage(f.im_id + 1, Path(f.rgb_path).name, cam.camera_id, f.R_w2c, f.t_w2c))
    return cameras, images


#: Millimetres per unit: of the ``# Units:`` header of a COLMAP model, and of every length unit of
#: :mod:`pose` (:func:`pose.model.unit_scale`).
MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0}


def colmap_unit_to_mm(
    model: ColmapModel, unit_to_mm: float | None = None, option: str = "unit_to_mm (millimetres per unit)"
) -> float:
    """Millimetres per unit of a COLMAP model's translations: ``unit_to_mm`` when given, else from the
    model's ``# Units:`` header (``mm``, ``cm`` or ``m``), else 1 (millimetres) without one.

    Args:
        model: the COLMAP model (its ``units`` as :func:`alcn_cv.formats.colmap.read_text_model` read them).
        unit_to_mm: an explicit factor; it wins over the header.
        option: how the error names the way to give the factor (a command-line option for the CLI).

    Raises:
        InputError: a units header other than mm/cm/m without ``unit_to_mm``.
    """
    if unit_to_mm is not None:
        return float(unit_to_mm)
    if model.units is not None and model.units not in MM_PER_UNIT:
        raise InputError(f"the COLMAP model's units are {model.units!r}; pass {option}")
    return MM_PER_UNIT[model.units or "mm"]


def bop_frames_from_colmap(
    model: ColmapModel, image_dir: str | os.PathLike, unit_to_mm: float | None = None
) -> list[BopFrame]:
    """BOP frames (K, pose in mm) of a COLMAP model whose images are named ``<im_id:06d>.png``
    (or any name: ids then follow the name order).

    Args:
        model: the COLMAP model.
        image_dir: folder of its images.
        unit_to_mm: millimetres per unit of the model's translations. Default: from the model's
            ``# Units:`` header (``mm``, ``cm`` or ``m``), or 1 (millimetres) without one.

    Raises:
        InputError: a camera with distortion (BOP images have none: undistort them first,
            e.g. ``alcn calib undistort --keep-K``), or a units header other than mm/cm/m
            without ``unit_to_mm``.
    """
    unit_to_mm = colmap_unit_to_mm(model, unit_to_mm)
    images = sorted(model.images.values(), key=lambda im: im.name)
    numeric = all(Path(im.name).stem.isdigit() for im in images)
    frames = []
    for k, im in enumerate(images):
        K, dist = model.cameras[im.camera_id].to_opencv()
        if np.any(dist):
            raise InputError(
                f"COLMAP camera {im.camera_id} has distortion, which BOP cannot hold; undistort the images first"
            )
        im_id = int(Path(im.name).stem) if numeric else k
        frames.append(BopFrame(im_id, Path(image_dir) / im.name, K, 1.0, [], im.R_w2c, im.t_w2c * unit_to_mm))
    return frames
