"""Pose on real light (`alcn pose planar`): a textured planar target of each webcam scene's reference
frame posed in every other frame of the fixed camera with the box's pipeline, % within 5 px; with the
500 strongest SIFT keypoints per frame, and with the corner CNN trained on the reference frame alone.

Data: ../shared/data/webcam (academic research only; cite TILDE and AMOS).
The SIFT part is in docs/results.md; the corner part is not (hours): the journal keeps its numbers as measured.
Time on 2 shared cores: the SIFT rows about 15 min; the corner rows about 8 min per network (4 scenes
x each normalization).

    python experiments/pose_planar.py                  # both
    python experiments/pose_planar.py --part features  # or: corners

Writes runs/pose_planar/<part>/planar_pose.{md,json,png}; keeps docs/reports/pose_planar_<part>.json.
"""

from __future__ import annotations

from _run import RUNS, add_part_option, alcn, command_line, keep, selected_parts

from alcn_cv.cli import run_script

PARTS = {"features": ["--detectors", "features", "--n-features", "500"], "corners": ["--detectors", "corners"]}


def main() -> None:
    parser = command_line(__doc__)
    add_part_option(parser, PARTS)
    args = parser.parse_args()
    for part in selected_parts(args, PARTS):
        out = RUNS / "pose_planar" / part
        alcn("pose", "planar", "--out", str(out), "--overwrite", *PARTS[part])
        keep(out / "planar_pose.json", f"pose_planar_{part}", drop=("details",))


if __name__ == "__main__":
    run_script(main)
