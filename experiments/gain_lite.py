"""The distilled lite model (`model="gain-lite"`) against the default it learns from, on real light: `alcn bench
relight`'s quick protocol (12 frames per scene, 150 patches, 12 pairs) over 3 seeds, no method tuned, on the test
scenes and leaving one webcam scene out; DLCN and `none` beside them.

Data: ../shared/data/webcam (academic research only) and ../shared/data/psm.

    python experiments/gain_lite.py                  # both parts, about 3 min on 2 cores
    python experiments/gain_lite.py --part split     # or: leave_one_out

Writes runs/gain_lite/{split,leave_one_out}/relight.{md,json,png}; keeps docs/reports/relight_gain_lite_<part>.json.
"""

from __future__ import annotations

from _run import RUNS, add_part_option, command_line, keep, selected_parts, short_relight

from alcn_cv.cli import SEED, run_script

METHODS = ["none", "dlcn", "alcn", "alcn:model=gain-lite"]
PARTS = {"split": [], "leave_one_out": ["--leave-one-out"]}


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--seeds", nargs="+", type=SEED, default=[0, 1, 2], help="sampling seeds (default: 0 1 2)")
    add_part_option(parser, PARTS)
    args = parser.parse_args()
    for part in selected_parts(args, PARTS):
        out = RUNS / "gain_lite" / part
        short_relight(out, METHODS, args.seeds, PARTS[part])
        keep(out / "relight.json", f"relight_gain_lite_{part}")


if __name__ == "__main__":
    run_script(main)
