"""Reader for the calibrated views of the Middlebury multi-view stereo data sets.

Seitz, Curless, Diebel, Scharstein, Szeliski, "A Comparison and Evaluation of Multi-View
Stereo Reconstruction Algorithms", CVPR 2006. Each set (e.g. ``templeSparseRing``) holds
PNG images and a ``<prefix>_par.txt`` whose first line is the number of images and whose
other lines are::

    imgname.png k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 r12 r13 r21 r22 r23 r31 r32 r33 t1 t2 t3

with the projection ``x = K [R | t] X`` (image origin top-left, world units metres).
``R, t`` therefore map world to camera, as in OpenCV; K is used here as OpenCV's K (pixel
centre (0, 0)), which is how the set's calibration is commonly consumed.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from alcn_cv.errors import DatasetError

logger = logging.getLogger(__name__)

__all__ = ["MiddleburyView", "read_middlebury", "find_par_file"]


@dataclass(frozen=True)
class MiddleburyView:
    """One calibrated view.

    Attributes:
        name: image file name (as in the ``_par.txt``).
        path: full path of the image.
        K: float64 (3, 3) intrinsics.
        R_w2c: float64 (3, 3) rotation world -> camera.
        t_w2c: float64 (3,) translation world -> camera, metres.
    """

    name: str
    path: Path
    K: np.ndarray
    R_w2c: np.ndarray
    t_w2c: np.ndarray

    @property
    def center(self) -> np.ndarray:
        """Camera centre in world coordinates (metres)."""
        return -self.R_w2c.T @ self.t_w2c

    @property
    def P(self) -> np.ndarray:
        """(3, 4) projection matrix ``K [R | t]``."""
        return self.K @ np.hstack([self.R_w2c, self.t_w2c[:, None]])


def find_par_file(folder: str | os.PathLike) -> Path:
    """Return the single ``*_par.txt`` of a Middlebury folder."""
    root = Path(folder)
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder")
    found = sorted(root.glob("*_par.txt"))
    if len(found) != 1:
        raise DatasetError(f"{root}: expected exactly one *_par.txt, found {[p.name for p in found]}")
    return found[0]


def read_middlebury(path: str | os.PathLike, check_images: bool = True) -> list[MiddleburyView]:
    """Read a Middlebury ``*_par.txt`` (or the folder holding it).

    Args:
        path: the ``_par.txt`` file or its folder.
        check_images: raise if an image named in the file is missing beside it.

    Returns:
        The views in file order.

    Raises:
        DatasetError: malformed file (names file, line and field), a count that does not
            match the lines, a rotation that is not orthonormal, or a missing image.
    """
    par = Path(path)
    if par.is_dir():
        par = find_par_file(par)
    if not par.is_file():
        raise DatasetError(f"{par}: file not found")
    try:
        text = par.read_text(encoding="utf-8")
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{par}: not a text file ({exc})") from None
    lines = [(n, line.split()) for n, line in enumerate(text.splitlines(), 1) if line.strip()]
    if not lines:
        raise DatasetError(f"{par}: empty file")
    n0, head = lines[0]
    try:
        count = int(head[0])
    except (ValueError, IndexError) as exc:
        raise DatasetError(f"{par}:{n0}: first line must be the number of images, got {' '.join(head)!r}") from exc
    if len(head) != 1:
        raise DatasetError(f"{par}:{n0}: first line must hold only the number of images")
    if count != len(lines) - 1:
        raise DatasetError(f"{par}: header says {count} images but {len(lines) - 1} lines follow")
    views = []
    for n, tok in lines[1:]:
        if len(tok) != 22:
            raise DatasetError(f"{par}:{n}: expected 'name k11..k33 r11..r33 t1 t2 t3' (22 fields), got {len(tok)}")
        try:
            values = np.array([float(t) for t in tok[1:]], dtype=np.float64)
        except ValueError as exc:
            raise DatasetError(f"{par}:{n}: field K/R/t: {exc}") from exc
        if not np.all(np.isfinite(values)):
            raise DatasetError(f"{par}:{n}: field K/R/t holds NaN or inf")
        K, R, t = values[:9].reshape(3, 3), values[9:18].reshape(3, 3), values[18:21]
        if not np.allclose(R @ R.T, np.eye(3), atol=1e-4) or np.linalg.det(R) < 0:
            raise DatasetError(f"{par}:{n}: field R is not a rotation matrix")
        if K[2, 2] == 0 or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise DatasetError(f"{par}:{n}: field K is not a camera matrix")
        img = par.parent / tok[0]
        if check_images and not img.is_file():
            raise DatasetError(f"{par}:{n}: image {tok[0]} not found beside the file")
        views.append(MiddleburyView(tok[0], img, K / K[2, 2], R, t))
    logger.debug("read %d Middlebury views from %s", len(views), par)
    return views
