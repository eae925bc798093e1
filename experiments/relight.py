"""Real-light benchmark (`alcn bench relight`): the identification, ORB/SIFT matching and homography-pose
tables of docs/results.md, on the test scenes (tuned on the training scenes) and leave-one-scene-out.

Data: ../shared/data/webcam (academic research only) and ../shared/data/psm.
Time on 2 shared cores at load 11-16 (2026-11-27), one seed: 22 min for the split, 46 min for
leave-one-scene-out (tuning per fold); more seeds add mostly evaluation time.

    python experiments/relight.py --part split                  # the published split: 3 seeds (0 1 2)
    python experiments/relight.py --part leave_one_out --quick  # the published leave-one-scene-out
    python experiments/relight.py --seeds 0                     # both protocols in full, one seed

--quick: `alcn bench relight`'s quick protocol (fewer frames, patches and pairs; about 3 times faster).

Writes runs/relight/{split,leave_one_out}/relight.{md,json,png}; keeps the JSON in
docs/reports/relight_split.json and docs/reports/relight_leave_one_out.json.
"""

from __future__ import annotations

from _run import RUNS, add_part_option, alcn, command_line, keep, quick_protocol, selected_parts

from alcn_cv.cli import SEED, run_script

PROTOCOLS = {"split": [], "leave_one_out": ["--leave-one-out"]}


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--seeds", nargs="+", type=SEED, default=[0, 1, 2], help="sampling seeds (default: 0 1 2)")
    add_part_option(parser, PROTOCOLS)
    parser.add_argument(
        "--quick",
        action="store_true",
        help="`alcn bench relight`'s quick protocol (`--conf quick`, spelled out in the recorded command)",
    )
    args = parser.parse_args()
    quick = quick_protocol() if args.quick else []
    seeds = [str(seed) for seed in args.seeds]
    for name in selected_parts(args, PROTOCOLS):
        out = RUNS / "relight" / name
        alcn("bench", "relight", "--out", str(out), "--overwrite", "--seeds", *seeds, *PROTOCOLS[name], *quick)
        keep(out / "relight.json", f"relight_{name}")


if __name__ == "__main__":
    run_script(main)
