"""Speed (`alcn bench speed`): the speed table of docs/results.md, every ALCN configuration against a raw
OpenCV DoG, CLAHE and none on the same frames, with the targets table.

Time on 2 shared cores: about 25 minutes for the full bench (640x480, 1280x800, 1920x1080, gray and BGR,
the video test); 17 minutes for the current table at load 15 (two sizes, no video test; 2026-11-27); under a minute with
--conf quick (the bench's tiny preset: a smoke test, its ratios mean little).

    python experiments/speed.py --sizes 640x480,1280x800 --video-frames 0 --budget 3   # the current table
    python experiments/speed.py                                                          # the full bench

Any option is passed to `alcn bench speed`, but --keep (a run with other options than the published report's
replaces docs/reports/speed.json only with it) and --out, which this script sets: it writes
runs/speed/speed.{md,json,png}.
"""

from __future__ import annotations

import sys

from _run import KEEP, RUNS, alcn, keep

from alcn_cv.cli import run_script


def main() -> None:
    if {"-h", "--help"} & set(sys.argv[1:]):
        print(f"usage: speed.py [OPTION ...] (the options of `alcn bench speed`)\n\n{__doc__}")
        return
    if any(a == "--out" or a.startswith("--out=") for a in sys.argv[1:]):
        print("speed.py: error: --out is the script's: it writes runs/speed/ (and keeps its report)", file=sys.stderr)
        sys.exit(2)
    out = RUNS / "speed"
    alcn("bench", "speed", "--out", str(out), "--overwrite", *(a for a in sys.argv[1:] if a != KEEP))
    keep(out / "speed.json", "speed")


if __name__ == "__main__":
    run_script(main)
