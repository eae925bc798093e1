"""COLMAP sparse models: text writer, text/binary reader, and OpenCV camera conversion.

The text format is COLMAP's (https://colmap.github.io/format.html):

- ``cameras.txt``: ``CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]``
- ``images.txt``: two lines per image, ``IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME`` then
  ``POINTS2D[] as (X, Y, POINT3D_ID)``; the quaternion (Hamilton, scalar first) and the
  translation map **world to camera**: ``x_cam = R_w2c @ x_world + t_w2c``.
- ``points3D.txt``: ``POINT3D_ID X Y Z R G B ERROR TRACK[] as (IMAGE_ID, POINT2D_IDX)``.

Pixel convention: COLMAP puts the centre of the top-left pixel at (0.5, 0.5), OpenCV at
(0, 0). This module owns that half pixel: :func:`points_opencv_to_colmap` and
:func:`points_colmap_to_opencv` add and remove it, on 2D points (those stored in ``images.txt``
are in COLMAP's convention) and, through :func:`camera_from_opencv` and
:meth:`ColmapCamera.to_opencv`, on the principal point: ``cx_colmap = cx_opencv + 0.5``.

Binary models (``cameras.bin`` ...) are read through ``pycolmap.Reconstruction``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import atomic_write, make_folder

if TYPE_CHECKING:
    import pycolmap

logger = logging.getLogger(__name__)

__all__ = [
    "ColmapCamera",
    "ColmapImage",
    "ColmapPoint3D",
    "ColmapModel",
    "CAMERA_MODEL_PARAMS",
    "camera_from_opencv",
    "camera_from_pycolmap",
    "points_opencv_to_colmap",
    "points_colmap_to_opencv",
    "qvec_from_rotmat",
    "rotmat_from_qvec",
    "write_text_model",
    "read_model",
    "read_text_model",
    "model_from_pycolmap",
]

#: Parameter names of the COLMAP camera models this module converts to and from OpenCV.
CAMERA_MODEL_PARAMS: dict[str, tuple[str, ...]] = {
    "SIMPLE_PINHOLE": ("f", "cx", "cy"),
    "PINHOLE": ("fx", "fy", "cx", "cy"),
    "SIMPLE_RADIAL": ("f", "cx", "cy", "k"),
    "RADIAL": ("f", "cx", "cy", "k1", "k2"),
    "OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2"),
    "FULL_OPENCV": ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
}

#: Number of parameters of every COLMAP camera model (used to validate files).
_MODEL_NUM_PARAMS: dict[str, int] = {
    **{name: len(p) for name, p in CAMERA_MODEL_PARAMS.items()},
    "OPENCV_FISHEYE": 8,
    "SIMPLE_RADIAL_FISHEYE": 4,
    "RADIAL_FISHEYE": 5,
    "THIN_PRISM_FISHEYE": 12,
    "FOV": 5,
    "RAD_TAN_THIN_PRISM_FISHEYE": 16,
    "SIMPLE_DIVISION": 4,
    "DIVISION": 5,
    "SIMPLE_FISHEYE": 3,
    "FISHEYE": 4,
    "EUCM": 6,
    "EQUIRECTANGULAR": 2,
}


def points_opencv_to_colmap(uv: np.ndarray | Sequence[float]) -> np.ndarray:
    """Pixel coordinates ``(..., 2)`` from OpenCV's convention to COLMAP's (+0.5), float64."""
    return np.asarray(uv, np.float64) + 0.5


def points_colmap_to_opencv(uv: np.ndarray | Sequence[float]) -> np.ndarray:
    """Pixel coordinates ``(..., 2)`` from COLMAP's convention to OpenCV's (-0.5), float64."""
    return np.asarray(uv, np.float64) - 0.5


@dataclass
class ColmapCamera:
    """One COLMAP camera.

    Attributes:
        camera_id: positive integer id.
        model: COLMAP model name, e.g. ``"PINHOLE"``, ``"OPENCV"``.
        width, height: image size in pixels.
        params: float64 (P,) parameters in COLMAP's order and pixel convention
            (principal point measured with the top-left pixel centre at (0.5, 0.5)).
    """

    camera_id: int
    model: str
    width: int
    height: int
    params: np.ndarray

    def __post_init__(self) -> None:
        self.params = np.asarray(self.params, dtype=np.float64).reshape(-1)
        expected = _MODEL_NUM_PARAMS.get(self.model)
        if expected is None:
            raise InputError(f"unknown COLMAP camera model {self.model!r}; known: {sorted(_MODEL_NUM_PARAMS)}")
        if self.params.size != expected:
            raise InputError(f"COLMAP camera model {self.model} takes {expected} parameters, got {self.params.size}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise InputError(f"camera size must be positive, got {self.width}x{self.height}")

    def to_opencv(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the OpenCV intrinsics of this camera.

        Returns:
            ``(K, dist)``: K float64 (3, 3) with the principal point in OpenCV's convention
            (``cx_opencv = cx_colmap - 0.5``); dist float64 (N,) in OpenCV's order
            ``(k1, k2, p1, p2[, k3, k4, k5, k6])``, N = 4 or 8 (zeros for models without
            distortion).

        Raises:
            InputError: for fisheye and other models OpenCV's pinhole model cannot represent.
        """
        names = CAMERA_MODEL_PARAMS.get(self.model)
        if names is None:
            raise InputError(
                f"COLMAP camera model {self.model} has no OpenCV pinhole equivalent; "
                f"supported: {sorted(CAMERA_MODEL_PARAMS)}"
            )
        p = dict(zip(names, self.params))
        fx = p.get("fx", p.get("f"))
        fy = p.get("fy", p.get("f"))
        cx, cy = points_colmap_to_opencv([p["cx"], p["cy"]])
        K = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        if self.model == "FULL_OPENCV":
            dist = np.array([p[k] for k in ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")])
        else:
            dist = np.array([p.get("k1", p.get("k", 0.0)), p.get("k2", 0.0), p.get("p1", 0.0), p.get("p2", 0.0)])
        return K, dist


def camera_from_opencv(
    K: np.ndarray,
    dist: np.ndarray | Sequence[float] | None,
    width: int,
    height: int,
    camera_id: int = 1,
) -> ColmapCamera:
    """Convert OpenCV intrinsics to the simplest COLMAP camera that holds them exactly.

    Args:
        K: (3, 3) camera matrix, OpenCV pixel convention (top-left pixel centre at (0, 0)),
            zero skew.
        dist: OpenCV distortion ``(k1, k2, p1, p2[, k3[, k4, k5, k6]])`` or None. Thin-prism
            and tilt terms (14 coefficients) must be zero.
        width, height: image size in pixels.
        camera_id: id of the camera in the model.

    Returns:
        ``PINHOLE`` when there is no distortion, ``OPENCV`` for ``(k1, k2, p1, p2)``, and
        ``FULL_OPENCV`` when any of ``k3..k6`` is non-zero. ``cx, cy`` get +0.5.
    """
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise InputError(f"K must be a finite 3x3 matrix, got shape {K.shape}")
    if abs(K[0, 1]) > 1e-9 * max(1.0, abs(K[0, 0])):
        raise InputError("COLMAP cameras have no skew; K[0, 1] must be 0")
    d = np.zeros(8) if dist is None else np.asarray(dist, dtype=np.float64).reshape(-1)
    if d.size not in (0, 4, 5, 8, 12, 14):
        raise InputError(f"OpenCV distortion has 4, 5, 8, 12 or 14 coefficients, got {d.size}")
    if d.size > 8 and np.any(d[8:] != 0):
        raise InputError("thin-prism/tilt distortion terms (coefficients 9..14) have no COLMAP equivalent")
    d8 = np.zeros(8)
    d8[: min(d.size, 8)] = d[:8]
    fx, fy = K[0, 0], K[1, 1]
    cx, cy = points_opencv_to_colmap(K[:2, 2])
    if not np.any(d8):
        return ColmapCamera(camera_id, "PINHOLE", int(width), int(height), np.array([fx, fy, cx, cy]))
    if not np.any(d8[4:]):
        return ColmapCamera(camera_id, "OPENCV", int(width), int(height), np.r_[fx, fy, cx, cy, d8[:4]])
    return ColmapCamera(camera_id, "FULL_OPENCV", int(width), int(height), np.r_[fx, fy, cx, cy, d8])


def qvec_from_rotmat(R: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) -> unit quaternion ``(qw, qx, qy, qz)`` (Hamilton, qw >= 0)."""
    from scipy.spatial.transform import Rotation  # here: scipy.spatial takes 0.2 s to import (every `alcn` start)

    q = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat(scalar_first=True)
    return q if q[0] >= 0 else -q


def rotmat_from_qvec(qvec: np.ndarray | Sequence[float]) -> np.ndarray:
    """Quaternion ``(qw, qx, qy, qz)`` (normalized here) -> rotation matrix float64 (3, 3)."""
    q = np.asarray(qvec, dtype=np.float64)
    n = np.linalg.norm(q)
    if q.shape != (4,) or not np.isfinite(n) or n < 1e-12:
        raise InputError(f"quaternion must be 4 finite numbers, not all zero; got {qvec!r}")
    from scipy.spatial.transform import Rotation

    return Rotation.from_quat(q / n, scalar_first=True).as_matrix()


@dataclass
class ColmapImage:
    """One registered COLMAP image.

    Attributes:
        image_id: positive integer id.
        name: file name relative to the image folder.
        camera_id: id of its :class:`ColmapCamera`.
        R_w2c: float64 (3, 3) rotation world -> camera.
        t_w2c: float64 (3,) translation world -> camera, in the model's units.
        points2d: float64 (N, 2) keypoints, COLMAP pixel convention; may be empty.
        point3d_ids: int64 (N,) id of the 3D point of each keypoint, -1 when none.
    """

    image_id: int
    name: str
    camera_id: int
    R_w2c: np.ndarray
    t_w2c: np.ndarray
    points2d: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    point3d_ids: np.ndarray = field(default_factory=lambda: np.zeros((0,), dtype=np.int64))

    def __post_init__(self) -> None:
        self.R_w2c = np.asarray(self.R_w2c, dtype=np.float64)
        self.t_w2c = np.asarray(self.t_w2c, dtype=np.float64).reshape(-1)
        self.points2d = np.asarray(self.points2d, dtype=np.float64).reshape(-1, 2)
        self.point3d_ids = np.asarray(self.point3d_ids, dtype=np.int64).reshape(-1)
        if self.R_w2c.shape != (3, 3) or self.t_w2c.shape != (3,):
            raise InputError(f"image {self.name!r}: R_w2c must be 3x3 and t_w2c 3 values")
        if len(self.points2d) != len(self.point3d_ids):
            raise InputError(f"image {self.name!r}: points2d and point3d_ids differ in length")
        if any(c.isspace() for c in self.name) or not self.name:
            raise InputError(f"image name {self.name!r} must be non-empty and contain no whitespace")

    @property
    def qvec(self) -> np.ndarray:
        """World-to-camera rotation as ``(qw, qx, qy, qz)``."""
        return qvec_from_rotmat(self.R_w2c)

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates, ``-R_w2c.T @ t_w2c`` (3,)."""
        return -self.R_w2c.T @ self.t_w2c


@dataclass
class ColmapPoint3D:
    """One triangulated point: id, xyz (3,), rgb uint8 (3,), reprojection error (px),
    and track int64 (M, 2) of ``(image_id, point2d_idx)``."""

    point3d_id: int
    xyz: np.ndarray
    rgb: np.ndarray = field(default_factory=lambda: np.zeros(3, dtype=np.uint8))
    error: float = 0.0
    track: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))

    def __post_init__(self) -> None:
        self.xyz = np.asarray(self.xyz, dtype=np.float64).reshape(3)
        self.rgb = np.asarray(self.rgb, dtype=np.uint8).reshape(3)
        self.track = np.asarray(self.track, dtype=np.int64).reshape(-1, 2)


