from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.errors import InputError
from board_scene import make_board_scene
from calib.board import BoardSpec
from calib.camera import Calibration, load_calibration
from calib.undistort import Undistorter, main

DIST = np.array([-0.15, 0.03, 0.0, 0.0, 0.0])


@pytest.fixture(scope="module")
def scene():
    return make_board_scene(2, seed=3, dist=DIST)


def test_undistorted_board_projects_with_pinhole_camera(scene, tmp_path):
    calib = Calibration(scene.K, DIST, (640, 480), 0.0)
    src = tmp_path / "in.png"
    cv2.imwrite(str(src), scene.images[0])
    yaml_path = main(src, tmp_path / "out.png", calib, alpha=0.0)
    new = load_calibration(yaml_path)
    assert not np.any(new.dist)
    image = cv2.imread(str(tmp_path / "out.png"))
    det = BoardSpec().detector()(image)
    proj, _ = cv2.projectPoints(det.object_points, cv2.Rodrigues(scene.R_w2c[0])[0], scene.t_w2c[0], new.K, None)
    err = np.abs(proj.reshape(-1, 2) - det.image_points).max()
    assert err < 0.5
    # Without undistortion the same check fails: the test can tell.
    det0 = BoardSpec().detector()(scene.images[0])
    proj0, _ = cv2.projectPoints(det0.object_points, cv2.Rodrigues(scene.R_w2c[0])[0], scene.t_w2c[0], scene.K, None)
    assert np.abs(proj0.reshape(-1, 2) - det0.image_points).max() > 4 * err


def test_folder_and_video(scene, tmp_path):
    calib = Calibration(scene.K, DIST, (640, 480), 0.0)
    folder = tmp_path / "imgs"
    folder.mkdir()
    for i, im in enumerate(scene.images):
        cv2.imwrite(str(folder / f"{i}.png"), im)
    main(folder, tmp_path / "und", calib, keep_K=True)
    assert sorted(p.name for p in (tmp_path / "und").iterdir()) == ["0.png", "1.png", "camera.yaml"]
    np.testing.assert_allclose(load_calibration(tmp_path / "und" / "camera.yaml").K, scene.K)
    single = Undistorter(calib, keep_K=True)
    for i, im in enumerate(scene.images):  # each image undistorted as one image alone would be (PNG: exactly)
        written = cv2.imread(str(tmp_path / "und" / f"{i}.png"))
        np.testing.assert_array_equal(written, single(im))
        assert np.abs(written.astype(float) - im).mean() > 5  # and not the input: the check can tell

    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5, (640, 480))
    for _ in range(3):
        for im in scene.images:
            writer.write(im)
    writer.release()
    main(video, tmp_path / "v_und.avi", calib, alpha=1.0)
    cap = cv2.VideoCapture(str(tmp_path / "v_und.avi"))
    n = 0
    while cap.read()[0]:
        n += 1
    cap.release()
    assert n == 6
    assert (tmp_path / "v_und.camera.yaml").is_file()
    # each frame undistorted as one image alone would be: within MJPG's loss (a mean of 2-3 here, against 25-40
    # for the input or another alpha's camera), and not the input
    single = Undistorter(calib, alpha=1.0)
    source, out = cv2.VideoCapture(str(video)), cv2.VideoCapture(str(tmp_path / "v_und.avi"))
    for _ in range(n):
        (ok_in, frame), (ok_out, written) = source.read(), out.read()
        assert ok_in and ok_out
        to_single, to_input = (float(np.abs(written.astype(float) - im).mean()) for im in (single(frame), frame))
        assert to_single < 6 and to_input > 15, (to_single, to_input)
    source.release()
    out.release()


def test_bad_input(scene, tmp_path):
    calib = Calibration(scene.K, DIST, (640, 480), 0.0)
    with pytest.raises(InputError, match="calibration is for 640x480"):
        Undistorter(calib)(np.zeros((240, 320, 3), np.uint8))
    with pytest.raises(InputError, match="alpha"):
        Undistorter(calib, alpha=2.0)
    with pytest.raises(InputError, match="no such file"):
        main(tmp_path / "missing.png", tmp_path / "o.png", calib)
    (tmp_path / "bad.png").write_bytes(b"not a png")
    with pytest.raises(InputError, match="cannot read"):
        main(tmp_path / "bad.png", tmp_path / "o.png", calib)


def test_an_output_that_is_the_input_is_refused(scene, tmp_path):
    """An image, a folder or a video onto itself (by any spelling of its path) would be overwritten."""
    calib = Calibration(scene.K, DIST, (640, 480), 0.0)
    folder = tmp_path / "imgs"
    folder.mkdir()
    image = folder / "0.png"
    cv2.imwrite(str(image), scene.images[0])
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5, (640, 480))
    writer.write(scene.images[0])
    writer.release()
    before = {path: path.read_bytes() for path in (image, video)}
    for source, output in ((image, folder / ".." / "imgs" / "0.png"), (folder, folder), (video, video)):
        with pytest.raises(InputError, match="is the input"):
            main(source, output, calib)
    assert {path: path.read_bytes() for path in before} == before
    assert sorted(p.name for p in folder.iterdir()) == ["0.png"]  # no camera.yaml either
    assert sorted(p.name for p in tmp_path.iterdir()) == ["imgs", "v.avi"]
