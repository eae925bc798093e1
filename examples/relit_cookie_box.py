"""Track the cookie box on a synthetically relit copy of its video, with and without ALCN.

    .venv/bin/python examples/relit_cookie_box.py [--out out/cookie_box_relit]
        [--methods none alcn:model=lite:mixture=pyramid]

Each frame of ``../shared/data/cookie_box/box.mp4`` is relit (``pose.evaluate.relight``: a strong
light gradient whose side changes every 30 frames, darkening and a gamma change). For each
normalization a part model is built from the *original* video (training lighting, as in the paper)
and tracked through the relit one. The reference poses are those tracked on the original video
without normalization (green); the boxes found on the relit video are drawn in the paper's Fig. 1
colours (ALCN blue, no normalization red) in one overlay video, and side by side, one panel per
method. The share of relit frames whose pose agrees with the reference (2D projection of the
box corners within 5 px) is printed and written to ``summary.json``.

Time with the defaults (60 frames, two lights; none and the real-time ALCN): 4 min 3 s on 2 cores
at a load average of about 1-2 (389 s of CPU time), two part models built (the reference, which `none` uses,
and the ALCN one) and 60 frames tracked
by each; 100% of the 60 frames agree for both. ``--max-frames 150`` took 884 s of CPU time.
"""

from __future__ import annotations

import argparse
import json
import logging
import tempfile
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np

import alcn_cv
from alcn_cv import io
from alcn_cv.cli import run_script
from alcn_cv.shared_data import shared_data_dir
from pose import build, evaluate, track
from pose import model as part_model
from pose.parts import FeaturePartDetector
from pose.sequence import TrainingSequence, TrainingView
from pose.solver import PoseEstimate, PoseSolver, PoseTracker


def frames(video: Path, max_frames: int | None) -> Iterator[tuple[int, np.ndarray]]:
    """``(index, frame)`` of the first ``max_frames`` frames (all when ``None``)."""
    for i, (_, frame) in enumerate(io.iter_frames(video, max_frames=max_frames)):
        yield i, frame


def found(est: PoseEstimate) -> tuple[np.ndarray, np.ndarray] | None:
    """``(rvec, tvec)`` of a pose found, ``None`` for a frame lost."""
    return (est.rvec, est.tvec) if est.ok and est.rvec is not None and est.tvec is not None else None


