"""The part model: what ``alcn pose build`` writes and ``alcn pose track`` reads.

A part model describes one rigid box-like object in its own *object frame*:

* the box: its size ``(3,)`` along the frame's axes and its 8 corners ``(8, 3)``; the learned
  detector's parts lie on it (:func:`pose.box.box_parts`: the corners of the Box experiment of
  Rad et al., BMVC 2017, Sec. 4.4, after Crivellaro et al., ICCV 2015, the edges' middles and
  the faces' centres), and the pose solver checks its inliers against its outline;
* the sparse 3D points triangulated from the training sequence, each with one or more
  descriptors (the classical detector matches image features to them) and its track length;
* the units of every length (``"mm"``, ``"cm"`` or ``"m"``).

File format (version :data:`FORMAT_VERSION`)
-------------------------------------------
One ``.npz`` archive (``numpy.savez``, no pickles) holding the arrays below and a JSON header
stored as a 0-d unicode array under the key ``header``:

====================  ============  =========  ===============================================
key                   shape         dtype      meaning
====================  ============  =========  ===============================================
``header``            ()            str        JSON: ``format``, ``version``, ``units``,
                                               ``feature`` (OpenCV detector name),
                                               ``normalization``, ``source``, ``box_fit`` (fit
                                               statistics), ``extra``
``corners``           (8, 3)        float64    box corners in the object frame, in the order
                                               of :func:`box_corners`
``box_size``          (3,)          float64    edge lengths along x, y, z
``points3d``          (N, 3)        float32    triangulated points in the object frame
``descriptors``       (M, D)        uint8/f32  descriptors (binary for ORB/AKAZE); a point
                                               may have several (seen from several views)
``descriptor_point``  (M,)          int32      the point (row of ``points3d``) each describes
``track_length``      (N,)          int32      number of training images that saw each point
``colors``            (N, 3)        uint8      RGB colour of each point (for the PLY)
====================  ============  =========  ===============================================

:func:`save` also writes the point cloud beside the archive as ``<stem>.ply`` (for MeshLab,
open3d, CloudCompare). Files are written atomically (temporary name, then rename).
Version 1 had one descriptor per point and no ``descriptor_point``; versions 1 and 2 name the
normalization ``normalizer`` in the header; both are still read. Reading an archive of another
version raises :class:`~alcn_cv.errors.WeightFileError` naming both versions.
"""

from __future__ import annotations

import io
import json
import logging
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from alcn_cv.errors import DatasetError, InputError, WeightFileError
from alcn_cv.formats import bop
from alcn_cv.io import atomic_write, is_video, with_suffix
from alcn_cv.weight_file import check_header, npz_array
from calib.conventions import MM_PER_UNIT
from pose.box import box_diameter, box_size

logger = logging.getLogger(__name__)

FORMAT_NAME = "alcn-part-model"
FORMAT_VERSION = 3
READABLE_VERSIONS = (1, 2, 3)
UNITS = tuple(MM_PER_UNIT)


def unit_scale(src: str, dst: str) -> float:
    """Factor that converts a length in ``src`` units into ``dst`` units (``"mm"``, ``"cm"``, ``"m"``)."""
    for u in (src, dst):
        if u not in MM_PER_UNIT:
            raise InputError(f"unknown unit {u!r}; expected one of {UNITS}")
    return MM_PER_UNIT[src] / MM_PER_UNIT[dst]


def box_corners(size: np.ndarray, origin: np.ndarray | None = None) -> np.ndarray:
    """The 8 corners ``(8, 3)`` float64 of an axis-aligned box ``[origin, origin + size]``.

    Order: corner ``i`` has ``x = origin_x + size_x`` if bit 2 of ``i`` is set (else ``origin_x``),
    ``y`` likewise from bit 1 and ``z`` from bit 0.
    """
    size = np.asarray(size, dtype=np.float64).reshape(3)
    origin = np.zeros(3) if origin is None else np.asarray(origin, dtype=np.float64).reshape(3)
    bits = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)], dtype=np.float64)
    return origin + bits * size


