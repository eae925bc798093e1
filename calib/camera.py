"""Camera calibration from images or a video of a chessboard or ChArUco board.

Zhang, "A flexible new technique for camera calibration", TPAMI 2000, as implemented by
``cv2.calibrateCamera`` (pinhole model with OpenCV's radial-tangential distortion
``k1, k2, p1, p2, k3``). Of more views than ``max_views`` (from a folder or a video), those showing little of
the board and the blurriest are left out, then views are chosen for board coverage and spread of poses
(:func:`select_views`); each view left out is logged and listed with the reason.

Outputs of :func:`main` in ``out_dir``:

- ``camera.yaml``: OpenCV FileStorage with ``camera_matrix`` (3x3), ``distortion_coefficients``
  (1x5), ``image_width``, ``image_height``, ``rms``; read it with :func:`load_calibration`.
- ``colmap/cameras.txt`` (+ empty ``images.txt``/``points3D.txt``): the same camera in COLMAP's
  convention (principal point + 0.5).
- ``views.json``: per-view reprojection errors of the views used, each with an ``outlier`` flag
  (:func:`calib.quality.outliers`), and the views found but left out, each with the reason (``unused_views``).
- ``calibration.png``: board coverage and per-view errors (:mod:`calib.report`).

They are written all or none (:func:`save_calibration`). Outlier views and a low coverage of the image
(:func:`calib.quality.coverage_hint`) are logged as warnings.
"""

from __future__ import annotations

import logging
import os
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats.colmap import ColmapCamera, camera_from_opencv, write_text_model
from alcn_cv.io import (
    VIDEO_SUFFIXES,
    atomic_paths,
    atomic_write,
    check_no_earlier_output,
    check_writable,
    count_frames,
    frame_progress,
    is_video,
    iter_frames,
    list_images,
    read_image,
    write_json,
)
from alcn_cv.report import listed

from .board import BoardSpec, Detection, suggest_chessboard_size
from .quality import COVERAGE_GRID, OUTLIER_RULE, coverage, coverage_hint, outlier_px, outliers

logger = logging.getLogger(__name__)

__all__ = [
    "BoardView",
    "Calibration",
    "detect_in_images",
    "detect_in_video",
    "select_views",
    "calibrate",
    "explain_no_board",
    "save_calibration",
    "load_calibration",
    "camera_once",
    "main",
]

#: RMS reprojection error (px) above which a calibration is reported as poor.
POOR_RMS_PX = 1.0
#: Fewest views accepted, and fewest views recommended.
MIN_VIEWS = 3
RECOMMENDED_VIEWS = 10
#: Chessboard sizes near OpenCV's sample board (9x6 inner corners) are tried when no ChArUco marker is seen.
_COMMON_CHESSBOARD = (9, 6)
#: :func:`detect_in_video` examines at most this many evenly spaced frames of a video.
MAX_VIDEO_CANDIDATES = 150
#: :func:`select_views` (with the board) first drops the views that show less than this share of its corners.
MIN_COVERAGE = 0.5
#: The files of the COLMAP text model in the output folder's ``colmap/``.
_COLMAP_FILES = ("cameras.txt", "images.txt", "points3D.txt")
#: The files :func:`main` writes into its output folder (an earlier run's are replaced only with ``overwrite``). Files,
#: not the folder ``colmap``: an interrupted first run leaves that folder empty, which does not refuse the rerun.
CALIBRATION_OUTPUTS = ("camera.yaml", "views.json", "calibration.png", *(f"colmap/{name}" for name in _COLMAP_FILES))


@dataclass
class BoardView:
    """One image in which the board was found: its name, the detection and its sharpness."""

    name: str
    detection: Detection
    sharpness: float = 0.0


