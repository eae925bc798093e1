"""ALCN in front of ORB or SIFT in an OpenCV app: match two frames of a video, one of them under another light.

    .venv/bin/python examples/feature_matching.py [--video ../shared/data/cookie_box/box.mp4] [--feature ORB]

Frame 0 of the video is matched with frame ``--second`` (default 20), which is first relit here: darkened to a
quarter, a light gradient across it, a gamma of 1.6 and the 8-bit rounding of a dark frame. Each normalization of
``--methods`` (``alcn_cv.create`` specs) runs before the features (1000 keypoints) on both frames; the matches pass
Lowe's ratio test (0.8) and a RANSAC homography (5 px), whose inliers, the matches that agree, are printed for each
normalization and drawn side by side in ``OUT/matches.png`` (one row per normalization). Only OpenCV and the runtime
are needed (``pip install .``); a second or two on 2 cores.

On the cookie box, frames 0 and 20 (60), matches that agree (``--methods none clahe tantriggs alcn``; the same
on every run): SIFT none 291 (201), CLAHE 416 (300), Tan-Triggs 397 (293), ALCN 496 (354); ORB none 319 (257),
CLAHE 404 (297), Tan-Triggs 225 (136), ALCN 231 (142). ORB orients each keypoint by the intensity centroid of its
patch, which a global light change keeps and a band-pass output does not (docs/journal.md, 2026-11-27 (night)):
with ORB, ALCN and Tan-Triggs agree on fewer matches than no normalization, and under such a change CLAHE is the
stronger choice.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

import alcn_cv
from alcn_cv.cli import run_script
from alcn_cv.errors import ALCNError
from alcn_cv.io import iter_frames, write_image
from alcn_cv.shared_data import shared_data_dir


def relight(frame: np.ndarray) -> np.ndarray:
    """The frame under another light: a quarter of the exposure, brighter to the right, gamma 1.6, rounded."""
    unit = frame.astype(np.float32) / 255
    gradient = np.linspace(0.1, 0.4, frame.shape[1], dtype=np.float32)[None, :, None]
    return np.clip(255 * (unit * gradient) ** 1.6 * 4, 0, 255).round().astype(np.uint8)


def match(
    first: np.ndarray, second: np.ndarray, feature: cv2.Feature2D
) -> tuple[Sequence[cv2.KeyPoint], Sequence[cv2.KeyPoint], list[cv2.DMatch]]:
    """Keypoints of both images and the ratio-tested matches that agree with a RANSAC homography (none when
    RANSAC finds no homography)."""
    kp1, des1 = feature.detectAndCompute(first, None)
    kp2, des2 = feature.detectAndCompute(second, None)
    if des1 is None or des2 is None:
        return kp1, kp2, []
    norm = cv2.NORM_HAMMING if des1.dtype == np.uint8 else cv2.NORM_L2
    pairs = cv2.BFMatcher(norm).knnMatch(des1, des2, k=2)
    good = [p[0] for p in pairs if len(p) == 2 and p[0].distance < 0.8 * p[1].distance]
    if len(good) < 4:
        return kp1, kp2, []
    src = np.array([kp1[m.queryIdx].pt for m in good], np.float32)
    dst = np.array([kp2[m.trainIdx].pt for m in good], np.float32)
    _, inliers = cv2.findHomography(src, dst, cv2.RANSAC, 5.0)
    if inliers is None:  # no homography (degenerate points, e.g. all on a line): no match agrees
        return kp1, kp2, []
    return kp1, kp2, [m for m, keep in zip(good, inliers.ravel()) if keep]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--video", type=Path, default=shared_data_dir() / "cookie_box" / "box.mp4", help="a video file")
    ap.add_argument("--second", type=int, default=20, help="the frame matched with frame 0 (default 20)")
    ap.add_argument(
        "--methods", nargs="+", default=["none", "clahe", "alcn"], help="normalizations (default: %(default)s)"
    )
    ap.add_argument("--feature", choices=("SIFT", "ORB"), default="SIFT", help="the features (default SIFT)")
    ap.add_argument("--out", type=Path, default=Path("out/matching"), help="output folder (default out/matching)")
    args = ap.parse_args()
    if args.second < 0:
        ap.error(f"--second {args.second}: a frame number, 0 or more")
    frames = [frame for _, frame in iter_frames(args.video, max_frames=args.second + 1)]
    if len(frames) <= args.second:
        raise ALCNError(f"{args.video} has {len(frames)} frames, fewer than --second {args.second} + 1")
    first, second = frames[0], relight(frames[args.second])
    feature = cv2.ORB.create(1000) if args.feature == "ORB" else cv2.SIFT.create(1000)
    normalizations = {spec: alcn_cv.create(spec) for spec in args.methods}  # a bad spec stops before the work
    rows = []
    for spec, normalization in normalizations.items():
        a, b = normalization.apply(first), normalization.apply(second)
        kp1, kp2, agreeing = match(a, b, feature)
        print(f"{spec:>12}: {len(kp1)} and {len(kp2)} keypoints, {len(agreeing)} matches that agree")
        drawn = cv2.drawMatches(a, kp1, b, kp2, agreeing, None, matchColor=(0, 255, 0), flags=2)
        rows.append(cv2.putText(drawn, f"{spec}: {len(agreeing)}", (10, 30), 0, 1.0, (0, 0, 255), 2))
    write_image(args.out / "matches.png", np.vstack(rows))
    print(f"wrote {args.out / 'matches.png'}")


if __name__ == "__main__":
    run_script(main)  # as alcn runs a command: FFmpeg's stream notes kept off the terminal, bad input in one line