def registered_build(
    video: Path,
    ref: part_model.PartModel,
    K: np.ndarray,
    normalization: str,
    path: Path,
    step: int = build.COOKIE_BOX["step"],
    max_frames: int | None = None,
) -> None:
    """A model on ``normalization``-normalized images of the original video, in the reference model's frame:
    the frames are registered by tracking the reference model, then triangulated with these poses fixed (every
    ``step``-th frame, as many keypoints as the reference's build: :data:`pose.build.COOKIE_BOX`)."""
    tracker, det = PoseTracker(PoseSolver(K, min_inliers=30)), FeaturePartDetector(ref, "none")
    with tempfile.TemporaryDirectory(dir=path.parent) as work:
        views, size = [], (0, 0)
        for i, frame in frames(video, max_frames):
            size = (frame.shape[1], frame.shape[0])
            est, _ = tracker.step(i, frame, det)
            pose = found(est)
            if pose is not None and i % step == 0:
                io.write_image(Path(work) / f"{i:06d}.png", frame)
                views.append(TrainingView(f"{i:06d}.png", K, None, est.R, pose[1].ravel()))
        info = {"format": "registered video", "path": str(video)}
        seq = TrainingSequence(Path(work), views, ref.units, size, info=info)
        n_features = build.COOKIE_BOX["n_features"]
        model, _ = build.build(
            seq, feature=ref.feature, n_features=n_features, normalization=normalization, work_dir=work
        )
    model.corners = ref.corners  # same object frame as the reference
    model.extra["K"] = K.tolist()
    part_model.save(model, path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--out", type=Path, default=Path("out/cookie_box_relit"), help="output folder; models there are reused"
    )
    ap.add_argument(
        "--methods",
        nargs="+",
        default=["none", "alcn:model=lite:mixture=pyramid"],
        help="normalizations (NAME[:KEY=VALUE...]; default: none and the real-time ALCN)",
    )
    ap.add_argument(
        "--data",
        type=Path,
        default=shared_data_dir() / "cookie_box",
        help="folder of box.mp4 and box.ply (default: the shared data's)",
    )
    ap.add_argument(
        "--max-frames",
        type=int,
        default=60,
        help="only the first N frames (default 60: two lights; 0: all 455); at least 60: each model is built "
        "from every 10th of them, and from the 4 views of 40 frames nothing is triangulated",
    )
    args = ap.parse_args()
    if args.max_frames < 0:
        ap.error(f"--max-frames {args.max_frames}: a number of frames, 0 (all) or at least 60")
    if 0 < args.max_frames < 60:
        ap.error(f"--max-frames {args.max_frames}: at least 60 (a model needs 6 views, one every 10 frames)")
    args.max_frames = args.max_frames or None
    for spec in args.methods:  # a bad spec stops here, not after the reference model's minutes of building
        alcn_cv.create(spec)
    logging.basicConfig(level=logging.INFO, format="[%(asctime)s %(name)s] %(message)s")
    args.out.mkdir(parents=True, exist_ok=True)
    video = args.data / "box.mp4"
    ref_path = args.out / "model_none.npz"
    if ref_path.is_file():
        logging.info("none: the reference model %s, built before (delete it to rebuild)", ref_path)
    else:  # the reference model: built from the video alone (see track_cookie_box.py)
        # the .ply and cameras figure of a model deleted to rebuild it are replaced with it
        build.main(video, ref_path, box_ply=args.data / "box.ply", overwrite=True, **build.COOKIE_BOX)
    ref = part_model.load(ref_path)
    K = np.asarray(ref.extra.get("K", build.COOKIE_BOX["K"]))  # the focal length refined when building
    models = {"none": ref}
    for name in args.methods:
        path = args.out / f"model_{evaluate.file_stem(name)}.npz"
        if name != "none" and not path.is_file():
            registered_build(video, ref, K, name, path, max_frames=args.max_frames)
        elif name != "none":
            logging.info("%s: the model %s, built before (delete it to rebuild)", name, path)
        if name != "none":
            models[name] = part_model.load(path)
    detectors = {n: FeaturePartDetector(models[n], n) for n in args.methods}
    ref_det = FeaturePartDetector(ref, "none")
    trackers = {n: PoseTracker(PoseSolver(K)) for n in args.methods}
    ref_tracker = PoseTracker(PoseSolver(K))
    agree: dict[str, list[bool]] = {n: [] for n in args.methods}
    total = io.count_frames(video, max_frames=args.max_frames)
    relit_frames = io.frame_progress(frames(video, args.max_frames), total, desc="track the relit video")
    # as context managers: a run stopped midway leaves no unfinished video behind
    with (
        track.OverlayWriter(args.out / "relit_overlay.mp4") as both,
        track.OverlayWriter(args.out / "relit_side_by_side.mp4") as side,
    ):
        for i, frame in relit_frames:
            name = str(i)
            relit = evaluate.relight(frame, seed=i // 30)
            c = ref_det.detect(frame)
            gt = ref_tracker.update(i, c.object_points, c.image_points)
            gt_pose = found(gt)
            vis = relit.copy()
            panels = []
            if gt_pose is not None:
                track.draw_box(vis, ref.corners, *gt_pose, K, track.color_for("gt"))
            for n in args.methods:
                c = detectors[n].detect(relit)
                est = trackers[n].update(i, c.object_points, c.image_points)
                pose = found(est)
                panel = relit.copy()
                if pose is not None:
                    for img in (vis, panel):
                        track.draw_box(img, models[n].corners, *pose, K, track.color_for(n))
                if gt_pose is not None:
                    agree[n].append(
                        pose is not None
                        and evaluate.projection_error(models[n].corners, est.R, pose[1], gt.R, gt_pose[1], K)
                        < evaluate.PROJ_PX
                    )
                panels.append(cv2.putText(panel, n, (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2))
            both.write(name, vis)
            side.write(name, np.hstack(panels))
            if i % 90 == 0:
                io.write_image(args.out / f"side_by_side_{i:04d}.png", np.hstack(panels))
    summary = {
        n: {"agreeing_frames_percent": 100.0 * float(np.mean(a)) if a else None, "reference_frames": len(a)}
        for n, a in agree.items()
    }
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1))
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    run_script(main)  # as alcn runs a command: FFmpeg's stream notes kept off the terminal, bad input in one line
