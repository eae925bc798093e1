"""``alcn calib``: camera calibration, printable boards, registration of training sequences,
and undistortion."""

from __future__ import annotations

import argparse
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from alcn_cv.cli import COUNT, add_progress_option, number_at_least, number_in
from alcn_cv.errors import InputError
from alcn_cv.extras import require

from .board import MAX_DPI, MIN_CHARUCO_CORNERS, MIN_DPI, default_marker

if TYPE_CHECKING:
    from .register import Registration

_BOARD_DEFAULTS = {"chessboard": {"square": 25.0}, "charuco": {"cols": 7, "rows": 5, "square": 35.0}}


def _add_board_args(p: argparse.ArgumentParser, with_chessboard: bool = True) -> None:
    """The board options (default a ChArUco board); ``with_chessboard=False``: ChArUco boards only,
    and the help says nothing of chessboards."""
    charuco, chess = _BOARD_DEFAULTS["charuco"], _BOARD_DEFAULTS["chessboard"]
    g = p.add_argument_group("board")
    if with_chessboard:
        g.add_argument(
            "--board", choices=("chessboard", "charuco"), default="charuco", help="target type (default charuco)"
        )
    else:
        g.add_argument(
            "--board",
            choices=("charuco",),
            default="charuco",
            help="target type: ChArUco only, the default (a chessboard's pose is ambiguous under a half turn)",
        )
    either = (
        (lambda chessboard, aruco: f"chessboard: {chessboard}; ChArUco: {aruco}")
        if with_chessboard
        else (lambda chessboard, aruco: aruco)
    )
    g.add_argument(
        "--cols",
        type=int,
        help=either("inner corners per row (required)", f"squares along x (default {charuco['cols']})"),
    )
    g.add_argument(
        "--rows",
        type=int,
        help=either("inner corners per column (required)", f"squares along y (default {charuco['rows']})"),
    )
    g.add_argument(
        "--square",
        type=float,
        help="square side in mm as printed (default "
        + either(f"{chess['square']:g}", f"{charuco['square']:g}")
        + "; it sets the units of poses, not the intrinsics)",
    )
    g.add_argument(
        "--marker",
        type=float,
        help=f"ChArUco marker side in mm (default 26/35 of --square: {default_marker(charuco['square']):g} for "
        f"{charuco['square']:g} mm squares; a board printed by alcn-cv before 2026-12-01 with other squares has "
        "26 mm markers: give --marker 26 for it)",
    )
    g.add_argument("--dictionary", default="DICT_5X5_100", help="ChArUco ArUco dictionary (default DICT_5X5_100)")
    g.add_argument("--legacy", action="store_true", help="ChArUco board printed by OpenCV < 4.6 (even row count)")


def _board_from_args(args: argparse.Namespace):
    from .board import BoardSpec

    defaults = _BOARD_DEFAULTS[args.board]
    if args.board == "chessboard" and (args.cols is None or args.rows is None):
        raise InputError(
            "a chessboard needs --cols and --rows (inner corners, e.g. --cols 9 --rows 6 for a 10x7-square board)"
        )
    square = args.square if args.square is not None else defaults["square"]
    return BoardSpec(
        kind=args.board,
        cols=args.cols if args.cols is not None else defaults["cols"],
        rows=args.rows if args.rows is not None else defaults["rows"],
        square=square,
        marker=args.marker if args.marker is not None else default_marker(square),
        dictionary=args.dictionary,
        legacy=args.legacy,
    )


