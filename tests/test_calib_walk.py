"""What a newcomer's walk through `alcn calib` found: outputs mixed or left behind by a failure, and what the
commands did without saying so or said without the way out."""

from __future__ import annotations

import json
import logging
from pathlib import Path

import cv2
import numpy as np
import pytest

from alcn_cv.cli import main as alcn
from alcn_cv.errors import InputError
from board_scene import make_board_scene
from calib import report
from calib.board import BoardSpec
from calib.camera import Calibration, main, save_calibration
from calib.quality import coverage_hint, outliers
from calib.register import register_charuco
from calib.undistort import main as undistort

K = np.array([[500.0, 0, 319.5], [0, 500, 239.5], [0, 0, 1]])


def _calibration(rms: float, points: np.ndarray) -> Calibration:
    """A calibration of one view whose corners are ``points``."""
    return Calibration(
        K, np.zeros(5), (640, 480), rms, ["v0"], np.array([rms]), [np.zeros(3)], [np.ones(3)], None, [points]
    )


def _files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_an_interrupted_calibration_leaves_the_earlier_one_whole(tmp_path, monkeypatch):
    """An interrupt while calibration.png was drawn left the new camera.yaml and views.json beside the old picture."""
    grid = np.mgrid[100:500:50, 100:400:50].T.reshape(-1, 2).astype(np.float32)
    save_calibration(_calibration(0.2, grid), tmp_path)
    earlier = _files(tmp_path)
    assert set(earlier) == {
        "camera.yaml",
        "views.json",
        "calibration.png",
        "colmap/cameras.txt",
        "colmap/images.txt",
        "colmap/points3D.txt",
    }

    def interrupted(*args: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(report, "plot_calibration", interrupted)
    moved = Calibration(K * [[1.1], [1.1], [1]], np.zeros(5), (640, 480), 0.3)
    with pytest.raises(KeyboardInterrupt):
        save_calibration(moved, tmp_path)
    assert _files(tmp_path) == earlier  # every file the earlier one, and no temporary file left
    assert sorted(p.name for p in tmp_path.iterdir()) == ["calibration.png", "camera.yaml", "colmap", "views.json"]
    with pytest.raises(KeyboardInterrupt):
        save_calibration(moved, tmp_path / "first")
    assert _files(tmp_path / "first") == {}  # a first run interrupted leaves no file to refuse its rerun


def test_undistort_checks_every_image_size_before_writing_any(tmp_path):
    """The 6th image of another size failed after five images were written, which then blocked a rerun."""
    folder = tmp_path / "frames"
    folder.mkdir()
    for i in range(6):
        cv2.imwrite(str(folder / f"{i}.png"), np.full((96, 128, 3) if i == 5 else (48, 64, 3), i, np.uint8))
    calib = Calibration(np.diag([50.0, 50.0, 1.0]), np.array([-0.1, 0, 0, 0, 0]), (64, 48), 0.1)
    with pytest.raises(InputError, match="5.png is 128x96 but the calibration is for 64x48"):
        undistort(folder, tmp_path / "out", calib, progress=False)
    assert not (tmp_path / "out").exists()
    (folder / "5.png").unlink()
    undistort(folder, tmp_path / "out", calib, progress=False)  # the rerun needs no --overwrite
    assert len(list((tmp_path / "out").glob("*.png"))) == 5


@pytest.mark.shared_data
def test_outlier_views_are_named_flagged_and_their_rule_stated(shared_data, tmp_path, monkeypatch, caplog):
    """left02.jpg (1.22 px against 0.409 px overall) was only a red bar in calibration.png, its rule unstated, and
    the coverage of 34/48 cells, none in a corner, unjudged."""
    figures = []

    def keep_figure(plt, fig, path):
        figures.append(fig)
        return path

    monkeypatch.setattr(report, "save_figure", keep_figure)
    with caplog.at_level(logging.WARNING, logger="calib.camera"):
        calib = main(shared_data / "chessboard", tmp_path, BoardSpec("chessboard", 9, 6, 25.0), progress=False)
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    outlier = next(m for m in warnings if "outlier" in m)
    assert "left02.jpg (1.22 px)" in outlier and "max(2 x RMS, 1 px) = 1.00 px" in outlier
    assert "left13.jpg" not in outlier
    coverage = next(m for m in warnings if "coverage" in m)
    assert "34/48 image cells, 0 of the 4 corner cells" in coverage and "--fix-k3" in coverage

    views = json.loads((tmp_path / "views.json").read_text())
    assert [v["name"] for v in views["views"] if v["outlier"]] == ["left02.jpg"]
    assert views["outlier_rule"] == "rms_px above max(2 x RMS, 1 px)" and views["outlier_px"] == 1.0

    coverage_axes, error_axes = figures[0].axes
    assert "34/48 image cells covered, 0/4 corner cells" in coverage_axes.get_title()
    assert "--fix-k3" in coverage_axes.get_title()
    legend = [t.get_text() for t in error_axes.get_legend().get_texts()]
    assert "outliers (red) above max(2 x RMS, 1 px) = 1.00 px" in legend
    assert outliers(calib).tolist() == [v["outlier"] for v in views["views"]]


def test_a_coverage_reaching_the_image_corners_gets_no_hint():
    everywhere = np.mgrid[5:640:40, 5:480:40].T.reshape(-1, 2).astype(np.float32)
    assert coverage_hint(_calibration(0.2, everywhere)) == ""
    central = everywhere[(np.abs(everywhere - [320, 240]) < [200, 150]).all(axis=1)]
    assert "--fix-k3" in coverage_hint(_calibration(0.2, central))
    # the corners alone are not enough: under 3/4 of the cells
    corners = np.array([[5, 5], [635, 5], [5, 475], [635, 475]], np.float32)
    assert "--fix-k3" in coverage_hint(_calibration(0.2, np.vstack([central, corners])))


@pytest.mark.shared_data
def test_views_left_out_by_the_selection_are_logged_and_listed(shared_data, tmp_path, caplog):
    """With --max-views 5 four views were dropped as the blurriest third without a word, and views.json listed
    none of the views left out."""
    with caplog.at_level(logging.INFO, logger="calib.camera"):
        main(shared_data / "chessboard", tmp_path, BoardSpec("chessboard", 9, 6), max_views=5, report=False)
    log = "\n".join(r.getMessage() for r in caplog.records)
    assert "left out 4 view(s) as the blurriest third" in log
    assert "selected 5 of 13 views" in log
    views = json.loads((tmp_path / "views.json").read_text())
    used = [v["name"] for v in views["views"]]
    unused = {v["name"]: v["reason"] for v in views["unused_views"]}
    images = sorted(p.name for p in (shared_data / "chessboard").glob("*.jpg"))
    assert len(used) == 5 and sorted(used + list(unused)) == images
    assert sum("blurriest third" in reason for reason in unused.values()) == 4
    for name in (n for n, reason in unused.items() if "blurriest" in reason):
        assert name in log


def test_camera_help_says_the_selection_applies_to_folders(capsys):
    with pytest.raises(SystemExit):
        alcn(["calib", "camera", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "from a video:" not in text
    assert "most views used, from a folder or a video" in text and "listed in views.json" in text


def test_the_default_marker_follows_the_square(tmp_path, capsys):
    """--square 20 failed on the 26 mm default marker, naming no --marker; --square 200 kept 26 mm markers."""
    for square, marker in (("20", 20 * 26 / 35), ("200", 200 * 26 / 35), (None, 26.0)):
        out = tmp_path / f"{square}.png"
        given = ["--square", square] if square else []
        assert alcn(["calib", "board", "--out", str(out), "--dpi", "72", *given]) == 0
        assert json.loads(out.with_suffix(".json").read_text())["board"]["marker"] == marker
    capsys.readouterr()
    assert alcn(["calib", "board", "--out", str(tmp_path / "b.png"), "--square", "20", "--marker", "26"]) == 2
    assert "give a smaller --marker (without one, the command line takes 26/35 of --square)" in capsys.readouterr().err


@pytest.mark.shared_data
def test_squares_counted_for_inner_corners_are_named(shared_data, tmp_path):
    """--cols 10 --rows 7 on the 9x6 board got a generic hint, though the search had seen the 9x6 board."""
    with pytest.raises(InputError, match="one fewer each way than the 10x7 given.*pass --cols 9 --rows 6"):
        main(shared_data / "chessboard", tmp_path, BoardSpec("chessboard", 10, 7), progress=False)


def test_registration_without_the_board_anywhere_is_diagnosed_as_the_calibration(tmp_path):
    """--cols 5 --rows 7 on a 7x5 board was 'dropped: N x board not found ... or relax --max-rms'."""
    scene = make_board_scene(2, seed=2)
    frames = tmp_path / "frames"
    frames.mkdir()
    for i, image in enumerate(scene.images):
        cv2.imwrite(str(frames / f"{i}.png"), image)
    calib = Calibration(scene.K, np.zeros(5), (640, 480), 0.0)
    with pytest.raises(InputError) as error:
        register_charuco(frames, tmp_path / "reg", calib, BoardSpec(cols=5, rows=7), progress=False)
    message = str(error.value)
    assert message.startswith("no 5x7 ChArUco board")
    assert "ArUco marker(s) of the board were seen" in message and "--legacy" in message
    assert "--max-rms" not in message and "--board" not in message
    assert not (tmp_path / "reg").exists()
