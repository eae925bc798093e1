"""Build a part model of the cookie box from its video and track it.

    .venv/bin/python examples/track_cookie_box.py [--out out/cookie_box] [--normalization none]

Input: ``../shared/data/cookie_box/box.mp4`` (455 frames, 640x480, a hand-held box in front of a
static camera), ``box.ply`` (the cuboid, 18.9 x 25.8 x 7.5 cm) and the intrinsics of OpenCV's
real-time pose tutorial (fx = 640*55/22.3, fy = 480*55/14.9, cx = 320, cy = 240).

1. ``alcn pose build`` on the unregistered video with the cookie box's preset (``alcn pose build --conf cookie-box``,
   ``pose.build.COOKIE_BOX``; docs/pose.md walks through the same commands):
   every 10th frame, features kept on what moves (static camera), pycolmap incremental reconstruction with
   the focal length refined by the bundle adjustment (to fx 651 px, fy 648 px; with the tutorial's fx = 1578 px
   held fixed, ``--no-refine-focal``, the fit is 3.8% off instead of 2.7% and ``alcn pose overlay-error`` puts the
   drawn box 7.5 px from the image's edges instead of 6.1 on every 10th frame), open3d box fit (frame from the lid,
   the best-seen face) scaled to box.ply's size.
2. ``alcn pose track`` on every frame with the refined intrinsics (stored in the model): poses as JSON and an overlay
   video with the box drawn.
3. A contact sheet PNG of a few overlay frames, to check that the box sits on the object.

Time: 180 s of CPU time (user) on 2 cores; 22 minutes wall under nice at a load average of 15 (a shared
2-core machine); 455 of 455 frames tracked.
"""

from __future__ import annotations

import argparse
import logging
from pathlib import Path

import cv2
import numpy as np

from alcn_cv import io
from alcn_cv.cli import run_script
from alcn_cv.enhance.registry import create, same_method
from alcn_cv.errors import DatasetError
from alcn_cv.shared_data import shared_data_dir
from pose import build, track
from pose import model as part_model


def contact_sheet(video: Path, out: Path, frames: tuple[int, ...] = (0, 60, 120, 180, 240, 300, 360, 420)) -> Path:
    """Write ``out``: the ``frames`` of ``video`` that it has, at 320x240 and numbered, four to a row.

    Raises:
        InputError: ``video`` cannot be opened or has no frame (:func:`alcn_cv.io.iter_frames`).
        DatasetError: ``video`` has none of ``frames``.
        OSError: ``out`` cannot be written.
    """
    tiles = [
        cv2.putText(cv2.resize(img, (320, 240)), f"#{i}", (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.7, (255, 255, 255), 2)
        for i, (_, img) in enumerate(io.iter_frames(video, max_frames=max(frames) + 1))
        if i in frames
    ]
    if not tiles:  # a video shorter than the first of frames
        raise DatasetError(f"{video}: none of the frames {', '.join(map(str, frames))}; no contact sheet")
    while len(tiles) % 4:  # the last row filled with black
        tiles.append(np.zeros_like(tiles[0]))
    rows = [np.hstack(tiles[k : k + 4]) for k in range(0, len(tiles), 4)]
    return io.write_image(out, np.vstack(rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", type=Path, default=Path("out/cookie_box"), help="output folder (default out/cookie_box)")
    ap.add_argument(
        "--normalization",
        default="none",
        help="normalization before the features, NAME[:KEY=VALUE...] (alcn_cv.available(); the real-time "
        "ALCN: alcn:model=lite:mixture=pyramid)",
    )
    ap.add_argument(
        "--data",
        type=Path,
        default=shared_data_dir() / "cookie_box",
        help="folder of OpenCV's cookie-box sample, box.mp4 and box.ply (default: the shared data's); the preset's "
        "intrinsics are for its 640x480 frames, and another video is refused",
    )
    args = ap.parse_args()
    logging.basicConfig(level=logging.INFO, format="[%(asctime)s %(name)s] %(message)s")
    video = args.data / "box.mp4"
    # checked before the output folder is made: a typo leaves no empty folder behind
    create(args.normalization)
    if not (video.is_file() and (args.data / "box.ply").is_file()):
        raise DatasetError(f"{video}: no such video or no box.ply beside it (--data: OpenCV's cookie-box sample)")
    args.out.mkdir(parents=True, exist_ok=True)
    model_path = args.out / "cookie_box_model.npz"
    # a model of an earlier run is reused when it was built after the same normalization
    if not model_path.is_file() or not same_method(part_model.load(model_path).normalization, args.normalization):
        build.main(
            video,
            model_path,
            box_ply=args.data / "box.ply",
            normalization=args.normalization,
            overwrite=True,  # an earlier run's model, built after another normalization
            **build.COOKIE_BOX,
        )
    K_track, K = np.asarray(part_model.load(model_path).extra["K"]), build.COOKIE_BOX["K"]
    print(
        f"intrinsics used for tracking (stored in the model): fx {K_track[0, 0]:.1f} fy {K_track[1, 1]:.1f} "
        f"(tutorial: {K[0, 0]:.1f} {K[1, 1]:.1f})"
    )
    summary = track.main(
        model_path,
        video,
        args.out / "poses.json",
        normalization=args.normalization,
        overlay=args.out / "overlay.mp4",
        overwrite=True,  # the poses of an earlier run into --out
    )
    sheet = contact_sheet(args.out / "overlay.mp4", args.out / "overlay_sheet.png")
    print(
        f"tracked {summary['tracked']}/{summary['frames']} frames at {summary['fps']:.1f} fps; "
        f"overlay {args.out / 'overlay.mp4'}, sheet {sheet}, model {model_path} (+ _cameras.png)"
    )


if __name__ == "__main__":
    run_script(main)  # as alcn runs a command: FFmpeg's stream notes kept off the terminal, bad input in one line
