"""Experiment (issue 39): does training matter when its data ask for it? The `gain` recipe with rendered
directional light among its scenes.

The shipped recipe (`alcn train-real-light --conf gain`: relit photographs that permit any use) ends where it
starts: its light changes are cancelled by the divisive step. Hard directional light is not (the faces kept
outside the repository, and their rendered stand-in in `experiments/directional_light.py`, rank Tan-Triggs above
ALCN). Parts (``--part``; default: all, in this order), each writing under ``--out`` (default
``runs/relief_training``), the rendered scenes and the files trained on them in ``DATA`` =
``OUT/identities_<identities>_seed_<seed>`` (a run with other ``--identities`` or ``--seed`` has its own):

* ``scenes``: ``alcn data scenes --lighting directional`` (the stand-in's scenes: a frontal light and 4 directional
  lights at each of 5 elevations, cast shadows, sensor noise) with ``--identities`` scenes, from another seed and at
  256 px, into ``DATA/scenes``;
* ``train``: ``alcn train-real-light --conf gain --set rendered=[DATA/scenes]`` with each of :data:`VARIANTS`'
  settings (the share of training steps that draw a rendered scene, the recipe's budget of 300 steps at lr 1e-3 or
  twice the steps at five times the rate, with the control that has no rendered scene), into ``DATA/<variant>`` (a
  variant whose weight file is there already, trained on the same scenes, is not trained again);
* ``faces``: the stand-in itself (``_stand_in.render_stand_in``: its seed, 80 identities, 128 px) at the
  most grazing light (12 degrees), outputs compared at 32 and 64 px, for the shipped file, each trained file and
  the hand-made methods that lead there;
* ``bench``: ``alcn bench relight``'s quick protocol (seed 0, no tuning) for the
  trained files, the shipped file and no normalization, on the test and the webcam training scenes.

The summary puts the two side by side: what the rendered faces gain against what real light's keypoints lose.

    python experiments/relief_training.py     # about 15 min on 2 cores

Writes OUT/relief_training.json; keeps docs/reports/relief_training.json.
"""

from __future__ import annotations

import json
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
)
from _stand_in import render_stand_in
from tqdm.auto import tqdm

from alcn_cv.bench.directional import identify
from alcn_cv.cli import run_script
from alcn_cv.data.relief_settings import ELEVATIONS
from alcn_cv.report import machine

PARTS = ("scenes", "train", "faces", "bench")
#: The trained variants: ``alcn train-real-light --conf gain --set ...`` settings besides the rendered scenes.
VARIANTS = {
    "share 0.25": {"rendered_fraction": 0.25},
    "share 0.5": {"rendered_fraction": 0.5},
    "share 0, 600 steps at lr 5e-3": {"rendered_fraction": 0.0, "steps": 600, "lr": 5e-3},
    "share 0.5, 600 steps at lr 5e-3": {"rendered_fraction": 0.5, "steps": 600, "lr": 5e-3},
}
#: The stand-in's probes under the most grazing light (12 degrees).
GRAZING = f"elevation {ELEVATIONS[-1]}"
FACE_BASELINES = ("tantriggs", "dlcn")


def faces(methods: dict[str, str]) -> dict[str, dict[str, float]]:
    """The stand-in's identification at 12 degrees, at each of its sizes, per method."""
    images = render_stand_in()
    return {
        name: {f"faces {size} px": result[GRAZING] for size, result in identify(spec, images).items()}
        for name, spec in tqdm(methods.items(), desc="faces", unit="method")
    }


def bench_means(report: dict[str, Any], spec: str) -> dict[str, float]:
    """Identification and ORB / SIFT matching of ``spec`` in an ``alcn bench relight`` report, test and training."""
    method = report["methods"][spec]
    return {
        f"{group} {metric.replace('_', ' ')}": method[f"mean_{group}"][metric]["mean"]
        for group in ("test", "train")
        for metric in ("identification", "matching_orb", "matching_sift")
    }


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument(
        "--out", type=Path, default=RUNS / "relief_training", help="run folder (default: runs/relief_training)"
    )
    add_part_option(parser, PARTS)
    parser.add_argument("--identities", type=int, default=40, help="rendered training scenes (default: 40)")
    parser.add_argument("--seed", type=int, default=11, help="their rendering seed (default: 11; the stand-in's is 7)")
    args = parser.parse_args()
    args.part = selected_parts(args, PARTS)  # the report's settings record the parts run
    command = script_command()
    # apart for each (identities, seed): another run's scenes would mix with these, its weight files pass for theirs
    data = args.out / f"identities_{args.identities}_seed_{args.seed}"
    scenes = data / "scenes"
    trained = {
        f"trained, {name}": data / name.replace(" ", "_").replace(",", "") / "gain_normalizer.npz" for name in VARIANTS
    }
    if "scenes" in args.part:
        alcn(
            "data",
            "scenes",
            "--out",
            str(scenes),
            "--lighting",
            "directional",
            "--scenes",
            str(args.identities),
            "--side",
            "256",
            "--seed",
            str(args.seed),
            "--overwrite",
        )
    if "train" in args.part:
        for settings, path in zip(VARIANTS.values(), trained.values()):
            if path.exists():
                continue
            overrides = [f"rendered=[{json.dumps(str(scenes))}]"] + [f"{k}={v}" for k, v in settings.items()]
            alcn(
                "train-real-light",
                "--conf",
                "gain",
                "--out",
                str(path.parent),
                "--overwrite",
                *(f"--set={o}" for o in overrides),
            )
    specs = {"shipped (trained without rendered scenes)": "alcn"} | {
        name: f"alcn:weights={p}" for name, p in trained.items()
    }
    summary: dict[str, dict[str, float]] = {}
    if "faces" in args.part:
        for name, row in faces(specs | {m: m for m in FACE_BASELINES}).items():
            summary.setdefault(name, {}).update(row)
    if "bench" in args.part:
        methods = [*specs.values(), "none"]
        short_relight(args.out / "bench", methods)
        report = json.loads((args.out / "bench" / "relight.json").read_text(encoding="utf-8"))
        for name, spec in (specs | {"none": "none"}).items():
            summary.setdefault(name, {}).update(bench_means(report, spec))
    result = {
        "summary": summary,
        "command": command,
        "machine": machine(),
        "settings": recorded_settings(args),
    }
    path = args.out / "relief_training.json"
    path.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")
    keep(path, "relief_training")


if __name__ == "__main__":
    run_script(main)
