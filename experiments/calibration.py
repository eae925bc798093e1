"""Calibration and the cookie box: the camera from OpenCV's chessboard photographs (against OpenCV's own
reference, RMS 0.409 px, fx 536.07), then the cookie box's part model built from its video and tracked
in every frame (the box's fitted size against its true 18.9 x 25.8 x 7.5 cm, the frames posed).

Data: ../shared/data/chessboard and ../shared/data/cookie_box (Apache-2.0, OpenCV's samples).
Time: under 2 min on 2 quiet cores (tracking 16 fps); several times that on a loaded machine.

    python experiments/calibration.py

Writes runs/calibration/{calib,cookie_box}/ and runs/calibration/calibration.json (the numbers of both);
keeps docs/reports/calibration.json.
"""

from __future__ import annotations

import json

from _run import RUNS, SHARED_DATA, alcn, command_line, keep

from alcn_cv.cli import run_script


def main() -> None:
    command_line(__doc__).parse_args()
    from alcn_cv.report import machine
    from calib.camera import load_calibration
    from pose.model import load as load_part_model
    from pose.track import SUMMARY_PATHS

    out = RUNS / "calibration"
    calib, box = out / "calib", out / "cookie_box"
    calib_argv = [
        "calib",
        "camera",
        "--images",
        str(SHARED_DATA / "chessboard"),
        "--board",
        "chessboard",
        "--cols",
        "9",
        "--rows",
        "6",
        "--square",
        "25",
        "--out",
        str(calib),
    ]
    build_argv = [
        "pose",
        "build",
        str(SHARED_DATA / "cookie_box" / "box.mp4"),
        str(box / "model.npz"),
        "--box-ply",
        str(SHARED_DATA / "cookie_box" / "box.ply"),
        "--conf",
        "cookie-box",  # pose.build.CONFS
    ]
    track_argv = [
        "pose",
        "track",
        str(box / "model.npz"),
        str(SHARED_DATA / "cookie_box" / "box.mp4"),
        str(box / "poses.json"),
    ]
    for argv in (calib_argv, build_argv, track_argv):
        alcn(*argv, "--overwrite")  # a rerun replaces the earlier run's files; the report records the commands
    camera = load_calibration(calib / "camera.yaml")
    model = load_part_model(box / "model.npz")
    track = json.loads((box / "poses_info.json").read_text(encoding="utf-8"))
    report = {
        "benchmark": "calibration",
        "commands": [" ".join(["alcn", *a]) for a in (calib_argv, build_argv, track_argv)],
        "machine": machine(),
        "calibration": {
            "rms_px": camera.rms,
            "fx": float(camera.K[0, 0]),
            "fy": float(camera.K[1, 1]),
            "cx": float(camera.K[0, 2]),
            "cy": float(camera.K[1, 2]),
        },
        "cookie_box": {
            "registered_images": model.extra["registered_images"],
            "refined_fx": model.extra["K"][0][0],
            "box_size_error_percent": 100 * model.box_fit["mean_abs_relative_size_error"],
        },
        # the paths of this machine's run stay out of the published report (the commands name the files)
        "tracking": {k: v for k, v in track["summary"].items() if k not in SUMMARY_PATHS},
    }
    (out / "calibration.json").write_text(json.dumps(report, indent=1), encoding="utf-8")
    keep(out / "calibration.json", "calibration")


if __name__ == "__main__":
    run_script(main)
