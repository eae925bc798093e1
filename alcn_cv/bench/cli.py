"""``alcn bench``: the benchmarks, one sub-subcommand each (detect, fewshot, invariance, relight, speed).

Each ``_add_<benchmark>`` adds its sub-subcommand and sets ``func`` to a handler returning an
exit code; the handler turns the options into the benchmark's settings (a copy of the preset of
``--conf``, the benchmark's ``CONFS``, then every option given) and runs its ``main``. Adding a
benchmark is adding its function to :data:`BENCHMARKS`.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

from alcn_cv.bench import detect, detect_settings, fewshot, invariance, relight, relight_settings, speed
from alcn_cv.bench.detect_settings import POLICIES, DetectSettings
from alcn_cv.cli import (
    COUNT,
    SEED,
    add_conf_option,
    add_progress_option,
    add_seeds_option,
    all_or_at_least,
    number_at_least,
    number_in,
    preset_values,
)
from alcn_cv.data import scenes
from alcn_cv.presets import preset, with_given
from alcn_cv.report import typed_command

__all__ = ["BENCHMARKS", "add_parser"]


def _list(item: Callable[[str], Any] = str) -> Callable[[str], list]:
    """An argparse ``type``: a comma-separated list, each item parsed by ``item``, itself an argparse ``type`` whose
    error says what an item must be (:func:`~alcn_cv.cli.number_at_least`)."""

    def parse(text: str) -> list:
        try:
            # commas inside brackets belong to an item: a tuned spec as the reports print it, sqi:sigmas=(0.5, 1.0)
            return [item(v.strip()) for v in re.split(r",(?![^()\[\]]*[)\]])", text) if v.strip()]
        except (argparse.ArgumentTypeError, ValueError) as exc:
            # argparse reports a ValueError as "invalid parse value": the item's own message says what is expected
            raise argparse.ArgumentTypeError(f"a comma-separated list, each item {exc}") from None

    return parse


def _sweep(text: str) -> list[tuple[int, int]]:
    """``--cnn-sweep``'s argparse ``type``: ``DEPTHxWIDTH,...``, each at least 1."""
    try:
        sweep = [tuple(int(v) for v in item.lower().split("x")) for item in text.split(",") if item.strip()]
    except ValueError:
        sweep = []
    if not sweep or any(len(dw) != 2 or min(dw) < 1 for dw in sweep):
        raise argparse.ArgumentTypeError(f"DEPTHxWIDTH,... of integers at least 1 (e.g. 1x32,2x32), got {text!r}")
    return sweep  # type: ignore[return-value]


def _size(text: str) -> tuple[int, int]:
    """A frame size's argparse ``type``: ``WIDTHxHEIGHT``, each side in :data:`~alcn_cv.bench.speed.SIDES`."""
    low, high = speed.SIDES
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        w = h = 0
    if not (low <= w <= high and low <= h <= high):
        raise argparse.ArgumentTypeError(
            f"WIDTHxHEIGHT, each side at least {low} and at most {high} pixels, got {text!r}"
        )
    return w, h


def _methods_help(default: Sequence[str] | None, suffix: str = "") -> str:
    """The help of a benchmark's ``--methods``: normalizations given as spec strings."""
    shown = ",".join(default) if default else "every registered normalization"
    return (
        f"comma-separated normalizations, each NAME[:KEY=VALUE...]{suffix}, e.g. alcn:model=lite "
        f"(`alcn normalize --list` lists the names; default: {shown})"
    )


def _add_policies(p: argparse.ArgumentParser, default: Sequence[str]) -> None:
    """The ``--policy`` option of the benchmarks that train a detector."""
    p.add_argument(
        "--policy",
        type=_list(str),
        dest="policies",
        metavar="POLICY[,POLICY...]",
        help=f"detector input policies: {', '.join(POLICIES)} (default {','.join(default)})",
    )


def _override(settings: Any, args: argparse.Namespace) -> Any:
    """The settings with every field that the command line gave replaced."""
    return with_given(settings, **{f.name: getattr(args, f.name, None) for f in dataclasses.fields(settings)})


