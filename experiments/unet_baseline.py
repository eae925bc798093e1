"""Experiment (issue 39, part 3): the free-form learned baseline, a U-Net trained exactly as the gain Normalizer.

Parts (``--part``; default: all, in this order), each writing under ``--out`` (default ``runs/unet``):

* ``unet``: ``alcn train-unet --conf CONF`` (:mod:`alcn_cv.train.unet`: the preset's scenes, draws,
  objective, steps and learning rate, the U-Net instead of Eq. 3) into ``OUT/train``;
* ``gain``: ``alcn train-real-light --conf CONF``, the gain Normalizer on the same preset, into ``OUT/gain``
  (the shipped ``alcn`` was made by the ``gain`` preset; another preset needs its own gain file to compare);
* ``objective``: the training objective (identification, consistency and repeatability) of both
  trained files on ``--draws`` draws (frames and locations, as training draws them) of each training and test
  scene, into ``OUT/objective.json``: how well each fits the training scenes and how much of it holds on new ones;
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

from collections.abc import Callable
from pathlib import Path
from typing import Any

from _run import RUNS, add_part_option, alcn, command_line, keep, quick_seed0_untuned, selected_parts

PARTS = ("unet", "gain", "objective", "bench")


def objective(conf: str, unet: Path, gain: Path, draws: int, out: Path) -> dict[str, Any]:
    """The mean objective of each file per scene and over the bench's training and test scenes, in ``out``."""
    import numpy as np
    import torch

    from alcn_cv.data.scenes import TEST_SCENES, TRAIN_SCENES, load_scenes, select_scenes, shared_root
    from alcn_cv.io import write_json
    from alcn_cv.nets.gain import GainNormalizer
    from alcn_cv.train.config import REAL_LIGHT_CONFS, preset
    from alcn_cv.train.real_light import draw_step, pair_loss, training_scene
    from alcn_cv.train.unet import unet_pair_loss
    from alcn_cv.train.unet_normalizer import UNetNormalizer
    from alcn_cv.weight_file import load_normalizer_file

    cfg = preset(REAL_LIGHT_CONFS, conf)
    # each network with its loss: the same objective, the U-Net's taken on the centres of its crops
    nets: dict[str, tuple[torch.nn.Module, Callable[..., torch.Tensor]]] = {
        "unet": (UNetNormalizer.from_file(load_normalizer_file(unet)), unet_pair_loss),
        "gain": (GainNormalizer.from_file(load_normalizer_file(gain)), pair_loss),
    }
    scenes = load_scenes([shared_root("webcam"), shared_root("psm")])
    groups = {"train": select_scenes(scenes, TRAIN_SCENES), "test": select_scenes(scenes, TEST_SCENES)}
    result: dict[str, Any] = {"conf": conf, "draws": draws, "scenes": {}}
    for group, members in groups.items():
        for scene in members:
            ready = training_scene(scene, cfg.crop // 2, cfg.patch)
            rng = np.random.default_rng(0)
            losses: dict[str, list[float]] = {name: [] for name in nets}
            for _ in range(draws):
                _, pair, centres, anywhere = draw_step([ready], [], cfg, rng)
                with torch.no_grad():
                    for name, (net, loss) in nets.items():
                        losses[name].append(float(loss(net, ready, pair, centres, cfg, anywhere)))
            result["scenes"][scene.name] = {"group": group, **{n: float(np.mean(v)) for n, v in losses.items()}}
            print(scene.name, group, {n: round(float(np.mean(v)), 3) for n, v in losses.items()})
    for group in groups:
        rows = [r for r in result["scenes"].values() if r["group"] == group]
        result[f"mean_{group}"] = {n: float(np.mean([r[n] for r in rows])) for n in nets}
        print(group, {n: round(v, 3) for n, v in result[f"mean_{group}"].items()})
    write_json(out / "objective.json", result)
    return result


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
        objective(args.conf, unet, gain, args.draws, args.out)
    if "bench" in parts:
        methods = [f"unet:weights={unet}", *([f"alcn:weights={gain}"] if gain.is_file() else []), "alcn", "none"]
        alcn(
            "bench", "relight", "--out", str(args.out / "bench"), "--methods", ",".join(methods), *quick_seed0_untuned()
        )
        keep(args.out / "bench" / "relight.json", "relight_unet")


if __name__ == "__main__":
    main()
