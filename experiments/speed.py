"""Speed (`alcn bench speed`): the speed table of docs/results.md, every ALCN configuration against a raw
OpenCV DoG, CLAHE and none on the same frames, with the targets table.

Time on 2 shared cores: under a minute with --quick (tiny frames, few repeats: the current table),
about 25 minutes for the full bench (640x480, 1280x800, 1920x1080, gray and BGR, the video test).

    python experiments/speed.py --quick   # the table in docs/results.md now
    python experiments/speed.py           # the full bench (the numbers of the journal)

Writes runs/speed/speed.{md,json,png}; keeps docs/reports/speed.json.
"""

from __future__ import annotations

import argparse

from _run import RUNS, alcn, keep


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="the bench's quick preset")
    args = parser.parse_args()
    out = RUNS / "speed"
    alcn("bench", "speed", "--out", str(out), *(["--quick"] if args.quick else []))
    keep(out / "speed.json", "speed")


if __name__ == "__main__":
    main()