def _add_out(p: argparse.ArgumentParser, report: str) -> None:
    """``--out`` and ``--overwrite`` of a benchmark that writes ``report``.json and ``report``.md into ``--out``."""
    p.add_argument(
        "--out", required=True, type=Path, help="output folder (held while the benchmark runs: a second run is refused)"
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help=f"replace the report of an earlier run in --out ({report}.json, {report}.md and its figures); without it, "
        "such a folder is refused before any work",
    )


def _add_detect(subparsers: argparse._SubParsersAction) -> None:
    d = DetectSettings()
    p = subparsers.add_parser(
        "detect",
        help="few-shot detection benchmark: every normalization with the same detector (AUC, PR curves)",
        description="For each method, train the same detector on windows normalized by it, built from 1 and 10 real "
        "images per object (simple synthetic images), run it on every window of every test image, and score with "
        "the PASCAL criterion (IoU 0.8, fixed-size boxes). Writes detect.md, detect.json and PR curves (PNG); "
        "while it runs, detect.partial.json holds the runs done so far (an interrupted run leaves it).",
    )
    p.add_argument(
        "--data",
        required=True,
        type=Path,
        help="benchmark folder: train.json, test.json, manifest.json and, for --tune, val.json (e.g. from "
        "`alcn data detect`)",
    )
    _add_out(p, "detect")
    add_conf_option(p, detect_settings.CONF_SUMMARIES)
    p.add_argument("--methods", type=_list(str), help=_methods_help(d.resolved().methods))
    p.add_argument("--real-images", type=_list(COUNT), help="real training images per object (default 1,10)")
    _add_policies(p, d.policies)
    p.add_argument(
        "--positives",
        type=COUNT,
        dest="positives_per_object",
        metavar="N",
        help=f"synthetic windows per object, spread over its --real-images (default {d.positives_per_object})",
    )
    p.add_argument(
        "--negatives-ratio",
        type=number_at_least(float, 0),
        help=f"background windows per object window (default {d.negatives_ratio})",
    )
    p.add_argument("--epochs", type=COUNT, help=f"detector training epochs (default {d.epochs})")
    p.add_argument("--batch-size", type=COUNT, help=f"training windows per batch (default {d.batch_size})")
    p.add_argument("--lr", type=number_at_least(float, 0, above=True), help=f"Adam learning rate (default {d.lr})")
    add_seeds_option(p, d.seeds, "repeat every run with each of these seeds", from_preset=True)
    p.add_argument(
        "--tune",
        dest="tune",
        action="store_const",
        const=True,
        help=f"tune {_spoken(detect.TUNING_GRIDS)} first, per number of real images: each of {_grid_size()} "
        "settings scored by the mean AUC on the data's validation images (val.json) of the detector trained as in the "
        "first seed's runs; the first best serves every seed (default: their defaults)",
    )
    p.add_argument("--cnn-sweep", type=_sweep, help="plain CNNs tried, DEPTHxWIDTH,... (default 1x32,2x32,3x32)")
    p.add_argument(
        "--nms-iou",
        type=number_in(float, 0, 1, below=True),
        help=f"IoU above which NMS removes a box, at least 0 and less than 1 (default {d.nms_iou})",
    )
    p.add_argument(
        "--match-iou",
        type=number_in(float, 0, 1, above=True),
        help=f"PASCAL criterion, an IoU greater than 0 and at most 1 (default {d.match_iou})",
    )
    p.add_argument("--max-test-images", type=COUNT, help="only the first N test images (default: all)")
    p.add_argument(
        "--working-scale",
        type=number_in(float, 0, 4, above=True),
        default=None,
        help="the scale the detector sees the images at, at most 4 (default: the data set's, its manifest's "
        "working_scale)",
    )
    p.add_argument(
        "--box-size",
        type=number_in(float, 0, above=True),
        default=None,
        help="the side of a detection box, pixels at the working scale (default: the data set's, its manifest's "
        "box_size)",
    )
    p.add_argument("--threads", type=COUNT, help="torch threads (default: torch's choice)")
    p.add_argument("--device", help="torch device: cpu, cuda, cuda:1, ... (default cpu)")
    add_progress_option(p)
    p.set_defaults(func=_run_detect)


