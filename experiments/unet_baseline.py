"""Experiment (issue 39, part 3): the free-form learned baseline, a U-Net trained exactly as the gain Normalizer.

Parts (``--part``; default: all, in this order), each writing under ``--out`` (default ``runs/unet``):

* ``unet``: ``alcn train-unet --conf CONF`` (:mod:`alcn_cv.train.unet`: the preset's scenes, draws,
  objective, steps and learning rate, the U-Net instead of Eq. 3) into ``OUT/train``;
* ``gain``: ``alcn train-real-light --conf CONF``, the gain Normalizer on the same preset, into ``OUT/gain``
  (the shipped ``alcn`` was made by the ``gain`` preset; another preset needs its own gain file to compare);
* ``objective``: the training objective (identification, consistency and repeatability) of both
  trained files on ``--draws`` draws (frames and locations, as training draws them) of each training and test
  scene (:mod:`alcn_cv.bench.objective`), into ``OUT/objective.json``: how well each fits the training scenes and
  how much of it holds on new ones;
* ``bench``: ``alcn bench relight``'s quick protocol (seed 0, no tuning; identification, ORB/SIFT matching and
  pose on the test and the training scenes) for the U-Net, the gain file of ``gain`` when there is one, the shipped
  ALCN (``alcn``) and no normalization, into ``OUT/bench/relight.{md,json,png}``; the JSON is kept as
  ``docs/reports/relight_unet.json``.

The preset ``gain`` trains on relit permissive photographs (it trained on the webcam scenes before 2026-11-27,
when these times were measured). Time on 2 shared cores at
load 4-9 (2026-11-27): ``unet`` 29 min (300 steps, about 5 s each), ``gain`` 2 min, ``objective`` 7 min,
``bench`` 3 to 5 min.

    python experiments/unet_baseline.py --conf gain
    python experiments/unet_baseline.py --part bench   # bench the trained files again
"""

from __future__ import annotations

from pathlib import Path

from _run import RUNS, add_part_option, alcn, command_line, keep, selected_parts, short_relight

from alcn_cv.cli import run_script

PARTS = ("unet", "gain", "objective", "bench")


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--conf", default="gain", help="the train-real-light preset (default: gain)")
    parser.add_argument("--out", type=Path, default=RUNS / "unet", help="run folder (default: runs/unet)")
    add_part_option(parser, PARTS)
    parser.add_argument("--draws", type=int, default=8, help="objective: draws per scene (default 8)")
    args = parser.parse_args()
    parts = selected_parts(args, PARTS)
    unet, gain = args.out / "train" / "unet_normalizer.npz", args.out / "gain" / "gain_normalizer.npz"
    if "unet" in parts:
        alcn("train-unet", "--conf", args.conf, "--out", str(unet.parent), "--overwrite")
    if "gain" in parts:
        alcn("train-real-light", "--conf", args.conf, "--out", str(gain.parent), "--overwrite")
    if "objective" in parts:
        from alcn_cv.bench import objective  # torch: only for this part

        objective.main(args.out, {"unet": unet, "gain": gain}, args.conf, args.draws)
    if "bench" in parts:
        methods = [f"unet:weights={unet}", *([f"alcn:weights={gain}"] if gain.is_file() else []), "alcn", "none"]
        short_relight(args.out / "bench", methods)
        keep(args.out / "bench" / "relight.json", "relight_unet")


if __name__ == "__main__":
    run_script(main)