@dataclass
class ColmapModel:
    """A sparse model: cameras and images keyed by id, and 3D points keyed by id."""

    cameras: dict[int, ColmapCamera]
    images: dict[int, ColmapImage]
    points3d: dict[int, ColmapPoint3D]
    units: str | None = None  #: from a ``# Units: ...`` header line (written by this module), else None

    def image_by_name(self, name: str) -> ColmapImage:
        """Return the image called ``name``; KeyError when absent."""
        for image in self.images.values():
            if image.name == name:
                return image
        raise KeyError(name)


def _fmt(x: float) -> str:
    return repr(float(x))


def write_text_model(
    path: str | os.PathLike,
    cameras: Iterable[ColmapCamera],
    images: Iterable[ColmapImage],
    points3d: Iterable[ColmapPoint3D] | None = None,
    units: str | None = None,
) -> Path:
    """Write a COLMAP text model (``cameras.txt``, ``images.txt``, ``points3D.txt``).

    Known poses are written as ``qvec``/``tvec`` world-to-camera. Without ``points3d``,
    ``points3D.txt`` is empty (header only) and each image's 2D-point line is empty unless
    the image carries ``points2d``. Every file is written to a temporary name and renamed,
    so a reader never sees a half-written file; ``points3D.txt`` is written last.

    Args:
        path: output folder (created if needed).
        cameras, images, points3d: the model. Every image's ``camera_id`` must exist.
        units: unit of translations and points (e.g. ``"mm"``), recorded as a ``# Units: mm``
            comment in every file (COLMAP ignores comments; :func:`read_model` returns it).

    Returns:
        The output folder.
    """
    out = Path(path)
    make_folder(out)
    cameras = list(cameras)
    images = list(images)
    points3d = list(points3d or [])
    cam_ids = [c.camera_id for c in cameras]
    if len(set(cam_ids)) != len(cam_ids):
        raise InputError("duplicate camera_id in cameras")
    img_ids = [i.image_id for i in images]
    if len(set(img_ids)) != len(img_ids):
        raise InputError("duplicate image_id in images")
    for image in images:
        if image.camera_id not in cam_ids:
            raise InputError(f"image {image.name!r} refers to camera_id {image.camera_id}, which is not given")

    unit_line = [f"# Units: {units}"] if units else []
    if units and (not units.strip() or any(c.isspace() for c in units)):
        raise InputError(f"units must be one word such as 'mm', got {units!r}")
    lines = [
        "# Camera list with one line of data per camera:",
        "#   CAMERA_ID, MODEL, WIDTH, HEIGHT, PARAMS[]",
        f"# Number of cameras: {len(cameras)}",
        *unit_line,
    ]
    for c in cameras:
        lines.append(" ".join([str(c.camera_id), c.model, str(c.width), str(c.height), *map(_fmt, c.params)]))
    atomic_write(out / "cameras.txt", "\n".join(lines) + "\n")

    n_obs = sum(len(i.points2d) for i in images)
    lines = [
        "# Image list with two lines of data per image:",
        "#   IMAGE_ID, QW, QX, QY, QZ, TX, TY, TZ, CAMERA_ID, NAME",
        "#   POINTS2D[] as (X, Y, POINT3D_ID)",
        f"# Number of images: {len(images)}, mean observations per image: {n_obs / max(len(images), 1):g}",
        *unit_line,
    ]
    for i in images:
        lines.append(" ".join([str(i.image_id), *map(_fmt, i.qvec), *map(_fmt, i.t_w2c), str(i.camera_id), i.name]))
        lines.append(" ".join(f"{_fmt(x)} {_fmt(y)} {int(pid)}" for (x, y), pid in zip(i.points2d, i.point3d_ids)))
    atomic_write(out / "images.txt", "\n".join(lines) + "\n")

    lines = [
        "# 3D point list with one line of data per point:",
        "#   POINT3D_ID, X, Y, Z, R, G, B, ERROR, TRACK[] as (IMAGE_ID, POINT2D_IDX)",
        f"# Number of points: {len(points3d)}",
        *unit_line,
    ]
    for p in points3d:
        track = " ".join(f"{int(a)} {int(b)}" for a, b in p.track)
        lines.append(" ".join([str(p.point3d_id), *map(_fmt, p.xyz), *map(str, p.rgb), _fmt(p.error), track]).rstrip())
    atomic_write(out / "points3D.txt", "\n".join(lines) + "\n")
    logger.debug(
        "wrote COLMAP text model (%d cameras, %d images, %d points) to %s",
        len(cameras),
        len(images),
        len(points3d),
        out,
    )
    return out