def _run_detect(args: argparse.Namespace) -> int:
    settings = _override(preset(detect_settings.CONFS, args.conf), args)
    result = detect.main(
        args.data,
        args.out,
        settings,
        args.working_scale,
        args.box_size,
        progress=not args.no_progress,
        overwrite=args.overwrite,
    )
    print((Path(args.out) / "detect.md").read_text(encoding="utf-8"))
    return 1 if all("error" in r for r in result["runs"].values()) else 0


def _add_fewshot(subparsers: argparse._SubParsersAction) -> None:
    d = fewshot.FewShotSettings()
    p = subparsers.add_parser(
        "fewshot",
        help="few-shot validation: a detector of new objects trained from one image under one light, per normalization",
        description="For each seed, render new objects seen in one image under one light, make the paper's simple "
        "synthetic training windows and test windows under held-out lighting; every method normalizes both through "
        "Normalization.normalize_windows (ALCN: Eq. 1), the same input policy and the same detector follow; ROC AUC "
        "(object vs. background) and accuracy per seed, and per seed whether each ALCN variant is above the best DoG. "
        "Writes fewshot.md, fewshot.json and fewshot.png.",
    )
    _add_out(p, "fewshot")
    p.add_argument("--methods", type=_list(str), help=_methods_help(d.methods))
    _add_policies(p, d.policies)
    add_seeds_option(
        p,
        d.seeds,
        "repeat every run with each of these seeds, each with its own new objects, windows and detector initialisation",
        from_preset=True,
    )
    p.add_argument(
        "--objects",
        dest="n_objects",
        metavar="OBJECTS",
        type=COUNT,
        help=f"new objects per seed (default {d.n_objects})",
    )
    p.add_argument(
        "--object-seed",
        type=SEED,
        help="object catalogue seed of seed 0; seed s uses it + s (at least 1 with --tune, whose validation objects "
        f"use it - 1; default {d.object_seed})",
    )
    p.add_argument("--real-images", type=COUNT, help=f"reference images per object (default {d.real_images})")
    p.add_argument(
        "--per-image",
        type=COUNT,
        help=f"synthetic windows per reference image, as in `alcn train-detector` (`alcn bench detect --positives` "
        f"counts them per object) (default {d.per_image})",
    )
    p.add_argument("--n-test", type=COUNT, help=f"test windows per seed, half background (default {d.n_test})")
    p.add_argument(
        "--test-lighting",
        type=_list(str),
        help=f"lighting families of the test windows (default {','.join(d.test_lighting)})",
    )
    p.add_argument("--epochs", type=COUNT, help=f"detector training epochs (default {d.epochs})")
    p.add_argument("--batch-size", type=COUNT, help=f"training windows per batch (default {d.batch_size})")
    p.add_argument("--lr", type=number_at_least(float, 0, above=True), help=f"Adam learning rate (default {d.lr})")
    p.add_argument(
        "--tune",
        dest="tune",
        action="store_const",
        const=True,
        help=f"tune {_spoken(detect.TUNING_GRIDS)} first: each of {_grid_size()} settings scored by the AUC of "
        "the same detector on a validation draw of new objects and windows of its own, averaged over the policies; the "
        "first best serves every seed (default: their defaults)",
    )
    p.add_argument("--threads", type=COUNT, help="torch threads (default: torch's choice)")
    add_progress_option(p)
    p.set_defaults(func=_run_fewshot)


def _run_fewshot(args: argparse.Namespace) -> int:
    settings = _override(fewshot.FewShotSettings(), args)
    result = fewshot.main(args.out, settings, progress=not args.no_progress, overwrite=args.overwrite)
    print((Path(args.out) / "fewshot.md").read_text(encoding="utf-8"))
    runs = [r for by_method in result["runs"].values() for seeded in by_method.values() for r in seeded]
    return 1 if all("error" in r for r in runs) else 0


def _add_invariance(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "invariance",
        help="agreement of normalized real photographs under different lights",
        description="For each object of a photometric-stereo folder, normalize its photographs under every "
        "light with each method and report their agreement inside the object mask (mean pairwise normalized "
        "cross-correlation) beside the detail they keep; writes invariance.md, invariance.json and (with "
        "matplotlib) a figure.",
    )
    p.add_argument(
        "--data", required=True, type=Path, help="folder of NAME/NAME.<i>.png + NAME.mask.png (e.g. ../shared/data/psm)"
    )
    _add_out(p, "invariance")
    p.add_argument("--methods", type=_list(str), default=None, help=_methods_help(None))
    p.add_argument(
        "--scale",
        type=number_in(float, 0, 1, above=True),
        default=1.0,
        help="shrink the photographs by this factor first, at most 1 (default 1)",
    )
    p.add_argument(
        "--erode", type=number_at_least(int, 0), default=5, help="pixels removed from the mask border (default 5)"
    )
    p.add_argument(
        "--figure-object", default=None, help="object shown in the figure (default: the first; 'all': every one)"
    )
    add_progress_option(p)
    p.set_defaults(func=_run_invariance)