@dataclass
class Calibration:
    """Result of a calibration.

    Attributes:
        K: float64 (3, 3) camera matrix, OpenCV pixel convention.
        dist: float64 (N,) OpenCV distortion ``k1, k2, p1, p2[, k3[, k4, k5, k6[, s1..s4[, tx, ty]]]]``: as
            ``cv2.calibrateCamera`` gives them in :func:`calibrate` (N = 5 without ``CALIB_RATIONAL_MODEL`` and the
            like in its ``flags``), or 4, 5, 8, 12 or 14 as the file read by :func:`load_calibration` holds them.
        image_size: (width, height) px.
        rms: overall RMS reprojection error, px.
        view_names: the views used.
        view_errors: float64 (V,) per-view RMS reprojection error, px.
        rvecs, tvecs: per-view board poses (board -> camera; tvec in the board's unit, mm).
        board: the target used.
        image_points: per-view detected points, for the report.
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple[int, int]
    rms: float
    view_names: list[str] = field(default_factory=list)
    view_errors: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rvecs: list[np.ndarray] = field(default_factory=list)
    tvecs: list[np.ndarray] = field(default_factory=list)
    board: BoardSpec | None = None
    image_points: list[np.ndarray] = field(default_factory=list)

    def colmap_camera(self, camera_id: int = 1) -> ColmapCamera:
        """The same camera as a COLMAP camera (``OPENCV``, or ``FULL_OPENCV`` when ``k3`` is non-zero;
        ``PINHOLE`` without distortion); the principal point gets COLMAP's +0.5."""
        return camera_from_opencv(self.K, self.dist, *self.image_size, camera_id=camera_id)


def _sharpness(gray: np.ndarray) -> float:
    """Variance of the Laplacian (higher is sharper)."""
    return float(cv2.Laplacian(gray, cv2.CV_64F).var())


def explain_no_board(
    board: BoardSpec,
    sample: np.ndarray | None,
    n_images: int,
    foreign: int,
    markers: int,
    frames: str = "image(s)",
    charuco_only: bool = False,
) -> str:
    """The message for a board found in none of the frames searched, with a diagnosis when one is possible.

    Args:
        board: the board searched for.
        sample: the first frame searched (gray or BGR), in which a chessboard of another size is looked for; or None.
        n_images: how many frames were searched.
        foreign, markers: the ArUco markers seen in them that are not on the board, and all of them
            (:attr:`calib.board.BoardDetector.last_foreign_markers`, ``last_num_markers``, summed).
        frames: what the frames are called in the message.
        charuco_only: the command takes ChArUco boards only: no chessboard is suggested, nor ``--board``.
    """
    msg = f"no {board.describe()} found in any of {n_images} {frames}."
    if board.kind == "chessboard" and sample is not None:
        guess = suggest_chessboard_size(sample, near=(board.cols, board.rows))
        if guess is not None and guess[0] * guess[1] > board.cols * board.rows:
            return (
                msg + f" The first image holds a {guess[0]}x{guess[1]} chessboard: the board definition does "
                f"not match the images; pass --cols {guess[0]} --rows {guess[1]} (inner corners, not squares)."
            )
        # Other smaller finds are not trusted (the detector also finds parts of boards); one fewer each way is
        # the board's squares counted instead of its inner corners.
        if guess is not None and sorted(guess) == sorted((board.cols - 1, board.rows - 1)):
            return (
                msg + f" The first image holds a {guess[0]}x{guess[1]} chessboard, one fewer each way than the "
                f"{board.cols}x{board.rows} given: --cols/--rows count inner corners, not squares; pass --cols "
                f"{guess[0]} --rows {guess[1]}."
            )
        return msg + (
            " Check --cols/--rows (inner corners, i.e. squares minus one), that the whole board is "
            "visible, in focus and well lit."
        )
    if foreign:
        return (
            msg + f" {foreign} ArUco marker(s) were seen whose ids are not on this board: the board definition "
            "does not match the images; check --cols/--rows (squares), --dictionary and --legacy."
        )
    if markers:
        return (
            msg + f" {markers} ArUco marker(s) of the board were seen but no ChArUco corner could be placed "
            "between them: the board layout does not match the images; check --cols/--rows (squares, "
            "not inner corners) and --legacy."
        )
    # No marker at all: perhaps the images show a chessboard (as the example images do).
    guess = None
    if sample is not None and not charuco_only:
        guess = suggest_chessboard_size(sample, near=_COMMON_CHESSBOARD)
    if guess is not None:
        return (
            msg + f" The first image holds a {guess[0]}x{guess[1]} chessboard: pass --board chessboard "
            f"--cols {guess[0]} --rows {guess[1]} (inner corners) and its --square size in mm."
        )
    return msg + (
        f" Check {'' if charuco_only else '--board, '}--dictionary, --cols/--rows (squares) and --legacy, and that "
        "the board is visible, in focus and well lit."
    )


