"""`alcn pose ...` on bad input: earlier outputs replaced only with --overwrite, and options out of range refused in
one line that names them, all before any work (the bad-input sweep's findings)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main
from alcn_cv.errors import DatasetError, InputError
from pose import model as part_model
from pose.model import box_corners
from pose.solver import camera_matrix

K_ARGS = ["--K", "500", "500", "160", "120"]


def _one_line_error(capsys, argv: list[str]) -> str:
    """The error of ``alcn *argv`` (exit 2) without a traceback: one line, or argparse's usage and its one line (the
    line returned)."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and (len(err.splitlines()) == 1 or err.startswith("usage:")), err
    return err.splitlines()[-1]


def test_pose_build_refuses_an_earlier_model_before_the_work(tmp_path, capsys):
    """A second `pose build` into the same MODEL.npz replaced it, its .ply and _cameras.png without a word."""
    model = tmp_path / "m.npz"
    argv = ["pose", "build", str(tmp_path / "seq"), str(model), "--box-size", "1", "2", "3"]
    for earlier in (model, model.with_suffix(".ply"), tmp_path / "m_cameras.png"):
        earlier.write_text("earlier")
        assert _one_line_error(capsys, argv).endswith(f"{earlier} exists (--overwrite replaces it)")
        assert earlier.read_text() == "earlier"
        earlier.unlink()
    model.write_text("earlier")
    # with --overwrite the build goes on, to the input (no such sequence here)
    assert _one_line_error(capsys, [*argv, "--overwrite"]).endswith(f"{tmp_path / 'seq'}: no such file or folder")


def test_pose_build_checks_the_box_the_camera_and_the_output_first(tmp_path, capsys):
    """--box-size 0 1 1 (or -1 -1 -1) and --K 0 0 0 0 started the reconstruction; an output that is a folder failed
    only after the build."""
    video = tmp_path / "v.mp4"
    video.write_bytes(b"not read: the checks come first")
    argv = ["pose", "build", str(video), str(tmp_path / "m.npz")]
    for size in (["0", "1", "1"], ["-1", "-1", "-1"]):
        err = _one_line_error(capsys, [*argv, *K_ARGS, "--box-size", *size])
        assert err.endswith(f"argument --box-size: a number greater than 0, got '{size[0]}'")
    err = _one_line_error(capsys, [*argv, "--K", "0", "0", "0", "0", "--box-size", "1", "1", "1"])
    assert err.endswith("--K FX FY CX CY: FX and FY greater than 0 and all four finite, got 0 0 0 0")
    (tmp_path / "dir.npz").mkdir()
    argv = ["pose", "build", str(video), str(tmp_path / "dir.npz"), *K_ARGS, "--box-size", "1", "1", "1"]
    err = _one_line_error(capsys, argv)
    assert err.endswith(f"{tmp_path / 'dir.npz'} is a folder; give the part model's file (.npz)")
    from pose import build

    with pytest.raises(InputError, match=r"--box-size W H D: three lengths greater than 0, got \[0.0, 1.0, 1.0\]"):
        build.main(video, tmp_path / "m.npz", K=camera_matrix(500, 500, 160, 120), box_size=(0, 1, 1))
    with pytest.raises(InputError, match=r"K must be .* positive focal lengths, got \[\[0.0, 0.0, 0.0\], \[0.0, "):
        build.main(video, tmp_path / "m.npz", K=np.diag([0.0, 0.0, 1.0]), box_size=(1, 1, 1))


@pytest.mark.parametrize("step", ["build", "track", "bench-corners"])
def test_max_frames_zero_names_the_option(step, tmp_path, capsys):
    """`--max-frames 0` said "max_frames must be a positive integer or None"."""
    paths = {"build": ["seq", "m.npz"], "track": ["m.npz", "v.mp4", "p.json"], "bench-corners": ["c.onnx", "v.mp4"]}
    argv = ["pose", step, *(str(tmp_path / p) for p in paths[step]), *K_ARGS, "--max-frames", "0"]
    assert _one_line_error(capsys, argv).endswith("argument --max-frames: an integer at least 1, got '0'")


@pytest.mark.parametrize("step", ["track", "bench-corners"])
def test_a_camera_matrix_without_focal_lengths_is_one_line_naming_k(step, tmp_path, capsys):
    """`--K 0 0 0 0` printed "K must be a finite 3x3 intrinsic matrix ..." and a numpy matrix over three lines."""
    paths = {"track": ["m.npz", "v.mp4", "p.json"], "bench-corners": ["c.onnx", "v.mp4"]}
    argv = ["pose", step, *(str(tmp_path / p) for p in paths[step]), "--K", "0", "0", "0", "0"]
    assert _one_line_error(capsys, argv).endswith(
        "--K FX FY CX CY: FX and FY greater than 0 and all four finite, got 0 0 0 0"
    )
    from pose.solver import PoseSolver

    with pytest.raises(InputError) as exc:  # a Python caller's: one line too
        PoseSolver(np.zeros((3, 3)))
    assert "\n" not in str(exc.value) and str(exc.value).endswith(
        "got [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]"
    )


