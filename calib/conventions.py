"""Camera conventions of OpenCV, COLMAP and BOP, and conversions between them.

All three use the same camera frame (x right, y down, z forward) and world-to-camera poses
``x_cam = R_w2c @ x_world + t_w2c``. They differ in:

- pixel convention: OpenCV and BOP put the centre of the top-left pixel at (0, 0), COLMAP at
  (0.5, 0.5); so ``cx_colmap = cx_opencv + 0.5`` and a COLMAP keypoint ``(u, v)`` is the OpenCV
  point ``(u - 0.5, v - 0.5)``;
- pose storage: OpenCV rvec/tvec or R, t; COLMAP a quaternion ``(qw, qx, qy, qz)`` and t in
  ``images.txt``; BOP row-major ``cam_R_w2c`` and ``cam_t_w2c`` in ``scene_camera.json``;
- units: BOP is in millimetres; a COLMAP model's are those of its ``# Units:`` header (the models written
  here have one, but for ``alcn calib register`` without a known length), else arbitrary
  (:func:`colmap_model_units`);
- distortion: COLMAP models carry it (``OPENCV``, ``FULL_OPENCV``); BOP images have none.

Pixel and camera conversions between OpenCV and COLMAP live in :mod:`alcn_cv.formats.colmap`
(:func:`~alcn_cv.formats.colmap.points_opencv_to_colmap`, :func:`~alcn_cv.formats.colmap.camera_from_opencv`,
:meth:`~alcn_cv.formats.colmap.ColmapCamera.to_opencv`) and BOP I/O in :mod:`alcn_cv.formats.bop`; this
module converts registrations from BOP to COLMAP and owns the units of lengths (:data:`MM_PER_UNIT`).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats.bop import BopFrame
from alcn_cv.formats.colmap import ColmapCamera, ColmapImage, ColmapModel, camera_from_opencv

__all__ = [
    "colmap_from_bop_frames",
    "colmap_model_units",
    "colmap_unit_to_mm",
    "registration_units",
    "ARBITRARY_UNITS",
    "MM_PER_UNIT",
]


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

#: The units of poses without a known scale: those ``alcn calib register --method sfm`` records in
#: ``registration.json`` without ``--known-distance`` or ``--reference``, and those of a COLMAP model without a
#: ``# Units:`` header (:func:`colmap_model_units`).
ARBITRARY_UNITS = "arbitrary"


def registration_units(folder: str | os.PathLike) -> str | None:
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


def colmap_model_units(model: ColmapModel, path: str | os.PathLike | None = None) -> str:
    """The units of a COLMAP model's translations and points, the one rule of ``alcn pose`` and ``alcn calib``:

    1. its ``# Units:`` header (:func:`alcn_cv.formats.colmap.write_text_model`; ``alcn calib register`` and
       ``alcn data pose`` write ``mm``);
    2. else, for the model folder ``path`` of a registration (``<out>/colmap`` of ``alcn calib register``, which
       writes no header without a known length), the units in ``registration.json`` beside it;
    3. else :data:`ARBITRARY_UNITS`: a model written by COLMAP has the arbitrary scale of its reconstruction, never
       taken for millimetres or metres.

    Raises:
        DatasetError: an unreadable ``registration.json`` (:func:`registration_units`).
    """
    if model.units:
        return model.units
    recorded = None if path is None else registration_units(Path(path).parent)
    return recorded or ARBITRARY_UNITS


def colmap_unit_to_mm(
    model: ColmapModel,
    path: str | os.PathLike | None = None,
    unit_to_mm: float | None = None,
    option: str = "unit_to_mm (millimetres per unit)",
) -> float:
    """Millimetres per unit of a COLMAP model's translations: ``unit_to_mm`` when given, else those of its units
    (:func:`colmap_model_units` of the model read from the folder ``path``) when they are mm, cm or m.

    Args:
        model: the COLMAP model (its ``units`` as :func:`alcn_cv.formats.colmap.read_model` read them).
        path: the model's folder (for the ``registration.json`` beside it), or None.
        unit_to_mm: an explicit factor; it wins over the header.
        option: how the error names the way to give the factor (a command-line option for the CLI).

    Raises:
        InputError: units other than mm/cm/m (arbitrary ones among them) without ``unit_to_mm``.
    """
    if unit_to_mm is not None:
        return float(unit_to_mm)
    units = colmap_model_units(model, path)
    if units == ARBITRARY_UNITS:
        raise InputError(
            "the COLMAP model's units are arbitrary (no '# Units:' header: a COLMAP reconstruction's scale, or "
            f"`alcn calib register` without a known length); pass {option}"
        )
    if units not in MM_PER_UNIT:
        raise InputError(f"the COLMAP model's units are {units!r}; pass {option}")
    return MM_PER_UNIT[units]
