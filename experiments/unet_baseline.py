"""Experiment (issue 39, part 3): the free-form learned baseline, a U-Net trained exactly as the gain Normalizer.

``alcn train-unet --conf CONF`` (:mod:`alcn_cv.train.unet`: the preset's scenes, objective, steps and
learning rate, the U-Net instead of Eq. 3), then ``alcn bench relight``'s quick protocol (seed 0, 12
frames, 150 patches, 12 pairs, no tuning; identification, ORB/SIFT matching and pose on the test and
the training scenes) for the U-Net, the shipped ALCN (``alcn``) and no normalization.

Writes ``OUT/train/{unet_normalizer.npz,train.log,history.json}`` and ``OUT/bench/relight.{md,json,png}``
(``OUT`` = ``--out``, default ``runs/unet``). The preset ``gain`` trains on the webcam training scenes
(academic research only).

    PYTHONPATH=$PWD nice -n 10 python experiments/unet_baseline.py --conf gain
    PYTHONPATH=$PWD nice -n 10 python experiments/unet_baseline.py --stages bench   # bench a trained run again
"""

from __future__ import annotations

import argparse
from pathlib import Path

from _run import RUNS, alcn

STAGES = ("train", "bench")
QUICK = ["--seeds", "0", "--max-frames", "12", "--patches", "150", "--max-pairs", "12", "--no-tune"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--conf", default="gain", help="the train-real-light preset (default: gain)")
    parser.add_argument("--out", type=Path, default=RUNS / "unet", help="run folder (default: runs/unet)")
    parser.add_argument("--stages", nargs="+", choices=STAGES, default=list(STAGES))
    parser.add_argument("--train-args", nargs=argparse.REMAINDER, default=[], help="more arguments of train-unet")
    args = parser.parse_args()
    weights = args.out / "train" / "unet_normalizer.npz"
    if "train" in args.stages:
        alcn("train-unet", "--conf", args.conf, "--out", str(args.out / "train"), *args.train_args)
    if "bench" in args.stages:
        methods = f"unet:weights={weights},alcn,none"
        alcn("bench", "relight", "--out", str(args.out / "bench"), "--methods", methods, *QUICK)


if __name__ == "__main__":
    main()
