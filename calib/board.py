"""Calibration targets: chessboards and ChArUco boards, their detection, and printable images.

A :class:`BoardSpec` describes a target in millimetres. Its detector returns, for one image,
the detected image points and the matching 3D points of the board frame (x right, y down
along the printed board, z = 0 on the board; units mm):

- ``chessboard``: ``cols x rows`` **inner corners** (OpenCV's ``patternSize``); detection with
  ``cv2.findChessboardCorners`` + ``cv2.cornerSubPix`` (11x11 window, as OpenCV's calibration
  sample). The whole board, with its white border, must be visible. (The sector-based
  ``findChessboardCornersSB`` is not used: it also reports part of a larger board, which
  would hide a board definition that does not match the images.)
- ``charuco``: ``cols x rows`` **squares** with ArUco markers in the white squares
  (Garrido-Jurado et al., Pattern Recognition 2014); detection with OpenCV 5's
  ``cv2.aruco.CharucoDetector`` and ``CharucoBoard.matchImagePoints``. Partial views work.
"""

from __future__ import annotations

import logging
import numbers
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from alcn_cv.errors import InputError
from alcn_cv.io import atomic_path, check_no_earlier_output, to_gray, write_json

logger = logging.getLogger(__name__)

__all__ = ["BoardSpec", "Detection", "default_marker", "write_board_image", "suggest_chessboard_size"]

_KINDS = ("chessboard", "charuco")
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
#: A ChArUco board is found in an image only with at least this many of its corners (:class:`BoardDetector`).
MIN_CHARUCO_CORNERS = 6
#: The print resolutions of :func:`write_board_image`, dots per inch: below, a pixel is wider than a third of a mm;
#: above, finer than printers place ink, the image only takes memory (the default board at 100000 dpi: over 600 GB).
MIN_DPI, MAX_DPI = 72, 1200
#: The largest board image :func:`write_board_image` makes, in pixels (an A0 sheet at 300 dpi is 140 million).
MAX_BOARD_PIXELS = 2**28


def default_marker(square: float) -> float:
    """The side, mm, of a ChArUco board's markers when none is given (``--marker``): 26/35 of the ``square``, the
    proportion of the default board (26 mm markers in 35 mm squares, exactly), for every square size."""
    return square * 26.0 / 35.0


@dataclass(frozen=True)
class Detection:
    """A board found in one image.

    Attributes:
        image_points: float32 (N, 2) pixel coordinates, OpenCV convention (pixel centre (0, 0)).
        object_points: float32 (N, 3) the same points in the board frame, mm (z = 0).
        ids: int32 (N,) corner ids (chessboard: row-major index; ChArUco: the board's ids).

    The ArUco markers an image shows, the board found or not, are the detector's
    (:attr:`BoardDetector.last_num_markers`).
    """

    image_points: np.ndarray
    object_points: np.ndarray
    ids: np.ndarray