def test_pose_track_refuses_earlier_poses_their_info_and_overlay_video(tmp_path, capsys):
    """`pose track` replaced the poses (its help said so) where `normalize` refuses an existing output."""
    poses = tmp_path / "p.json"
    argv = ["pose", "track", str(tmp_path / "m.npz"), str(tmp_path / "v.mp4"), str(poses), *K_ARGS]
    for earlier in (poses, tmp_path / "p_info.json"):
        earlier.write_text("{}")
        assert _one_line_error(capsys, argv).endswith(f"{earlier} exists (--overwrite replaces it)")
        earlier.unlink()
    (tmp_path / "ov.mp4").write_bytes(b"earlier")
    err = _one_line_error(capsys, [*argv, "--overlay", str(tmp_path / "ov.mp4")])
    assert err.endswith(f"{tmp_path / 'ov.mp4'} exists (--overwrite replaces it)")
    poses.write_text("{}")
    # with --overwrite the tracking goes on, to the model (none here)
    assert "part model not found" in _one_line_error(capsys, [*argv, "--overwrite"])
    with pytest.raises(SystemExit):
        main(["pose", "track", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "replaced in any case" not in text and "any of them that exists is refused before the tracking" in text


def test_train_corners_refuses_an_earlier_detector_and_a_negative_seed(tmp_path, capsys):
    """`pose train-corners` replaced the .onnx of an earlier run (minutes of training); --seed -1 gave numpy's
    "expected non-negative integer"."""
    onnx = tmp_path / "c.onnx"
    onnx.write_bytes(b"earlier")
    argv = ["pose", "train-corners", str(tmp_path / "seq"), str(onnx), "--box-ply", str(tmp_path / "box.ply")]
    assert _one_line_error(capsys, argv).endswith(f"{onnx} exists (--overwrite replaces it)")
    assert onnx.read_bytes() == b"earlier"
    assert "box.ply" in _one_line_error(capsys, [*argv, "--overwrite"])  # on to the box, which is missing
    err = _one_line_error(capsys, [*argv, "--seed", "-1"])
    assert err.endswith("argument --seed: an integer at least 0, got '-1'")
    models = tmp_path / "models"  # a folder given where the detector goes: no --overwrite would replace it
    models.mkdir()
    argv[3] = str(models)
    assert _one_line_error(capsys, argv).endswith(f"a corner detector must end in .onnx, got {models}")


def test_bench_corners_and_corner_recall_refuse_an_earlier_report(tmp_path, capsys):
    """`pose bench-corners --out` and `pose corner-recall --out` replaced the earlier report."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "bench_corners.json").write_text("{}")
    argv = ["pose", "bench-corners", str(tmp_path / "c.onnx"), str(tmp_path / "frames"), *K_ARGS, "--out", str(out)]
    assert _one_line_error(capsys, argv).endswith(f"{out / 'bench_corners.json'} exists (--overwrite replaces it)")
    assert "no such video or folder" in _one_line_error(capsys, [*argv, "--overwrite"])
    (out / "corner_recall_grey.json").write_text("{}")
    argv = ["pose", "corner-recall", str(tmp_path / "c.onnx"), str(tmp_path / "scene"), "--out", str(out)]
    argv += ["--background", "keep", "grey"]
    assert _one_line_error(capsys, argv).endswith(f"{out / 'corner_recall_grey.json'} exists (--overwrite replaces it)")
    assert "corner detector not found" in _one_line_error(capsys, [*argv, "--overwrite"])


def test_bench_corners_and_corner_recall_refuse_an_out_under_a_file_before_the_work(tmp_path, capsys):
    """An --out that is a file was found after the whole benchmark (or corner-recall's first pass)."""
    out = tmp_path / "afile"
    out.write_text("")
    argv = ["pose", "bench-corners", str(tmp_path / "c.onnx"), str(tmp_path / "frames"), *K_ARGS, "--out", str(out)]
    assert _one_line_error(capsys, argv).endswith(f"cannot write {out / 'bench_corners.md'}: {out} is a file")
    argv = ["pose", "corner-recall", str(tmp_path / "c.onnx"), str(tmp_path / "scene"), "--out", str(out)]
    assert _one_line_error(capsys, argv).endswith(f"cannot write {out / 'corner_recall_keep.json'}: {out} is a file")


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--repeats", "0"], "argument --repeats: an integer at least 1, got '0'"),
        (["--frame-size", "0", "0"], "argument --frame-size: an integer at least 32 and at most 4096, got '0'"),
        (
            ["--frame-size", "640", "100000"],
            "argument --frame-size: an integer at least 32 and at most 4096, got '100000'",
        ),
    ],
)
def test_bench_corners_ranges_are_checked_first(option, message, tmp_path, capsys):
    """`--repeats 0` ended in ZeroDivisionError, `--frame-size 0 0` and `100000 100000` in cv2.error tracebacks."""
    argv = ["pose", "bench-corners", str(tmp_path / "c.onnx"), str(tmp_path / "frames"), *K_ARGS, *option]
    assert _one_line_error(capsys, argv).endswith(message)
    from pose import corner_bench

    with pytest.raises(InputError, match="--frame-size W H: each 32 to 4096 pixels, got 0 0"):
        corner_bench.benchmark(tmp_path / "c.onnx", tmp_path / "frames", np.eye(3), size=(0, 0))
    with pytest.raises(InputError, match="--max-frames and --repeats must be at least 1, got 60 and 0"):
        corner_bench.benchmark(tmp_path / "c.onnx", tmp_path / "frames", np.eye(3), repeats=0)


def _posed_frame(tmp_path, frame: np.ndarray) -> list[str]:
    """A part model with a camera, one frame of ``frame`` and its pose: the arguments of one ``--run``."""
    corners = box_corners([20.0, 14.0, 6.0])
    model = part_model.PartModel(corners=corners, points3d=np.zeros((1, 3)), descriptors=np.zeros((1, 32), np.uint8))
    model.extra["K"] = camera_matrix(600.0, 600.0, 320.0, 240.0).tolist()
    part_model.save(model, tmp_path / "m.npz")
    (tmp_path / "frames").mkdir()
    cv2.imwrite(str(tmp_path / "frames" / "0000.png"), frame)
    R = cv2.Rodrigues(np.array([np.radians(-35.0), np.radians(10.0), 0.0]))[0]
    pose = [{"obj_id": 1, "cam_R_m2c": R.ravel().tolist(), "cam_t_m2c": [-10.0, -4.0, 60.0]}]
    (tmp_path / "p.json").write_text(json.dumps({"0000": pose}))
    return ["--run", "track", str(tmp_path / "m.npz"), str(tmp_path / "p.json")]


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--max-angle", "-5"], "argument --max-angle: a number greater than 0 and at most 90, got '-5'"),
        (["--max-angle", "500"], "argument --max-angle: a number greater than 0 and at most 90, got '500'"),
        (["--max-distance", "0"], "argument --max-distance: a number at least 1 and at most 200, got '0'"),
        (["--max-distance", "100000"], "argument --max-distance: a number at least 1 and at most 200, got '100000'"),
    ],
)
def test_overlay_error_ranges(option, message, tmp_path, capsys):
    """`--max-angle -5` ended in "Out of range float values are not JSON compliant: nan" after a partial report;
    `--max-distance 0` reported "mean 0.00 px"; 100000 px and 500 degrees were taken."""
    argv = ["pose", "overlay-error", str(tmp_path / "frames"), "--run", "a", "m.npz", "p.json", "--out", str(tmp_path)]
    assert _one_line_error(capsys, [*argv, *option]).endswith(message)
    from pose.overlay import EdgeSettings

    key = option[0][2:].replace("-", "_")
    with pytest.raises(InputError, match=f"^{option[0]} must be"):
        EdgeSettings(**{key: float(option[1])})


