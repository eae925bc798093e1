"""Experiment (issue 39, part 1 and 3): the gain Normalizer trained on relit permissive photographs only.

Stages, each writing under ``--out`` (default ``runs/relit``):

* ``speed``: pairs per second of :func:`alcn_cv.data.light_changes.sample_pair` on the photographs;
* ``scenes``: every permissive photograph (:func:`alcn_cv.data.permissive_images.permissive_photographs`:
  scikit-image's public-domain and CC0 photographs, a third of the chessboard views, 4 frames and
  the still of the cookie box) relit ``--frames`` times without a homography
  (:func:`alcn_cv.data.light_changes.relit_frames`), grayscale PNG, one folder per photograph:
  the registered-scene layout of :mod:`alcn_cv.train.real_light`; ``scenes.json`` lists each
  one's source and licence;
* ``train``: ``alcn train-real-light`` on those folders with the shipped recipe's settings
  (``--conf gain``: 300 steps, seed 0), and the same network untrained (``untrained.npz``);
* ``bench``: ``alcn bench relight``'s quick protocol (the test scenes mexico and the psm objects,
  12 frames, 150 patches, 12 pairs, seed 0; identification, ORB/SIFT matching and pose) for
  none, CLAHE, DLCN and Tan-Triggs (default and tuned on the webcam training scenes), the
  shipped default, the relit-trained file and its untrained start.

``--light hard`` relights with more shadows, shading and noise, ``--light relief`` adds the shading of the
photograph read as a relief under a directional light (:data:`alcn_cv.data.light_changes.LIGHTS`);
``--jitter`` moves each relit copy by up to that many pixels (a fixed camera's registration error); ``--with-
webcam F`` trains on the webcam scenes with a share F of the steps on the relit ones (an academic-only
variant); ``--no-baselines`` benches the two new files only (the same plans, so their rows compare with a run
that had the baselines); ``--train-args`` passes more arguments to ``alcn train-real-light``.

Run from the checkout's root::

    PYTHONPATH=$PWD nice -n 10 python experiments/real_light_relit.py --out runs/relit
    PYTHONPATH=$PWD nice -n 10 python experiments/real_light_relit.py --out runs/relit_hard --light hard \
        --stages scenes train bench --no-baselines
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np
from _run import command_line, untrained_start

from alcn_cv.cli import main as alcn
from alcn_cv.data.light_changes import LIGHTS, sample_pair
from alcn_cv.data.permissive_images import Photograph, relit_scenes, training_photographs
from alcn_cv.data.scenes import TRAIN_SCENES
from alcn_cv.io import write_json
from alcn_cv.shared_data import shared_data_dir

STAGES = ("speed", "scenes", "train", "bench")
BASELINES = ["none", "clahe", "dlcn", "tantriggs", "alcn"]
QUICK = ["--seeds", "0", "--max-frames", "12", "--patches", "150", "--max-pairs", "12"]


def speed(photos: list[Photograph], out: Path, seconds: float = 10.0) -> dict:
    rng = np.random.default_rng(0)
    count, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        sample_pair(photos[count % len(photos)].image, rng)
        count += 1
    elapsed = time.perf_counter() - start
    sizes = sorted({p.image.shape for p in photos})
    result = {
        "pairs": count,
        "seconds": elapsed,
        "pairs_per_s": count / elapsed,
        "images": len(photos),
        "sizes": [list(s) for s in sizes],
        "threads": cv2.getNumThreads(),
    }
    write_json(out / "speed.json", result)
    print(f"{count / elapsed:.1f} pairs/s over {len(photos)} photographs (longer side <= 640)")
    return result


def scenes(photos: list[Photograph], out: Path, frames: int, seed: int, light: str, jitter: float) -> list[Path]:
    folders, listing = [], []
    for photo, scene in zip(photos, relit_scenes(photos, frames, seed, light, jitter)):
        folder = out / "scenes" / scene.name
        folder.mkdir(parents=True, exist_ok=True)
        for file, frame in zip(scene.files, scene.frames):
            cv2.imwrite(str(folder / file), frame)
        folders.append(folder)
        listing.append(
            {
                "folder": folder.name,
                "source": photo.source,
                "licence": photo.licence,
                "size": list(photo.image.shape[:2]),
            }
        )
    write_json(
        out / "scenes.json", {"frames": frames, "seed": seed, "light": light, "jitter": jitter, "scenes": listing}
    )
    return folders


def train(
    folders: list[Path], out: Path, steps: int, seed: int, extra: list[str], webcam: float | None
) -> tuple[Path, Path]:
    run = out / "train"
    # relit=0: the relit copies are the folders written by the scenes stage, not the preset's own.
    data = (
        [f"scenes={json.dumps(list(map(str, folders)))}", "relit=0"]
        if webcam is None
        else [
            f"scenes={json.dumps(list(TRAIN_SCENES))}",
            "relit=0",
            f"rendered={json.dumps([str(out / 'scenes')])}",
            f"rendered_fraction={webcam}",
        ]
    )
    settings = [word for item in [*data, f"steps={steps}"] for word in ("--set", item)]
    args = ["train-real-light", "--conf", "gain", "--out", str(run), *settings, "--seed", str(seed), *extra]
    if alcn(args) != 0:
        raise SystemExit("training failed")
    trained = run / "gain_normalizer.npz"
    return trained, untrained_start(trained, out / "untrained.npz", "the relit recipe's untrained start")


def bench(out: Path, trained: Path, untrained: Path, baselines: bool) -> None:
    methods = [*(BASELINES if baselines else []), f"alcn:weights={trained}", f"alcn:weights={untrained}"]
    tuning = [] if baselines else ["--no-tune"]
    if alcn(["bench", "relight", "--out", str(out / "bench"), "--methods", ",".join(methods), *QUICK, *tuning]) != 0:
        raise SystemExit("benchmark failed")


def main(argv: list[str] | None = None) -> int:
    parser = command_line(__doc__, keeps=False)
    parser.add_argument("--out", type=Path, default=Path("runs/relit"))
    parser.add_argument("--stages", nargs="+", choices=STAGES, default=list(STAGES))
    parser.add_argument("--frames", type=int, default=16, help="relit copies per photograph (default 16)")
    parser.add_argument("--steps", type=int, default=300, help="training steps (default 300, the shipped recipe's)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--light", choices=tuple(LIGHTS), default="default", help="the light changes (default: default)"
    )
    parser.add_argument(
        "--jitter",
        type=float,
        default=0.0,
        help="registration error of the relit copies, pixels (default 0: pixel-exact)",
    )
    parser.add_argument(
        "--with-webcam",
        type=float,
        default=None,
        metavar="FRACTION",
        help="train on the shipped recipe's webcam scenes (academic use only) with this share of "
        "steps on the relit scenes (the trainer's second group), instead of the relit ones alone",
    )
    parser.add_argument("--no-baselines", action="store_true", help="bench the two new files only (no tuning)")
    parser.add_argument(
        "--train-args", nargs=argparse.REMAINDER, default=[], help="more arguments of alcn train-real-light (last)"
    )
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    photos = training_photographs(shared_data_dir())
    print(f"{len(photos)} photographs: " + ", ".join(sorted({p.licence for p in photos})))
    if "speed" in args.stages:
        speed(photos, args.out)
    folders = sorted(p for p in (args.out / "scenes").glob("*") if p.is_dir())
    if "scenes" in args.stages:
        folders = scenes(photos, args.out, args.frames, args.seed, args.light, args.jitter)
    trained, untrained = args.out / "train" / "gain_normalizer.npz", args.out / "untrained.npz"
    if "train" in args.stages:
        trained, untrained = train(folders, args.out, args.steps, args.seed, args.train_args, args.with_webcam)
    if "bench" in args.stages:
        bench(args.out, trained, untrained, not args.no_baselines)
    json.dump({"argv": sys.argv}, (args.out / "command.json").open("w"))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