@dataclass(frozen=True)
class BoardSpec:
    """A planar calibration target.

    Attributes:
        kind: ``"chessboard"`` or ``"charuco"``.
        cols, rows: chessboard: inner corners per row and per column (``patternSize``);
            ChArUco: squares along x and along y.
        square: side of a square, mm.
        marker: ChArUco only: side of an ArUco marker, mm (< ``square``; the command line's default:
            :func:`default_marker` of the square).
        dictionary: ChArUco only: name of a predefined ArUco dictionary (``cv2.aruco.DICT_*``).
        legacy: ChArUco only: boards printed by OpenCV < 4.6 with an even number of rows
            (``CharucoBoard.setLegacyPattern``).
    """

    kind: str = "charuco"
    cols: int = 7
    rows: int = 5
    square: float = 35.0
    marker: float = 26.0
    dictionary: str = "DICT_5X5_100"
    legacy: bool = False

    def __post_init__(self) -> None:
        if self.kind not in _KINDS:
            raise InputError(f"board kind must be one of {_KINDS}, got {self.kind!r}")
        counted = "inner corners" if self.kind == "chessboard" else "squares"
        if not all(isinstance(n, numbers.Integral) and not isinstance(n, bool) for n in (self.cols, self.rows)):
            raise InputError(f"cols and rows count {counted}: integers, got {self.cols!r} and {self.rows!r}")
        sizes = (self.square, self.marker)
        if not all(isinstance(s, numbers.Real) and not isinstance(s, bool) for s in sizes):
            raise InputError(f"square and marker are sizes in mm: numbers, got {self.square!r} and {self.marker!r}")
        # Python's own numbers (a NumPy scalar given is not JSON, which views.json is written in)
        for name, kind in (("cols", int), ("rows", int), ("square", float), ("marker", float)):
            object.__setattr__(self, name, kind(getattr(self, name)))
        minimum = 2 if self.kind == "chessboard" else 3
        if self.cols < minimum or self.rows < minimum:
            raise InputError(f"a {self.kind} needs at least {minimum}x{minimum} {counted}, got {self.cols}x{self.rows}")
        if not self.square > 0:
            raise InputError(f"square size must be positive (mm), got {self.square}")
        if self.kind == "charuco":
            if not 0 < self.marker < self.square:
                raise InputError(
                    f"marker size must be in (0, square={self.square:g}) mm, got {self.marker:g}; give a smaller "
                    "--marker (without one, the command line takes 26/35 of --square)"
                )
            if not hasattr(cv2.aruco, self.dictionary):
                raise InputError(f"unknown ArUco dictionary {self.dictionary!r} (e.g. DICT_5X5_100)")
            needed = (self.cols * self.rows) // 2
            size = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary)).bytesList.shape[0]
            if needed > size:
                raise InputError(
                    f"a {self.cols}x{self.rows} ChArUco board needs {needed} markers but "
                    f"{self.dictionary} has {size}; choose a larger dictionary"
                )

    # -- geometry ---------------------------------------------------------------------
    @property
    def num_corners(self) -> int:
        """Number of corners of the whole board."""
        if self.kind == "chessboard":
            return self.cols * self.rows
        return (self.cols - 1) * (self.rows - 1)

    @property
    def squares(self) -> tuple[int, int]:
        """(columns, rows) of squares of the checkered area (chessboard: one square beyond the outer inner corners on
        every side)."""
        return (self.cols + 1, self.rows + 1) if self.kind == "chessboard" else (self.cols, self.rows)

    def corners_3d(self) -> np.ndarray:
        """float32 (num_corners, 3) all corners in the board frame (mm), in id order."""
        if self.kind == "charuco":
            return np.asarray(self.charuco_board().getChessboardCorners(), np.float32).reshape(-1, 3)
        grid = np.mgrid[0 : self.cols, 0 : self.rows].T.reshape(-1, 2)
        return np.c_[(grid + 1) * self.square, np.zeros(len(grid))].astype(np.float32)

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board (ChArUco only); units mm, origin at the board's top-left corner."""
        if self.kind != "charuco":
            raise InputError("charuco_board() needs a ChArUco board spec")
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        board = cv2.aruco.CharucoBoard((self.cols, self.rows), float(self.square), float(self.marker), dictionary)
        board.setLegacyPattern(bool(self.legacy))
        return board

    def describe(self) -> str:
        """A short human-readable description, used in messages."""
        if self.kind == "chessboard":
            return f"{self.cols}x{self.rows} chessboard (inner corners, {self.square:g} mm squares)"
        return (
            f"{self.cols}x{self.rows} ChArUco board ({self.square:g} mm squares, {self.marker:g} mm markers, "
            f"{self.dictionary}{', legacy' if self.legacy else ''})"
        )

    def to_dict(self) -> dict:
        return asdict(self)

    # -- detection --------------------------------------------------------------------
    def detector(self) -> BoardDetector:
        """A reusable detector for this board (builds the ArUco detector once)."""
        return BoardDetector(self)


