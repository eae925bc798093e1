"""``alcn pose build|track|eval|train-corners|bench-corners|corner-recall|planar|overlay-error``: the 3D pose
pipeline on the command line. The corner detector's training takes a named recipe (``--conf``, the presets
of :data:`pose.corner_train.CONFS`) and ``--set KEY=VALUE`` overrides of its keys; the part model's build a named
preset of its options (``--conf``, :data:`pose.build.CONFS`), which the options given override."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from alcn_cv.cli import (
    COUNT,
    SEED,
    add_conf_option,
    add_progress_option,
    add_seeds_option,
    all_or_at_least,
    number_at_least,
    number_in,
)
from alcn_cv.errors import InputError
from alcn_cv.presets import print_config
from alcn_cv.report import machine, typed_command


def _intrinsics(values: list[float] | None) -> np.ndarray | None:
    """The camera matrix of ``--K FX FY CX CY`` (``None`` without it).

    Raises:
        InputError: focal lengths not greater than 0, or a value not finite (one line naming ``--K``).
    """
    from pose.solver import camera_matrix, check_intrinsics

    if values is None:
        return None
    try:
        return check_intrinsics(camera_matrix(*values))
    except InputError:  # the same rule, in the option's words
        raise InputError(
            f"--K FX FY CX CY: FX and FY greater than 0 and all four finite, got {' '.join(f'{v:g}' for v in values)}"
        ) from None


def _build(args: argparse.Namespace) -> int:
    from pose import build

    path = build.main(
        args.input,
        args.output,
        images=args.images,
        K=_intrinsics(args.K),
        camera=args.camera,
        step=args.step,
        max_frames=args.max_frames,
        motion_mask=args.motion_mask,
        feature=args.feature,
        n_features=args.n_features,
        normalization=args.normalization,
        box_ply=args.box_ply,
        box_size=args.box_size,
        box_units=args.box_units,
        refine_focal=args.refine_focal,
        conf=args.conf,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        what="alcn pose build",
    )
    cameras = build.cameras_plot(path)
    print(f"part model -> {path} (its points: {path.with_suffix('.ply')}, its cameras: {cameras})")
    return 0


def _track(args: argparse.Namespace) -> int:
    import shlex

    from pose import track

    summary = track.main(
        args.model,
        args.input,
        args.output,
        _intrinsics(args.K),
        camera=args.camera,
        normalization=args.normalization,
        overlay=args.overlay,
        overwrite=args.overwrite,
        method=args.method,
        n_features=args.n_features,
        n_features_global=args.n_features_global,
        min_inliers=args.min_inliers,
        reprojection_error=args.reprojection_error,
        detector=args.detector,
        step=args.step,
        max_frames=args.max_frames,
        progress=not args.no_progress,
    )
    lost = summary["frames"] - summary["tracked"]
    why = f"; {lost} lost, most often: {summary['lost_reason']}" if lost else ""
    overlay = f"; overlay: {summary['overlay']}" if summary["overlay"] else ""
    print(
        f"tracked {summary['tracked']} of {summary['frames']} frames at {summary['fps']:.1f} fps{why}\n"
        f"poses: {summary['poses']} (object to camera, cam_t_m2c in {summary['translation_units']}; the model is in "
        f"{summary['units']}), per frame: {summary['info']}{overlay}"
    )
    # overlay-error draws the box of a part model (not the corner CNN's) with the camera the poses record
    if summary["tracked"] and summary["detector"] == "features":
        out = Path(summary["poses"]).with_name(Path(summary["poses"]).stem + "_overlay_error")
        words = ["alcn", "pose", "overlay-error", str(args.input), "--run", "track", str(args.model)]
        print(
            "next: how far the drawn box is from the object's edges, per frame:\n    "
            + shlex.join([*words, summary["poses"], "--out", str(out)])
        )
    return 0


def _recipe(args: argparse.Namespace):
    """The corner recipe of ``--conf`` with the ``--set`` items applied."""
    from alcn_cv.presets import preset
    from pose.corner_train import CONFS

    recipe = preset(CONFS, args.conf, args.settings)
    recipe.check()
    return recipe


def _eval(args: argparse.Namespace) -> int:
    from alcn_cv.io import check_no_earlier_output
    from pose import evaluate

    if args.print_config:
        return print_config(_recipe(args))
    if not (args.middlebury or args.data):
        raise InputError("give --data (pose sequences) and/or --middlebury (a Middlebury set)")
    reports = [name for name, given in (("middlebury", args.middlebury), ("table1", args.data)) if given]
    check_no_earlier_output([Path(args.out) / f"{r}.{ext}" for r in reports for ext in ("md", "json")], args.overwrite)
    normalizations = args.normalizations or evaluate.DEFAULT_NORMALIZATIONS
    recipe = _recipe(args)
    if args.data:  # the arguments first, then the data, before the Middlebury sets' models
        evaluate.data_layout(args.data, sequences=args.sequences)
    if args.middlebury:
        evaluate.middlebury_main(
            args.middlebury,
            args.out,
            normalizations=normalizations,
            feature=args.feature,
            command=typed_command(args.argv),
            progress=not args.no_progress,
        )
    if args.data:
        evaluate.main(
            args.data,
            args.out,
            normalizations=normalizations,
            feature=args.feature,
            detectors=args.detectors,
            corner_recipe=recipe,
            corner_conf=args.conf,
            corner_device=args.device,
            seeds=args.seeds,
            sequences=args.sequences,
            command=typed_command(args.argv),
            progress=not args.no_progress,
        )
    print("report -> " + ", ".join(str(Path(args.out) / f"{r}.md") for r in reports))
    return 0


def _train_corners(args: argparse.Namespace) -> int:
    from pose import corner_train

    if args.print_config:
        return print_config(_recipe(args))
    path = corner_train.main(
        args.input,
        args.output,
        _recipe(args),
        box_ply=args.box_ply,
        model=args.model,
        normalization=args.normalization,
        seed=args.seed,
        device=args.device,
        conf=args.conf,
        command=typed_command(args.argv),
        overwrite=args.overwrite,
        progress=not args.no_progress,
    )
    print(f"corner detector ({args.normalization}) -> {path}")
    return 0


def _planar(args: argparse.Namespace) -> int:
    from alcn_cv.io import check_no_earlier_output
    from pose import planar

    if args.print_config:
        return print_config(_recipe(args))
    out = Path(args.out)
    check_no_earlier_output([out / "planar_pose.md", out / "planar_pose.json"], args.overwrite)
    planar.main(
        args.out,
        args.data,
        scenes=args.scenes,
        normalizations=args.normalizations,
        detectors=args.detectors,
        feature=args.feature,
        n_features=args.n_features,
        target_fraction=args.target_fraction,
        hfov=args.hfov,
        max_frames=args.max_frames or None,  # 0: all
        recipe=_recipe(args),
        command=typed_command(args.argv),
        progress=not args.no_progress,
    )
    print((Path(args.out) / "planar_pose.md").read_text(encoding="utf-8"))
    return 0


def _add_recipe(parser: argparse.ArgumentParser, default: str) -> None:
    """:func:`~alcn_cv.cli.add_conf_option` of the corner detector's training (:data:`pose.corner_train.CONFS`), with
    ``--set`` overrides of its keys and ``--print-config``, for every command that trains it."""
    from pose.corner_train import CONF_SUMMARIES

    add_conf_option(parser, CONF_SUMMARIES, default, example="iterations=1000")


#: ``--normalization``'s help: the pose commands normalize nothing unless asked.
NORMALIZATION_HELP = (
    "the normalization applied first, a spec NAME[:KEY=VALUE...] (default none, which costs nothing per frame; "
    "`alcn pose eval` compares normalizations on your sequences, docs/results.md on the rendered Table 1)"
)


def _build_summaries() -> dict[str, str]:
    """The presets of ``alcn pose build`` (:data:`pose.build.CONFS`), each with what it is and the options it stands
    for (the camera's rounded), for its ``--help``."""
    from pose.build import CONF_SUMMARIES, CONFS, build_options

    summaries = {}
    for name, settings in CONFS.items():
        words = []
        for key, value in settings.items():
            if key == "K":
                words += ["--K", *(f"{v:.1f}" for v in (value[0, 0], value[1, 1], value[0, 2], value[1, 2]))]
            else:
                words += build_options({key: value})
        summaries[name] = f"{CONF_SUMMARIES[name]}: {' '.join(words)}"
    return summaries


def _add_planar(sub: argparse._SubParsersAction) -> None:
    from pose import planar
    from pose.parts import FEATURES

    r = sub.add_parser(
        "planar",
        help="pose of a planar target under real light (fixed webcams): real-light Table 1",
        description="Per scene of fixed outdoor cameras (the camera did not move, the light changes): "
        "a textured rectangle of the reference frame (median brightness) is the target, its part "
        "model is built from that frame after each normalization (assumed pinhole camera), and its "
        "pose is estimated in every other frame with the box's pipeline (part detector + PoseSolver). "
        "Truth: the reference pose. Writes OUT/planar_pose.md, .json, .png and OUT/targets.png. "
        "The Webcam frames are for academic research only (cite TILDE and AMOS).",
    )
    r.add_argument(
        "--out", type=Path, required=True, help="report folder (held while it runs: a second run is refused)"
    )
    r.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the report of an earlier run in --out (planar_pose.*, targets.png); without it, such a folder "
        "is refused before any work",
    )
    r.add_argument(
        "--data",
        help="folder of scenes, one sub-folder of registered frames each (default: "
        "$ALCN_SHARED_DATA/webcam, else ../shared/data/webcam)",
    )
    r.add_argument("--scenes", nargs="+", help="scene names (default: every scene of --data)")
    r.add_argument(
        "--normalizations",
        nargs="+",
        default=list(planar.DEFAULT_NORMALIZATIONS),
        help="rows, NAME[:KEY=VALUE...] (default: " + " ".join(planar.DEFAULT_NORMALIZATIONS) + ")",
    )
    r.add_argument(
        "--detectors",
        nargs="+",
        default=["features"],
        choices=sorted(planar.DETECTORS),
        help="part detectors, each giving rows (default features: OpenCV features matched to the target's "
        "descriptors; corners: the corner CNN trained on the reference frame for the target's corners and "
        "side middles, one network per scene and normalization, by --conf: about 8 min each on 2 CPU "
        "cores, trained on the GPU where torch sees one)",
    )
    _add_recipe(r, "planar")
    r.add_argument("--feature", default="SIFT", choices=FEATURES, help="OpenCV feature (default SIFT)")
    r.add_argument(
        "--n-features",
        type=number_at_least(int, 0),
        default=0,
        help="the strongest keypoints kept per frame (default 0: all; the target's model keeps all of "
        "the reference frame's)",
    )
    r.add_argument(
        "--target-fraction",
        type=float,
        default=planar.DEFAULT_TARGET_FRACTION,
        help="target side as a fraction of the frame's width and height; the window with the most "
        f"keypoints of the reference frame is chosen (default {planar.DEFAULT_TARGET_FRACTION:g})",
    )
    r.add_argument(
        "--hfov",
        type=number_in(float, 0, 180, above=True, below=True),
        default=planar.DEFAULT_HFOV,
        help=f"assumed horizontal field of view, degrees (default {planar.DEFAULT_HFOV:g})",
    )
    r.add_argument(
        "--max-frames",
        type=all_or_at_least(2),
        default=0,
        help="frames per scene, evenly spaced, at least 2 (default 0: all), as `alcn bench relight --max-frames`",
    )
    add_progress_option(r)
    r.set_defaults(func=_planar)


