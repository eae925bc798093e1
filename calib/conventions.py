"""Camera conventions of OpenCV, COLMAP and BOP, and conversions between them.

All three use the same camera frame (x right, y down, z forward) and world-to-camera poses
``x_cam = R_w2c @ x_world + t_w2c``. They differ in:

============  ===========================  ==========================  ===================
              pixel of the top-left centre  pose storage                units
============  ===========================  ==========================  ===================
OpenCV        (0, 0)                        rvec/tvec or R, t           any (board: mm)
COLMAP        (0.5, 0.5)                    quaternion (w, x, y, z), t  arbitrary (ours: mm)
BOP           (0, 0) (as OpenCV)            ``cam_R_w2c`` (row-major    mm
                                            3x3), ``cam_t_w2c``
============  ===========================  ==========================  ===================

so ``cx_colmap = cx_opencv + 0.5`` and a COLMAP keypoint ``(u, v)`` is the OpenCV point
``(u - 0.5, v - 0.5)``. BOP's ``scene_camera.json`` (Hodan et al., ECCV 2018 and the BOP
toolkit) holds, per image id, ``cam_K`` (row-major 3x3), ``cam_R_w2c``, ``cam_t_w2c`` (mm)
and ``depth_scale``; BOP images carry no distortion.

The COLMAP camera conversions live in :mod:`alcn_cv.formats.colmap`
(:func:`~alcn_cv.formats.colmap.camera_from_opencv`, :meth:`ColmapCamera.to_opencv`) and are
re-exported here.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from alcn_cv.data.manifest import read_json, write_json
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats.colmap import ColmapCamera, camera_from_opencv, qvec_from_rotmat, rotmat_from_qvec

__all__ = [
    "camera_from_opencv",
    "ColmapCamera",
    "qvec_from_rotmat",
    "rotmat_from_qvec",
    "points_opencv_to_colmap",
    "points_colmap_to_opencv",
    "bop_camera_entry",
    "pose_from_bop_entry",
    "write_scene_camera",
    "read_scene_camera",
]


def points_opencv_to_colmap(uv: np.ndarray) -> np.ndarray:
    """Pixel coordinates (..., 2) from OpenCV's convention to COLMAP's (+0.5)."""
    return np.asarray(uv, np.float64) + 0.5


def points_colmap_to_opencv(uv: np.ndarray) -> np.ndarray:
    """Pixel coordinates (..., 2) from COLMAP's convention to OpenCV's (-0.5)."""
    return np.asarray(uv, np.float64) - 0.5


def bop_camera_entry(K: np.ndarray, R_w2c: np.ndarray | None = None, t_w2c: np.ndarray | None = None,
                     unit_to_mm: float = 1.0, depth_scale: float = 1.0) -> dict:
    """One ``scene_camera.json`` entry.

    Args:
        K: (3, 3) intrinsics (OpenCV/BOP convention, no distortion).
        R_w2c, t_w2c: optional pose world -> camera; ``t_w2c`` in units converted to mm by
            ``unit_to_mm`` (1000 for metres).
        depth_scale: BOP's depth scale (depth images are absent here; kept for readers that
            expect the key).
    """
    K = np.asarray(K, float)
    if K.shape != (3, 3):
        raise InputError(f"K must be 3x3, got {K.shape}")
    entry = {"cam_K": K.reshape(-1).tolist(), "depth_scale": float(depth_scale)}
    if R_w2c is not None:
        R = np.asarray(R_w2c, float)
        t = np.asarray(t_w2c, float).reshape(3) * unit_to_mm
        if R.shape != (3, 3):
            raise InputError(f"R_w2c must be 3x3, got {R.shape}")
        entry["cam_R_w2c"] = R.reshape(-1).tolist()
        entry["cam_t_w2c"] = t.tolist()
    return entry


def pose_from_bop_entry(entry: dict, where: str = "scene_camera.json") -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
    """``(K, R_w2c, t_w2c_mm)`` of an entry (pose None when absent)."""
    try:
        K = np.array(entry["cam_K"], float).reshape(3, 3)
    except (KeyError, ValueError, TypeError) as exc:
        raise DatasetError(f"{where}: field cam_K missing or not 9 numbers") from exc
    if "cam_R_w2c" not in entry:
        return K, None, None
    try:
        R = np.array(entry["cam_R_w2c"], float).reshape(3, 3)
        t = np.array(entry["cam_t_w2c"], float).reshape(3)
    except (KeyError, ValueError, TypeError) as exc:
        raise DatasetError(f"{where}: fields cam_R_w2c/cam_t_w2c missing or malformed") from exc
    return K, R, t


def write_scene_camera(path: str | os.PathLike, entries: dict[int, dict]) -> Path:
    """Write a BOP ``scene_camera.json`` (keys: image ids) atomically."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_json(path, {str(int(k)): v for k, v in sorted(entries.items())})


def read_scene_camera(path: str | os.PathLike) -> dict[int, tuple[np.ndarray, np.ndarray | None, np.ndarray | None]]:
    """Read a BOP ``scene_camera.json`` -> ``{image_id: (K, R_w2c, t_w2c_mm)}``."""
    path = Path(path)
    data = read_json(path)
    if not isinstance(data, dict):
        raise DatasetError(f"{path}: expected an object keyed by image id")
    out = {}
    for key, entry in data.items():
        try:
            image_id = int(key)
        except ValueError as exc:
            raise DatasetError(f"{path}: key {key!r} is not an image id") from exc
        out[image_id] = pose_from_bop_entry(entry, f"{path} [{key}]")
    return out