class BoardDetector:
    """Detects one :class:`BoardSpec` in images. Call it with a gray or BGR uint8 image.

    Attributes:
        last_num_markers: the ArUco markers the last image showed (0 for chessboards), the board found or not.
        last_foreign_markers: those of them that are not the board's (another dictionary or board).
    """

    def __init__(self, spec: BoardSpec) -> None:
        self.spec = spec
        self._object = spec.corners_3d()
        if spec.kind == "charuco":
            self._board = spec.charuco_board()
            params = cv2.aruco.DetectorParameters()
            params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_NONE
            self._detector = cv2.aruco.CharucoDetector(self._board, cv2.aruco.CharucoParameters(), params)
            self._valid_ids = set(int(i) for i in np.asarray(self._board.getIds()).ravel())
        self.last_num_markers = 0
        self.last_foreign_markers = 0

    def __call__(self, image: np.ndarray) -> Detection | None:
        gray = to_gray(image)
        if self.spec.kind == "chessboard":
            return self._chessboard(gray)
        return self._charuco(gray)

    def _chessboard(self, gray: np.ndarray) -> Detection | None:
        size = (self.spec.cols, self.spec.rows)
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE + cv2.CALIB_CB_FAST_CHECK
        found, corners = cv2.findChessboardCorners(gray, size, flags=flags)
        if not found:
            return None
        corners = cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), _SUBPIX_CRITERIA)
        pts = np.asarray(corners, np.float32).reshape(-1, 2)
        return Detection(pts, self._object.copy(), np.arange(len(pts), dtype=np.int32))

    def _charuco(self, gray: np.ndarray) -> Detection | None:
        corners, ids, _, marker_ids = self._detector.detectBoard(gray)
        seen = [] if marker_ids is None else [int(i) for i in np.asarray(marker_ids).ravel()]
        self.last_num_markers = len(seen)
        self.last_foreign_markers = sum(i not in self._valid_ids for i in seen)
        if ids is None or len(ids) < MIN_CHARUCO_CORNERS:
            return None
        ids = np.asarray(ids, np.int32).ravel()
        if self._board.checkCharucoCornersCollinear(ids):
            return None
        obj, img = self._board.matchImagePoints(corners, ids)
        return Detection(np.asarray(img, np.float32).reshape(-1, 2), np.asarray(obj, np.float32).reshape(-1, 3), ids)


def suggest_chessboard_size(
    image: np.ndarray, near: tuple[int, int] | None = None, max_side: int = 12
) -> tuple[int, int] | None:
    """Find the inner-corner count of a chessboard seen in ``image`` by trying sizes.

    Used to explain a failed or partial detection ("you said 7x5, the image holds a 9x6
    board"). Only sizes within 2 of ``near`` (or of its transpose) are tried, from the largest
    (every size up to ``max_side`` without ``near``: slow, about 0.1 s per size on 640x480).
    The detector also finds part of a larger board, and finds parts unreliably (on OpenCV's
    sample image left01.jpg of a 9x6 board: 7x6, not 8x6), so a size found is then grown to the
    whole board: to the board the sector-based detector sees around it
    (``cv2.findChessboardCornersSB`` with ``CALIB_CB_LARGER``) when the detector used for the
    calibration finds that board too, then by a row or a column while the larger board is found.
    A result smaller than the true board is still possible. Returns ``(cols, rows)`` or None.
    """
    gray = to_gray(image)
    scale = min(1.0, 640.0 / max(gray.shape))
    if scale < 1:
        gray = cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE + cv2.CALIB_CB_FAST_CHECK
    tried: dict[tuple[int, int], bool] = {}

    def found(size: tuple[int, int]) -> bool:
        if size not in tried:
            tried[size] = bool(cv2.findChessboardCorners(gray, size, flags=flags)[0])
        return tried[size]

    everything = [(c, r) for c in range(3, max_side + 1) for r in range(3, max_side + 1)]
    if near is None:
        candidates, ref = everything, (0, 0)
    else:
        ref = tuple(near)
        candidates = [s for s in everything if min(abs(s[0] - b[0]) + abs(s[1] - b[1]) for b in (ref, ref[::-1])) <= 2]

    def closeness(size: tuple[int, int]) -> int:
        return abs(size[0] - ref[0]) + abs(size[1] - ref[1])

    def whole_board(size: tuple[int, int]) -> tuple[int, int]:
        """The board the sector-based detector sees around ``size``, in the orientation that holds ``size`` (the
        closer one to ``near`` when both do), if found as a whole; else ``size``. That detector's rows and columns
        may come transposed."""
        ok, _, meta = cv2.findChessboardCornersSBWithMeta(gray, size, cv2.CALIB_CB_LARGER)
        if not ok or meta is None:
            return size
        seen = (meta.shape[1], meta.shape[0])
        for whole in sorted({seen, seen[::-1]}, key=lambda s: (closeness(s), s)):
            holds = whole[0] >= size[0] and whole[1] >= size[1] and whole != size
            if holds and max(whole) <= max_side and found(whole):
                return whole
        return size

    # Largest first; among equal areas, the orientation closest to the one given.
    for size in sorted(candidates, key=lambda s: (-s[0] * s[1], closeness(s))):
        if found(size):
            size = whole_board(size)
            while True:
                bigger = [b for b in ((size[0] + 1, size[1]), (size[0], size[1] + 1)) if max(b) <= max_side]
                grown = next((b for b in bigger if found(b)), None)
                if grown is None:
                    return size
                size = grown
    return None


#: The narrowest margin, in pixels, that the board's label is written in.
_LABEL_MARGIN_PX = 20