def _overlay_error(args: argparse.Namespace) -> int:
    from pose import overlay

    settings = overlay.EdgeSettings(max_distance=args.max_distance, max_angle=args.max_angle)
    overlay.main(
        args.video,
        [tuple(r) for r in args.run],
        args.out,
        settings=settings,
        command=typed_command(args.argv),
        show=args.show,
        overwrite=args.overwrite,
        progress=not args.no_progress,
    )
    print((Path(args.out) / "overlay_error.md").read_text(encoding="utf-8"))
    return 0


def _add_overlay_error(sub: argparse._SubParsersAction) -> None:
    from pose.overlay import MAX_ANGLE, MAX_DISTANCE, EdgeSettings

    d = EdgeSettings()
    o = sub.add_parser(
        "overlay-error",
        help="how far the drawn box is from the object's edges, per frame",
        description="For every frame posed by `alcn pose track`: the mean distance (px) from "
        "samples of the box's visible projected edges to the nearest image edge parallel to them "
        "(Canny, gradient direction), no ground truth needed. Writes OUT/overlay_error.md, .json "
        "(per frame, per box edge) and .png (the error over the video, one line per run).",
    )
    o.add_argument("video", help="the video (or image folder) that was tracked")
    o.add_argument(
        "--run",
        nargs=3,
        action="append",
        required=True,
        metavar=("LABEL", "MODEL", "POSES"),
        help="a run to measure: its label, the part model it was tracked with (.npz of `alcn pose build`) and "
        "its poses (.json of `alcn pose track`, drawn with the camera they were solved with); repeat to compare runs",
    )
    o.add_argument("--out", type=Path, required=True, help="report folder")
    o.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the report of an earlier run in --out (overlay_error.*, overlay_frames.png); without it, such a "
        "folder is refused before any work",
    )
    o.add_argument(
        "--max-distance",
        type=number_in(float, 1, MAX_DISTANCE),
        default=d.max_distance,
        help=f"search range along each edge's normal, px, 1 to {MAX_DISTANCE:g}; no image edge within it counts as "
        f"this (default {d.max_distance:g})",
    )
    o.add_argument(
        "--max-angle",
        type=number_in(float, 0, MAX_ANGLE, above=True),
        default=d.max_angle,
        help=f"largest angle between an image edge's gradient and the drawn edge's normal, degrees, above 0 and at "
        f"most {MAX_ANGLE:g} (90: any edge; default {d.max_angle:g})",
    )
    o.add_argument(
        "--show",
        nargs="*",
        default=["frame_000300"],
        help="frames drawn in OUT/overlay_frames.png with every run's box, besides the first run's two "
        "worst (default frame_000300)",
    )
    add_progress_option(o)
    o.set_defaults(func=_overlay_error)


