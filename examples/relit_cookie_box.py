"""Track the cookie box on a synthetically relit copy of its video, with and without ALCN.

    .venv/bin/python examples/relit_cookie_box.py [--out out/cookie_box_relit]
        [--methods none alcn:model=lite:mixture=pyramid] [--max-frames 60]

Each frame of ``../shared/data/cookie_box/box.mp4`` is relit (``pose.evaluate.relight``: a strong
light gradient whose side changes every 30 frames, darkening and a gamma change).

A reference part model is built from every 10th frame of the whole original video, as
``examples/track_cookie_box.py`` builds it (``OUT/reference_model.npz``). It serves only to register the frames and
to give the reference poses; no method tracks with it. For each normalization of ``--methods``, ``none`` included,
a part model is built from the *original* video's first ``--max-frames`` frames (training lighting, as
in the paper): the reference model's poses register them, and every 10th frame is triangulated with its pose fixed
(``OUT/model_<method>.npz``). Every method's model thus comes from the same views, in the reference model's
object frame.

Each model is then tracked through the relit frames, and the reference model through the original frames, as
``alcn pose track`` tracks (``pose.track.open_tracker``: a search around the pose predicted from the previous frames,
the whole frame when that finds none, the pose verified). The reference poses are drawn in green, the boxes found
on the relit video in the paper's Fig. 1 colours (ALCN blue, no normalization red) in one overlay video, and side by
side, one panel per method. The share of the frames with a reference pose whose relit pose agrees with it (2D
projection of the box corners within 5 px) is printed and written to ``summary.json``.

Time with the defaults (60 frames, two lights; none and the real-time ALCN) on a 2-core AMD EPYC VM at a load
average of about 1.4-2: 2 min 4 s (142 s of CPU time), three part models built (the reference, about 90 s of it;
none's, 957 points, and the real-time ALCN's, 266 points, from the same 6 views) and the 60 frames tracked by the
reference and by each method at 0.2 s a frame for the three; 100% of the 60 frames agree for both methods.
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
from pose.sequence import TrainingSequence, TrainingView
from pose.solver import PoseEstimate

#: Inliers a reference pose needs to register a frame for a build: more than tracking needs
#: (:data:`pose.track.MIN_INLIERS`), as a wrong pose there would misplace every point triangulated from the frame.
REGISTRATION_MIN_INLIERS = 30


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
    """Write to ``path`` a model on ``normalization``-normalized images of the original video, in the reference
    model's frame: the first ``max_frames`` frames (all when ``None``) are registered by tracking the reference
    model ``ref`` with camera ``K`` as ``alcn pose track`` does (a pose needs :data:`REGISTRATION_MIN_INLIERS`
    inliers), then every ``step``-th frame registered is triangulated with its pose fixed (as many keypoints as
    the reference's build: :data:`pose.build.COOKIE_BOX`). The model records the frames it was built from in
    ``extra["registered_frames"]`` (:func:`built_from`)."""
    reference = track.open_tracker(ref, K, min_inliers=REGISTRATION_MIN_INLIERS)
    with tempfile.TemporaryDirectory(dir=path.parent) as work:
        views, size = [], (0, 0)
        for i, frame in frames(video, max_frames):
            size = (frame.shape[1], frame.shape[0])
            est = reference.step(frame)
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
    model.extra["registered_frames"] = {"max_frames": max_frames, "step": step}
    part_model.save(model, path)


def built_from(model: part_model.PartModel) -> dict | None:
    """The frames :func:`registered_build` built ``model`` from (``{"max_frames", "step"}``), ``None`` for a model
    it did not build (the reference model of an earlier run under a method's file name, say)."""
    return model.extra.get("registered_frames")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--out",
        type=Path,
        default=Path("out/cookie_box_relit"),
        help="output folder; models there are reused (the methods' when built from the same frames)",
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
        help="track the first N frames (default 60: two lights; 0: all 455), and build each method's model, none's "
        "included, from every 10th of them that the reference model registers (6 views of 60 frames; from the 4 "
        "views of 40 frames nothing is triangulated, hence at least 60); the reference model is built from every "
        "10th frame of the whole video",
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
    ref_path = args.out / "reference_model.npz"
    if ref_path.is_file():
        logging.info("the reference model %s, built before (delete it to rebuild)", ref_path)
    else:  # built from the video alone (see track_cookie_box.py)
        # the .ply and cameras figure of a model deleted to rebuild it are replaced with it
        build.main(video, ref_path, box_ply=args.data / "box.ply", overwrite=True, **build.COOKIE_BOX)
    ref = part_model.load(ref_path)
    K = np.asarray(ref.extra.get("K", build.COOKIE_BOX["K"]))  # the focal length refined when building
    wanted = {"max_frames": args.max_frames, "step": build.COOKIE_BOX["step"]}
    models = {}
    for name in args.methods:
        path = args.out / f"model_{evaluate.file_stem(name)}.npz"
        model = part_model.load(path) if path.is_file() else None
        if model is not None and built_from(model) == wanted:
            logging.info("%s: the model %s, built before from the same frames (delete it to rebuild)", name, path)
        else:  # absent, or built from other frames: the methods' models are compared only when built alike
            registered_build(video, ref, K, name, path, max_frames=args.max_frames)
            model = part_model.load(path)
        models[name] = model
    # tracked as `alcn pose track` tracks, each model after the normalization it was built after
    reference = track.open_tracker(ref, K)
    boxes = {n: track.open_tracker(models[n], K) for n in args.methods}
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
            gt = reference.step(frame)
            gt_pose = found(gt)
            vis = relit.copy()
            panels = []
            if gt_pose is not None:
                track.draw_box(vis, ref.corners, *gt_pose, K, track.color_for("gt"))
            for n, box in boxes.items():
                est = box.step(relit)
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
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1), encoding="utf-8")
    print(json.dumps(summary, indent=1))


if __name__ == "__main__":
    run_script(main)  # as alcn runs a command: FFmpeg's stream notes kept off the terminal, bad input in one line
