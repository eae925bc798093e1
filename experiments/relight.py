"""Real-light benchmark (`alcn bench relight`): the identification, ORB/SIFT matching and homography-pose
tables of docs/results.md, on the test scenes (tuned on the training scenes) and leave-one-scene-out.

Data: ../shared/data/webcam (academic research only) and ../shared/data/psm.
Time on 2 shared cores at load 11-16 (2026-11-27), one seed: 22 min for the split, 46 min for
leave-one-scene-out (tuning per fold); more seeds add mostly evaluation time.

    python experiments/relight.py                # 1 seed (0)
    python experiments/relight.py --seeds 0 1 2  # the 3-seed protocol of the journal's older entries
    python experiments/relight.py --only leave_one_out --quick  # 12 frames, 150 patches, 12 pairs: 3x faster

Writes runs/relight/{split,leave_one_out}/relight.{md,json,png}; keeps the JSON in
docs/reports/relight_split.json and docs/reports/relight_leave_one_out.json.
"""

from __future__ import annotations

from _run import RUNS, alcn, command_line, keep


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--seeds", nargs="+", default=["0"], help="sampling seeds (default: 0)")
    parser.add_argument("--only", choices=("split", "leave_one_out"), help="run one of the two protocols")
    parser.add_argument(
        "--quick", action="store_true", help="the quick protocol: 12 frames per scene, 150 patches, 12 pairs"
    )
    args = parser.parse_args()
    quick = ["--max-frames", "12", "--patches", "150", "--max-pairs", "12"] if args.quick else []
    protocols = {"split": [], "leave_one_out": ["--leave-one-out"]}
    for name, extra in protocols.items():
        if args.only and name != args.only:
            continue
        out = RUNS / "relight" / name
        alcn("bench", "relight", "--out", str(out), "--seeds", *args.seeds, *extra, *quick)
        keep(out / "relight.json", f"relight_{name}")


if __name__ == "__main__":
    main()