def _run_invariance(args: argparse.Namespace) -> int:
    result = invariance.main(
        args.data,
        args.out,
        args.methods,
        args.scale,
        args.erode,
        args.figure_object,
        not args.no_progress,
        overwrite=args.overwrite,
    )
    failed = [n for n, r in result["methods"].items() if "error" in r]
    print((Path(args.out) / "invariance.md").read_text(encoding="utf-8"))
    return 1 if failed and len(failed) == len(result["methods"]) else 0


def _add_speed(subparsers: argparse._SubParsersAction) -> None:
    d = speed.SpeedSettings()
    p = subparsers.add_parser(
        "speed",
        help="time ALCN (every backend and fast variant) against none, CLAHE and DoG",
        description="Time apply() of none, clahe, dog and every ALCN backend and approximate variant on the same "
        "frames (640x480, 1280x800, 1920x1080, gray and BGR): median, IQR, fps, ratio to dog in the same run, "
        "ALCN's network/mixture split, peak memory, the approximations' difference from the exact Eq. 3, and "
        "memory over a 1920x1080 video. Writes speed.md, speed.json and speed.png.",
    )
    _add_out(p, "speed")
    add_conf_option(p, speed.CONF_SUMMARIES)
    p.add_argument(
        "--sizes",
        type=_list(_size),
        help=f"comma-separated WIDTHxHEIGHT, each side at least {speed.SIDES[0]} and at most {speed.SIDES[1]} pixels "
        "(default " + ",".join(f"{w}x{h}" for w, h in d.sizes) + ")",
    )
    p.add_argument("--colours", type=_list(str), help="gray and/or bgr (default both)")
    p.add_argument(
        "--methods",
        type=_list(str),
        help="comma-separated labels to run (default all; dog always runs). Labels: none, clahe, dog, "
        + ", ".join(f"'{v}'" for v in [*speed.GAIN_VARIANTS, *speed.ALCN_VARIANTS])
        + ", 'alcn fast', 'alcn torch cpu', 'alcn torch cuda' "
        "('alcn': the default, the gain Normalizer; the last three: the default on those backends)",
    )
    p.add_argument(
        "--weights",
        help="weight file of the paper-model variants, checked before any timing (default: the shipped "
        "alcn_normalizer.npz)",
    )
    p.add_argument(
        "--lite-weights",
        help="weight file of the 'alcn lite' variants, checked before any timing (default: the shipped "
        "alcn_normalizer_lite.npz)",
    )
    p.add_argument("--image", help="time on this image resized to each size (default: synthetic frames)")
    p.add_argument("--warmup", type=number_at_least(int, 0), help=f"untimed runs per case (default {d.warmup})")
    p.add_argument(
        "--repeats",
        type=COUNT,
        dest="max_repeats",
        metavar="N",
        help=f"at most this many timed runs per case (default {d.max_repeats})",
    )
    p.add_argument(
        "--min-repeats",
        type=number_at_least(int, 0),
        help=f"at least this many timed runs per case, at most --repeats (0 needs a --budget above 0; default "
        f"{d.min_repeats})",
    )
    p.add_argument(
        "--budget",
        type=number_at_least(float, 0),
        dest="budget_s",
        metavar="SECONDS",
        help=f"seconds per case before stopping at --min-repeats (default {d.budget_s:g})",
    )
    p.add_argument(
        "--video-frames",
        type=number_at_least(int, 0),
        help=f"frames of the video-memory test (0: skip; default {d.video_frames})",
    )
    p.add_argument(
        "--video-size",
        type=_size,
        help="frame size of the video-memory test (default " + "x".join(map(str, d.video_size)) + ")",
    )
    p.add_argument(
        "--video-budget",
        type=number_at_least(float, 0),
        dest="video_budget_s",
        metavar="SECONDS",
        help=f"seconds per method of the video test (default {d.video_budget_s:g})",
    )
    p.add_argument(
        "--video-methods",
        type=_list(str),
        help="labels run in the video test (default: alcn and the fastest ALCN variant)",
    )
    p.add_argument("--threads", type=COUNT, help="OpenCV and torch threads (default: theirs)")
    p.add_argument(
        "--device",
        help="measure only ALCN's batched torch path on this device (cuda, cpu): end to end "
        "host uint8 to host uint8, on the device, float16, against the CPU, beside kornia's DoG and CLAHE",
    )
    p.add_argument(
        "--device-batches",
        type=_list(COUNT),
        help="batch sizes of --device (default " + ",".join(map(str, d.device_batches)) + ")",
    )
    add_progress_option(p)
    p.set_defaults(func=_run_speed)


