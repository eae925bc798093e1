from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main as alcn
from board_scene import make_board_scene
from calib.camera import write_camera_yaml


def test_calib_help(capsys):
    with pytest.raises(SystemExit) as exc:
        alcn(["calib", "--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for sub in ("camera", "board", "register", "undistort"):
        assert sub in out


def test_board_command(tmp_path, capsys):
    assert alcn(["calib", "board", "--out", str(tmp_path / "b.png"), "--dpi", "100", "--cols", "5", "--rows", "4"]) == 0
    assert "print at 100%" in capsys.readouterr().out
    info = json.loads((tmp_path / "b.json").read_text())
    assert info["board"]["cols"] == 5 and cv2.imread(str(tmp_path / "b.png")) is not None


@pytest.mark.shared_data
def test_camera_command_on_real_chessboard(shared_data, tmp_path, capsys):
    rc = alcn(
        [
            "calib",
            "camera",
            "--images",
            str(shared_data / "chessboard"),
            "--board",
            "chessboard",
            "--cols",
            "9",
            "--rows",
            "6",
            "--square",
            "25",
            "--out",
            str(tmp_path),
            "--no-report",
        ]
    )
    assert rc == 0
    assert "RMS 0.409 px over 13 views" in capsys.readouterr().out
    assert (tmp_path / "camera.yaml").is_file() and (tmp_path / "colmap" / "cameras.txt").is_file()


def test_register_and_undistort_commands(tmp_path, capsys):
    scene = make_board_scene(3, seed=2)
    frames = tmp_path / "frames"
    frames.mkdir()
    for i, image in enumerate(scene.images):
        cv2.imwrite(str(frames / f"{i}.png"), image)
    write_camera_yaml(tmp_path / "camera.yaml", scene.K, np.zeros(5), (640, 480))
    rc = alcn(
        ["calib", "register", str(frames), "--camera", str(tmp_path / "camera.yaml"), "--out", str(tmp_path / "reg")]
    )
    assert rc == 0
    assert "registered 3 of 3 frames (mm)" in capsys.readouterr().out
    rc = alcn(
        [
            "calib",
            "undistort",
            str(frames / "0.png"),
            str(tmp_path / "u.png"),
            "--camera",
            str(tmp_path / "camera.yaml"),
        ]
    )
    assert rc == 0 and (tmp_path / "u.camera.yaml").is_file()


def test_bad_input_gives_one_line_error(tmp_path, capsys):
    (tmp_path / "camera.yaml").write_text("not: [valid\n")
    rc = alcn(["calib", "undistort", str(tmp_path), str(tmp_path / "o"), "--camera", str(tmp_path / "camera.yaml")])
    err = capsys.readouterr().err
    assert rc == 2 and "calib camera" in err and "Traceback" not in err
    rc = alcn(["calib", "camera", "--images", str(tmp_path), "--board", "chessboard", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 2 and "--cols and --rows" in err
    rc = alcn(["calib", "register", str(tmp_path), "--out", str(tmp_path / "r")])
    err = capsys.readouterr().err
    assert rc == 2 and "--camera" in err


@pytest.mark.shared_data
def test_register_sfm_with_known_distance(shared_data, tmp_path, capsys):
    """6 consecutive Middlebury views, no board: SfM, scaled by one known camera distance."""
    from scipy.spatial.transform import Rotation

    from alcn_cv.formats import bop
    from alcn_cv.formats.middlebury import read_middlebury

    views = read_middlebury(shared_data / "middlebury" / "templeSparseRing")[5:11]
    frames = tmp_path / "frames"
    frames.mkdir()
    for v in views:
        (frames / v.name).symlink_to(v.path.resolve())
    write_camera_yaml(tmp_path / "camera.yaml", views[0].K, np.zeros(5), (640, 480))
    a, b = views[0], views[-1]
    mm = np.linalg.norm(a.center - b.center) * 1000.0
    rc = alcn(
        [
            "calib",
            "register",
            str(frames),
            "--method",
            "sfm",
            "--camera",
            str(tmp_path / "camera.yaml"),
            "--known-distance",
            a.name,
            b.name,
            f"{mm:.3f}",
            "--threads",
            "2",
            "--out",
            str(tmp_path / "reg"),
        ]
    )
    assert rc == 0
    assert "registered 6 of 6 frames (mm)" in capsys.readouterr().out
    est = [(f.R_w2c, f.t_w2c) for f in bop.load_scene(tmp_path / "reg").frames]
    assert len(est) == 6
    for i in range(6):
        for j in range(i + 1, 6):
            rel = est[i][0] @ est[j][0].T @ (views[i].R_w2c @ views[j].R_w2c.T).T
            assert np.degrees(Rotation.from_matrix(rel).magnitude()) < 2.0
            d_est = np.linalg.norm(-est[i][0].T @ est[i][1] + est[j][0].T @ est[j][1])
            d_gt = np.linalg.norm(views[i].center - views[j].center) * 1000.0
            assert d_est == pytest.approx(d_gt, rel=0.02)


def _help(capsys, *args: str) -> str:
    with pytest.raises(SystemExit) as exc:
        alcn([*args, "--help"])
    assert exc.value.code == 0
    return " ".join(capsys.readouterr().out.split())


def test_help_texts_have_no_literal_percent_escapes(capsys):
    for sub in ("camera", "board", "register", "undistort"):
        assert "%%" not in _help(capsys, "calib", sub), sub
    assert "print at 100% scale" in _help(capsys, "calib", "board")


def test_register_help_describes_only_the_boards_it_accepts(capsys):
    text = _help(capsys, "calib", "register")
    assert "{charuco}" in text and "inner corners" not in text and "chessboard:" not in text
    assert "squares along x (default 7)" in text


def test_camera_help_gives_the_chessboard_example(capsys):
    assert "--board chessboard --cols 9 --rows 6 --square 25" in _help(capsys, "calib", "camera")


@pytest.mark.shared_data
def test_default_charuco_board_on_chessboard_images_names_the_chessboard(shared_data, tmp_path, capsys):
    """The example images are a chessboard: with the default board the error says what to pass."""
    rc = alcn(["calib", "camera", "--images", str(shared_data / "chessboard"), "--out", str(tmp_path), "--no-report"])
    err = capsys.readouterr().err
    assert rc == 2 and "Traceback" not in err
    assert "--board chessboard --cols 9 --rows 6" in err


def test_undistort_help_says_where_the_camera_yaml_goes(capsys):
    text = _help(capsys, "calib", "undistort")
    assert "<stem>.camera.yaml beside it" in text and "output folder, camera.yaml inside it" in text


def test_undistort_onto_its_input_is_a_one_line_error(tmp_path, capsys):
    image = tmp_path / "left02.png"
    cv2.imwrite(str(image), np.zeros((48, 64, 3), np.uint8))
    write_camera_yaml(tmp_path / "camera.yaml", np.diag([50.0, 50.0, 1.0]), np.zeros(5), (64, 48))
    rc = alcn(["calib", "undistort", str(image), str(image), "--camera", str(tmp_path / "camera.yaml")])
    err = capsys.readouterr().err
    assert rc == 2 and "is the input" in err and "Traceback" not in err


def test_camera_max_views_below_the_minimum_is_a_one_line_error(tmp_path, capsys):
    rc = alcn(["calib", "camera", "--images", str(tmp_path), "--out", str(tmp_path / "o"), "--max-views", "2"])
    err = capsys.readouterr().err
    assert rc == 2 and "--max-views 2: a calibration needs at least 3 views" in err


def test_calib_outputs_under_a_file_or_existing_are_one_line_errors(tmp_path, capsys):
    """Under a file: "is a file", as the other commands say (not [Errno 17]); an existing --out: the
    CLI's option, not the Python keyword."""
    blocker = tmp_path / "afile"
    blocker.write_text("mine")
    write_camera_yaml(tmp_path / "camera.yaml", np.diag([50.0, 50.0, 1.0]), np.zeros(5), (64, 48))
    camera = ["--camera", str(tmp_path / "camera.yaml")]
    rc = alcn(["calib", "camera", "--images", str(tmp_path), "--out", str(blocker), "--no-report"])
    err = capsys.readouterr().err
    assert rc == 2 and f"{blocker} is a file" in err  # before the search finds no image there
    rc = alcn(["calib", "register", str(tmp_path), *camera, "--out", str(blocker / "x")])
    err = capsys.readouterr().err
    assert rc == 2 and f"{blocker} is a file" in err and "Errno" not in err
    (tmp_path / "reg").mkdir()
    (tmp_path / "reg" / "mine.txt").write_text("mine")
    rc = alcn(["calib", "register", str(tmp_path), *camera, "--out", str(tmp_path / "reg")])
    err = capsys.readouterr().err.strip()  # --overwrite would not replace it either: not offered
    assert rc == 2 and "is not an earlier output" in err and "--overwrite" not in err
    (tmp_path / "reg" / "registration.json").write_text("{}")
    rc = alcn(["calib", "register", str(tmp_path), *camera, "--out", str(tmp_path / "reg")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and err.endswith(f"{tmp_path / 'reg'} exists (--overwrite replaces it)")


def test_register_known_distance_names_are_checked_before_the_reconstruction(tmp_path, capsys, monkeypatch):
    """With --step 2 frame b is not an input frame: said before SfM, which would take minutes."""
    from calib import register

    monkeypatch.setattr(register, "_reconstruct", lambda *a, **k: pytest.fail("the reconstruction ran"))
    frames = tmp_path / "frames"
    frames.mkdir()
    for name in "abcde":
        cv2.imwrite(str(frames / f"{name}.png"), np.zeros((48, 64, 3), np.uint8))
    args = ["calib", "register", str(frames), "--method", "sfm", "--step", "2", "--out", str(tmp_path / "reg")]
    rc = alcn([*args, "--known-distance", "a.png", "b", "100"])
    err = capsys.readouterr().err
    assert rc == 2 and "--known-distance: 'b' is not an input frame" in err and "a, c, e" in err


def test_register_takes_n_features_as_the_pose_commands(capsys):
    """SIFT keypoints per image: --n-features, as `alcn pose build` and `alcn bench relight` name them."""
    from alcn_cv.cli import build_parser

    args = build_parser().parse_args(["calib", "register", "frames", "--out", "reg", "--n-features", "2048"])
    assert args.n_features == 2048
    assert "--n-features" in _help(capsys, "calib", "register")


def test_register_names_a_missing_source_before_a_missing_camera(tmp_path, capsys):
    """The board method needs --camera, but a source that does not exist is the first thing wrong."""
    rc = alcn(["calib", "register", str(tmp_path / "missing"), "--out", str(tmp_path / "reg")])
    err = capsys.readouterr().err
    assert rc == 2 and err.strip().endswith(f"no such video or folder: {tmp_path / 'missing'}"), err
    assert not (tmp_path / "reg").exists()


def test_register_reference_model_follows_its_units_header(tmp_path, capsys, monkeypatch):
    """A COLMAP --reference in metres (``# Units: m``) registers as the same model in mm: its header is
    read (it was taken as mm, the poses 1000x too small). One without a header is in arbitrary units, as pose reads
    it (calib.conventions.colmap_model_units): refused without --reference-unit (it was taken as mm)."""
    from scipy.spatial.transform import Rotation

    from alcn_cv.formats import bop
    from alcn_cv.formats.colmap import ColmapImage, ColmapModel, camera_from_opencv, write_text_model
    from calib import register

    K = np.array([[80.0, 0, 31.5], [0, 80.0, 23.5], [0, 0, 1]])
    R = Rotation.random(4, random_state=3).as_matrix()
    t_mm = np.random.default_rng(3).normal(0, 80, (4, 3)) + [0, 0, 700]
    # SfM's arbitrary frame: the world scaled by 1/250, turned and moved.
    R0, t0, s0 = Rotation.random(random_state=5).as_matrix(), np.array([0.3, -0.2, 1.0]), 1 / 250
    camera = camera_from_opencv(K, None, 64, 48)

    def reconstruct(frames, *args, **kwargs):
        images = {}
        for i, out in enumerate(frames.out_names):
            R_sfm = R[i] @ R0.T
            images[i + 1] = ColmapImage(i + 1, out, 1, R_sfm, s0 * t_mm[i] - R_sfm @ t0)
        return ColmapModel({1: camera}, images, {})

    monkeypatch.setattr(register, "_reconstruct", reconstruct)
    frames = tmp_path / "frames"
    frames.mkdir()
    for name in "abcd":
        cv2.imwrite(str(frames / f"{name}.png"), np.zeros((48, 64, 3), np.uint8))
    for units, scale in (("mm", 1.0), ("m", 1e-3)):
        images = [ColmapImage(i + 1, f"{n}.png", 1, R[i], t_mm[i] * scale) for i, n in enumerate("abc")]
        write_text_model(tmp_path / f"ref_{units}", [camera], images, units=units)
    args = ["calib", "register", str(frames), "--method", "sfm", "--no-progress"]
    poses = {}
    for units in ("mm", "m"):
        out = tmp_path / f"reg_{units}"
        assert alcn([*args, "--reference", str(tmp_path / f"ref_{units}"), "--out", str(out)]) == 0
        assert "registered 4 of 4 frames (mm)" in capsys.readouterr().out
        poses[units] = [(f.R_w2c, f.t_w2c) for f in bop.load_scene(out).frames]
    for (R_mm, t_mm_est), (R_m, t_m), R_gt, t_gt in zip(poses["mm"], poses["m"], R, t_mm):
        np.testing.assert_allclose(R_m, R_mm, atol=1e-9)
        np.testing.assert_allclose(t_m, t_mm_est, atol=1e-6)
        # The world of the reference, in mm: the 4th frame, not in the reference, too.
        np.testing.assert_allclose(R_m, R_gt, atol=1e-9)
        np.testing.assert_allclose(t_m, t_gt, atol=1e-6)
    # An explicit --reference-unit still wins over the header (as unit_to_mm does); an unknown unit needs one.
    out = tmp_path / "reg_forced"
    assert alcn([*args, "--reference", str(tmp_path / "ref_m"), "--reference-unit", "mm", "--out", str(out)]) == 0
    capsys.readouterr()
    t_forced = bop.load_scene(out).frames[0].t_w2c
    np.testing.assert_allclose(t_forced, t_mm[0] * 1e-3, atol=1e-9)
    images = [ColmapImage(i + 1, f"{n}.png", 1, R[i], t_mm[i]) for i, n in enumerate("ab")]
    write_text_model(tmp_path / "ref_ft", [camera], images, units="ft")
    rc = alcn([*args, "--reference", str(tmp_path / "ref_ft"), "--out", str(tmp_path / "reg_ft")])
    err = capsys.readouterr().err
    assert rc == 2 and "units are 'ft'; pass --reference-unit" in err, err
    write_text_model(tmp_path / "ref_none", [camera], images)
    rc = alcn([*args, "--reference", str(tmp_path / "ref_none"), "--out", str(tmp_path / "reg_none")])
    err = capsys.readouterr().err
    assert rc == 2 and "units are arbitrary" in err and "pass --reference-unit" in err, err
    assert not (tmp_path / "reg_none").exists()
    out = tmp_path / "reg_none"
    assert alcn([*args, "--reference", str(tmp_path / "ref_none"), "--reference-unit", "mm", "--out", str(out)]) == 0
    capsys.readouterr()
    np.testing.assert_allclose(bop.load_scene(out).frames[0].t_w2c, t_mm[0], atol=1e-6)


def test_calib_outputs_are_replaced_only_with_overwrite(tmp_path, capsys):
    """`calib board`, `camera` and `undistort` replaced an earlier run's files without a word; now each refuses
    before any work (the camera's image folder is empty: the refusal comes before it is searched)."""
    board = ["calib", "board", "--out", str(tmp_path / "b.png"), "--dpi", "100"]
    assert alcn(board) == 0
    capsys.readouterr()
    assert alcn(board) == 2 and "b.png and 1 more exist (--overwrite replaces them)" in capsys.readouterr().err
    assert alcn([*board, "--overwrite"]) == 0

    image = tmp_path / "in.png"
    cv2.imwrite(str(image), np.zeros((48, 64, 3), np.uint8))
    write_camera_yaml(tmp_path / "camera.yaml", np.diag([50.0, 50.0, 1.0]), np.zeros(5), (64, 48))
    undistort = ["calib", "undistort", str(image), str(tmp_path / "u.png"), "--camera", str(tmp_path / "camera.yaml")]
    assert alcn(undistort) == 0
    capsys.readouterr()
    assert alcn(undistort) == 2 and "u.png and 1 more exist" in capsys.readouterr().err
    assert alcn([*undistort, "--overwrite"]) == 0
    (tmp_path / "u.png").unlink()  # the camera YAML alone is an earlier output too
    assert alcn(undistort) == 2 and "u.camera.yaml exists (--overwrite replaces it)" in capsys.readouterr().err

    folder = tmp_path / "frames"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.zeros((48, 64, 3), np.uint8))
    (tmp_path / "out").mkdir()
    cv2.imwrite(str(tmp_path / "out" / "a.png"), np.ones((48, 64, 3), np.uint8))
    rc = alcn(["calib", "undistort", str(folder), str(tmp_path / "out"), "--camera", str(tmp_path / "camera.yaml")])
    assert rc == 2 and "a.png exists" in capsys.readouterr().err
    assert cv2.imread(str(tmp_path / "out" / "a.png")).max() == 1  # the earlier image is kept

    calibrated = tmp_path / "calibrated"
    calibrated.mkdir()
    (calibrated / "views.json").write_text("{}")
    empty = tmp_path / "empty"
    empty.mkdir()
    rc = alcn(["calib", "camera", "--images", str(empty), "--out", str(calibrated), "--no-report"])
    assert rc == 2 and "views.json exists (--overwrite replaces it)" in capsys.readouterr().err
