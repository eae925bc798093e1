"""Does learning matter? The shipped default against its own untrained start and against the same recipe trained
on the webcam scenes (academic research only), beside the tuned hand-made methods: `alcn bench relight`'s quick
protocol (12 frames per scene, 150 patches, 12 pairs) over 3 seeds, on the test scenes (tuned on the training ones).

The untrained start is the default's network as the preset initialises it (seed 0): the DoG G1 - G2, the divisive
normalization and the equalization, no learning. The webcam variant is `alcn train-real-light --conf gain --set
"scenes=['courbevoie','frankfurt','panorama']" --set relit=0` (the default's recipe on real light changes).

    python experiments/learning.py      # about 15 min on 2 cores

Writes runs/learning/{untrained.npz,webcam/,bench/}; keeps docs/reports/relight_learning.json.
"""

from __future__ import annotations

from _run import RUNS, alcn, command_line, keep, quick_protocol, untrained_start

from alcn_cv.cli import SEED, run_script
from alcn_cv.runtime import MODELS

BASELINES = ["none", "clahe", "dog", "dlcn", "tantriggs"]


def main() -> None:
    parser = command_line(__doc__)
    parser.add_argument("--seeds", nargs="+", type=SEED, default=[0, 1, 2], help="sampling seeds (default: 0 1 2)")
    args = parser.parse_args()
    out = RUNS / "learning"
    out.mkdir(parents=True, exist_ok=True)
    untrained = untrained_start(MODELS["gain"], out / "untrained.npz", "the default's start")
    webcam = out / "webcam"
    scenes = "scenes=['courbevoie','frankfurt','panorama']"
    alcn("train-real-light", "--conf", "gain", "--set", scenes, "--set", "relit=0", "--out", str(webcam), "--overwrite")
    methods = [*BASELINES, "alcn", f"alcn:weights={untrained}", f"alcn:weights={webcam / 'gain_normalizer.npz'}"]
    bench = out / "bench"
    seeds = [str(seed) for seed in args.seeds]
    alcn(
        "bench",
        "relight",
        "--out",
        str(bench),
        "--overwrite",
        "--methods",
        ",".join(methods),
        "--seeds",
        *seeds,
        *quick_protocol(),
    )
    keep(bench / "relight.json", "relight_learning")


if __name__ == "__main__":
    run_script(main)