def _data_lines(file: Path) -> list[tuple[int, str]]:
    """(line number, text) of the lines of ``file`` that are not comments (blank lines kept)."""
    try:
        text = file.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{file}: not a UTF-8 text file ({exc})") from exc
    return [(n, line.rstrip("\r\n")) for n, line in enumerate(text.split("\n"), 1) if not line.startswith("#")]


def _floats(file: Path, lineno: int, what: str, tokens: Sequence[str]) -> np.ndarray:
    try:
        values = np.array([float(t) for t in tokens], dtype=np.float64)
    except ValueError as exc:
        raise DatasetError(f"{file}:{lineno}: field {what}: {exc}") from exc
    if not np.all(np.isfinite(values)):
        raise DatasetError(f"{file}:{lineno}: field {what} holds NaN or inf")
    return values


def _int(file: Path, lineno: int, what: str, token: str) -> int:
    try:
        return int(token)
    except ValueError as exc:
        raise DatasetError(f"{file}:{lineno}: field {what} must be an integer, got {token!r}") from exc


def _read_cameras_txt(file: Path) -> dict[int, ColmapCamera]:
    cameras = {}
    for n, line in _data_lines(file):
        tok = line.split()
        if not tok:
            continue
        if len(tok) < 5:
            raise DatasetError(f"{file}:{n}: expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[], got {line!r}")
        cid = _int(file, n, "CAMERA_ID", tok[0])
        if cid in cameras:
            raise DatasetError(f"{file}:{n}: field CAMERA_ID: duplicate id {cid}")
        try:
            cameras[cid] = ColmapCamera(
                cid,
                tok[1],
                _int(file, n, "WIDTH", tok[2]),
                _int(file, n, "HEIGHT", tok[3]),
                _floats(file, n, "PARAMS", tok[4:]),
            )
        except InputError as exc:
            raise DatasetError(f"{file}:{n}: {exc}") from exc
    return cameras


