"""Rendered detection (`alcn bench detect`): a detector learnt from 1 and 10 images per object after each
normalization, mean AUC over 3 objects and 3 seeds (Rad et al. 2017, Sec. 4.3, Fig. 5), at the reduced
settings the journal's entries used on the shared 2-core machine; DoG and DLCN tuned first by detection on the
data's validation images (``--tune``).

Time on 2 shared cores (2026-11-30, another job running beside it): 2 min to render the data, then 22 min for the
tuning and the methods below.

    python experiments/detect.py

Writes runs/detect/data (from `alcn data detect`) and runs/detect/bench/detect.{md,json} and the PR
curves; keeps docs/reports/detect.json.
"""

from __future__ import annotations

from _run import RUNS, alcn, command_line, keep

from alcn_cv.cli import run_script

METHODS = "none,dog,dlcn,tantriggs,alcn,alcn:model=gain-lite,alcn:model=lite"


def main() -> None:
    command_line(__doc__).parse_args()
    data, out = RUNS / "detect" / "data", RUNS / "detect" / "bench"
    if not (data / "manifest.json").exists():
        alcn("data", "detect", "--out", str(data))
    alcn(
        "bench",
        "detect",
        "--data",
        str(data),
        "--out",
        str(out),
        "--overwrite",
        "--tune",
        "--methods",
        METHODS,
        "--real-images",
        "1,10",
        "--policy",
        "raw,local",
        "--positives",
        "100",
        "--epochs",
        "4",
        "--seeds",
        "0,1,2",
        "--max-test-images",
        "16",
    )
    keep(out / "detect.json", "detect")


if __name__ == "__main__":
    run_script(main)