def _bench_corners(args: argparse.Namespace) -> int:
    from calib.camera import camera_once
    from pose import corner_bench

    K = _intrinsics(args.K)
    calibration = camera_once(args.camera, K)
    if calibration is not None:
        K = calibration.K
    if K is None:
        raise InputError("give the intrinsics of the frames: --K FX FY CX CY or --camera camera.yaml")
    r = corner_bench.main(
        args.detector,
        args.input,
        K,
        args.out,
        command=typed_command(args.argv),
        size=tuple(args.frame_size),
        max_frames=args.max_frames,
        repeats=args.repeats,
        threads=args.threads,
        overwrite=args.overwrite,
    )
    print(
        f"{r['fps']:.1f} fps at {r['size'][0]}x{r['size'][1]} ({r['normalization']} in front; normalize "
        f"{r['ms']['normalize']:.1f} ms, network {r['ms']['network']:.1f} ms, peaks + pose "
        f"{r['ms']['peaks_and_pose']:.1f} ms; CPU {r['cpu_ms_per_frame']:.1f} ms per frame; torch imported: "
        f"{r['torch_imported']}; load "
        f"{r['machine'].get('load_average_1_5_15')})"
    )
    return 0


def _corner_recall(args: argparse.Namespace) -> int:
    from alcn_cv.io import atomic_paths, check_no_earlier_output, check_writable, write_json
    from pose import corner_bench

    reports = [args.out / f"corner_recall_{b}.json" for b in args.background] if args.out is not None else []
    check_no_earlier_output(reports, args.overwrite)
    if reports:  # an --out under a file: refused now, not after the first pass
        check_writable(reports[0])
    results = []
    made = {"command": typed_command(args.argv), "machine": machine()}
    for background in args.background:
        r = corner_bench.corner_recall(args.detector, args.scene, obj_id=args.obj_id, background=background)
        print(
            f"{args.scene} ({background} background): {r['visible']} visible parts in {r['frames']} frames; "
            f"found as the best candidate {100 * r['best']:.0f}%, among the candidates "
            f"{100 * r['candidates']:.0f}%, in the gates of the true pose {100 * r['gated']:.0f}%; background "
            f"scored higher {100 * r['background_wins']:.0f}%"
        )
        results.append({**r, **made})
    with atomic_paths(*reports) as paths:  # one per background, all or none
        for path, r in zip(paths, results):
            write_json(path, r)
    return 0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``pose`` with ``build``, ``track``, ``eval``, ``train-corners``, ``bench-corners``, ``corner-recall``,
    ``planar`` and ``overlay-error`` to ``alcn``."""
    from pose.build import CONFS as BUILD_CONFS
    from pose.build import DEFAULTS as BUILD_DEFAULTS
    from pose.corner_bench import MAX_SIDE, MIN_SIDE
    from pose.parts import FEATURES
    from pose.sequence import VIDEO_MAX_FRAMES, VIDEO_STEP
    from pose.solver import METHODS

    p = subparsers.add_parser(
        "pose",
        help="3D box pose: build a part model, track it, evaluate",
        description="Part-based 3D pose of a box after contrast normalization "
        "(Rad, Roth & Lepetit, BMVC 2017, Sec. 4.4).",
    )
    sub = p.add_subparsers(dest="pose_command", metavar="STEP", required=True)

    b = sub.add_parser(
        "build",
        help="part model from a registered sequence or a video",
        description="Triangulate features of the training images (pycolmap, known poses held "
        "fixed; or incremental reconstruction for an unregistered video), fit the box (open3d) "
        "and write MODEL.npz, MODEL.ply and MODEL_cameras.png. A box fit more than 5% off the known size is "
        "warned; more than 20% off on the edges its points cover, the build fails (its points are not that box, "
        "or not in its units). Poses in arbitrary units are refused: `alcn calib register --method sfm` without a "
        "known length, or a COLMAP model with neither a `# Units: mm` (cm, m) line in its images.txt nor the "
        "registration.json of `alcn calib register` beside it. pycolmap's log is shown with `alcn --verbose`.\n\n"
        "A video of a hand-held object before a static camera builds with --conf static-camera: without it the "
        "focal length is held fixed and the background's features are kept (the shared cookie box built so is "
        "11.8% off its size, 2.7% with the preset). Walkthrough: docs/pose.md.",
    )
    b.add_argument("input", help="BOP scene folder, COLMAP model folder, Middlebury set, or a video file")
    b.add_argument("output", help="part model to write (.npz)")
    b.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the part model of an earlier build (OUTPUT and its .ply and _cameras.png); without it, they "
        "are refused before any work",
    )
    b.add_argument("--images", help="image folder of a COLMAP model")
    bcam = b.add_mutually_exclusive_group()
    bcam.add_argument(
        "--K", nargs=4, type=float, metavar=("FX", "FY", "CX", "CY"), help="intrinsics of a video (OpenCV convention)"
    )
    bcam.add_argument(
        "--camera",
        help="camera.yaml of a video's camera from `alcn calib camera` (OpenCV FileStorage; instead of --K): its K, "
        "held fixed unless --refine-focal is given (whatever the preset), and its lens distortion, which the "
        "reconstruction models (the frames are not undistorted); the model stores both, and `alcn pose track` "
        "tracks with them",
    )
    add_conf_option(b, _build_summaries(), None)
    b.add_argument(
        "--step",
        type=COUNT,
        help=f"use every N-th frame of a video (default: the preset's, else {VIDEO_STEP})",
    )
    b.add_argument(
        "--max-frames",
        type=COUNT,
        help=f"at most this many of the frames --step keeps (default: the preset's, else {VIDEO_MAX_FRAMES})",
    )
    b.add_argument(
        "--motion-mask",
        action=argparse.BooleanOptionalAction,
        help="static camera, moving object: keep features on what moves (default: the preset's, else not)",
    )
    b.add_argument(
        "--feature",
        choices=FEATURES,
        help=f"OpenCV feature (default: the preset's, else {BUILD_DEFAULTS['feature']})",
    )
    b.add_argument(
        "--n-features",
        type=int,
        help=f"keypoints per training image (default: the preset's, else {BUILD_DEFAULTS['n_features']})",
    )
    b.add_argument("--normalization", help=NORMALIZATION_HELP)
    b.add_argument(
        "--box-ply",
        help="cuboid .ply of the box. For a video: its true size only (the box is fitted to the points). For a "
        "registered sequence: the box placed in the sequence's world frame (a BOP model, e.g. the object of a BOP "
        "scene), whose corners become the model's; for poses in another frame use --box-size",
    )
    b.add_argument(
        "--box-size",
        nargs=3,
        type=number_at_least(float, 0, above=True),
        metavar=("W", "H", "D"),
        help="the box's true edge lengths (any order), fitted to the points wherever the box stands: for a video, or "
        "a registered sequence whose world frame is not the box's",
    )
    b.add_argument(
        "--box-units",
        choices=["mm", "cm", "m"],
        help="units of --box-ply/--box-size (default: for a video the preset's ("
        + ", ".join(f"{name}: {c['box_units']}" for name, c in BUILD_CONFS.items() if "box_units" in c)
        + "), else cm; for a registered sequence its units)",
    )
    b.add_argument(
        "--refine-focal",
        action=argparse.BooleanOptionalAction,
        help="video: refine the focal length in the bundle adjustment (stored in the model, used by `alcn pose "
        "track`; default: the preset's, else held fixed; with --camera held fixed whatever the preset)",
    )
    add_progress_option(b)
    b.set_defaults(func=_build)

    t = sub.add_parser(
        "track",
        help="pose of the box in every frame of a video or image folder",
        description="Writes BOP scene_gt-style JSON (OUTPUT: per frame cam_R_m2c and cam_t_m2c, object to "
        "camera, OpenCV convention, cam_t_m2c in mm as BOP's whatever the model's units) and OUTPUT_info.json (per "
        "frame inliers and timings, the model's units); with --overlay a video (.mp4/.avi) or PNG folder with the "
        "box drawn. The camera is the one stored in the part model (`alcn pose build` from a video, refined with "
        "--refine-focal, with the lens distortion of a --camera it was built with; for the frames of its size) unless "
        "--K or --camera is given. Python: "
        "pose.track.open_tracker, the same tracker one frame at a time.",
    )
    t.add_argument(
        "model",
        help="part model (.npz) from `alcn pose build`, or with --detector corners a corner "
        "detector (.onnx) from `alcn pose train-corners`",
    )
    t.add_argument("input", help="video file or image folder")
    t.add_argument("output", help="poses (.json; translations in mm)")
    cam = t.add_mutually_exclusive_group()
    cam.add_argument(
        "--K",
        nargs=4,
        type=float,
        metavar=("FX", "FY", "CX", "CY"),
        help="intrinsics (default: the camera stored in the part model by `alcn pose build`)",
    )
    cam.add_argument(
        "--camera",
        help="camera.yaml from `alcn calib camera` (OpenCV FileStorage; default: the camera stored in the part model)",
    )
    t.add_argument(
        "--detector",
        default="features",
        choices=["features", "corners"],
        help="features (default): OpenCV features matched to the part model; corners: the corner CNN (cv2.dnn)",
    )
    t.add_argument(
        "--normalization",
        help="the normalization applied first, a spec NAME[:KEY=VALUE...] (default: the one the part model was "
        "built after, or the corner detector trained after, recorded in each; another warns for a part model, "
        "and is an error for a corner detector)",
    )
    t.add_argument(
        "--overlay",
        help="write the overlay here: a video (.mp4, .avi, .mkv, ...) or a folder of PNGs (a path without a suffix, or "
        "an existing folder; one that holds frames only with --overwrite); written under a temporary name, renamed "
        "when complete",
    )
    t.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the outputs of an earlier run: OUTPUT, the OUTPUT_info.json beside it and the --overlay; without "
        "it, any of them that exists is refused before the tracking",
    )
    t.add_argument("--step", type=COUNT, default=1, metavar="N", help="track every N-th frame (default 1)")
    t.add_argument(
        "--max-frames",
        type=COUNT,
        metavar="N",
        help="track the first N frames (of those --step keeps; default all)",
    )
    t.add_argument(
        "--method", default="usac_default", choices=sorted(METHODS), help="RANSAC variant (default usac_default)"
    )
    t.add_argument(
        "--n-features",
        type=number_at_least(int, 0),
        default=1000,
        help="keypoints per frame kept around the predicted box (default 1000; 0: all)",
    )
    t.add_argument(
        "--n-features-global",
        type=number_at_least(int, 0),
        default=0,
        metavar="N",
        help="keypoints kept where the whole frame is searched: the first frame and while the box is lost (default "
        "0: all, each matched to every descriptor of the model, the cost of a frame without the box; docs/pose.md, "
        "Speed, gives its times; the strongest keypoints of a cluttered frame may all miss the box)",
    )
    t.add_argument(
        "--min-inliers",
        type=number_at_least(int, 4),
        help="fewer inliers: frame lost (default 12; 5 with corners; a pose needs 4)",
    )
    t.add_argument(
        "--reprojection-error",
        type=number_at_least(float, 0, above=True),
        default=4.0,
        help="inlier threshold, px (default 4)",
    )
    add_progress_option(t)
    t.set_defaults(func=_track)

    e = sub.add_parser(
        "eval",
        help="Table-1-style report and Middlebury errors",
        description="Build a part model (or train the corner CNN) of the box for each detector and normalization "
        "on the training sequence of --data, track every test sequence and score the poses as Table 1 (Rad et "
        "al.): BB8's 2D projection within 5 px, ADD within 10% of the diameter, 5 cm / 5 deg. Writes table1.md "
        "(with the machine and command), table1.json, table1.png and the models into --out; with --middlebury, "
        "Middlebury's photographs posed (middlebury.md, middlebury.json).",
    )
    e.add_argument(
        "--data",
        help="pose data set from `alcn data pose` (train/, test/, models/); a small one: "
        "`alcn data pose --conf small --frames 12 --out DATA` (320x240, 12 frames a sequence; about 15 s, "
        "then about 2 min of CPU for this command on 2 cores). `--conf small` alone (3 frames) gives too "
        "few views to triangulate the box",
    )
    e.add_argument(
        "--middlebury",
        nargs="+",
        help="Middlebury sets (e.g. ../shared/data/middlebury/templeSparseRing): each view posed from a model (of "
        "--feature keypoints) of the views on either side (two folds), as taken and relit, counted when within 5 deg "
        "and 5 cm (middlebury.md, middlebury.json)",
    )
    e.add_argument(
        "--normalizations",
        nargs="+",
        help="rows of the table, NAME[:KEY=VALUE...] (default: none dog:sigma1=1:sigma2=2 alcn, "
        "the DoG tuned for pose at 640x480)",
    )
    e.add_argument(
        "--feature",
        default="SIFT",
        choices=FEATURES,
        help="feature of the classical detector (default SIFT: on the data engine's sequences it "
        "gave more correct poses than ORB; `track` uses ORB for speed)",
    )
    e.add_argument(
        "--detectors",
        nargs="+",
        default=["features"],
        choices=["features", "corners"],
        help="part detectors, each giving rows (default features; corners: trained on the training "
        "sequence first, by --conf)",
    )
    _add_recipe(e, "box")
    e.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        help="where the corner CNNs train (default: cuda where torch sees it, else cpu)",
    )
    add_seeds_option(e, [0], "train the corner CNN once with each of these seeds")
    e.add_argument("--sequences", nargs="+", type=int, metavar="N", help="only these test sequences (default all)")
    e.add_argument(
        "--out",
        type=Path,
        required=True,
        help="report folder (held while the evaluation runs: a second run is refused)",
    )
    e.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the reports of an earlier evaluation in --out (table1.*, middlebury.*; its models go too); "
        "without it, such a folder is refused before any work",
    )
    add_progress_option(e)
    e.set_defaults(func=_eval)

    c = sub.add_parser(
        "train-corners",
        help="train the corner CNN on a registered sequence, export ONNX",
        description="Dense training on the views of the sequence and augmented copies of them "
        "(homographies, new backgrounds, intensity changes), normalized, labelled with the box's "
        "parts (corners, edge middles, face centres) projected by the known poses and their sub-stride "
        "offsets; the network is written as "
        "ONNX for `alcn pose track --detector corners` (cv2.dnn, no torch).",
    )
    c.add_argument("input", help="registered training sequence (BOP scene folder, COLMAP model, Middlebury set)")
    c.add_argument("output", help="corner detector to write (.onnx)")
    c.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the corner detector of an earlier run at OUTPUT; without it, it is refused before the training",
    )
    box = c.add_mutually_exclusive_group(required=True)
    box.add_argument("--box-ply", help="cuboid .ply of the box in the object frame (mm; BOP models/obj_000001.ply)")
    box.add_argument("--model", help="part model (.npz) whose box corners to use")
    c.add_argument("--normalization", default="none", help=NORMALIZATION_HELP)
    _add_recipe(c, "box")
    c.add_argument(
        "--device",
        choices=("cpu", "cuda"),
        help="where the network trains (default: cuda where torch sees it, else cpu; the box recipe's "
        "4000 steps take about 8 min on 2 CPU cores)",
    )
    c.add_argument("--seed", type=SEED, default=0, help="seed of the frames and the network (default 0)")
    add_progress_option(c)
    c.set_defaults(func=_train_corners)

    bc = sub.add_parser(
        "bench-corners",
        help="frames per second of the corner detector (cv2.dnn, no torch)",
        description="Tracks with the corner detector through the frames of a video or image folder "
        "resized to --frame-size and reports the time of normalization, network, peaks and pose, the "
        "frames per second and the machine's load; with --out as Markdown and JSON.",
    )
    bc.add_argument("detector", help="corner detector (.onnx) from `alcn pose train-corners`")
    bc.add_argument("input", help="video file or image folder (e.g. DATA/test/000001/rgb of `alcn data pose`)")
    bcam = bc.add_mutually_exclusive_group(required=True)
    bcam.add_argument("--K", nargs=4, type=float, metavar=("FX", "FY", "CX", "CY"), help="intrinsics of the frames")
    bcam.add_argument("--camera", help="camera.yaml from `alcn calib camera`")
    bc.add_argument(
        "--frame-size",
        nargs=2,
        type=number_in(int, MIN_SIDE, MAX_SIDE),
        default=[640, 480],
        metavar=("W", "H"),
        help=f"width and height in pixels the frames are resized to, each from {MIN_SIDE} (the network's window) to "
        f"{MAX_SIDE} (the frames are held in memory; default 640 480)",
    )
    bc.add_argument("--max-frames", type=COUNT, default=60, help="frames used (default 60)")
    bc.add_argument("--repeats", type=COUNT, default=2, help="passes over them (default 2)")
    bc.add_argument("--threads", type=COUNT, help="OpenCV threads, 1 or more (default OpenCV's)")
    bc.add_argument("--out", type=Path, help="write bench_corners.md and .json here")
    bc.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the report of an earlier run in --out; without it, it is refused before any work",
    )
    bc.set_defaults(func=_bench_corners)

    cr = sub.add_parser(
        "corner-recall",
        help="parts the corner detector finds in a rendered scene, before PnP",
        description="Compares the corner detector's candidates with the true corners of a BOP scene "
        "(`alcn data pose`): the share of visible parts (corners, edge middles, face centres) found "
        "as the best candidate, among the candidates of the whole frame, and within the gates of the "
        "true pose; with --background grey also with everything but the object replaced by grey "
        "(the table and clutter removed).",
    )
    cr.add_argument("detector", help="corner detector (.onnx) from `alcn pose train-corners`")
    cr.add_argument(
        "scene", type=Path, help="BOP scene folder with scene_gt.json and mask_visib/ (e.g. DATA/test/000001)"
    )
    cr.add_argument("--obj-id", type=int, default=1, help="the box's object id (default 1)")
    cr.add_argument(
        "--background",
        nargs="+",
        default=["keep"],
        choices=["keep", "grey"],
        help="keep the frames as they are and/or grey everything but the object (default keep)",
    )
    cr.add_argument("--out", type=Path, help="write corner_recall_<background>.json here")
    cr.add_argument(
        "--overwrite",
        action="store_true",
        help="replace the corner_recall_<background>.json of an earlier run in --out; without it, they are refused "
        "before any work",
    )
    cr.set_defaults(func=_corner_recall)
    _add_planar(sub)
    _add_overlay_error(sub)
