"""Command line of the training stage: ``alcn train``, ``alcn train-detector``, ``alcn distill`` and ``alcn export``.

``alcn train``, ``alcn train-real-light``, ``alcn train-unet`` (the free-form baseline) and ``alcn distill`` each
take a named preset (``--conf``, :mod:`alcn_cv.train.config`) and ``--set KEY=VALUE`` overrides;
``alcn train-detector`` is the paper's second stage, a new detector for new objects from a few real images on the frozen
Normalizer; ``alcn export`` writes a Normalizer as ONNX for the torch-free OpenCV runtime. torch is
imported only when a command runs.
"""

from __future__ import annotations

import argparse
import json
import logging
import shlex
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from alcn_cv.cli import COUNT, SEED, add_conf_option, add_progress_option, interrupt_exit_code, number_at_least
from alcn_cv.presets import preset, print_config
from alcn_cv.train.config import (
    DISTILL_CONF_SUMMARIES,
    REAL_LIGHT_CONF_SUMMARIES,
    TRAIN_CONF_SUMMARIES,
    UNET_CONF_SUMMARIES,
)

if TYPE_CHECKING:
    from alcn_cv.train.real_light import TrainingInterrupted

__all__ = ["add_parser"]

logger = logging.getLogger(__name__)

#: What the training commands import: torch and kornia ([train]) and scikit-image, whose photographs their data are
#: made from ([data]); checked before any work, every missing one named at once.
_TRAINING_NEEDS = ("torch", "kornia", "skimage")
#: The ``type`` of a ``--threads``, where 0 is the libraries' own default.
_THREADS = number_at_least(int, 0)


def _add_run(parser: argparse.ArgumentParser, out: str) -> None:
    """``--out`` (the run folder, default ``out``), ``--seed`` and ``--no-progress``, the same on the real-light
    training commands."""
    parser.add_argument("--out", type=Path, default=Path(out), help=f"run folder (default: {out})")
    parser.add_argument("--seed", type=SEED, help="seed (default: the preset's)")
    add_progress_option(parser)


def _command(name: str, args: argparse.Namespace, *extra: str, conf: str | None = None) -> str:
    """The command line that makes this run again, recorded in the weight file or its card (``conf``: the preset,
    default ``args.conf``)."""
    return shlex.join(["alcn", name, "--conf", conf or args.conf, *extra, *_setting_words(args)])