def _run_speed(args: argparse.Namespace) -> int:
    settings = _override(preset(speed.CONFS, args.conf), args)
    if args.max_repeats is not None and args.min_repeats is None:  # "at most N runs" caps the preset's minimum
        settings = dataclasses.replace(settings, min_repeats=min(settings.min_repeats, settings.max_repeats))
    result = speed.main(args.out, settings, progress=not args.no_progress, overwrite=args.overwrite)
    print((Path(args.out) / "speed.md").read_text(encoding="utf-8"))
    return 0 if result["rows"] else 1


def _preset_flags(sampling: relight_settings.Sampling) -> str:
    """A preset of ``alcn bench relight`` as the options it stands for (0: all)."""
    return " ".join(sampling.options())


def _spoken(methods: Iterable[str]) -> str:
    """Method names as a help text lists them: ``"dog, slcn and dlcn"`` (from the grids they are tuned over)."""
    *first, last = methods
    return f"{', '.join(first)} and {last}"


def _grid_size() -> int:
    """The settings each method of ``--tune`` tries in the detection benches (one number for all: a test checks)."""
    return len(next(iter(detect.TUNING_GRIDS.values())))


def _add_relight(subparsers: argparse._SubParsersAction) -> None:
    confs = relight_settings.CONFS
    p = subparsers.add_parser(
        "relight",
        help="patch identification, keypoint matching and pose on real changes of light (fixed cameras)",
        description="Normalize the registered frames of fixed-camera scenes under different light with each "
        "method's apply(), then score patch identification (NCC), ORB/SIFT matching and RANSAC-homography pose "
        f"between frames; {_spoken(relight.TUNING_GRIDS)} are tuned on the training scenes only. "
        "Writes relight.md, relight.json and (with matplotlib) relight.png, with each method's difference from the "
        "first, paired by "
        "seed. The default runs "
        f"{len(relight.DEFAULT_METHODS)} methods, seeds {' '.join(map(str, relight.DEFAULT_SEEDS))}, with tuning, "
        "at the sampling sizes of --conf (listed below), which --max-frames, --patches and --max-pairs override; "
        "--conf quick --seeds 0 --no-tune is the shortest run.",
    )
    d = relight_settings.Settings()
    _add_out(p, "relight")
    p.add_argument(
        "--data",
        nargs="+",
        type=Path,
        default=None,
        help="folders of registered multi-light scenes (default: ../shared/data/webcam and ../shared/data/psm): "
        "ROOT/SCENE/*.jpg, one scene a folder, its frames in name order; or files NAME.<i>.<ext>, the scene NAME "
        "with its frames in the order of the integer <i> (so 2024.06.10.png is frame 10 of the scene 2024.06: "
        "rename date-named frames); ROOT's sub-folders are read one level deep",
    )
    p.add_argument(
        "--methods",
        type=_list(str),
        default=list(relight.DEFAULT_METHODS),
        help=_methods_help(relight.DEFAULT_METHODS, "[+lstd] (+lstd: followed by a local standardization)"),
    )
    p.add_argument(
        "--train-scenes",
        nargs="+",
        default=None,
        help="scenes or data sets to tune on, evaluated too (default: "
        f"{' '.join(scenes.TRAIN_SCENES)} when tuning, looked up in --data, or with neither --data nor --test-scenes; "
        "else none: with --no-tune only the test scenes are evaluated)",
    )
    p.add_argument(
        "--test-scenes",
        nargs="+",
        default=None,
        help=f"scenes or data sets evaluated only (default: {' '.join(scenes.TEST_SCENES)}; with --data, every scene "
        "of it that is not a training scene)",
    )
    p.add_argument(
        "--leave-one-out",
        nargs="*",
        default=None,
        metavar="SCENE",
        help="evaluate each scene with parameters tuned on the others, instead of the split: no --train-scenes or "
        f"--test-scenes (no scene given: {' '.join(relight.DEFAULT_LEAVE_ONE_OUT)}; with --data, every scene of it)",
    )
    add_seeds_option(
        p,
        relight.DEFAULT_SEEDS,
        "sampling seeds (with each scene's name, they draw its gallery frames, patch locations and pairs: a scene "
        "renamed draws others)",
    )
    add_conf_option(
        p, {name: f"{what}: {_preset_flags(confs[name])}" for name, what in relight_settings.CONF_SUMMARIES.items()}
    )
    p.add_argument(
        "--max-frames",
        type=all_or_at_least(2),
        help="frames per scene, evenly spaced, at least 2 (default: the preset's: "
        f"{preset_values(confs, 'max_frames')}; 0: all)",
    )
    p.add_argument(
        "--patch", type=number_at_least(int, 4), default=d.patch, help=f"patch side in pixels (default {d.patch})"
    )
    p.add_argument(
        "--patches",
        type=number_at_least(int, 2),
        help=f"patch locations per gallery frame (default: the preset's: {preset_values(confs, 'patches')})",
    )
    p.add_argument(
        "--gallery", type=COUNT, default=d.gallery, help=f"gallery frames per scene and seed (default {d.gallery})"
    )
    p.add_argument(
        "--max-pairs",
        type=number_at_least(int, 0),
        help="frame pairs per scene and seed, drawn at random (default: the preset's: "
        f"{preset_values(confs, 'max_pairs')}; 0: all)",
    )
    p.add_argument(
        "--n-features",
        type=number_at_least(int, 4),
        default=d.keypoints,
        help=f"ORB/SIFT keypoints per frame, the strongest, the same number for every method (default {d.keypoints}; "
        "unlike the pose commands', no 0 for all: the matching score divides by the keypoints found, so methods are "
        "compared at one budget, and ORB keeps none with 0)",
    )
    p.add_argument("--no-keypoints", action="store_true", help="identification only (skip matching and pose)")
    p.add_argument("--no-tune", action="store_true", help="default parameters only")
    p.add_argument(
        "--tune-frames",
        type=number_at_least(int, 2),
        default=8,
        help="frames per training scene the tuning scores on (default 8)",
    )
    add_progress_option(p)
    p.set_defaults(func=_run_relight)


