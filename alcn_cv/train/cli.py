"""Command line of the training stage: ``alcn train``, ``alcn train-detector``, ``alcn distill`` and ``alcn export``.

``alcn train`` trains the Normalizer jointly with a detector (Eq. 2) or, with
``--method dog|none``, the same detector on a fixed filter, for comparison;
``alcn train-detector`` is the paper's second stage, a new detector for new objects from a few
real images on the frozen Normalizer; ``alcn distill`` distils the light real-time Normalizer
from a trained one (:mod:`alcn_cv.train.distill`); ``alcn export`` writes a Normalizer as ONNX
for the torch-free OpenCV runtime. torch is imported only when a command runs.
"""

from __future__ import annotations

import argparse
import functools
import shlex
import sys
from pathlib import Path

from alcn_cv.data.scenes import scene_dirs
from alcn_cv.train.config import RealLightConfig

__all__ = ["add_parser"]

# Command-line flags that override configuration keys: flag -> key.
_FLAGS = {
    "epochs": "optim.epochs",
    "batch_size": "optim.batch_size",
    "lr": "optim.lr",
    "normalizer_lr": "optim.normalizer_lr",
    "seed": "seed",
    "device": "run.device",
    "workers": "run.workers",
    "threads": "run.threads",
    "n_train": "data.n_train",
    "data": "data.path",
    "val_data": "data.val_path",
    "method": "model.method",
}


