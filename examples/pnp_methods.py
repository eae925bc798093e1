"""Measure every RANSAC variant of pose.solver (``pose.solver.METHODS``) on the first frames of a video.

    .venv/bin/python examples/pnp_methods.py MODEL.npz VIDEO [--K FX FY CX CY] [--normalization SPEC]
        [--max-frames 40]

The camera is the one stored in the model (``alcn pose build`` stores it), unless --K is given; the
normalization before the features is the one the model was built after (as ``alcn pose track``), unless
--normalization is given. The video is checked before any work.

Features are detected once per frame; then for each method of ``pose.solver.METHODS`` the frames
are solved independently (no prior) and as a tracked sequence (previous pose as prior), by a
``pose.solver.PoseSolver`` with its defaults but the method. Printed per method: time per frame (ms), frames
with a pose, mean inliers, mean reprojection error (px), and the median frame-to-frame jump of the
translation (model units; lower = steadier).

On the model ``examples/track_cookie_box.py`` builds (``OUT/cookie_box_model.npz``) and the first 40 frames of
the cookie box, the methods are not told apart: each posed 40 of 40 frames, with and without the prior, with the
same mean inliers (2060.5-2060.6), reprojection error (1.42 px) and jump (0.040 cm without the prior, 0.037 cm
with it); 49-134 ms per frame, ``usac_default`` 59 ms without the prior and 52 ms with it, not the fastest
(timings on a 2-core machine shared with other jobs, which vary from run to run). With matches that many and that
clean, any method finds the pose; the default (``pose.solver``'s docstring says why) matters where they are few
and noisy.

Time with the defaults: 1 min 38 s on 2 cores at a load average of about 2 (150 s of CPU time); it grows
linearly with --max-frames.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from tqdm import tqdm

from alcn_cv import io
from alcn_cv.cli import run_script
from alcn_cv.enhance.registry import same_method
from pose import model as part_model
from pose.parts import FeaturePartDetector
from pose.solver import METHODS, PoseEstimate, PoseSolver, PoseTracker, camera_matrix
from pose.track import camera_matrix_for


def translations(results: list[PoseEstimate]) -> np.ndarray:
    """``(N, 3)``: each frame's translation, NaN where no pose was found."""
    return np.array([r.tvec.ravel() if r.ok and r.tvec is not None else [np.nan] * 3 for r in results])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("model", help="part model (.npz) of the box: `alcn pose build`, examples/track_cookie_box.py")
    ap.add_argument("video", help="video of the box")
    ap.add_argument(
        "--K",
        nargs=4,
        type=float,
        metavar=("FX", "FY", "CX", "CY"),
        help="intrinsics (default: the camera stored in the model)",
    )
    ap.add_argument(
        "--normalization",
        help="NAME[:KEY=VALUE...] (default: the one the model was built after, as `alcn pose track` uses)",
    )
    ap.add_argument("--max-frames", type=int, default=40, help="the first N frames (default 40)")
    args = ap.parse_args()
    if args.max_frames < 1:
        ap.error(f"--max-frames {args.max_frames}: at least 1")
    model = part_model.load(args.model)
    K = camera_matrix_for(model.extra.get("K"), None if args.K is None else camera_matrix(*args.K), args.model)
    normalization = args.normalization or model.normalization
    if not same_method(normalization, model.normalization):  # measured, but the descriptors may not match
        print(f"note: {args.model} was built after {model.normalization!r}, the features after {normalization!r}")
    det = FeaturePartDetector(model, normalization)
    # opened before the bar starts: a missing or unreadable video ends in its one line, not after an empty bar
    with io.FrameReader(args.video, max_frames=args.max_frames) as reader:
        total = io.count_frames(args.video, max_frames=args.max_frames)
        frames = io.frame_progress(reader, total, desc="features")
        corr = [det.detect(frame) for _, frame in frames]
    runs = [(name, use_prior) for name in sorted(METHODS) for use_prior in (False, True)]
    # the rows are written above the bar (tqdm.write), the bar counts the solved frames of every run
    bar = tqdm(total=len(runs) * len(corr), desc="solve", unit="frame")
    bar.write(f"{'method':18s} {'prior':5s} {'ms':>6s} {'posed':>9s} {'inliers':>8s} {'err px':>7s} {'jump':>7s}")
    for name, use_prior in runs:
        solver = PoseSolver(K, method=name)
        tracker = PoseTracker(solver)
        res, seconds = [], 0.0
        for i, c in enumerate(corr):
            t0 = time.perf_counter()  # the solver's time only, not the bar's
            res.append(
                tracker.update(i, c.object_points, c.image_points)
                if use_prior
                else solver.solve(c.object_points, c.image_points)
            )
            seconds += time.perf_counter() - t0
            bar.update()
        ms = 1e3 * seconds / len(corr)
        ok = [r for r in res if r.ok]
        t = translations(res)
        jump = np.nanmedian(np.linalg.norm(np.diff(t, axis=0), axis=1)) if len(ok) > 1 else np.nan
        bar.write(
            f"{name:18s} {use_prior!s:5s} {ms:6.2f} {len(ok):4d}/{len(res):4d} "
            f"{np.mean([len(r.inliers) for r in ok]) if ok else 0:8.1f} "
            f"{np.mean([r.reprojection_error for r in ok]) if ok else np.nan:7.2f} {jump:7.3f}"
        )
    bar.close()


if __name__ == "__main__":
    run_script(main)  # as alcn runs a command: FFmpeg's stream notes kept off the terminal, bad input in one line