def _run_relight(args: argparse.Namespace) -> int:
    sampling = _override(preset(relight_settings.CONFS, args.conf), args)
    settings = relight_settings.Settings(
        patch=args.patch,
        patches=sampling.patches,
        gallery=args.gallery,
        max_pairs=sampling.max_pairs or None,
        keypoints=args.n_features,
        keypoint_protocols=not args.no_keypoints,
    )
    result = relight.main(
        args.out,
        args.data,
        args.methods,
        args.train_scenes,
        args.test_scenes,
        args.leave_one_out,
        args.seeds,
        settings,
        sampling.max_frames or None,
        not args.no_tune,
        args.tune_frames,
        command=typed_command(args.argv),
        progress=not args.no_progress,
        overwrite=args.overwrite,
    )
    print((Path(args.out) / "relight.md").read_text(encoding="utf-8"))
    return 1 if all("errors" in r for r in result["methods"].values()) else 0


BENCHMARKS = (_add_detect, _add_fewshot, _add_invariance, _add_relight, _add_speed)


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``bench`` subcommand and its sub-subcommands to the ``alcn`` command."""
    parser = subparsers.add_parser(
        "bench",
        help="benchmarks: detection from few images, few-shot validation, invariance and identification under "
        "real light, speed",
        description="Benchmarks comparing ALCN with the classical normalizations (Rad et al. 2017, Sec. 4.3).",
    )
    benches = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for add in BENCHMARKS:
        add(benches)
