"""Experiment (issue 39): the band-pass ALCN starts from, now that identification registers each pair of frames, and
whether training keeps a sharper one.

The default's untrained start is the DoG G1 - G2, chosen on the webcam training scenes when identification took the
frames as registered: mexico's and frankfurt's are 1-3 px apart, and a smooth output, which tolerates the shift, was
rewarded. With the pairs registered, a sharper centre may identify better; the keypoint detectors may pay for it.

* ``starts``: the shipped default's untrained start (``_run.untrained_start``: its recipe, seed 0) with the mixture
  starting as another DoG, :data:`STARTS` (the kernels ``k * sigma_step``, ``k = 1..N``, the weights of the DoG on
  them), saved to ``OUT/<name>.npz``;
* ``train``: the default's recipe (``alcn train-real-light --conf gain``: relit photographs) with a wider choice of
  bands: kernels 0.5, 1, 1.5 and 2 px from the default's G1 - G2 (``--set net.num_kernels=4 --set
  net.sigma_step=0.5``), and from the sharpest start, G0.5 - G1.5 (the preset has no key for the start, so the
  stage is called with the network's arguments), into ``OUT/trained_*``;
* ``bench``: ``alcn bench relight``'s quick protocol, seeds 0-2, no tuning, on the test scenes and on the four webcams
  one by one (``--leave-one-out``: with no tuning, each scene with the methods' defaults), for the starts, the trained
  files, the shipped default and the hand-made methods.

    python experiments/dog_band.py     # about 15 min on 2 cores

Writes OUT/dog_band.json (OUT: ``--out``, default runs/dog_band); keeps docs/reports/dog_band.json.
"""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path
from typing import Any

from _run import (
    RUNS,
    add_part_option,
    alcn,
    command_line,
    keep,
    recorded_settings,
    script_command,
    selected_parts,
    short_relight,
    untrained_start,
)

from alcn_cv.cli import run_script
from alcn_cv.report import machine
from alcn_cv.runtime import MODELS

PARTS = ("starts", "train", "bench")
#: The untrained starts: the network's arguments that differ from the default recipe's (``net`` of the ``gain``
#: preset), the mixture's kernels and the DoG's weights on them.
STARTS: dict[str, dict[str, Any]] = {
    "start G1 - G2 (the default's)": {},
    "start G0.75 - G1.5": {"num_kernels": 2, "sigma_step": 0.75, "init_weights": [1.0, -1.0]},
    "start G0.5 - G1.5": {"num_kernels": 3, "sigma_step": 0.5, "init_weights": [1.0, 0.0, -1.0]},
    "start G0.5 - G2": {"num_kernels": 4, "sigma_step": 0.5, "init_weights": [1.0, 0.0, 0.0, -1.0]},
}
#: The trained files: the preset's ``--set`` options, or the start of :data:`STARTS` trained by the preset's recipe.
TRAINED: dict[str, list[str] | str] = {
    "trained, kernels 0.5-2 from G1 - G2": ["net.num_kernels=4", "net.sigma_step=0.5"],
    "trained from G0.5 - G1.5": "start G0.5 - G1.5",
}
BASELINES = ("none", "dog", "dlcn", "alcn")
#: The groups of scenes: ``alcn bench relight`` options beside the methods and the protocol.
GROUPS = {"test": [], "webcams": ["--leave-one-out"]}
METRICS = ("identification", "matching_orb", "matching_sift", "pose_orb", "pose_sift")


def _file_name(name: str) -> str:
    """``name`` as a file name: its words and numbers joined by ``_`` ("start G0.5 - G2" -> "start_G0.5_G2")."""
    return re.sub(r"[^0-9A-Za-z.]+", "_", name).strip("_")


def train_from(net_args: dict[str, Any], out: Path, command: str) -> None:
    """The ``gain`` preset's recipe for a network of ``net_args`` (over the preset's ``net``), into ``out``."""
    from alcn_cv.train.config import REAL_LIGHT_CONFS
    from alcn_cv.train.real_light import train_real_light

    cfg = copy.deepcopy(REAL_LIGHT_CONFS["gain"])
    cfg.net.update(net_args)
    train_real_light(cfg, out, command=command, conf="gain", overwrite=True)


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--out", type=Path, default=RUNS / "dog_band", help="run folder (default: runs/dog_band)")
    add_part_option(parser, PARTS)
    args = parser.parse_args()
    args.part = selected_parts(args, PARTS)
    command = script_command()
    args.out.mkdir(parents=True, exist_ok=True)
    starts = {name: args.out / f"{_file_name(name)}.npz" for name in STARTS}
    trained = {name: args.out / _file_name(name) / "gain_normalizer.npz" for name in TRAINED}
    if "starts" in args.part:
        for name, path in starts.items():
            untrained_start(MODELS["gain"], path, f"ALCN's untrained {name}", **STARTS[name])
    if "train" in args.part:
        for name, how in TRAINED.items():
            if isinstance(how, str):
                train_from(STARTS[how], trained[name].parent, command)
            else:
                sets = [f"--set={s}" for s in how]
                alcn("train-real-light", "--conf", "gain", "--out", str(trained[name].parent), "--overwrite", *sets)
    specs = {m: m for m in BASELINES} | {n: f"alcn:weights={p}" for n, p in (starts | trained).items()}
    summary: dict[str, dict[str, float]] = {name: {} for name in specs}
    if "bench" in args.part:
        for group, options in GROUPS.items():
            out = args.out / f"bench_{group}"
            short_relight(out, list(specs.values()), seeds=(0, 1, 2), options=options)
            report = json.loads((out / "relight.json").read_text(encoding="utf-8"))
            for name, spec in specs.items():
                means = report["methods"][spec]["mean_test"]
                summary[name] |= {f"{group} {m.replace('_', ' ')}": means[m]["mean"] for m in METRICS}
    result = {"summary": summary, "command": command, "machine": machine(), "settings": recorded_settings(args)}
    path = args.out / "dog_band.json"
    path.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    keep(path, "dog_band")


if __name__ == "__main__":
    run_script(main)