def _setting_words(args: argparse.Namespace, folders: dict[str, str] | None = None) -> list[str]:
    """The ``--set`` and ``--seed`` options given, as words of a command line; with ``folders`` (key -> the run's
    absolute folder), those keys set to them instead of as given (a command that works from any working folder)."""
    folders = {k: v for k, v in (folders or {}).items() if v}
    items = [item for item in args.settings if item.split("=", 1)[0].strip() not in folders]
    items += [f"{key}={json.dumps(value)}" for key, value in folders.items()]  # a JSON string is a TOML one
    words = [word for item in items for word in ("--set", item)]
    return words + ([] if args.seed is None else ["--seed", str(args.seed)])


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train``, ``train-detector``, ``distill``, ``train-real-light``, ``train-unet`` and ``export`` to the
    ``alcn`` command."""
    p = subparsers.add_parser(
        "train",
        help="train the ALCN Normalizer with a detector (paper: objective meta; paper-full: Eq. 2)",
        description="Train ALCN's Normalizer with a detector on Phos-like rendered windows, validating on held-out "
        "lightings. The paper preset (the shipped alcn_normalizer.npz) uses the objective meta: the detector learns "
        "from the anchor lighting's windows only, the Normalizer from all; paper-full and --set optim.objective=joint "
        "train both on every window, Eq. 2 of Rad et al. 2017. --set model.method=dog (or none) trains the same "
        "detector on a fixed DoG (or raw windows) for comparison. Writes checkpoint.pt, train.log, config.toml "
        "(the settings), history.json, curves.png, summary.md, fewshot.json (the few-shot validation) and "
        "alcn_normalizer.npz (its ONNX twin: alcn export --weights) into --out, and keeps the rendered windows there "
        "for --resume (windows-KEY.npz, about 4 kB a window: delete it when the run is done). The shipped "
        "alcn_normalizer.npz is `alcn train --conf paper`. Multi-process: run under torchrun.",
    )
    add_conf_option(
        p, TRAIN_CONF_SUMMARIES, "paper", example="optim.lr=3e-4", or_file="a TOML file of alcn_cv.train.config's keys"
    )
    p.add_argument("--out", type=Path, default=Path("out/alcn"), help="run folder (default: out/alcn)")
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue from OUT/checkpoint.pt: give the run's --conf, --set and --seed again (the command printed on "
        "Ctrl-C does); its seed and model.*, data.* and optim.* settings must equal the checkpoint's (optim.epochs "
        "too), run.* (--device) and fewshot.* may change",
    )
    p.add_argument("--overwrite", action="store_true", help="replace the earlier run that OUT holds")
    p.add_argument("--seed", type=SEED, help="seed (default: the preset's)")
    p.add_argument("--device", choices=("cpu", "cuda"), help="run.device (default: the preset's)")
    add_progress_option(p)
    p.set_defaults(func=_train, needs=_TRAINING_NEEDS)

    d = subparsers.add_parser(
        "train-detector",
        help="train a detector for new objects from a few images (second stage)",
        description="The second stage of ALCN: from a few real images of new objects (one folder per object, "
        "images showing the object; NAME.mask.png beside NAME.png, or OBJECT.mask.png in the object's folder for "
        "all its images, marks it), make the paper's simple synthetic images, normalize them with the frozen "
        "Normalizer (or another method) and train a new detector. Writes detector.pt (torch state and "
        "configuration: alcn_cv.train.stage2) and classes.json (the class names, 0 the background) into --out.",
    )
    d.add_argument("images", type=Path, help="folder with one sub-folder of images per object")
    d.add_argument("--out", type=Path, required=True, help="output folder")
    d.add_argument("--overwrite", action="store_true", help="replace the detector an earlier run wrote into --out")
    d.add_argument(
        "--method",
        default="alcn",
        help="normalization applied to the windows, a spec NAME[:KEY=VALUE...] (default alcn; ALCN at scale=1, "
        "the windows' own; detector.pt records the spec with its scale and ALCN's model named)",
    )
    d.add_argument("--weights", type=Path, help="Normalizer weight file for --method alcn (default: shipped)")
    d.add_argument("--per-image", type=COUNT, default=300, help="synthetic windows per real image (default 300)")
    d.add_argument(
        "--negatives",
        type=number_at_least(int, 0),
        default=0,
        help="background windows (default: as many as all positive windows)",
    )
    d.add_argument(
        "--extent", type=float, default=40.0, help="the object's size in the 64-px window, pixels (default 40)"
    )
    d.add_argument("--epochs", type=COUNT, default=15, help="training epochs (default 15)")
    d.add_argument("--batch-size", type=COUNT, default=64, help="windows per batch (default 64)")
    d.add_argument(
        "--lr", type=number_at_least(float, 0, above=True), default=1e-3, help="Adam learning rate (default 1e-3)"
    )
    d.add_argument("--seed", type=SEED, default=0, help="seed of the synthetic images and the detector (default 0)")
    add_progress_option(d)
    d.set_defaults(func=_train_detector, needs=_TRAINING_NEEDS)

    s = subparsers.add_parser(
        "distill",
        help="distil a light Normalizer from a trained one",
        description="Train a LiteNormalizer to reproduce the paper-model Normalizer's mixture weights on rendered "
        "windows (--conf lite), or a smaller gain Normalizer to reproduce the gain Normalizer's maps on relit "
        "photographs with no known restriction on use (--conf gain-lite) (alcn_cv.train.distill); writes the weight "
        "file, its ONNX export (.onnx) and its model card (.md), beside each other, the command recorded in the "
        "header and the card. The shipped alcn_normalizer_lite.npz is `alcn distill --conf lite --out "
        "alcn_cv/weights/alcn_normalizer_lite.npz --overwrite`, alcn_normalizer_gain_lite.npz the same with --conf "
        "gain-lite (its terms: those of the photographs, any use); that replaces the shipped card with the one "
        "generated (git shows what the hand-edited card added). To compare with a shipped file, write to another "
        "--out.",
    )
    add_conf_option(s, DISTILL_CONF_SUMMARIES, None, required=True, example="teacher=FILE")
    s.add_argument(
        "--out",
        type=Path,
        help="weight file to write (.npz; the card is .md beside it); needed but with --print-config",
    )
    s.add_argument("--overwrite", action="store_true", help="replace an existing weight file, its card and export")
    s.add_argument("--seed", type=SEED, help="seed (default: the preset's)")
    s.add_argument(
        "--threads",
        type=_THREADS,
        default=1,
        help="torch and OpenCV threads (default 1, as the shipped files were made; 0: the libraries' default)",
    )
    add_progress_option(s)
    s.set_defaults(func=_distill, needs=_TRAINING_NEEDS)

    r = subparsers.add_parser(
        "train-real-light",
        help="train the gain Normalizer on relit photographs or registered scenes (identification objective)",
        description="Train the gain-adaptive Normalizer (alcn_cv.nets.gain) on fixed-camera views under changing "
        "light: each textured location is a class seen under every frame's light (alcn_cv.train.real_light). "
        "The gain preset trains on photographs with no known restriction on use, each relit several times (relit=4); "
        "--set \"scenes=['a', 'b']\" adds registered scenes (folders, or the webcam scenes courbevoie, frankfurt, "
        "panorama: academic research only). Writes OUT/gain_normalizer.npz, checkpoints, train.log and "
        "history.json; Ctrl-C saves a checkpoint at the step reached and prints the command that goes on from it. "
        "The logged loss is the objective on pairs drawn afresh at each step, so its mean moves with the draws: each "
        "line also gives the untrained start's loss on the draws of its last steps. "
        "The shipped alcn_normalizer_gain.npz is `alcn train-real-light --conf gain`.",
    )
    add_conf_option(r, REAL_LIGHT_CONF_SUMMARIES, "gain", example="steps=600")
    r.set_defaults(conf=None)  # --resume without --conf takes the checkpoint's settings
    _add_run(r, "out/gain")
    r.add_argument(
        "--threads",
        type=_THREADS,
        default=1,
        help="torch threads (default 1, as the shipped file was made; 0: torch's default)",
    )
    r.add_argument(
        "--resume",
        action="store_true",
        help="go on from OUT/checkpoint.pt, as if never stopped, with its settings; the one change it takes is a "
        "larger steps (--set steps=N trains on to step N): any other --set, and --seed, must repeat the checkpoint's "
        "value; with --conf, the preset's settings with --set and --seed, which must equal the checkpoint's alike; "
        "--threads and --no-progress are free",
    )
    r.add_argument("--overwrite", action="store_true", help="replace the earlier run that OUT holds")
    r.set_defaults(func=_train_real_light, needs=_TRAINING_NEEDS)

    u = subparsers.add_parser(
        "train-unet",
        help="train the free-form U-Net baseline exactly as train-real-light trains the gain Normalizer",
        description="Train a small U-Net that outputs the normalized image (alcn_cv.train.unet_normalizer; Jenicek & "
        "Chum's jointly trained U-Net) with train-real-light's data, objective and budget (alcn_cv.train.unet): the "
        "same keys, but net.* are the U-Net's (channels, levels, eps), and the same log (the untrained start's loss "
        "beside each line's). Writes "
        "OUT/unet_normalizer.npz, train.log and history.json. A baseline, not an ALCN model: `alcn bench relight "
        "--methods alcn,unet:weights=OUT/unet_normalizer.npz` compares them (no other command runs it).",
    )
    add_conf_option(u, UNET_CONF_SUMMARIES, "gain", example="net.channels=16")
    _add_run(u, "out/unet")
    u.add_argument("--threads", type=_THREADS, default=1, help="torch threads (default 1; 0: torch's default)")
    u.add_argument("--overwrite", action="store_true", help="replace the earlier run that OUT holds")
    u.set_defaults(func=_train_unet, needs=_TRAINING_NEEDS)

    e = subparsers.add_parser(
        "export",
        help="export the Normalizer to ONNX (for the torch-free OpenCV runtime)",
        description="Export the Normalizer of a weight file as a fully-convolutional ONNX model with dynamic "
        "image size, run by cv2.dnn in alcn_cv.nets.opencv_runtime (no torch needed). backend='opencv' reads the "
        "export beside its weight file under the same name (W.npz: W.onnx), where it is written by default; "
        "createALCN takes the .npz.",
    )
    e.add_argument(
        "--onnx",
        type=Path,
        help="output .onnx path (default: beside the weights, W.onnx for W.npz, where backend='opencv' reads it)",
    )
    e.add_argument(
        "--weights",
        type=Path,
        help="Normalizer weight file (.npz); required unless --onnx is given, in which case the default model's is "
        "exported",
    )
    e.add_argument("--overwrite", action="store_true", help="replace an existing .onnx")
    e.set_defaults(func=_export)


def _operational(args: argparse.Namespace, **keys: str) -> list[str | dict]:
    """The ``--set`` items, then the operational flags given (``flag=key``) as settings."""
    items: list[str | dict] = list(args.settings)
    for flag, key in keys.items():
        value = getattr(args, flag)
        if value is not None:
            *tables, last = key.split(".")
            node: dict = {last: value}
            for t in reversed(tables):
                node = {t: node}
            items.append(node)
    return items


def _train(args: argparse.Namespace) -> int:
    from alcn_cv.train.config import TRAIN_CONFS, load_config

    cfg = load_config(args.conf, _operational(args, seed="seed", device="run.device"))
    if args.print_config:
        return print_config(cfg)
    from alcn_cv.train import distributed
    from alcn_cv.train.trainer import train

    try:
        result = train(
            cfg,
            args.out,
            resume=args.resume,
            overwrite=args.overwrite,
            progress=not args.no_progress,
            command=_command(
                "train", args, "--out", str(args.out), *(["--device", args.device] if args.device else [])
            ),
            conf=args.conf if args.conf in TRAIN_CONFS else None,  # None: a TOML file of the user's
        )
    finally:
        distributed.shutdown()
    if result.status == "interrupted":
        epoch, step = result.stopped_at or (1, 0)
        conf = args.conf if args.conf in TRAIN_CONFS else str(Path(args.conf).absolute())  # a TOML file's path
        words = ["alcn", "train", "--out", str(args.out.absolute()), "--resume", "--conf", conf]
        words += _setting_words(args, folders=cfg.resolved().folders())  # as the checkpoint holds them
        words += ["--device", args.device] if args.device else []
        words += ["--no-progress"] if args.no_progress else []
        return _interrupted(f"interrupted at epoch {epoch}, step {step}", result.interruption, words)
    return 0


def _interrupted(stopped: str, interrupt: BaseException | None, resume: Sequence[str] = ()) -> int:
    """End a training command that an interrupt stopped, alike for all: print where it stopped and the command that
    goes on from its checkpoint (``resume``; none: ``stopped`` says why there is none) and return the exit code
    (:func:`~alcn_cv.cli.interrupt_exit_code`: 143 on SIGTERM, 130 on Ctrl-C)."""
    print(f"{stopped}; continue with: {shlex.join(resume)}" if resume else stopped, file=sys.stderr)
    return interrupt_exit_code(interrupt)


def _fit_interrupted(exc: TrainingInterrupted, resume: Sequence[str] = ()) -> int:
    """:func:`_interrupted` for a run of :func:`~alcn_cv.train.real_light.fit` (``exc``; its ``__cause__`` the
    interrupt): ``resume`` printed only where a checkpoint holds the steps done."""
    if exc.checkpoint:
        return _interrupted(f"interrupted at step {exc.step}", exc.__cause__, resume)
    if exc.step:
        return _interrupted(
            f"interrupted at step {exc.step}: no checkpoint to go on from (this command writes none; history.json "
            "holds the steps done)",
            exc.__cause__,
        )
    return _interrupted("interrupted before the first step: nothing saved", exc.__cause__)


def _train_detector(args: argparse.Namespace) -> int:
    from alcn_cv.train.stage2 import main

    main(
        args.images,
        args.out,
        method=args.method,
        weights=args.weights,
        per_image=args.per_image,
        negatives=args.negatives,
        extent=args.extent,
        epochs=args.epochs,
        batch_size=args.batch_size,
        lr=args.lr,
        seed=args.seed,
        overwrite=args.overwrite,
        progress=not args.no_progress,
    )
    return 0


def _distill(args: argparse.Namespace) -> int:
    from alcn_cv.errors import InputError
    from alcn_cv.train.config import DISTILL_CONFS

    cfg = preset(DISTILL_CONFS, args.conf, _operational(args, seed="seed"))
    cfg.check()  # a setting out of range: named, before printing or any work
    if args.print_config:
        return print_config(cfg)
    if args.out is None:
        raise InputError("alcn distill needs --out (the weight file to write)")
    import cv2

    from alcn_cv.nn import torch_threads
    from alcn_cv.train.distill import main

    previous = cv2.getNumThreads()
    if args.threads:
        cv2.setNumThreads(args.threads)
    try:
        command = _command("distill", args, "--out", str(args.out))
        with torch_threads(args.threads or None):
            path = main(args.out, cfg, command, conf=args.conf, progress=not args.no_progress, overwrite=args.overwrite)
    finally:
        cv2.setNumThreads(previous)
    print(path)
    return 0


def _train_real_light(args: argparse.Namespace) -> int:
    from alcn_cv.train.config import REAL_LIGHT_CONFS

    settings = _operational(args, seed="seed")
    checkpoint = None
    if args.resume and args.conf is None:  # the checkpoint's settings, with those given
        from alcn_cv.train.checkpoint import load_checkpoint
        from alcn_cv.train.real_light import resumed_config

        checkpoint = load_checkpoint(args.out / "checkpoint.pt")  # read once: the run takes it too
        cfg, record = resumed_config(args.out, settings, checkpoint=checkpoint)
        conf, first = record["conf"], record["command"]
        command = shlex.join([*shlex.split(first), *_setting_words(args)]) if first else ""
    else:
        conf = args.conf or "gain"
        cfg = preset(REAL_LIGHT_CONFS, conf, settings)
        command = _command("train-real-light", args, conf=conf)
    if args.print_config:  # a run checks its settings itself (training_run)
        cfg = cfg.resolved()  # the folders the run reads, as its checkpoint records them
        cfg.check()
        return print_config(cfg)
    from alcn_cv.nn import torch_threads
    from alcn_cv.train.real_light import TrainingInterrupted, train_real_light

    try:
        with torch_threads(args.threads or None):
            path = train_real_light(
                cfg,
                args.out,
                command=command,
                conf=conf,
                progress=not args.no_progress,
                resume=args.resume,
                overwrite=args.overwrite,
                checkpoint=checkpoint,
            )
    except TrainingInterrupted as exc:
        # its settings: the checkpoint's (their folders absolute); the folder absolute too: from any working folder
        words = ["alcn", "train-real-light", "--out", str(args.out.absolute()), "--resume"]
        words += ["--threads", str(args.threads)] if args.threads != 1 else []
        words += ["--no-progress"] if args.no_progress else []
        return _fit_interrupted(exc, words)
    changed = conf if conf is not None and cfg != REAL_LIGHT_CONFS.get(conf) else None  # None: the preset alone
    print(_next_steps(Path(path), changed))
    return 0


def _next_steps(weights: Path, changed: str | None) -> str:
    """Where a run's weights are and the commands that use them: normalize, export, and the README's comparison on
    real light changes. A run that changed its preset (``changed``, the preset's name) is compared with the preset
    alone, trained once beside it (``RUN_recipe``: another machine gives other weights than the shipped file's); a run
    of its preset alone (``changed`` None) with the shipped model. The bench writes beside the run (``RUN_bench``) with
    ``--overwrite``: after the run is replaced (``--overwrite``), the report on the weights it replaced is replaced
    too."""
    w = str(weights)
    where = "needs the shared data, or --data DIR of your own registered scenes"
    steps = [
        ("normalize an image with them", ["alcn", "normalize", "IMAGE", "OUTPUT", "-m", f"alcn:weights={w}"]),
        ("export them for backend='opencv' (ONNX, beside them)", ["alcn", "export", "--weights", w]),
    ]
    if changed is None:
        compare = (
            "compare them with the shipped model on real light changes (the same recipe: another machine gives other "
            f"weights; {where})"
        )
        methods = f"alcn,alcn:weights={w}"
    else:
        recipe = _beside(weights.parent, "recipe")
        steps.append(
            (
                "train the recipe alone too, once (another machine gives other weights than the shipped file's)",
                ["alcn", "train-real-light", "--conf", changed, "--out", str(recipe)],
            )
        )
        compare = (
            "compare the two on real light changes: relight.md's paired difference of the second from the first is "
            f"what your settings changed ({where})"
        )
        methods = f"alcn:weights={recipe / weights.name},alcn:weights={w}"
    bench = ["alcn", "bench", "relight", "--conf", "quick", "--methods", methods]
    steps.append((compare, [*bench, "--out", str(_beside(weights.parent, "bench")), "--overwrite"]))
    return "\n".join([f"weights: {w}", "next:", *(f"  {what}:\n    {shlex.join(words)}" for what, words in steps)])


def _beside(run: Path, what: str) -> Path:
    """The folder ``RUN_what`` beside the run folder ``run``: not inside it, where a later ``--overwrite`` of the run
    would leave a report on weights it replaced."""
    named = run if run.name not in ("", ".", "..") else run.absolute().resolve()
    return named.with_name(f"{named.name}_{what}")


def _train_unet(args: argparse.Namespace) -> int:
    from alcn_cv.train.config import UNET_CONFS

    cfg = preset(UNET_CONFS, args.conf, _operational(args, seed="seed"))
    if args.print_config:
        cfg = cfg.resolved()  # the folders the run reads
        cfg.check()
        return print_config(cfg)
    from alcn_cv.train.real_light import TrainingInterrupted
    from alcn_cv.train.unet import train_unet

    command = _command("train-unet", args)
    try:
        return _print_with_threads(
            args.threads,
            lambda: train_unet(
                cfg,
                args.out,
                command=command,
                conf=args.conf,
                progress=not args.no_progress,
                overwrite=args.overwrite,
            ),
        )
    except TrainingInterrupted as exc:
        return _fit_interrupted(exc)


def _print_with_threads(threads: int, run: Callable[[], object]) -> int:
    """Print what ``run()`` returns, run with ``threads`` torch threads (0: torch's default), in a
    :func:`~alcn_cv.nn.torch_threads` block."""
    from alcn_cv.nn import torch_threads

    with torch_threads(threads or None):
        print(run())
    return 0


def _export(args: argparse.Namespace) -> int:
    from alcn_cv.errors import InputError
    from alcn_cv.io import output_path
    from alcn_cv.runtime import resolve_weights
    from alcn_cv.train.export import export_onnx
    from alcn_cv.weight_file import WEIGHTS_DIR, load_normalizer_file

    weights = resolve_weights(None, args.weights)
    shipped = WEIGHTS_DIR.resolve()  # the package's own weights and exports
    beside = weights.with_suffix(".onnx")
    if args.weights is None and args.onnx is None:
        raise InputError(
            (f"the default model's export is installed already ({beside}); " if beside.is_file() else "")
            + "give --weights FILE to export your own weights (beside them), or --onnx PATH"
        )
    load_normalizer_file(weights)  # a folder (the file meant named), a missing or corrupt file: before a path beside it
    # its suffix and folder first: a path that no --overwrite would let be written is refused as such
    onnx = beside if args.onnx is None else output_path(args.onnx, ".onnx", "an ONNX export")
    if onnx.is_dir():
        raise InputError(f"{onnx} is a folder: --onnx names the .onnx file to write")
    if onnx.exists() and not args.overwrite:
        if onnx.resolve().is_relative_to(shipped):
            raise InputError(f"{onnx} is an export installed with alcn-cv; give --onnx PATH to write another")
        raise InputError(f"{onnx} exists (--overwrite replaces it)")
    if onnx.resolve() != beside.resolve():
        logger.warning(
            "writing %s: backend='opencv' reads the export of %s at %s, beside it, and will not find this one",
            onnx,
            weights,
            beside,
        )
    print(export_onnx(onnx, weights))
    return 0