def _read_images_txt(file: Path) -> dict[int, ColmapImage]:
    lines = _data_lines(file)
    while lines and not lines[-1][1].strip():  # trailing newline(s)
        lines.pop()
    # Images come in pairs of lines; the second (2D points) may be empty.
    images = {}
    k = 0
    while k < len(lines):
        n, line = lines[k]
        tok = line.split()
        if not tok:  # tolerate stray blank lines between records
            k += 1
            continue
        if len(tok) != 10:
            raise DatasetError(
                f"{file}:{n}: expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME, got {line!r} "
                "(image names with spaces are not supported)"
            )
        n2, pts_line = lines[k + 1] if k + 1 < len(lines) else (n + 1, "")
        pts = pts_line.split()
        if len(pts) % 3:
            raise DatasetError(f"{file}:{n2}: field POINTS2D must hold triples (X, Y, POINT3D_ID)")
        pts_arr = _floats(file, n2, "POINTS2D", pts).reshape(-1, 3) if pts else np.zeros((0, 3))
        iid = _int(file, n, "IMAGE_ID", tok[0])
        if iid in images:
            raise DatasetError(f"{file}:{n}: field IMAGE_ID: duplicate id {iid}")
        if np.any(pts_arr[:, 2] != np.round(pts_arr[:, 2])):
            raise DatasetError(f"{file}:{n2}: field POINT3D_ID must be integers")
        q = _floats(file, n, "QVEC", tok[1:5])
        if np.linalg.norm(q) < 1e-12:
            raise DatasetError(f"{file}:{n}: field QVEC is zero")
        images[iid] = ColmapImage(
            iid,
            tok[9],
            _int(file, n, "CAMERA_ID", tok[8]),
            rotmat_from_qvec(q),
            _floats(file, n, "TVEC", tok[5:8]),
            pts_arr[:, :2],
            pts_arr[:, 2].astype(np.int64),
        )
        k += 2
    return images