def _check_chessboard_size(
    board: BoardSpec, samples: Sequence[tuple[str, np.ndarray]], missed: tuple[str, np.ndarray] | None, num_found: int
) -> None:
    """The chessboard detector also finds part of a larger board: check on a few images
    where the board was found that it does not extend by a row or a column; and when the
    board was found in too few images, whether the others hold a board of another size."""
    if board.kind != "chessboard":
        return
    if missed is not None and num_found < MIN_VIEWS:
        guess = suggest_chessboard_size(missed[1], near=(board.cols, board.rows))
        if guess is not None and set(guess) != {board.cols, board.rows}:
            raise InputError(
                f"the {board.describe()} was found in only {num_found} image(s) and {missed[0]} holds a "
                f"{guess[0]}x{guess[1]} chessboard: the board definition does not match the images; "
                f"pass --cols {guess[0]} --rows {guess[1]} (inner corners, not squares)"
            )
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE + cv2.CALIB_CB_FAST_CHECK
    for name, gray in samples:
        for size in ((board.cols + 1, board.rows), (board.cols, board.rows + 1)):
            if cv2.findChessboardCorners(gray, size, flags=flags)[0]:
                guess = suggest_chessboard_size(gray, near=(board.cols, board.rows)) or size
                raise InputError(
                    f"{name} holds a {guess[0]}x{guess[1]} chessboard, larger than the {board.cols}x"
                    f"{board.rows} given: the board definition does not match the images; pass --cols "
                    f"{guess[0]} --rows {guess[1]} (inner corners of the whole board)"
                )


class _BoardViews:
    """The board detected frame by frame, for :func:`detect_in_images` and :func:`detect_in_video`: the views found,
    and what explains a board found nowhere or a chessboard of the wrong size (:meth:`found`). ``log_misses``: log
    each frame without the board (a few images named by the user; not a video's many sampled frames)."""

    def __init__(self, board: BoardSpec, log_misses: bool) -> None:
        self.board, self.detector, self.log_misses = board, board.detector(), log_misses
        self.views: list[BoardView] = []
        self.samples: list[tuple[str, np.ndarray]] = []
        self.first: np.ndarray | None = None
        self.missed: tuple[str, np.ndarray] | None = None
        self.n = self.foreign = self.markers = 0

    def add(self, name: str, gray: np.ndarray) -> None:
        self.first = gray if self.first is None else self.first
        self.n += 1
        det = self.detector(gray)
        self.foreign += self.detector.last_foreign_markers
        self.markers += self.detector.last_num_markers
        if det is None:
            if self.log_misses:
                logger.info("%s: board not found", name)
            self.missed = self.missed or (name, gray)
            return
        if len(self.samples) < 3:
            self.samples.append((name, gray))
        self.views.append(BoardView(name, det, _sharpness(gray)))

    def found(self, what: str) -> list[BoardView]:
        """The views, once the board was found in one at least (``what``: the frames' word, for the log).

        Raises:
            InputError: the board found in none, or a chessboard larger than the one given."""
        if not self.views:
            raise InputError(explain_no_board(self.board, self.first, self.n, self.foreign, self.markers))
        _check_chessboard_size(self.board, self.samples, self.missed, len(self.views))
        logger.info("board found in %d of %d %s", len(self.views), self.n, what)
        return self.views