def test_overlay_error_refuses_an_earlier_report_and_leaves_none_in_part(tmp_path, capsys, monkeypatch):
    """`pose overlay-error --out` replaced an earlier report; a frame where no image edge was found (NaN statistics)
    failed in the JSON after the Markdown was written, leaving a partial report."""
    from pose import overlay

    def no_plot(runs, path, max_distance):  # an empty file: matplotlib's import was a second of this test
        Path(path).write_bytes(b"")
        return Path(path)

    monkeypatch.setattr(overlay, "plot_errors", no_plot)
    run = _posed_frame(tmp_path, np.full((480, 640, 3), 128, np.uint8))  # a flat frame: no image edge anywhere
    out = tmp_path / "out"
    argv = ["pose", "overlay-error", str(tmp_path / "frames"), *run, "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    record = json.loads((out / "overlay_error.json").read_text())
    assert record["runs"]["track"]["matched_px"] is None and record["runs"]["track"]["found"] == 0.0
    capsys.readouterr()
    assert _one_line_error(capsys, argv).endswith(
        f"{out / 'overlay_error.md'} and 3 more exist (--overwrite replaces them)"
    )

    def fails(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(overlay, "plot_frames", fails)
    with pytest.raises(OSError, match="disk full"):  # replacing the earlier report: none of it is left beside
        overlay.main(tmp_path / "frames", [tuple(run[1:])], out, progress=False, overwrite=True)
    assert list(out.iterdir()) == []
    with pytest.raises(OSError, match="disk full"):
        overlay.main(tmp_path / "frames", [tuple(run[1:])], out, progress=False)
    assert list(out.iterdir()) == []


def test_planar_refuses_a_negative_number_of_features(tmp_path, capsys):
    """`pose planar --n-features -1` was accepted; 0 means all, as in the other pose commands."""
    err = _one_line_error(capsys, ["pose", "planar", "--out", str(tmp_path / "o"), "--n-features", "-1"])
    assert err.endswith("argument --n-features: an integer at least 0, got '-1'")
    with pytest.raises(SystemExit):
        main(["pose", "planar", "--help"])
    assert "(default 0: all;" in " ".join(capsys.readouterr().out.split())


@pytest.mark.parametrize(
    ("option", "message"),
    [
        (["--max-frames", "1"], "argument --max-frames: 0 (all) or an integer at least 2, got '1'"),
        (["--hfov", "180"], "argument --hfov: a number greater than 0 and less than 180, got '180'"),
    ],
)
def test_planar_checks_its_frames_and_field_of_view_first(option, message, tmp_path, capsys):
    """`pose planar --max-frames 0` read the scenes, then said "max_frames must be at least 2" (the Python keyword;
    `bench relight --max-frames 0` reads all frames); `--hfov 180` said "hfov must be in (0, 180) degrees"."""
    assert _one_line_error(capsys, ["pose", "planar", "--out", str(tmp_path / "o"), *option]).endswith(message)


def test_planar_max_frames_zero_reads_every_frame(tmp_path, monkeypatch):
    from pose import planar

    seen = {}

    def run(out: str, *args: object, **kwargs: object) -> None:
        seen.update(kwargs)
        Path(out).mkdir()
        (Path(out) / "planar_pose.md").write_text("the report")

    monkeypatch.setattr(planar, "main", run)
    assert main(["pose", "planar", "--out", str(tmp_path / "o"), "--max-frames", "0"]) == 0
    assert seen["max_frames"] is None


def test_pose_eval_says_a_missing_data_folder_is_missing(tmp_path, capsys):
    """`pose eval --data nope` said "expected train/000001 ..." (and after the --middlebury sets' models)."""
    err = _one_line_error(capsys, ["pose", "eval", "--data", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    assert err.endswith(f"{tmp_path / 'nope'}: no such folder; --data is a pose data set of `alcn data pose`")
    (tmp_path / "file").write_text("")
    err = _one_line_error(capsys, ["pose", "eval", "--data", str(tmp_path / "file"), "--out", str(tmp_path / "o")])
    assert "file: not a folder" in err
    assert not (tmp_path / "o").exists()


def test_pose_eval_box_fit_failure_names_what_its_user_can_change(tmp_path, capsys, monkeypatch):
    """When the box fit failed, `pose eval` said to check --box-size/--box-ply and --box-units, options of
    `pose build`: it names the data set's frames, --feature and the normalization."""
    import types

    from pose import build, evaluate

    data = tmp_path / "data"
    for folder in ("train/000001", "test/000001", "models"):
        (data / folder).mkdir(parents=True)
    (data / "models" / "obj_000001.ply").write_text("")
    views = types.SimpleNamespace(views=[object()] * 4)
    monkeypatch.setattr(evaluate, "load_sequence", lambda *args, **kwargs: views)
    monkeypatch.setattr(evaluate, "read_box_corners", lambda path: box_corners([140.0, 95.0, 55.0]))
    monkeypatch.setattr(evaluate, "check_known_units", lambda *args: None)
    stats = {"mean_abs_relative_size_error": 0.5, "known_size": [140, 95, 55], "size_error": [-80, -26, -41]}

    def fit_fails(seq, **kwargs):  # build's check of the fit, with the hint evaluate gives it
        build.check_box_fit(stats, "mm", hint=kwargs.get("fit_hint"))

    monkeypatch.setattr(evaluate, "build_model", fit_fails)
    argv = ["pose", "eval", "--data", str(data), "--out", str(tmp_path / "o"), "--normalizations", "none"]
    err = _one_line_error(capsys, [*argv, "--no-progress"])
    assert "box fit is 50% off" in err and "--box-units" not in err and "--box-size" not in err
    assert "4 views" in err and "`alcn data pose --frames 12` or more" in err and "--feature" in err
    with pytest.raises(DatasetError, match="check --box-size/--box-ply and --box-units"):  # `pose build`'s, unchanged
        build.check_box_fit(stats, "mm")
