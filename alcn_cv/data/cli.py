"""``alcn data``: generate the data engine's datasets, preview them, compare with real images."""

from __future__ import annotations

import argparse
import logging
import time
from pathlib import Path

from alcn_cv.cli import COUNT, SEED, add_conf_option, add_progress_option, number_at_least, number_in, preset_values
from alcn_cv.extras import require

logger = logging.getLogger(__name__)

__all__ = ["add_parser"]


def _require_textures(command: str) -> None:
    # the generators texture their scenes with scikit-image's photographs: the extra is named before any work
    require("skimage", what=f"alcn data {command}", preferred="data")


def _phos(args: argparse.Namespace) -> int:
    _require_textures("phos")
    from alcn_cv.data import phos

    t = time.perf_counter()
    out = phos.generate(
        args.out,
        args.n,
        args.seed,
        n_objects=args.objects,
        object_seed=args.object_seed,
        lighting=args.lighting,
        background_fraction=args.background_fraction,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        workers=args.workers,
    )
    logger.info("wrote %d windows to %s in %.1f s", args.n, out, time.perf_counter() - t)
    return 0


def _detect(args: argparse.Namespace) -> int:
    _require_textures("detect")
    from alcn_cv.data import detect

    t = time.perf_counter()
    out = detect.generate(
        args.out,
        seed=args.seed,
        conf=args.conf,
        object_seed=args.object_seed,
        n_test=args.n_test,
        n_val=args.n_val,
        n_train=args.n_train,
        width=args.width,
        height=args.height,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        workers=args.workers,
    )
    logger.info("wrote the detection benchmark to %s in %.1f s", out, time.perf_counter() - t)
    return 0


def _pose(args: argparse.Namespace) -> int:
    _require_textures("pose")
    from alcn_cv.data import pose

    t = time.perf_counter()
    out = pose.generate(
        args.out,
        seed=args.seed,
        conf=args.conf,
        n_frames=args.frames,
        n_test=args.n_test,
        clutter=not args.no_clutter,
        training_light=args.training_light,
        train_sweeps=args.train_sweeps or pose.TRAIN_SWEEPS,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        workers=args.workers,
    )
    logger.info("wrote the pose sequences to %s in %.1f s", out, time.perf_counter() - t)
    return 0


def _scenes(args: argparse.Namespace) -> int:
    _require_textures("scenes")
    from alcn_cv.data import relief_scenes

    t = time.perf_counter()
    out = relief_scenes.generate(
        args.out,
        scenes=args.scenes,
        frames=args.frames,
        side=args.side,
        seed=args.seed,
        lighting=args.lighting,
        overwrite=args.overwrite,
        progress=not args.no_progress,
        workers=args.workers,
    )
    logger.info("wrote the rendered scenes to %s in %.1f s", out, time.perf_counter() - t)
    return 0


def _preview(args: argparse.Namespace) -> int:
    from alcn_cv.data.preview import preview

    out = preview(args.dataset, args.out, n=args.n, overwrite=args.overwrite)
    logger.info("wrote %s", out)
    return 0


