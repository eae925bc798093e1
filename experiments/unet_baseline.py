"""Experiment (issue 39, part 3): the free-form learned baseline, a U-Net trained exactly as the gain Normalizer.

Stages, each writing under ``--out`` (default ``runs/unet``):

* ``unet``: ``alcn train-unet --conf CONF`` (:mod:`alcn_cv.train.unet`: the preset's scenes, draws,
  objective, steps and learning rate, the U-Net instead of Eq. 3) into ``OUT/train``;
* ``gain``: ``alcn train-real-light --conf CONF``, the gain Normalizer on the same preset, into ``OUT/gain``
  (the shipped ``alcn`` was made by the ``gain`` preset; another preset needs its own gain file to compare);
* ``bench``: ``alcn bench relight``'s quick protocol (seed 0, 12 frames, 150 patches, 12 pairs, no
  tuning; identification, ORB/SIFT matching and pose on the test and the training scenes) for the
  U-Net, the gain file of ``gain`` when there is one, the shipped ALCN (``alcn``) and no normalization,
  into ``OUT/bench/relight.{md,json,png}``.

The preset ``gain`` trains on the webcam training scenes (academic research only).

    PYTHONPATH=$PWD nice -n 10 python experiments/unet_baseline.py --conf gain
    PYTHONPATH=$PWD nice -n 10 python experiments/unet_baseline.py --stages bench   # bench the trained files again
"""

from __future__ import annotations

import argparse
from pathlib import Path

from _run import RUNS, alcn

STAGES = ("unet", "gain", "bench")
QUICK = ["--seeds", "0", "--max-frames", "12", "--patches", "150", "--max-pairs", "12", "--no-tune"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--conf", default="gain", help="the train-real-light preset (default: gain)")
    parser.add_argument("--out", type=Path, default=RUNS / "unet", help="run folder (default: runs/unet)")
    parser.add_argument("--stages", nargs="+", choices=STAGES, default=list(STAGES))
    args = parser.parse_args()
    unet, gain = args.out / "train" / "unet_normalizer.npz", args.out / "gain" / "gain_normalizer.npz"
    if "unet" in args.stages:
        alcn("train-unet", "--conf", args.conf, "--out", str(unet.parent))
    if "gain" in args.stages:
        alcn("train-real-light", "--conf", args.conf, "--out", str(gain.parent))
    if "bench" in args.stages:
        methods = [f"unet:weights={unet}", *([f"alcn:weights={gain}"] if gain.is_file() else []), "alcn", "none"]
        alcn("bench", "relight", "--out", str(args.out / "bench"), "--methods", ",".join(methods), *QUICK)


if __name__ == "__main__":
    main()