# The 12 edges of a box as pairs of corner indices in the order of :func:`box_corners`.
BOX_EDGES: tuple[tuple[int, int], ...] = tuple(
    (i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1
)


@dataclass
class PartModel:
    """A box-shaped object's parts and sparse 3D points in its object frame (see module doc)."""

    corners: np.ndarray
    points3d: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    descriptors: np.ndarray = field(default_factory=lambda: np.zeros((0, 32), np.uint8))
    descriptor_point: np.ndarray | None = None
    track_length: np.ndarray | None = None
    colors: np.ndarray | None = None
    units: str = "mm"
    feature: str = "ORB"
    normalization: str = "none"
    source: str = ""
    box_fit: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.corners = np.asarray(self.corners, dtype=np.float64)
        if self.corners.shape != (8, 3) or not np.isfinite(self.corners).all():
            raise InputError(f"corners must be a finite (8, 3) array, got shape {self.corners.shape}")
        self.points3d = np.asarray(self.points3d, dtype=np.float32).reshape(-1, 3)
        n = len(self.points3d)
        if self.descriptor_point is None:  # one descriptor per point
            if len(self.descriptors) != n:
                raise InputError(f"{len(self.descriptors)} descriptors for {n} points")
            self.descriptor_point = np.arange(n, dtype=np.int32)
        self.descriptor_point = np.asarray(self.descriptor_point, dtype=np.int32).reshape(-1)
        if len(self.descriptor_point) != len(self.descriptors):
            raise InputError(
                f"{len(self.descriptors)} descriptors but {len(self.descriptor_point)} descriptor_point entries"
            )
        if len(self.descriptor_point) and (self.descriptor_point.min() < 0 or self.descriptor_point.max() >= n):
            raise InputError(
                f"descriptor_point must index the {n} points, got values in "
                f"[{self.descriptor_point.min()}, {self.descriptor_point.max()}]"
            )
        if self.track_length is None:
            self.track_length = np.ones(n, np.int32)
        self.track_length = np.asarray(self.track_length, dtype=np.int32).reshape(n)
        if self.colors is None:
            self.colors = np.full((n, 3), 200, np.uint8)
        self.colors = np.asarray(self.colors, dtype=np.uint8).reshape(n, 3)
        if self.units not in UNITS:
            raise InputError(f"unknown unit {self.units!r}; expected one of {UNITS}")

    @property
    def box_size(self) -> np.ndarray:
        """Edge lengths ``(3,)`` of the box (:func:`pose.box.box_size`: from corner 0 to corners 4, 2, 1)."""
        return box_size(self.corners)

    @property
    def diameter(self) -> float:
        """Largest distance between two corners (the box's diagonal, :func:`pose.box.box_diameter`), in
        :attr:`units`."""
        return box_diameter(self.corners)

    def header(self) -> dict[str, Any]:
        return {
            "format": FORMAT_NAME,
            "version": FORMAT_VERSION,
            "units": self.units,
            "feature": self.feature,
            "normalization": self.normalization,
            "source": self.source,
            "box_fit": self.box_fit,
            "extra": self.extra,
        }


def write_point_cloud(path: str | Path, points: np.ndarray, colors: np.ndarray | None = None) -> Path:
    """Write a coloured point cloud ``(N, 3)`` (RGB ``(N, 3)`` uint8) as a binary PLY, atomically."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return bop.write_ply(
        path,
        bop.PlyModel(
            vertices=pts,
            faces=np.zeros((0, 3), np.int64),
            colors=None if colors is None else np.asarray(colors, np.uint8),
        ),
    )


#: How far, as a share of the box's edge, a vertex of a box's PLY may lie from the corner it is (the text of an ASCII
#: PLY rounds).
BOX_PLY_TOLERANCE = 1e-3


def read_box_corners(path: str | Path) -> np.ndarray:
    """The 8 corners ``(8, 3)`` (order of :func:`box_corners`) of the axis-aligned box a PLY mesh's vertices are
    the corners of, in the file's units (a cuboid such as ``cookie_box/box.ply``, a BOP model of one: a corner may
    be repeated, once per face).

    Raises:
        DatasetError: no vertices, vertices that are not finite, a flat box, or vertices that are not the 8 corners
            of a box (another shape, whose bounding box would be taken for the object's).
    """
    verts = bop.read_ply(path, unit_check=False).vertices
    if len(verts) == 0:
        raise DatasetError(f"{path}: field 'vertex': no vertices")
    finite = np.isfinite(verts).all(1)
    if not finite.all():
        raise DatasetError(f"{path}: field 'vertex': {np.count_nonzero(~finite)} of its vertices are not finite")
    lo, hi = verts.min(0), verts.max(0)
    if np.any(hi - lo <= 0):
        raise DatasetError(f"{path}: field 'vertex': the vertices span a flat or empty box {hi - lo}")
    tolerance = BOX_PLY_TOLERANCE * (hi - lo)
    at_lo, at_hi = np.abs(verts - lo) <= tolerance, np.abs(verts - hi) <= tolerance
    # each vertex at a corner (at the low or high end of every axis), and each of the 8 corners one of them
    if not (at_lo | at_hi).all() or len({tuple(row) for row in at_hi}) < 8:
        raise DatasetError(
            f"{path}: field 'vertex': its {len(verts)} vertices are not the 8 corners of a box (a cuboid mesh)"
        )
    return box_corners(hi - lo, lo)


def model_file(path: str | Path) -> Path:
    """``path`` as a part model's file: ``.npz``, which is appended to a path without a suffix, as ``numpy.savez``
    does (another suffix is an error)."""
    path = Path(path)
    return with_suffix(path if path.suffix else path.with_suffix(".npz"), ".npz", "a part model")


def save(model: PartModel, path: str | Path) -> Path:
    """Write ``model`` to ``path`` (``.npz``) and its point cloud to ``<stem>.ply`` beside it."""
    path = model_file(path)  # the write itself says why it cannot be written
    buf = io.BytesIO()
    np.savez(
        buf,
        header=np.array(json.dumps(model.header())),
        corners=model.corners,
        box_size=model.box_size,
        points3d=model.points3d,
        descriptors=model.descriptors,
        descriptor_point=model.descriptor_point,
        track_length=model.track_length,
        colors=model.colors,
    )
    atomic_write(path, buf.getvalue())
    write_point_cloud(path.with_suffix(".ply"), model.points3d, model.colors)
    logger.info(
        "wrote part model %s (%d points, box %s %s)",
        path,
        len(model.points3d),
        np.round(model.box_size, 3).tolist(),
        model.units,
    )
    return path


def load(path: str | Path) -> PartModel:
    """Read a part model written by :func:`save`.

    Raises:
        WeightFileError: missing, corrupt or truncated file, arrays of pickled objects, another format, or another
            version.
    """
    path = Path(path)
    if not path.is_file():
        raise WeightFileError(f"{path}: part model not found")
    if path.suffix.lower() == ".ply":
        beside = path.with_suffix(".npz")
        if beside.is_file():
            raise WeightFileError(f"{path}: the point cloud of a part model; the model is {beside}")
        raise WeightFileError(f"{path}: a point cloud or mesh, not a part model (the .npz of `alcn pose build`)")
    if not zipfile.is_zipfile(path):  # np.load would read it as a pickle and say how to load one unsafely
        what = "a video" if is_video(path) else "no .npz archive"
        raise WeightFileError(f"{path}: {what}, not a part model (the .npz of `alcn pose build`)")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: npz_array(z, k, path, "a part model") for k in z.files}
    except WeightFileError:
        raise
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise WeightFileError(f"{path}: corrupt or truncated part model ({exc})") from None
    try:
        header = json.loads(str(arrays.pop("header")))
    except (KeyError, json.JSONDecodeError) as exc:
        raise WeightFileError(f"{path}: field 'header' missing or not JSON") from exc
    check_header(
        header, path, FORMAT_NAME, READABLE_VERSIONS, what="part model", again="rebuild it with `alcn pose build`"
    )
    try:
        return PartModel(
            corners=arrays["corners"],
            points3d=arrays["points3d"],
            descriptors=arrays["descriptors"],
            descriptor_point=arrays["descriptor_point"] if header["version"] >= 2 else None,
            track_length=arrays["track_length"],
            colors=arrays["colors"],
            units=header["units"],
            feature=header["feature"],
            normalization=header.get("normalization" if header["version"] >= 3 else "normalizer", "none"),
            source=header.get("source", ""),
            box_fit=header.get("box_fit", {}),
            extra=header.get("extra", {}),
        )
    except KeyError as exc:
        raise WeightFileError(f"{path}: field {exc.args[0]!r} missing") from exc
    except InputError as exc:
        raise WeightFileError(f"{path}: {exc}") from exc
