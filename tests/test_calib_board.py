from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest
from PIL import Image

from alcn_cv.errors import InputError
from calib.board import BoardSpec, suggest_chessboard_size, write_board_image


def test_printable_charuco_board_is_detected_whole(tmp_path):
    spec = BoardSpec(cols=5, rows=4, square=30.0, marker=22.0)
    info = write_board_image(spec, tmp_path / "board.png", dpi=150)
    assert not list(tmp_path.glob(".*tmp*"))
    meta = json.loads((tmp_path / "board.json").read_text())
    assert meta["board"]["cols"] == 5 and meta["dpi"] == 150
    with Image.open(tmp_path / "board.png") as im:
        assert im.info["dpi"] == pytest.approx((150, 150), abs=0.05)  # PNG stores pixels per metre
        assert im.size == tuple(info["image_size_px"])
    # The printed square is the requested one to within one pixel at this DPI.
    assert abs(info["square_mm_printed"] - 30.0) <= 25.4 / 150
    image = cv2.imread(str(tmp_path / "board.png"), cv2.IMREAD_GRAYSCALE)
    det = spec.detector()(image)
    assert det is not None and len(det.ids) == spec.num_corners
    # Corner spacing in the image is the square in pixels: a consistent homography board -> image.
    H, _ = cv2.findHomography(det.object_points[:, :2], det.image_points)
    proj = cv2.perspectiveTransform(det.object_points[None, :, :2], H)[0]
    assert np.abs(proj - det.image_points).max() < 0.5
    assert H[0, 0] == pytest.approx(info["square_px"] / 30.0, rel=1e-2)


def test_printable_chessboard(tmp_path):
    spec = BoardSpec("chessboard", 6, 4, 20.0)
    write_board_image(spec, tmp_path / "cb.png", dpi=100)
    image = cv2.imread(str(tmp_path / "cb.png"), cv2.IMREAD_GRAYSCALE)
    det = spec.detector()(image)
    assert det is not None and len(det.image_points) == 24
    assert suggest_chessboard_size(image, near=(5, 4)) == (6, 4)  # one column too few given


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(kind="aruco"), "kind"),
        (dict(cols=2, rows=5), "at least"),
        (dict(marker=40.0), "marker size"),
        (dict(dictionary="DICT_NOPE"), "dictionary"),
        (dict(cols=20, rows=20, dictionary="DICT_4X4_50"), "needs 200 markers"),
        (dict(square=0.0), "square"),
        # from a config file or argv as text, or a float: refused here, not by np.mgrid or OpenCV's patternSize later
        (dict(kind="chessboard", cols="9", rows=6), r"cols and rows count inner corners: integers, got '9' and 6"),
        (dict(kind="chessboard", cols=9.0, rows=6), "integers, got 9.0 and 6"),
        (dict(cols=True), "integers"),
        (dict(square="25"), r"square and marker are sizes in mm: numbers, got '25' and 26.0"),
    ],
)
def test_bad_board_specs(kwargs, match):
    with pytest.raises(InputError, match=match):
        BoardSpec(**kwargs)


def test_board_image_needs_png(tmp_path):
    with pytest.raises(InputError, match=".png"):
        write_board_image(BoardSpec(), tmp_path / "b.jpg")


def test_a_negative_margin_is_one_line_and_no_margin_draws_no_label(tmp_path):
    """`alcn calib board --margin -5` ended in cv2.copyMakeBorder's traceback; `--margin 0` drew the label over the
    board's last row of squares."""
    with pytest.raises(InputError, match="the margin must be 0 mm or more, got -5"):
        write_board_image(BoardSpec(), tmp_path / "b.png", margin_mm=-5)
    spec = BoardSpec(kind="chessboard", cols=5, rows=4, square=10.0)
    write_board_image(spec, tmp_path / "b.png", dpi=100, margin_mm=0)
    image = cv2.imread(str(tmp_path / "b.png"), cv2.IMREAD_GRAYSCALE)
    assert set(np.unique(image)) == {0, 255}  # the squares alone: no anti-aliased text


def test_chessboard_frame_is_that_of_the_printed_board(tmp_path):
    """The chessboard's object points are in mm from the printed checkered area's top-left corner (as a ChArUco
    board's): each detected corner lies where its 3D point falls on the printed image."""
    spec = BoardSpec("chessboard", 6, 4, 20.0)
    info = write_board_image(spec, tmp_path / "cb.png", dpi=100)
    image = cv2.imread(str(tmp_path / "cb.png"), cv2.IMREAD_GRAYSCALE)
    det = spec.detector()(image)
    margin = (info["image_size_px"][0] - spec.squares[0] * info["square_px"]) / 2
    # a square's edge lies between two pixels: at half a pixel before the first pixel of the next square
    expected = spec.corners_3d()[:, :2] / spec.square * info["square_px"] + margin - 0.5
    # each corner where its own 3D point falls, the detector numbering from either end of this 180-degree
    # symmetric board
    off = min(np.abs(det.image_points - expected).max(), np.abs(det.image_points - expected[::-1]).max())
    assert off < 0.5
    np.testing.assert_allclose(spec.corners_3d()[[0, -1]], [[20, 20, 0], [120, 80, 0]])


def test_the_printed_chessboard_starts_with_a_black_square(tmp_path):
    """OpenCV's printed pattern and ChArUco boards have a black top-left square; so does ours (not inverted colours)."""
    spec = BoardSpec("chessboard", 6, 4, 20.0)
    info = write_board_image(spec, tmp_path / "cb.png", dpi=100)
    image = cv2.imread(str(tmp_path / "cb.png"), cv2.IMREAD_GRAYSCALE)
    square = info["square_px"]
    margin = (info["image_size_px"][0] - spec.squares[0] * square) // 2
    assert image[margin + square // 2, margin + square // 2] == 0
    assert image[margin + square // 2, margin + square + square // 2] == 255


def test_numpy_counts_and_sizes_become_pythons_own(tmp_path):
    """A board of NumPy scalars (counts read from an array, say) was taken as it was, and the calibration's
    views.json then failed to be written (an int64 is not JSON)."""
    spec = BoardSpec(kind="chessboard", cols=np.int64(9), rows=np.int32(6), square=np.float32(25.0))
    assert [type(v) for v in (spec.cols, spec.rows, spec.square, spec.marker)] == [int, int, float, float]
    assert json.loads(json.dumps(dataclasses.asdict(spec)))["cols"] == 9