def _read_points3d_txt(file: Path) -> dict[int, ColmapPoint3D]:
    points = {}
    for n, line in _data_lines(file):
        tok = line.split()
        if not tok:
            continue
        if len(tok) < 8 or (len(tok) - 8) % 2:
            raise DatasetError(f"{file}:{n}: expected POINT3D_ID X Y Z R G B ERROR TRACK[], got {line!r}")
        pid = _int(file, n, "POINT3D_ID", tok[0])
        if pid in points:
            raise DatasetError(f"{file}:{n}: field POINT3D_ID: duplicate id {pid}")
        rgb = _floats(file, n, "RGB", tok[4:7])
        if np.any((rgb < 0) | (rgb > 255) | (rgb != np.round(rgb))):
            raise DatasetError(f"{file}:{n}: field RGB must be integers in 0..255, got {tok[4:7]}")
        track = _floats(file, n, "TRACK", tok[8:])
        if np.any(track != np.round(track)):
            raise DatasetError(f"{file}:{n}: field TRACK must hold integers (IMAGE_ID, POINT2D_IDX)")
        track = track.astype(np.int64).reshape(-1, 2)
        points[pid] = ColmapPoint3D(
            pid,
            _floats(file, n, "XYZ", tok[1:4]),
            rgb.astype(np.uint8),
            float(_floats(file, n, "ERROR", tok[7:8])[0]),
            track,
        )
    return points