def write_board_image(
    spec: BoardSpec, path: str | os.PathLike, dpi: int = 300, margin_mm: float = 10.0, overwrite: bool = False
) -> dict:
    """Write a printable image of the board and a JSON of its dimensions beside it.

    The PNG carries its DPI so that printing at 100 % scale gives squares of exactly
    ``spec.square`` mm; measure a printed square and pass the measured size to
    calibration if the printer scaled it.

    Args:
        spec: the board.
        path: output ``.png``; ``<path>.json`` (same stem) gets the dimensions.
        dpi: print resolution, dots per inch.
        margin_mm: white margin around the board, mm (>= 0; the label needs about 2 mm at 300 dpi).
        overwrite: replace an earlier image or JSON at ``path``.

    Returns:
        The dimensions written to the JSON (board spec, pixel and mm sizes, DPI).

    Raises:
        InputError: ``dpi`` outside :data:`MIN_DPI` to :data:`MAX_DPI`, a negative margin, an image of more than
            :data:`MAX_BOARD_PIXELS` (a board of too many or too large squares), a path not ending in ``.png``, or
            an earlier image or JSON there without ``overwrite``.
    """
    from PIL import Image

    if not MIN_DPI <= dpi <= MAX_DPI:
        raise InputError(
            f"--dpi must be from {MIN_DPI} to {MAX_DPI} (finer than printers print, the image only takes memory), "
            f"got {dpi}"
        )
    if margin_mm < 0:
        raise InputError(f"the margin must be 0 mm or more, got {margin_mm:g}")
    path = Path(path)
    if path.suffix.lower() != ".png":
        raise InputError(f"board image must be a .png, got {path.name}")
    check_no_earlier_output([path, path.with_suffix(".json")], overwrite)
    px_per_mm = dpi / 25.4
    square_px = int(round(spec.square * px_per_mm))
    margin_px = int(round(margin_mm * px_per_mm))
    columns, rows = spec.squares
    size = (columns * square_px, rows * square_px)
    pixels = (size[0] + 2 * margin_px) * (size[1] + 2 * margin_px)
    if pixels > MAX_BOARD_PIXELS:  # before the image is made: it would take that many bytes, and more
        raise InputError(
            f"the board image would be {size[0] + 2 * margin_px}x{size[1] + 2 * margin_px} px at {dpi} dpi, more "
            f"than {MAX_BOARD_PIXELS / 1e6:.0f} million pixels: give a smaller board, --square, --margin or --dpi"
        )
    if spec.kind == "charuco":
        board_img = spec.charuco_board().generateImage(size, marginSize=0, borderBits=1)
    else:
        yy, xx = np.mgrid[0 : size[1], 0 : size[0]]
        board_img = np.where(((xx // square_px) + (yy // square_px)) % 2 == 0, 0, 255).astype(np.uint8)
    image = cv2.copyMakeBorder(board_img, margin_px, margin_px, margin_px, margin_px, cv2.BORDER_CONSTANT, value=255)
    # Label outside the board so that a printed sheet says what it is; a margin too narrow for it gets none (drawn
    # over the squares, it would hide corners).
    label = f"{spec.describe()} - print at 100% ({dpi} dpi)"
    font_scale = max(0.4, margin_px / 60.0)
    if margin_px >= _LABEL_MARGIN_PX:
        cv2.putText(
            image,
            label,
            (margin_px, image.shape[0] - max(4, margin_px // 4)),
            cv2.FONT_HERSHEY_SIMPLEX,
            font_scale,
            0,
            max(1, int(font_scale * 1.5)),
            cv2.LINE_AA,
        )
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG", dpi=(dpi, dpi))
    true_square = square_px / px_per_mm
    info = {
        "board": spec.to_dict(),
        "dpi": dpi,
        "image_size_px": [int(image.shape[1]), int(image.shape[0])],
        "image_size_mm": [image.shape[1] / px_per_mm, image.shape[0] / px_per_mm],
        "square_px": square_px,
        "square_mm_printed": true_square,
        "marker_mm_printed": spec.marker * true_square / spec.square if spec.kind == "charuco" else None,
        "board_size_mm": [size[0] / px_per_mm, size[1] / px_per_mm],
    }
    write_json(path.with_suffix(".json"), info, indent=2)
    if abs(true_square - spec.square) > 2e-3 * spec.square:  # beyond what printers hold anyway
        logger.warning(
            "at %d dpi a square is %d px = %.3f mm instead of %.3f mm; calibrate with --square %.3f",
            dpi,
            square_px,
            true_square,
            spec.square,
            true_square,
        )
    return info
