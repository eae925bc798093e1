"""What `alcn calib ...` says about bad values: the option, in one line, before any work (a sweep of bad inputs found
a ZeroDivisionError, pycolmap's and OpenCV's errors, Python's names, values taken, a board size suggested one run at a
time, and an undistorted folder written under an image's name)."""

from __future__ import annotations

import shutil

import cv2
import numpy as np
import pytest

from alcn_cv.cli import build_parser, main
from alcn_cv.errors import InputError
from calib.board import BoardSpec, write_board_image
from calib.camera import write_camera_yaml
from calib.register import SfmSettings


def _argparse_error(args: list[str], capsys) -> str:
    """The last line of argparse's error for ``alcn calib ARGS`` (exit code 2)."""
    with pytest.raises(SystemExit) as exit_:
        main(["calib", *args])
    assert exit_.value.code == 2
    return capsys.readouterr().err.strip().splitlines()[-1]


def _error(args: list[str], capsys) -> str:
    """The one line of ``alcn calib ARGS``'s error (exit code 2)."""
    assert main(["calib", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    return err


@pytest.mark.parametrize(
    ("args", "said"),
    [
        (["--step", "0"], "argument --step: an integer at least 1, got '0'"),  # a ZeroDivisionError
        (["--max-frames", "0"], "argument --max-frames: an integer at least 1, got '0'"),  # "max_frames must be ..."
        (["--min-corners", "-1"], "argument --min-corners: an integer at least 6, got '-1'"),  # taken
        (["--max-rms", "0"], "argument --max-rms: a number greater than 0, got '0'"),  # taken
        # pycolmap's "[extract_features.cc:35] Check failed", after the frames were written
        (["--method", "sfm", "--n-features", "0"], "argument --n-features: an integer at least 1, got '0'"),
        (["--method", "sfm", "--threads", "-3"], "argument --threads: an integer at least -1, got '-3'"),
    ],
)
def test_register_value_out_of_range_names_its_option(args, said, tmp_path, capsys):
    """Were a ZeroDivisionError, Python's max_frames, pycolmap's failed check, or a value taken."""
    assert _argparse_error(["register", str(tmp_path), "--out", str(tmp_path / "reg"), *args], capsys).endswith(said)
    assert not (tmp_path / "reg").exists()


def test_register_threads_minus_one_and_zero_are_all():
    """pycolmap takes -1 and 0 for every core (COLMAP's GetEffectiveNumThreads): both pass, as the help says."""
    parse = build_parser().parse_args
    assert [parse(["calib", "register", "f", "--out", "o", "--threads", t]).threads for t in ("-1", "0")] == [-1, 0]
    with pytest.raises(InputError, match="n_features must be at least 1"):
        SfmSettings(n_features=0)  # a Python caller: refused before the frames are written, not by pycolmap
    with pytest.raises(InputError, match="num_threads must be at least -1"):
        SfmSettings(num_threads=-3)


def test_board_dpi_above_the_maximum_is_refused(tmp_path, capsys):
    """--dpi 100000 ended in cv2.error (insufficient memory: 664 GB); a board of 1000x1000 squares too."""
    out = tmp_path / "b.png"
    with pytest.raises(SystemExit):
        main(["calib", "board", "--out", str(out), "--dpi", "100000"])
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.endswith("argument --dpi: an integer at least 72 and at most 1200, got '100000'")
    with pytest.raises(InputError, match=r"--dpi must be from 72 to 1200 \(finer than printers print"):
        write_board_image(BoardSpec(), out, dpi=100000)  # a Python caller
    err = _error(["board", "--out", str(out), "--board", "chessboard", "--cols", "1000", "--rows", "1000"], capsys)
    assert "the board image would be 295531x295531 px at 300 dpi, more than 268 million pixels" in err
    assert not out.exists()
    small = ["--board", "chessboard", "--cols", "3", "--rows", "3", "--square", "5", "--margin", "0"]
    assert main(["calib", "board", "--out", str(out), "--dpi", "1200", *small]) == 0


def _tilted_9x6_chessboard(tmp_path) -> np.ndarray:
    """A 9x6 (inner corners) chessboard seen at a tilt, 480x360, in which OpenCV's detector finds 7x6 but not 8x6."""
    write_board_image(BoardSpec("chessboard", 9, 6, 20.0), tmp_path / "board.png", dpi=72, margin_mm=15)
    board = cv2.imread(str(tmp_path / "board.png"), cv2.IMREAD_GRAYSCALE)
    h, w = board.shape
    corners = np.float32([[0, 0], [w, 0], [w, h], [0, h]])
    seen = np.float32([[45, 22.5], [435, 37.5], [465, 337.5], [15, 322.5]])
    image = cv2.warpPerspective(board, cv2.getPerspectiveTransform(corners, seen), (480, 360), borderValue=128)
    return cv2.GaussianBlur(image, (3, 3), 0)


def test_chessboard_suggestion_names_the_whole_board_at_once(tmp_path, capsys):
    """--cols 7 --rows 5 on a 9x6 board: the part of the board found (7x6) was suggested, and a rerun with it
    suggested 9x6; now the whole board at once."""
    images = tmp_path / "images"
    images.mkdir()
    cv2.imwrite(str(images / "a.png"), _tilted_9x6_chessboard(tmp_path))
    args = ["camera", "--images", str(images), "--out", str(tmp_path / "cam"), "--board", "chessboard", "--no-report"]
    err = _error([*args, "--cols", "7", "--rows", "5"], capsys)
    assert "The first image holds a 9x6 chessboard" in err and "pass --cols 9 --rows 6" in err, err


@pytest.mark.shared_data
def test_chessboard_suggestion_on_the_real_images_is_the_whole_board(shared_data, tmp_path, capsys):
    """left01-03 of the 9x6 chessboard with --cols 7 --rows 5 said "7x6", and the rerun with 7x6 said "9x6"."""
    images = tmp_path / "images"
    images.mkdir()
    for name in ("left01.jpg", "left02.jpg", "left03.jpg"):
        shutil.copy(shared_data / "chessboard" / name, images / name)
    args = ["camera", "--images", str(images), "--out", str(tmp_path / "cam"), "--board", "chessboard", "--no-report"]
    for cols, rows in ((7, 5), (7, 6)):
        err = _error([*args, "--cols", str(cols), "--rows", str(rows)], capsys)
        assert "holds a 9x6 chessboard" in err and "pass --cols 9 --rows 6" in err, err


def test_undistort_output_of_another_kind_than_the_source_is_refused(tmp_path, capsys):
    """A folder undistorted into `ud4.png` made a folder of that name; an image into an existing folder was "exists
    (--overwrite replaces it)", and with --overwrite "cannot write an image to ... (a folder)"."""
    write_camera_yaml(tmp_path / "camera.yaml", np.diag([50.0, 50.0, 1.0]), np.zeros(5), (64, 48))
    camera = ["--camera", str(tmp_path / "camera.yaml")]
    folder = tmp_path / "frames"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.zeros((48, 64, 3), np.uint8))
    out = tmp_path / "ud4.png"
    err = _error(["undistort", str(folder), str(out), *camera], capsys)
    assert err.endswith(f"the output of a folder must be a folder, got the file name {out}") and not out.exists()
    (tmp_path / "afile").write_text("mine")
    err = _error(["undistort", str(folder), str(tmp_path / "afile"), *camera], capsys)
    assert err.endswith(f"the output of a folder must be a folder, but {tmp_path / 'afile'} is a file")

    existing = tmp_path / "existing"
    existing.mkdir()
    for overwrite in ([], ["--overwrite"]):
        err = _error(["undistort", str(folder / "a.png"), str(existing), *camera, *overwrite], capsys)
        assert err.endswith(f"the output of an image must be an image file, but {existing} is a folder")
    video = tmp_path / "v.mp4"  # the output is checked before the video is opened
    video.write_bytes(b"")
    for output in (existing, tmp_path / "v_out"):
        err = _error(["undistort", str(video), str(output), *camera], capsys)
        assert err.endswith(f"the output of a video must be a video file (.mp4, .avi, ...), got {output}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile", "camera.yaml", "existing", "frames", "v.mp4"]
    assert not any(existing.iterdir())