# The options of ``alcn distill`` that its model card records when they differ from the defaults.
_DISTILL_OPTIONS = ("teacher", "windows", "val", "epochs", "batch", "lr", "channels", "objects", "seed", "threads",
                    "dilations", "scenes", "rendered")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train``, ``train-detector``, ``distill`` and ``export`` to the ``alcn`` command."""
    p = subparsers.add_parser(
        "train", help="train the ALCN Normalizer jointly with a detector (Eq. 2)",
        description="Train ALCN's Normalizer jointly with a detector on Phos-like rendered windows (Eq. 2 of "
        "Rad et al. 2017), validating on held-out lightings. With --method dog or none, train the same detector "
        "on a fixed DoG or on raw windows instead, for comparison. Writes checkpoint.pt, train.log, "
        "history.json, curves.png and alcn_normalizer.npz into --out. Multi-process: run under torchrun.",
    )
    p.add_argument("--config", default="default",
                   help="preset (default, paper) or TOML file; see alcn_cv.train.config for the schema")
    p.add_argument("--out", type=Path, default=Path("runs/alcn"), help="run folder (default: runs/alcn)")
    p.add_argument("--resume", action="store_true", help="continue from OUT/checkpoint.pt")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override any configuration key, e.g. --set optim.lr=3e-4 (repeatable)")
    p.add_argument("--epochs", type=int, help="optim.epochs")
    p.add_argument("--batch-size", type=int, help="optim.batch_size")
    p.add_argument("--lr", type=float, help="optim.lr (the detector's learning rate)")
    p.add_argument("--normalizer-lr", type=float, help="optim.normalizer_lr")
    p.add_argument("--seed", type=int, help="seed")
    p.add_argument("--device", choices=("cpu", "cuda"), help="run.device")
    p.add_argument("--workers", type=int, help="run.workers (processes rendering windows)")
    p.add_argument("--threads", type=int, help="run.threads (torch threads, 0 = default)")
    p.add_argument("--n-train", type=int, help="data.n_train (windows rendered for training)")
    p.add_argument("--data", help="data.path: a folder written by `alcn data phos` (training windows)")
    p.add_argument("--val-data", help="data.val_path: a folder of validation windows")
    p.add_argument("--method", choices=("alcn", "dog", "none"), help="model.method")
    p.add_argument("--print-config", action="store_true", help="print the effective configuration as TOML and exit")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_train)

    d = subparsers.add_parser(
        "train-detector", help="train a detector for new objects from a few images (second stage)",
        description="The second stage of ALCN: from a few real images of new objects (one folder per object, "
        "images showing the object; an optional *.mask.png beside an image marks it), make the paper's simple "
        "synthetic images, normalize them with the frozen Normalizer (or another method) and train a new "
        "detector. Writes detector.pt (torch state and configuration) into --out.",
    )
    d.add_argument("images", type=Path, help="folder with one sub-folder of images per object")
    d.add_argument("--out", type=Path, required=True, help="output folder")
    d.add_argument("--method", default="alcn", help="normalization applied to the windows, any registered name (default alcn)")
    d.add_argument("--weights", type=Path, help="Normalizer weight file for --method alcn (default: shipped)")
    d.add_argument("--per-image", type=int, default=300, help="synthetic windows per real image (default 300)")
    d.add_argument("--negatives", type=int, default=0,
                   help="background windows (default: as many as all positive windows)")
    d.add_argument("--extent", type=float, default=40.0, help="object size in window pixels (default 40)")
    d.add_argument("--epochs", type=int, default=15, help="training epochs (default 15)")
    d.add_argument("--batch-size", type=int, default=64, help="windows per batch (default 64)")
    d.add_argument("--lr", type=float, default=1e-3, help="Adam learning rate (default 1e-3)")
    d.add_argument("--seed", type=int, default=0, help="seed of the synthetic images and the detector (default 0)")
    d.add_argument("--no-progress", action="store_true", help="no progress bars")
    d.set_defaults(func=_train_detector)

    s = subparsers.add_parser(
        "distill", help="distil the light real-time Normalizer from a trained one",
        description="Train a LiteNormalizer to reproduce a Normalizer's mixture weights on rendered windows, or, "
        "from a gain Normalizer, a smaller gain Normalizer to reproduce its maps on the frames of the real "
        "training scenes and rendered ones (alcn_cv.train.distill); writes the weight file and its model card "
        "(.md beside it), which records this command, and for a gain student its ONNX export. The shipped "
        "alcn_normalizer_lite.npz is `alcn distill --out alcn_cv/weights/alcn_normalizer_lite.npz`, "
        "alcn_normalizer_gain_lite.npz `alcn distill --teacher alcn_cv/weights/alcn_normalizer_gain.npz "
        "--out alcn_cv/weights/alcn_normalizer_gain_lite.npz` (academic research only, as the webcam frames).",
    )
    s.add_argument("--out", required=True, type=Path, help="weight file to write (.npz; the card is .md beside it)")
    s.add_argument("--teacher", type=Path, default=None, help="teacher weight file (default: the shipped one)")
    s.add_argument("--windows", type=int, default=20000, help="training windows (default 20000; lite student)")
    s.add_argument("--val", type=int, default=2000, help="validation windows (default 2000; lite student)")
    s.add_argument("--epochs", type=int, default=None, help="epochs (default 30, 60 for a gain teacher)")
    s.add_argument("--batch", type=int, default=256, help="batch size (default 256; lite student)")
    s.add_argument("--lr", type=float, default=3e-3, help="Adam learning rate (default 3e-3)")
    s.add_argument("--channels", type=lambda v: tuple(int(c) for c in v.split(",")), default=None,
                   help="the student's widths: c1,c2 (default 8,16), or for a gain teacher its hidden width (default 8)")
    s.add_argument("--objects", type=int, default=100, help="objects in the rendered windows (default 100; lite student)")
    s.add_argument("--dilations", type=lambda v: tuple(int(c) for c in v.split(",")), default=None,
                   help="gain teacher: the student's dilated convolutions (default 1,2,4)")
    s.add_argument("--scenes", type=Path, nargs="+", default=None,
                   help="gain teacher: folders of registered frames (default: courbevoie frankfurt panorama of the "
                   "shared webcam data; never the test scenes)")
    s.add_argument("--rendered", type=int, default=6, help="gain teacher: rendered registered scenes added (default 6)")
    s.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    s.add_argument("--threads", type=int, default=1,
                   help="torch and OpenCV threads (default 1, as the shipped file was made; 0: the libraries' default)")
    s.add_argument("--no-progress", action="store_true", help="no progress bars")
    s.set_defaults(func=functools.partial(_distill, parser=s))

    r = subparsers.add_parser(
        "train-real-light", help="train the gain Normalizer on registered real scenes (identification objective)",
        description="Train the gain-adaptive Normalizer (alcn_cv.nets.gain: F_k = exp(g) w_k, the response divided "
        "by its local energy, on a grid or per pixel, then tanh(x / tau)) "
        "on fixed-camera scenes under changing light: each textured location is a class seen under every "
        "frame's light (alcn_cv.train.real_light). Writes OUT/gain_normalizer.npz, checkpoints, train.log and "
        "history.json. The shipped alcn_normalizer_gain.npz is this command with --divisive-sigma 2; the webcam "
        "scenes are for academic research only.",
    )
    defaults = RealLightConfig()
    r.add_argument("--scenes", nargs="+", type=Path, default=None,
                   help="folders of registered frames, one per scene (default: the courbevoie, frankfurt and "
                   "panorama scenes of the shared webcam data)")
    r.add_argument("--rendered", type=Path, default=None,
                   help="a folder of rendered registered scenes (`alcn data scenes`), each subfolder a scene "
                   "(default: none)")
    r.add_argument("--rendered-fraction", type=float, default=defaults.rendered_fraction,
                   help=f"share of the steps on a rendered scene (default {defaults.rendered_fraction})")
    r.add_argument("--out", type=Path, default=Path("runs/gain"), help="run folder (default: runs/gain)")
    for name, kind, what in (("steps", int, "optimisation steps"), ("locations", int, "textured locations per step"),
                             ("crop", int, "side of the crops the network sees"), ("patch", int, "side of the identified centre"),
                             ("min_distance", int, "least distance between a step's locations"),
                             ("temperature", float, "of the softmax over similarities"),
                             ("consistency", float, "weight of the term asking for the same output under both lights"),
                             ("anywhere", int, "locations per step drawn anywhere, for that term only"),
                             ("lr", float, "Adam learning rate"),
                             ("seed", int, "seed"), ("save_every", int, "steps between checkpoints")):
        r.add_argument(f"--{name.replace('_', '-')}", type=kind, default=getattr(defaults, name),
                       help=f"{what} (default {getattr(defaults, name)})")
    r.add_argument("--channels", type=int, default=16, help="width of the network's convolutions (default 16)")
    r.add_argument("--stride", type=int, default=8, help="spacing of the network's grid, in pixels (default 8)")
    r.add_argument("--num-kernels", type=int, default=2, help="Gaussian kernels of the mixture (default 2)")
    r.add_argument("--sigma-step", type=float, default=1.0, help="the kernels' sigmas are k * step, k = 1..N (default 1)")
    r.add_argument("--dilations", type=int, nargs="+", default=[1, 2, 4], help="one 3x3 convolution per dilation (default 1 2 4)")
    r.add_argument("--sharpness", action="store_true", help="feed the network each cell's finest-scale energy too")
    r.add_argument("--learn-floor", action="store_true",
                   help="learn the Weber gain's floor (1 / (m + floor)), starting at --eps")
    r.add_argument("--gain", choices=("weber", "divisive"), default="divisive",
                   help="the log-gain's fixed part: the Weber gain 1 / (m + eps) inside Eq. 3, or the divisive "
                        "normalization of Eq. 3's response on the grid, floored by c times its image mean (default divisive)")
    r.add_argument("--floor-scale", type=float, default=1.0,
                   help="c of the divisive floor (--gain divisive; default 1)")
    r.add_argument("--divisive-sigma", type=float, default=None,
                   help="divide by a per-pixel energy sqrt(G_sigma * r^2), this sigma in working pixels, instead of "
                        "the grid's cells (--gain divisive; default: the cells)")
    r.add_argument("--learn-scales", action="store_true",
                   help="learn tau and the divisive floor's c (otherwise they keep the values given)")
    r.add_argument("--tau", type=float, default=3.0,
                   help="scale of the final tanh(x / tau) (default 3)")
    r.add_argument("--eps", type=float, default=0.01,
                   help="added to intensities in [0, 1] before every log: the gain's noise floor (default 0.01)")
    r.add_argument("--threads", type=int, default=1,
                   help="torch threads (default 1, as the shipped file was made; 0: torch's default)")
    r.set_defaults(func=_train_real_light)

    e = subparsers.add_parser(
        "export", help="export the Normalizer to ONNX (for the torch-free OpenCV runtime)",
        description="Export the Normalizer of a weight file as a fully-convolutional ONNX model with dynamic "
        "image size, run by cv2.dnn in alcn_cv.nets.opencv_runtime (no torch needed).",
    )
    e.add_argument("--onnx", type=Path, required=True, help="output .onnx path")
    e.add_argument("--weights", type=Path, help="Normalizer weight file (.npz; default: the shipped one)")
    e.set_defaults(func=_export)


def _overrides(args: argparse.Namespace) -> list[str | dict]:
    """The flags as nested dicts, then the ``--set`` items (applied last)."""
    items: list[str | dict] = []
    for flag, key in _FLAGS.items():
        value = getattr(args, flag)
        if value is not None:
            node: dict = {}
            item = node
            *tables, last = key.split(".")
            for t in tables:
                node = node.setdefault(t, {})
            node[last] = value
            items.append(item)
    return items + list(args.set)


def _train(args: argparse.Namespace) -> int:
    from alcn_cv.train.config import dump_toml, load_config

    cfg = load_config(args.config, _overrides(args))
    if args.print_config:
        sys.stdout.write(dump_toml(cfg))
        return 0
    from alcn_cv.train import distributed
    from alcn_cv.train.trainer import train

    try:
        result = train(cfg, args.out, resume=args.resume, progress=not args.no_progress)
    finally:
        distributed.shutdown()
    if result.status == "interrupted":
        print(f"interrupted; continue with: alcn train --resume --out {args.out} ...", file=sys.stderr)
        return 130
    return 0


def _train_detector(args: argparse.Namespace) -> int:
    from alcn_cv.train.stage2 import main

    main(args.images, args.out, method=args.method, weights=args.weights, per_image=args.per_image,
         negatives=args.negatives, extent=args.extent, epochs=args.epochs, batch_size=args.batch_size, lr=args.lr,
         seed=args.seed, progress=not args.no_progress)
    return 0


def _distill(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    import cv2
    import torch

    from alcn_cv.train.distill import main
    from alcn_cv.weight_file import load_normalizer_file

    words = ["alcn", "distill", "--out", str(args.out)]
    for name in _DISTILL_OPTIONS:
        value = getattr(args, name)
        if value != parser.get_default(name):
            if isinstance(value, list):
                words += [f"--{name}", *map(str, value)]
            else:
                words += [f"--{name}", ",".join(map(str, value)) if isinstance(value, tuple) else str(value)]
    previous = torch.get_num_threads(), cv2.getNumThreads()
    if args.threads:
        torch.set_num_threads(args.threads)
        cv2.setNumThreads(args.threads)
    try:
        if args.teacher is not None and load_normalizer_file(args.teacher).meta.get("architecture") == "gain":
            gain_student = {"channels": args.channels[0]} if args.channels else {}
            gain_student.update({"dilations": args.dilations} if args.dilations else {})
            gain_student.update({"epochs": args.epochs} if args.epochs else {})
            path = main(args.out, args.teacher, shlex.join(words), scenes=args.scenes, rendered=args.rendered, lr=args.lr,
                        seed=args.seed, progress=not args.no_progress, **gain_student)
        else:
            path = main(args.out, args.teacher, shlex.join(words), n_windows=args.windows, n_val=args.val,
                        epochs=args.epochs or 30, batch_size=args.batch, lr=args.lr, channels=args.channels or (8, 16),
                        n_objects=args.objects, seed=args.seed, progress=not args.no_progress)
    finally:
        torch.set_num_threads(previous[0])
        cv2.setNumThreads(previous[1])
    print(path)
    return 0


def _train_real_light(args: argparse.Namespace) -> int:
    import torch

    from alcn_cv.train.real_light import train_real_light

    scenes = args.scenes or scene_dirs()
    names = ("steps", "locations", "crop", "patch", "min_distance", "temperature", "consistency", "anywhere", "lr", "seed",
             "save_every")
    rendered = sorted(str(p) for p in args.rendered.iterdir() if p.is_dir()) if args.rendered else []
    cfg = RealLightConfig(
        scenes=[str(s) for s in scenes], rendered=rendered, rendered_fraction=args.rendered_fraction,
        **{k: getattr(args, k) for k in names},
        net={"channels": args.channels, "stride": args.stride, "dilations": list(args.dilations), "sharpness": args.sharpness,
             "num_kernels": args.num_kernels, "sigma_step": args.sigma_step, "eps": args.eps,
             "learn_floor": args.learn_floor, "gain": args.gain, "floor_scale": args.floor_scale, "tau": args.tau,
             "learn_scales": args.learn_scales,
             **({} if args.divisive_sigma is None else {"divisive_sigma": args.divisive_sigma})},
        command=shlex.join(["alcn", *sys.argv[1:]]),
    )
    previous = torch.get_num_threads()
    if args.threads:
        torch.set_num_threads(args.threads)
    try:
        print(train_real_light(cfg, args.out))
    finally:
        torch.set_num_threads(previous)
    return 0


def _export(args: argparse.Namespace) -> int:
    from alcn_cv.train.export import export_onnx

    path = export_onnx(args.onnx, args.weights)
    print(path)
    return 0