def detect_in_images(
    paths: Sequence[str | os.PathLike], board: BoardSpec, progress: bool = True
) -> tuple[list[BoardView], tuple[int, int]]:
    """Detect the board in every image.

    Returns:
        The views where the board was found (name = file name) and the common image size
        ``(width, height)``.

    Raises:
        InputError: unreadable image, images of different sizes, or the board found in none.
    """
    paths = [Path(p) for p in paths]
    if not paths:
        raise InputError("no images given")
    views = _BoardViews(board, log_misses=True)
    sizes: dict[tuple[int, int], list[str]] = {}
    for path in tqdm(paths, desc="detecting board", unit="image", disable=not progress or len(paths) < 20):
        gray = read_image(path, gray=True)
        sizes.setdefault((gray.shape[1], gray.shape[0]), []).append(path.name)
        views.add(path.name, gray)
    if len(sizes) > 1:
        listing = "; ".join(
            f"{w}x{h}: {', '.join(names[:3])}{' ...' if len(names) > 3 else ''}" for (w, h), names in sizes.items()
        )
        raise InputError(
            f"images have different sizes ({listing}); calibrate each camera/resolution separately "
            "or resize them all to one size first"
        )
    return views.found("images"), next(iter(sizes))


def detect_in_video(
    path: str | os.PathLike, board: BoardSpec, progress: bool = True
) -> tuple[list[BoardView], tuple[int, int]]:
    """Detect the board in evenly spaced frames of a video (at most :data:`MAX_VIDEO_CANDIDATES`
    frames are examined). View names are ``frame_000123``."""
    path = Path(path)
    total = count_frames(path)
    step = max(1, -(-total // MAX_VIDEO_CANDIDATES)) if total else 1
    views = _BoardViews(board, log_misses=False)
    size = None
    for name, frame in frame_progress(
        iter_frames(path, step), -(-total // step) if total else None, desc="detecting board", disable=not progress
    ):
        gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)
        size = (gray.shape[1], gray.shape[0])
        views.add(name, gray)
    return views.found("examined frames"), size


def _view_features(view: BoardView, image_size: tuple[int, int]) -> np.ndarray:
    """Pose descriptor of a view for diversity: board centre and apparent size in the image
    (normalized), and the board's tilt from a homography-based pose with a rough camera."""
    w, h = image_size
    pts = view.detection.image_points
    obj = view.detection.object_points
    centre = pts.mean(axis=0) / np.array([w, h])
    extent = np.sqrt(cv2.contourArea(cv2.convexHull(pts)) / (w * h))
    f = float(max(w, h))
    K = np.array([[f, 0, (w - 1) / 2], [0, f, (h - 1) / 2], [0, 0, 1]])
    tilt = np.zeros(2)
    if len(pts) >= 4:
        ok, rvec, _ = cv2.solvePnP(obj, pts, K, None, flags=cv2.SOLVEPNP_IPPE)
        if ok:
            normal = cv2.Rodrigues(rvec)[0][:, 2]  # board z axis in the camera frame
            tilt = normal[:2]  # 0 when the board faces the camera
    return np.r_[centre, extent, tilt]


def _leave_out(unused: dict[str, str], left: Sequence[tuple[BoardView, str]], rule: str) -> None:
    """Record the views that one ``rule`` leaves out, each with its reason, in ``unused``, and log them."""
    unused.update((view.name, reason) for view, reason in left)
    if left:
        logger.info("left out %d view(s) %s: %s", len(left), rule, listed([view.name for view, _ in left], 10))


def select_views(
    views: Sequence[BoardView],
    image_size: tuple[int, int],
    max_views: int = 30,
    board: BoardSpec | None = None,
) -> tuple[list[BoardView], dict[str, str]]:
    """Choose at most ``max_views`` views for board coverage and spread of poses.

    Of more views than that, those showing fewer than :data:`MIN_COVERAGE` of the ``board``'s corners, then the
    blurriest third (variance of the Laplacian) are left out, each rule only while ``max_views`` views remain;
    then views are picked greedily by farthest-point sampling on (board centre, apparent size, tilt), starting
    with the view that covers most of the image, so that the chosen set spans the image and many orientations.
    The views left out are logged by rule.

    Returns:
        The chosen views, in their original order, and the views left out: name to the reason.
    """
    views = list(views)
    unused: dict[str, str] = {}
    if len(views) <= max_views:
        return views, unused
    found = len(views)
    if board is not None:
        full = board.num_corners
        kept = [v for v in views if len(v.detection.ids) >= MIN_COVERAGE * full]
        if len(kept) >= max_views:
            few = [
                (v, f"shows {len(v.detection.ids)} of the board's {full} corners, under {MIN_COVERAGE:.0%}")
                for v in views
                if len(v.detection.ids) < MIN_COVERAGE * full
            ]
            _leave_out(unused, few, f"that show under {MIN_COVERAGE:.0%} of the board's corners")
            views = kept
    if len(views) > max_views:
        sharp = np.array([v.sharpness for v in views])
        threshold = float(np.quantile(sharp, 1 / 3))
        kept = [v for v, s in zip(views, sharp) if s >= threshold]
        if len(kept) >= max_views:
            blurred = [
                (v, f"among the blurriest third: sharpness {s:.1f} below {threshold:.1f} (variance of the Laplacian)")
                for v, s in zip(views, sharp)
                if s < threshold
            ]
            _leave_out(unused, blurred, f"as the blurriest third (variance of the Laplacian below {threshold:.1f})")
            views = kept
    feats = np.array([_view_features(v, image_size) for v in views])
    weights = np.array([1.0, 1.0, 1.0, 1.5, 1.5])
    feats = feats * weights
    chosen = [int(np.argmax(feats[:, 2]))]
    dist = np.linalg.norm(feats - feats[chosen[0]], axis=1)
    while len(chosen) < max_views:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(feats - feats[nxt], axis=1))
    chosen.sort()
    reason = "a chosen view has a close pose (board position, size and tilt)"
    close = [(v, reason) for i, v in enumerate(views) if i not in chosen]
    _leave_out(unused, close, "whose pose is close to a chosen view's (board position, size and tilt)")
    logger.info("selected %d of %d views (at most %d) for coverage and pose spread", len(chosen), found, max_views)
    return [views[i] for i in chosen], unused


def calibrate(
    views: Sequence[BoardView],
    image_size: tuple[int, int],
    board: BoardSpec | None = None,
    flags: int = 0,
    min_views: int = MIN_VIEWS,
) -> Calibration:
    """Run ``cv2.calibrateCamera`` on the detected views and measure per-view errors.

    Args:
        views: detections (each with at least 4 points for chessboards, 6 for ChArUco).
        image_size: (width, height) px.
        board: recorded in the result.
        flags: ``cv2.CALIB_*`` flags (e.g. ``cv2.CALIB_FIX_K3``).
        min_views: fewest views accepted.

    Raises:
        InputError: fewer than ``min_views`` views.
    Warns (logging): RMS above :data:`POOR_RMS_PX`, or fewer than :data:`RECOMMENDED_VIEWS` views.
    """
    views = list(views)
    if len(views) < min_views:
        raise InputError(
            f"only {len(views)} view(s) with the board; calibration needs at least {min_views} "
            f"(about {RECOMMENDED_VIEWS}-20 recommended): take more images of the board at different "
            "positions and tilts"
        )
    if len(views) < RECOMMENDED_VIEWS:
        logger.warning(
            "only %d views: the calibration may be unreliable (about %d-20 recommended)", len(views), RECOMMENDED_VIEWS
        )
    obj = [v.detection.object_points.reshape(-1, 1, 3).astype(np.float32) for v in views]
    img = [v.detection.image_points.reshape(-1, 1, 2).astype(np.float32) for v in views]
    criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-9)
    try:
        rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(
            obj, img, tuple(image_size), None, None, flags=flags, criteria=criteria
        )
    except cv2.error as exc:
        raise InputError(
            f"calibration failed in OpenCV ({exc.err}); the views may be degenerate (all "
            "fronto-parallel, or too few points): add views with the board tilted"
        ) from exc
    errors = []
    for o, i, r, t in zip(obj, img, rvecs, tvecs):
        proj, _ = cv2.projectPoints(o, r, t, K, dist)
        errors.append(float(np.sqrt(np.mean(np.sum((proj - i).reshape(-1, 2) ** 2, axis=1)))))
    result = Calibration(
        K,
        np.asarray(dist, np.float64).ravel(),
        (int(image_size[0]), int(image_size[1])),
        float(rms),
        [v.name for v in views],
        np.array(errors),
        [np.asarray(r).ravel() for r in rvecs],
        [np.asarray(t).ravel() for t in tvecs],
        board,
        [v.detection.image_points for v in views],
    )
    if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError("calibration diverged (non-finite or negative focal length); add more varied views")
    if rms > POOR_RMS_PX:
        worst = sorted(zip(errors, result.view_names), reverse=True)[:3]
        logger.warning(
            "poor calibration: RMS reprojection error %.3f px > %.1f px; worst views: %s. Check the "
            "--square size, remove blurred views, or check that the board is flat",
            rms,
            POOR_RMS_PX,
            ", ".join(f"{n} ({e:.2f} px)" for e, n in worst),
        )
    logger.info(
        "calibrated %dx%d camera from %d views: RMS %.3f px, fx %.2f fy %.2f cx %.2f cy %.2f",
        image_size[0],
        image_size[1],
        len(views),
        rms,
        K[0, 0],
        K[1, 1],
        K[0, 2],
        K[1, 2],
    )
    bad = [f"{n} ({e:.2f} px)" for n, e, outlier in zip(result.view_names, errors, outliers(result)) if outlier]
    if bad:
        logger.warning(
            '%d outlier view(s), RMS reprojection error above %s = %.2f px (red in calibration.png, "outlier" '
            "in views.json): %s. Check them for blur or a misplaced corner, and calibrate without them if so",
            len(bad),
            OUTLIER_RULE,
            outlier_px(result),
            ", ".join(bad),
        )
    hint = coverage_hint(result)
    if hint:
        cells, corners = coverage(result)
        logger.warning(
            "board coverage: %d/%d image cells, %d of the 4 corner cells: %s",
            cells,
            COVERAGE_GRID[0] * COVERAGE_GRID[1],
            corners,
            hint,
        )
    return result