def _camera(args: argparse.Namespace) -> int:
    from .camera import main

    if not args.no_report:  # before the work, not after the files are written
        require(
            "matplotlib",
            what="alcn calib camera (its calibration.png; --no-report writes the rest without it)",
            preferred="data",
        )
    flags = (cv2.CALIB_FIX_K3 if args.fix_k3 else 0) | (cv2.CALIB_ZERO_TANGENT_DIST if args.zero_tangent else 0)
    calib = main(
        args.images or args.video,
        args.out,
        _board_from_args(args),
        max_views=args.max_views,
        flags=flags,
        report=not args.no_report,
        progress=not args.no_progress,
        overwrite=args.overwrite,
    )
    K, d = calib.K, calib.dist
    print(
        f"RMS {calib.rms:.3f} px over {len(calib.view_names)} views; fx {K[0, 0]:.2f} fy {K[1, 1]:.2f} "
        f"cx {K[0, 2]:.2f} cy {K[1, 2]:.2f}; dist {np.array2string(d, precision=4)}; written to {args.out}"
    )
    return 0


def _board(args: argparse.Namespace) -> int:
    from .board import write_board_image

    info = write_board_image(
        _board_from_args(args), args.out, dpi=args.dpi, margin_mm=args.margin, overwrite=args.overwrite
    )
    w, h = info["image_size_mm"]
    print(
        f"{args.out}: {info['image_size_px'][0]}x{info['image_size_px'][1]} px = {w:.1f} x {h:.1f} mm at "
        f"{info['dpi']} dpi; squares {info['square_mm_printed']:.3f} mm"
        + (f", markers {info['marker_mm_printed']:.3f} mm" if info["marker_mm_printed"] else "")
        + f"; print at 100% scale and measure a square. Dimensions in {Path(args.out).with_suffix('.json')}"
    )
    return 0


