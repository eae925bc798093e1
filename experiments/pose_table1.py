"""Pose Table 1 on rendered sequences (`alcn pose eval`): % of frames posed within 5 px on the eight test
sequences of `alcn data pose --frames 30`, for the corner CNN (3 training seeds per normalization) and the
SIFT parts, the same networks under the training light, the held-out scene's #1 and Middlebury's real
photographs (Rad et al. 2017, Table 1).

The SIFT parts and Middlebury are in docs/results.md; the corner CNN parts are not (hours): the journal keeps
their numbers as measured. A part makes the rendered data it needs when they are missing. Time on 2 shared cores:
the data about 20 min; the corner CNN about 8 min per network (5 normalizations x 3 seeds, so about
2 hours per data set; `alcn pose eval` trains them on a GPU where torch sees one, in 1.5-2 min each); the SIFT rows
about 30 min; Middlebury about 10 min.

    python experiments/pose_table1.py                      # every part below, in turn
    python experiments/pose_table1.py --part features      # one part: data, features, corners,
                                                           # control, heldout, middlebury

Writes runs/pose_table1/<part>/table1.{md,json} (middlebury.{md,json} for Middlebury); keeps
docs/reports/pose_table1_<part>.json (pose_middlebury.json for Middlebury).
"""

from __future__ import annotations

from pathlib import Path

from _run import RUNS, SHARED_DATA, add_part_option, alcn, command_line, keep, selected_parts

from alcn_cv.cli import SEED, run_script

NORMALIZATIONS = ["none", "dog:sigma1=1:sigma2=2", "tantriggs", "alcn", "alcn:model=lite"]
PARTS = ("data", "features", "corners", "control", "heldout", "middlebury")


def main() -> None:
    parser = command_line(__doc__)
    add_part_option(parser, PARTS)
    parser.add_argument(
        "--seeds", nargs="+", type=SEED, default=[0, 1, 2], help="corner CNN training seeds (default: 0 1 2)"
    )
    args = parser.parse_args()
    parts = selected_parts(args, PARTS)
    seeds = [str(seed) for seed in args.seeds]
    root = RUNS / "pose_table1"
    data, control, heldout = root / "data", root / "data_training_light", root / "data_heldout"
    renderings = {data: [], control: ["--training-light"], heldout: ["--seed", "1", "--n-test", "1"]}

    def rendered(folder: Path) -> Path:
        if not (folder / "test").exists():
            alcn("data", "pose", "--out", str(folder), "--frames", "30", *renderings[folder])
        return folder

    if "data" in parts:
        for folder in renderings:
            rendered(folder)
    runs = {
        "features": (data, ["--detectors", "features"]),
        "corners": (data, ["--detectors", "corners", "--seeds", *seeds]),
        "control": (control, ["--detectors", "corners", "--seeds", *seeds]),
        "heldout": (heldout, ["--detectors", "corners", "--seeds", *seeds]),
    }
    for part, (folder, extra) in runs.items():
        if part in parts:
            out = root / part
            evaluation = ["--data", str(rendered(folder)), "--normalizations", *NORMALIZATIONS, *extra]
            alcn("pose", "eval", *evaluation, "--out", str(out), "--overwrite")
            keep(out / "table1.json", f"pose_table1_{part}", drop=("details",))
    if "middlebury" in parts:
        out = root / "middlebury"
        sets = [str(SHARED_DATA / "middlebury" / name) for name in ("templeSparseRing", "dinoSparseRing")]
        alcn(
            "pose", "eval", "--middlebury", *sets, "--normalizations", *NORMALIZATIONS, "--out", str(out), "--overwrite"
        )
        keep(out / "middlebury.json", "pose_middlebury", drop=("details",))


if __name__ == "__main__":
    run_script(main)