def save_calibration(
    calib: Calibration,
    out_dir: str | os.PathLike,
    report: bool = True,
    unused_views: Mapping[str, str] | None = None,
) -> dict[str, Path]:
    """Write ``camera.yaml``, ``colmap/``, ``views.json`` and (optionally) ``calibration.png`` into ``out_dir``, all
    or none of them (:func:`~alcn_cv.io.atomic_paths`: an error or an interrupt leaves an earlier calibration there
    whole); without ``report`` an earlier ``calibration.png`` in ``out_dir`` is removed with them.

    Args:
        calib: the calibration.
        out_dir: the output folder, created when missing.
        report: also draw ``calibration.png``.
        unused_views: views found but not used, name to the reason (:func:`select_views`), listed in views.json.

    Returns:
        Paths of the written files by kind.
    """
    out = Path(out_dir)
    colmap_dir = out / "colmap"
    finals = {
        "yaml": out / "camera.yaml",
        "views": out / "views.json",
        **({"report": out / "calibration.png"} if report else {}),
        **{name: colmap_dir / name for name in _COLMAP_FILES},
    }
    is_outlier = outliers(calib)
    info = {
        "image_size": list(calib.image_size),
        "rms_px": calib.rms,
        "camera_matrix": calib.K.tolist(),
        "distortion_coefficients": calib.dist.tolist(),
        "board": calib.board.to_dict() if calib.board else None,
        "outlier_rule": f"rms_px above {OUTLIER_RULE}",
        "outlier_px": outlier_px(calib),
        "views": [
            {
                "name": n,
                "rms_px": float(e),
                "outlier": bool(outlier),
                "num_points": int(len(p)),
                "rvec": r.tolist(),
                "tvec": t.tolist(),
            }
            for n, e, outlier, p, r, t in zip(
                calib.view_names, calib.view_errors, is_outlier, calib.image_points, calib.rvecs, calib.tvecs
            )
        ],
        "unused_views": [{"name": name, "reason": reason} for name, reason in (unused_views or {}).items()],
    }
    # without a report, an earlier run's picture, which would stand beside this calibration as if it showed it, goes
    with atomic_paths(*finals.values(), stale=[out / "calibration.png"]) as tmps:
        tmp = dict(zip(finals, tmps))
        write_camera_yaml(tmp["yaml"], calib.K, calib.dist, calib.image_size, rms=calib.rms)
        # write_text_model writes a folder of fixed names: written aside, its files join the others' renaming
        with tempfile.TemporaryDirectory(dir=out, prefix=".colmap.") as staging:
            write_text_model(staging, [calib.colmap_camera()], [])
            for name in _COLMAP_FILES:
                os.replace(Path(staging) / name, tmp[name])
        write_json(tmp["views"], info)
        if report:
            from .report import plot_calibration

            plot_calibration(calib, tmp["report"])
    paths = {"yaml": finals["yaml"], "colmap": colmap_dir, "views": finals["views"]}
    if report:
        paths["report"] = finals["report"]
    return paths