def _compare_psm(args: argparse.Namespace) -> int:
    from alcn_cv.data.stats import compare_psm
    from alcn_cv.shared_data import shared_data_dir

    psm = Path(args.psm) if args.psm else shared_data_dir() / "psm"
    compare_psm(psm, args.out, seed=args.seed, overwrite=args.overwrite)
    print((Path(args.out) / "psm_comparison.md").read_text(encoding="utf-8"), end="")
    return 0


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """The options every generator shares: ``--overwrite``, ``--workers`` and ``--no-progress``."""
    parser.add_argument("--overwrite", action="store_true", help="replace an existing output folder")
    parser.add_argument(
        "--workers",
        type=COUNT,
        default=1,
        help="worker processes (default 1; the output does not depend on it)",
    )
    add_progress_option(parser)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``data`` subcommand and its sub-subcommands to the ``alcn`` parser."""
    from alcn_cv.data import (  # not the renderers: this runs at every start
        detect_settings,
        pose_settings,
        relief_settings,
    )

    p = subparsers.add_parser(
        "data",
        help="generate training data, the detection benchmark and pose sequences",
        description="The illumination data engine: rendered Normalizer training windows (Phos-like), an "
        "ALCN-2D-like detection benchmark (COCO) and Box/Duck-like pose sequences (BOP + COLMAP), all "
        "deterministic for a seed.",
    )
    sub = p.add_subparsers(dest="data_command", metavar="DATA_COMMAND", required=True)

    q = sub.add_parser(
        "phos",
        help="64x64 Normalizer training windows (windows.npz + manifest.json)",
        description="Render labelled 64x64 grayscale windows of textured relief objects under "
        "many lightings (Phos-like), plus background windows.",
    )
    q.add_argument("--out", required=True, help="output folder")
    q.add_argument("-n", type=COUNT, default=100_000, help="number of windows (default 100000)")
    q.add_argument("--seed", type=SEED, default=0, help="seed of the windows (default 0)")
    q.add_argument(
        "--objects",
        type=COUNT,
        default=100,
        help="number of catalogue objects (labels 1..N; default 100)",
    )
    q.add_argument("--object-seed", type=SEED, default=0, help="seed of the object catalogue (default 0)")
    q.add_argument(
        "--lighting",
        default="random",
        help="'random' or comma-separated families: ambient,dark,bright,side,shadow,spot,point,"
        "colour,mixed (default random)",
    )
    q.add_argument(
        "--background-fraction",
        type=number_in(float, 0, 1),
        default=0.35,
        help="fraction of background windows, from 0 to 1 (default 0.35)",
    )
    _add_run_options(q)
    q.set_defaults(func=_phos)

    q = sub.add_parser(
        "detect",
        help="ALCN-2D-like detection benchmark (COCO train.json, test.json, val.json)",
        description="Render 3 objects (matte, velvet-like, specular): training images under one "
        "lighting, test images with clutter under varied lighting, and validation images drawn like the test "
        "images from other seeds (for `alcn bench detect --tune`), in COCO format.",
    )
    q.add_argument("--out", required=True, help="output folder")
    add_conf_option(q, detect_settings.CONF_SUMMARIES)
    q.add_argument("--seed", type=SEED, default=0, help="seed of the images (default 0)")
    q.add_argument("--object-seed", type=SEED, default=0, help="seed of the three objects (default 0)")
    pixels = number_in(int, 1, detect_settings.MAX_SIDE)
    side = f"in pixels, from twice the objects' size to {detect_settings.MAX_SIDE}"
    for field, kind, what in [
        ("n_test", COUNT, "number of test images, at least 1 (`alcn bench detect` scores them)"),
        ("n_val", number_at_least(int, 0), "number of validation images, test-like, for `alcn bench detect --tune`"),
        ("n_train", COUNT, "training images per object"),
        ("width", pixels, f"image width {side}"),
        ("height", pixels, f"image height {side}"),
    ]:
        values = preset_values(detect_settings.CONFS, field)
        q.add_argument(f"--{field.replace('_', '-')}", type=kind, help=f"{what} (default: the preset's: {values})")
    _add_run_options(q)
    q.set_defaults(func=_detect)

    q = sub.add_parser(
        "pose",
        help="box and duck pose sequences (BOP layout + COLMAP model)",
        description="Render a registered training sequence and 8 test sequences (#1 training "
        "lighting, #2-#4 mild, #5-#8 drastic changes) of a textured box and a duck.",
    )
    q.add_argument("--out", required=True, help="dataset root")
    add_conf_option(q, pose_settings.CONF_SUMMARIES)
    q.add_argument("--seed", type=SEED, default=0, help="seed (default 0)")
    q.add_argument(
        "--frames",
        type=int,
        help="frames per test sequence and per loop of the training sequence (default: the preset's: "
        f"{preset_values(pose_settings.CONFS, 'n_frames')})",
    )
    q.add_argument(
        "--n-test",
        type=int,
        help="number of test sequences, 0 to 8 (0: training data only; default: the preset's: "
        f"{preset_values(pose_settings.CONFS, 'n_test')})",
    )
    q.add_argument("--no-clutter", action="store_true", help="no clutter on the table")
    q.add_argument(
        "--training-light",
        action="store_true",
        help="render every test sequence under the training lighting: the control of the same seed's "
        "dataset (same scenes, trajectories and noise), to tell what the light costs a method from what "
        "the scene and viewpoints do",
    )
    q.add_argument(
        "--train-sweeps",
        type=number_at_least(float, 0),
        nargs="+",
        default=None,
        metavar="N",
        help="the training sequence's loops around the box, --frames views each, by the up-and-down sweeps "
        "of their elevation (30-60 deg) (default: 1 3, once as the test trajectories, then three times so "
        "that every stretch of azimuth is seen from high and low; 1: a single loop); the test sequences do not "
        "depend on it",
    )
    _add_run_options(q)
    q.set_defaults(func=_pose)

    q = sub.add_parser(
        "scenes",
        help="registered scenes under many lights, to train the gain Normalizer",
        description="Render fixed views of textured relief scenes, each under many lightings "
        "(directional, spot, point, cast shadows, dark, over-exposed), one folder of registered "
        "grayscale frames per scene: the layout `alcn train-real-light --set 'rendered=[\"DIR\"]' --set "
        "rendered_fraction=0.5` reads.",
    )
    q.add_argument("--out", required=True, help="output folder")
    q.add_argument("--scenes", type=int, default=24, help="number of scenes (default 24)")
    q.add_argument(
        "--frames",
        type=int,
        help=f"lightings (frames) per scene (default {relief_settings.FRAMES}; --lighting directional: "
        f"{relief_settings.DIRECTIONAL_FRAMES}, the only value it takes)",
    )
    q.add_argument(
        "--side",
        type=number_in(int, relief_settings.MIN_SIDE, relief_settings.MAX_SIDE),
        default=320,
        metavar="PIXELS",
        help=f"side of the square frames in pixels, from {relief_settings.MIN_SIDE} to {relief_settings.MAX_SIDE} "
        "(default 320; a scene's frames are rendered together: about 3 GB at 1024 with 12 frames, growing with the "
        "side's square)",
    )
    q.add_argument("--seed", type=SEED, default=0, help="seed (default 0)")
    q.add_argument(
        "--lighting",
        choices=relief_settings.LIGHTINGS,
        default="families",
        help="families: each frame's light drawn from the light families; directional: a frontal light (the gallery) "
        f"then {relief_settings.AZIMUTHS} directional lights from random azimuths at each of the elevations "
        f"{', '.join(map(str, relief_settings.ELEVATIONS))} degrees (the probes), the stand-in for faces under hard "
        "directional light (default families)",
    )
    _add_run_options(q)
    q.set_defaults(func=_scenes)

    q = sub.add_parser(
        "preview",
        help="contact sheet of a dataset with its ground truth drawn",
        description="Write a PNG contact sheet of a data-engine folder (phos, detect, pose, scenes), a COCO JSON "
        "file or a BOP scene folder, with boxes, projected model boxes, labels or light families drawn.",
    )
    q.add_argument("dataset", help="dataset folder, COCO .json file or BOP scene folder")
    q.add_argument("--out", required=True, help="output PNG")
    q.add_argument("--overwrite", action="store_true", help="replace an existing --out")
    q.add_argument(
        "-n",
        type=int,
        default=16,
        help="how many samples to show (default 16): Phos windows, COCO images split between train and test, "
        "BOP frames (at least one per sequence of a pose dataset), frames of the rendered scenes (a few frames "
        "of a few scenes)",
    )
    q.set_defaults(func=_preview)

    q = sub.add_parser(
        "compare-psm",
        help="intensity statistics of renderings vs. the real PSM photographs",
        description="Compare mean, contrast, dynamic range, saturation, local contrast and "
        "across-light changes of rendered images with ../shared/data/psm; writes a figure and a "
        "table.",
    )
    q.add_argument("--psm", default=None, help="PSM folder (default: <shared data>/psm)")
    q.add_argument("--out", required=True, help="output folder")
    q.add_argument("--seed", type=SEED, default=0, help="seed of the renderings (default 0)")
    q.add_argument("--overwrite", action="store_true", help="replace an earlier comparison in --out")
    q.set_defaults(func=_compare_psm)