def _load_reference(path: Path, unit: str | None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Known poses ``{image name: (R_w2c, t_w2c in mm)}`` from a Middlebury ``*_par.txt``
    (metres) or a COLMAP model folder: in ``unit`` when given, else in the model's units
    (:func:`calib.conventions.colmap_unit_to_mm`: its ``# Units:`` header, or the ``registration.json`` beside it);
    a model in arbitrary units needs ``unit``."""
    from alcn_cv.formats.colmap import read_model
    from alcn_cv.formats.middlebury import read_middlebury

    from .conventions import MM_PER_UNIT, colmap_unit_to_mm

    if path.is_file() and path.name.endswith("_par.txt"):
        return {v.name: (v.R_w2c, v.t_w2c * 1000.0) for v in read_middlebury(path, check_images=False)}
    if path.is_dir():
        model = read_model(path)
        if unit is not None and model.units is not None and unit != model.units:
            logging.getLogger(__name__).warning(
                "--reference-unit %s overrides the reference model's units header (%s)", unit, model.units
            )
        scale = colmap_unit_to_mm(
            model, path, None if unit is None else MM_PER_UNIT[unit], option="--reference-unit (mm, cm or m)"
        )
        return {im.name: (im.R_w2c, im.t_w2c * scale) for im in model.images.values()}
    raise InputError(f"{path}: --reference must be a Middlebury *_par.txt or a COLMAP model folder")


def _register(args: argparse.Namespace) -> int:
    reg = _registration(args)
    print(
        f"registered {len(reg.registered)} of {len(reg.frames)} frames ({reg.units}); dropped {len(reg.dropped)} "
        f"(reasons in {Path(args.out) / 'registration.json'}); BOP: {Path(args.out) / 'scene_camera.json'}, "
        f"COLMAP: {Path(args.out) / 'colmap'} (images in rgb/)"
    )
    return 0


def _registration(args: argparse.Namespace) -> Registration:
    from .camera import load_calibration
    from .register import SfmSettings, register_charuco, register_colmap

    if not Path(args.source).exists():  # the first argument is checked first, before what the method needs
        raise InputError(f"no such video or folder: {args.source}")
    calib = load_calibration(args.camera) if args.camera else None
    if args.method == "board":
        if calib is None:
            raise InputError("--method board needs --camera camera.yaml (from `alcn calib camera`)")
        return register_charuco(
            args.source,
            args.out,
            calib,
            _board_from_args(args),
            step=args.step,
            max_frames=args.max_frames,
            min_points=args.min_corners,
            max_rms_px=args.max_rms,
            overwrite=args.overwrite,
            progress=not args.no_progress,
        )
    known = None
    if args.known_distance:
        a, b, mm = args.known_distance
        try:
            known = (a, b, float(mm))
        except ValueError:
            raise InputError(f"--known-distance: {mm!r} is not a number of millimetres") from None
    reference = _load_reference(Path(args.reference), args.reference_unit) if args.reference else None
    settings = SfmSettings(
        step=args.step, max_frames=args.max_frames, n_features=args.n_features, num_threads=args.threads
    )
    return register_colmap(
        args.source,
        args.out,
        calib,
        known_distance=known,
        reference=reference,
        settings=settings,
        overwrite=args.overwrite,
        progress=not args.no_progress,
    )


def _undistort(args: argparse.Namespace) -> int:
    from .camera import load_calibration
    from .undistort import main

    yaml_path = main(
        args.source,
        args.output,
        load_calibration(args.camera),
        alpha=args.alpha,
        keep_K=args.keep_K,
        progress=not args.no_progress,
        overwrite=args.overwrite,
    )
    print(f"undistorted {args.source} -> {args.output}; camera of the output: {yaml_path}")
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``alcn calib`` and its subcommands."""
    calib = subparsers.add_parser(
        "calib",
        help="camera calibration, boards, registration of training sequences, undistortion",
        description="Calibrate a camera from a chessboard or ChArUco board, print a board, register a training "
        "sequence (poses in mm, BOP + COLMAP output) for `alcn pose build`, and undistort images/videos.",
    )
    sub = calib.add_subparsers(dest="calib_command", metavar="SUBCOMMAND", required=True)

    p = sub.add_parser(
        "camera",
        help="calibrate intrinsics and distortion from images or a video of a board",
        description="Detect the board, choose at most --max-views views (from a folder or a video), run "
        "cv2.calibrateCamera, and write camera.yaml (OpenCV FileStorage), colmap/cameras.txt, "
        "views.json (per-view errors, outlier views flagged, the views left out and why) and calibration.png into "
        "--out. The default board is "
        "ChArUco; the example images in ../shared/data/chessboard show a chessboard: "
        "--board chessboard --cols 9 --rows 6 --square 25.",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--images", help="folder of images of the board")
    src.add_argument("--video", help="video of the board")
    p.add_argument("--out", required=True, help="output folder")
    _add_board_args(p)
    p.add_argument(
        "--max-views",
        type=int,
        default=30,
        help="most views used, from a folder or a video (default 30): of more views with the board, those showing "
        "under half of it, then the blurriest third are left out, then views are chosen for coverage and pose "
        "spread; the views left out are logged and listed in views.json",
    )
    p.add_argument("--fix-k3", action="store_true", help="fix k3 = 0 (few or central views)")
    p.add_argument("--zero-tangent", action="store_true", help="fix p1 = p2 = 0")
    p.add_argument("--no-report", action="store_true", help="do not write calibration.png")
    p.add_argument("--overwrite", action="store_true", help="replace an earlier calibration in --out")
    add_progress_option(p)
    p.set_defaults(func=_camera)

    p = sub.add_parser(
        "board",
        help="write a printable board image (PNG with its DPI) and its dimensions (JSON)",
        description="Write a board (the PNG of --out) to print at 100% scale, and a JSON of its dimensions beside "
        "it (board.json for --out board.png).",
    )
    p.add_argument("--out", required=True, help="output .png")
    _add_board_args(p)
    p.add_argument(
        "--dpi",
        type=number_in(int, MIN_DPI, MAX_DPI),
        default=300,
        help=f"print resolution, {MIN_DPI} to {MAX_DPI} (default 300)",
    )
    p.add_argument("--margin", type=float, default=10.0, help="white margin in mm (default 10)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out and its JSON")
    p.set_defaults(func=_board)

    p = sub.add_parser(
        "register",
        help="register a training sequence: a pose per frame, in mm (BOP + COLMAP)",
        description="With a ChArUco board in view (--method board): per-frame solvePnP on the board "
        "corners, unreliable frames dropped and reported. Without (--method sfm): pycolmap "
        "incremental reconstruction, then a similarity to mm from --known-distance or "
        "--reference (without either the poses are in arbitrary units, recorded in registration.json, and "
        "`alcn pose build` cannot use them). Writes rgb/, scene_camera.json, colmap/, registration.json/.png.",
    )
    p.add_argument("source", help="folder of images or a video")
    p.add_argument("--out", required=True, help="output folder (must not exist unless --overwrite)")
    p.add_argument(
        "--method",
        choices=("board", "sfm"),
        default="board",
        help="board (a ChArUco board in view) or sfm (pycolmap, no board) (default board)",
    )
    p.add_argument(
        "--camera",
        help="camera.yaml from `alcn calib camera` (required for board; optional for sfm, which without it "
        "estimates one focal length, for square pixels, with the principal point at the image centre)",
    )
    _add_board_args(p, with_chessboard=False)
    p.add_argument("--step", type=COUNT, default=1, help="use every STEP-th frame (default 1)")
    p.add_argument("--max-frames", type=COUNT, help="use at most this many frames")
    p.add_argument(
        "--min-corners",
        type=number_at_least(int, MIN_CHARUCO_CORNERS),
        default=8,
        help=f"board: fewest corners for a pose (default 8; at least {MIN_CHARUCO_CORNERS}, the fewest with which "
        "the board is found)",
    )
    p.add_argument(
        "--max-rms",
        type=number_at_least(float, 0, above=True),
        default=1.0,
        help="board: largest RMS reprojection error, px (default 1)",
    )
    p.add_argument(
        "--known-distance",
        nargs=3,
        metavar=("FRAME_A", "FRAME_B", "MM"),
        help="sfm: distance in mm between the centres of two input frames (image file names or "
        "stems; frame_000123 for a video)",
    )
    p.add_argument("--reference", help="sfm: known poses to align to: a Middlebury *_par.txt or a COLMAP model folder")
    p.add_argument(
        "--reference-unit",
        choices=("mm", "cm", "m"),
        help="sfm: units of a COLMAP --reference (default: its '# Units:' header, or the registration.json beside "
        "it; needed for a model without either)",
    )
    p.add_argument(
        "--n-features",
        type=COUNT,
        default=4096,
        help="sfm: SIFT keypoints kept per image, as the pose commands' --n-features, but at least 1: COLMAP's "
        "SIFT has no 0 for all (default 4096)",
    )
    p.add_argument("--threads", type=number_at_least(int, -1), default=-1, help="sfm: threads (default -1: all; 0 too)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    add_progress_option(p)
    p.set_defaults(func=_register)

    p = sub.add_parser(
        "undistort",
        help="undistort an image, a folder of images or a video",
        description="Remove lens distortion, and write the pinhole camera of the output (no distortion) as "
        "YAML: for an output image or video, <stem>.camera.yaml beside it (out.mp4: out.camera.yaml); for an "
        "output folder, camera.yaml inside it.",
    )
    p.add_argument("source", help="image, folder of images, or video")
    p.add_argument("output", help="output image, folder, or video (.mp4/.avi)")
    p.add_argument("--camera", required=True, help="camera.yaml from `alcn calib camera`")
    p.add_argument(
        "--alpha",
        type=float,
        default=0.0,
        help="0: crop to (nearly) only valid pixels (a strong distortion can leave a few black ones at the border); "
        "1: keep all source pixels (default 0)",
    )
    p.add_argument("--keep-K", action="store_true", help="keep the input camera matrix as the output's")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs (and the output's camera YAML)")
    add_progress_option(p)
    p.set_defaults(func=_undistort)