def write_camera_yaml(
    path: str | os.PathLike, K: np.ndarray, dist: np.ndarray, image_size: tuple[int, int], rms: float | None = None
) -> Path:
    """Write intrinsics as OpenCV FileStorage YAML (``camera_matrix``, ``distortion_coefficients``,
    ``image_width``, ``image_height`` and optionally ``rms``), atomically."""
    path = Path(path)
    # written in memory, the format named by the suffix, and saved by Python: OpenCV opens a file by a narrow
    # string, which fails on Windows for a path its code page cannot spell (a user name with accents)
    fs = cv2.FileStorage(path.suffix or ".yaml", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY)
    fs.write("image_width", int(image_size[0]))
    fs.write("image_height", int(image_size[1]))
    fs.write("camera_matrix", np.asarray(K, np.float64))
    fs.write("distortion_coefficients", np.asarray(dist, np.float64).reshape(1, -1))
    if rms is not None:
        fs.write("rms", float(rms))
    return atomic_write(path, fs.releaseAndGetString())


def load_calibration(path: str | os.PathLike | Calibration) -> Calibration:
    """Read intrinsics from an OpenCV FileStorage YAML/XML/JSON written by :func:`save_calibration`
    (or OpenCV's calibration sample: ``camera_matrix``, ``distortion_coefficients``,
    ``image_width``, ``image_height``); a :class:`Calibration` is returned as it is, so that a function
    taking a camera as a file or as one read already calls this alone.

    Raises:
        DatasetError: missing or corrupt file, or a missing/invalid field (named).
    """
    if isinstance(path, Calibration):
        return path
    path = Path(path)
    hint = "re-create it with `alcn calib camera`"
    if not path.is_file():
        raise DatasetError(f"{path}: calibration file not found; {hint}")
    try:
        if path.suffix.lower() == ".gz":  # compressed: OpenCV reads it by name alone
            fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
        else:  # read by Python, parsed from memory (a path of any characters, as write_camera_yaml's)
            fs = cv2.FileStorage(path.read_text(encoding="utf-8"), cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
        ok = fs.isOpened()
    except UnicodeDecodeError as exc:
        raise DatasetError(f"{path}: not a text file ({exc.reason}); {hint}") from None
    except (cv2.error, SystemError) as exc:  # OpenCV's parser errors surface as either
        detail = getattr(exc, "err", None) or str(exc.__cause__ or exc)
        raise DatasetError(f"{path}: not a valid OpenCV FileStorage file ({detail.strip()}); {hint}") from exc
    if not ok:
        raise DatasetError(f"{path}: cannot be opened as an OpenCV FileStorage file; {hint}")
    try:
        K = fs.getNode("camera_matrix").mat()
        dist = fs.getNode("distortion_coefficients").mat()
        width = fs.getNode("image_width").real()
        height = fs.getNode("image_height").real()
        rms_node = fs.getNode("rms")
        rms = rms_node.real() if not rms_node.empty() else float("nan")
    except cv2.error:  # OpenCV reads any JSON or YAML; a top level that is not a map fails its assertions
        raise DatasetError(
            f"{path}: not a camera calibration (an OpenCV FileStorage with the matrices camera_matrix and "
            "distortion_coefficients: the camera.yaml of `alcn calib camera`, not its views.json)"
        ) from None
    finally:
        fs.release()
    if K is None or np.asarray(K).shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise DatasetError(f"{path}: field camera_matrix is missing or not a valid 3x3 camera matrix; {hint}")
    dist = np.zeros(5) if dist is None else np.asarray(dist, np.float64).ravel()
    if dist.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
        raise DatasetError(f"{path}: field distortion_coefficients must hold 4, 5, 8, 12 or 14 finite numbers; {hint}")
    if not (width > 0 and height > 0):
        raise DatasetError(f"{path}: fields image_width/image_height are missing or not positive; {hint}")
    return Calibration(np.asarray(K, np.float64), dist, (int(width), int(height)), rms)


def camera_once(camera: str | os.PathLike | Calibration | None, *intrinsics: object) -> Calibration | None:
    """The :class:`Calibration` of ``camera`` (:func:`load_calibration`), or ``None`` without one, for every command
    and function that takes a camera either as a calibration or as intrinsics (``alcn pose build`` and ``track``:
    ``--camera`` or ``--K``; :func:`pose.track.open_tracker`: ``camera=`` or ``K=`` with ``dist=``, ``image_size=``).

    Raises:
        InputError: ``camera`` given with any of ``intrinsics`` (not ``None``): the camera is given once.
        DatasetError: what :func:`load_calibration` raises.
    """
    if camera is None:
        return None
    if any(value is not None for value in intrinsics):
        raise InputError(
            "give the camera once: --K or --camera, not both (in Python: K=, with dist= and image_size=, or camera=)"
        )
    return load_calibration(camera)


def _is_video(path: Path) -> bool:
    return path.is_file() and is_video(path)


def main(
    source: str | os.PathLike,
    out_dir: str | os.PathLike,
    board: BoardSpec,
    max_views: int = 30,
    flags: int = 0,
    report: bool = True,
    progress: bool = True,
    overwrite: bool = False,
) -> Calibration:
    """Calibrate from a folder of images or a video and write the outputs into ``out_dir``.

    Args:
        source: a folder of images, or a video file.
        out_dir: output folder (see the module docstring).
        board: the target.
        max_views: most views used; of more views found, :func:`select_views` chooses for coverage, sharpness and
            pose spread.
        flags: ``cv2.CALIB_*`` flags.
        report: also write ``calibration.png``.
        progress: a progress bar over the frames searched for the board.
        overwrite: replace the outputs of an earlier calibration in ``out_dir``.

    Raises:
        InputError: ``max_views`` below :data:`MIN_VIEWS`, an output folder that cannot be written or that holds an
            earlier calibration's outputs without ``overwrite`` (all before the board is searched for), or bad
            input (see :func:`detect_in_images`, :func:`calibrate`).
    """
    if max_views < MIN_VIEWS:  # else the selection, not the images, would leave too few views, found only at the end
        raise InputError(
            f"--max-views {max_views}: a calibration needs at least {MIN_VIEWS} views (about "
            f"{RECOMMENDED_VIEWS}-20 recommended); give --max-views {RECOMMENDED_VIEWS} or more"
        )
    out = Path(out_dir)
    for name in ("camera.yaml", "colmap/cameras.txt"):  # a folder under a file fails now, not after the calibration
        check_writable(out / name)
    check_no_earlier_output([out / name for name in CALIBRATION_OUTPUTS], overwrite)
    source = Path(source)
    if source.is_dir():
        views, size = detect_in_images(list_images(source), board, progress)
    elif _is_video(source):
        views, size = detect_in_video(source, board, progress=progress)
    elif source.is_file():
        raise InputError(f"{source}: expected a folder of images or a video ({', '.join(sorted(VIDEO_SUFFIXES))})")
    else:
        raise InputError(f"{source}: no such file or folder")
    views, unused = select_views(views, size, max_views=max_views, board=board)
    calib = calibrate(views, size, board=board, flags=flags)
    paths = save_calibration(calib, out_dir, report=report, unused_views=unused)
    logger.info("wrote %s", ", ".join(str(p) for p in paths.values()))
    return calib