def read_text_model(path: str | os.PathLike) -> ColmapModel:
    """Read a COLMAP text model; ``points3D.txt`` may be missing (no points).

    Raises:
        DatasetError: a missing ``cameras.txt``/``images.txt``, a malformed line (the message
            gives file, line and field), or an image whose camera is not defined.
    """
    root = Path(path)
    for name in ("cameras.txt", "images.txt"):
        if not (root / name).is_file():
            raise DatasetError(f"{root / name}: missing (a COLMAP text model needs cameras.txt and images.txt)")
    cameras = _read_cameras_txt(root / "cameras.txt")
    images = _read_images_txt(root / "images.txt")
    points = _read_points3d_txt(root / "points3D.txt") if (root / "points3D.txt").is_file() else {}
    for image in images.values():
        if image.camera_id not in cameras:
            raise DatasetError(
                f"{root / 'images.txt'}: image {image.name!r} field CAMERA_ID={image.camera_id} is not in cameras.txt"
            )
    units = None
    for line in (root / "images.txt").read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        if line.startswith("# Units:"):
            units = line.split(":", 1)[1].strip() or None
    return ColmapModel(cameras, images, points, units)


def camera_from_pycolmap(camera: pycolmap.Camera) -> ColmapCamera:
    """Convert a ``pycolmap.Camera`` (COLMAP's pixel convention) to a :class:`ColmapCamera`; its
    :meth:`~ColmapCamera.to_opencv` gives OpenCV's ``K`` and distortion.

    Raises:
        InputError: a camera model this module does not know.
    """
    return ColmapCamera(
        int(camera.camera_id), camera.model.name, int(camera.width), int(camera.height), np.array(camera.params)
    )


def model_from_pycolmap(rec: pycolmap.Reconstruction) -> ColmapModel:
    """Convert a ``pycolmap.Reconstruction`` to a :class:`ColmapModel` (registered images only)."""
    cameras = {int(cid): camera_from_pycolmap(c) for cid, c in rec.cameras.items()}
    images = {}
    for iid, im in rec.images.items():
        if not im.has_pose:
            continue
        pose = im.cam_from_world()
        pts = im.points2D
        xy = np.array([p.xy for p in pts]).reshape(-1, 2)
        ids = np.array([p.point3D_id if p.has_point3D() else -1 for p in pts], dtype=np.int64).reshape(-1)
        images[int(iid)] = ColmapImage(
            int(iid), im.name, int(im.camera_id), pose.rotation.matrix(), np.array(pose.translation), xy, ids
        )
    points = {
        int(pid): ColmapPoint3D(
            int(pid),
            np.array(p.xyz),
            np.array(p.color),
            float(p.error),
            np.array([(e.image_id, e.point2D_idx) for e in p.track.elements], dtype=np.int64).reshape(-1, 2),
        )
        for pid, p in rec.points3D.items()
    }
    return ColmapModel(cameras, images, points)


def _read_binary_model(root: Path) -> ColmapModel:
    import pycolmap

    try:
        rec = pycolmap.Reconstruction(str(root))
    except Exception as exc:  # pycolmap raises plain RuntimeError/ValueError with C++ messages
        raise DatasetError(f"{root}: cannot read the COLMAP binary model ({exc})") from exc
    try:
        return model_from_pycolmap(rec)
    except InputError as exc:  # e.g. a camera model this module does not know
        raise DatasetError(f"{root}: {exc}") from exc


def read_model(path: str | os.PathLike) -> ColmapModel:
    """Read a COLMAP sparse model from a folder, text (``*.txt``) or binary (``*.bin``).

    Text is preferred when both exist. Binary models are read with ``pycolmap``; images
    without a pose are skipped.

    Returns:
        :class:`ColmapModel` with poses world-to-camera and cameras in COLMAP's convention
        (use :meth:`ColmapCamera.to_opencv` for OpenCV's K).

    Raises:
        DatasetError: no model in the folder, or a malformed file.
    """
    root = Path(path)
    if (root / "cameras.txt").is_file() or (root / "images.txt").is_file():
        return read_text_model(root)
    if (root / "cameras.bin").is_file():
        return _read_binary_model(root)
    raise DatasetError(f"{root}: no COLMAP model (expected cameras.txt/images.txt or cameras.bin/images.bin)")
