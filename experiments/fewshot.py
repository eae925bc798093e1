"""Few-shot validation (`alcn bench fewshot`): a detector from one image per new object under one light,
ROC AUC under held-out lights, per seed, each ALCN against the best DoG; DoG and DLCN tuned first on a validation
draw of their own (`--tune`).

Time on 2 shared cores: about 10 min (2026-11-30; 5 min without the tuning, beside the test suite).

    python experiments/fewshot.py

Writes runs/fewshot/fewshot.{md,json,png}; keeps docs/reports/fewshot.json.
"""

from __future__ import annotations

from _run import RUNS, alcn, command_line, keep

from alcn_cv.cli import run_script

METHODS = "none,dog,dog:sigma1=1:sigma2=2,dlcn,alcn,alcn:model=gain-lite,alcn:model=lite"


def main() -> None:
    command_line(__doc__).parse_args()
    out = RUNS / "fewshot"
    alcn(
        "bench",
        "fewshot",
        "--out",
        str(out),
        "--overwrite",
        "--methods",
        METHODS,
        "--policy",
        "raw,local",
        "--seeds",
        "0",
        "1",
        "2",
        "--per-image",
        "100",
        "--epochs",
        "5",
        "--n-test",
        "1500",
        "--tune",
    )
    keep(out / "fewshot.json", "fewshot")


if __name__ == "__main__":
    run_script(main)
