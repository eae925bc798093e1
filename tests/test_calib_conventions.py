from __future__ import annotations

import cv2
import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from alcn_cv.errors import InputError
from alcn_cv.formats import bop
from alcn_cv.formats.bop import BopFrame
from alcn_cv.formats.colmap import camera_from_opencv, read_model, write_text_model
from calib.conventions import (
    bop_frames_from_colmap,
    colmap_from_bop_frames,
    points_colmap_to_opencv,
    points_opencv_to_colmap,
)

K = np.array([[610.0, 0, 322.4], [0, 605.0, 238.9], [0, 0, 1]])


def _frames(n: int = 3) -> list[BopFrame]:
    R = Rotation.random(n, random_state=4).as_matrix()
    t = np.random.default_rng(4).normal(0, 50, (n, 3)) + [0, 0, 600]
    return [BopFrame(i, f"rgb/{i:06d}.png", K, 1.0, [], R[i], t[i]) for i in range(n)]


def test_same_point_in_opencv_and_colmap():
    R = Rotation.from_euler("xyz", [20, -10, 5], degrees=True).as_matrix()
    t = np.array([50.0, -20.0, 700.0])
    X = np.array([[10.0, 20.0, 30.0], [-50.0, 40.0, 0.0]])
    uv, _ = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, None)
    uv = uv.reshape(-1, 2)
    cam = camera_from_opencv(K, None, 640, 480)
    rec_cam = pycolmap.Camera(model=cam.model, width=640, height=480, params=cam.params)
    uv_colmap = np.array(rec_cam.img_from_cam((R @ X.T).T + t))
    np.testing.assert_allclose(uv_colmap, points_opencv_to_colmap(uv), atol=1e-9)
    np.testing.assert_allclose(points_colmap_to_opencv(uv_colmap), uv, atol=1e-9)


def test_bop_colmap_round_trip(tmp_path):
    frames = _frames()
    bop.write_scene(tmp_path / "scene", frames)
    scene = bop.load_scene(tmp_path / "scene")
    cameras, images = colmap_from_bop_frames(scene.frames, (640, 480))
    assert len(cameras) == 1 and cameras[0].params[2] == pytest.approx(K[0, 2] + 0.5)
    write_text_model(tmp_path / "colmap", cameras, images, units="mm")
    model = read_model(tmp_path / "colmap")
    assert model.units == "mm"
    back = bop_frames_from_colmap(model, tmp_path / "scene" / "rgb")
    for a, b in zip(frames, back):
        assert a.im_id == b.im_id
        np.testing.assert_allclose(b.K, K, atol=1e-9)
        np.testing.assert_allclose(b.R_w2c, a.R_w2c, atol=1e-9)
        np.testing.assert_allclose(b.t_w2c, a.t_w2c, atol=1e-6)
        # Both conventions project a point to the same OpenCV pixel.
        X = np.array([[5.0, -3.0, 2.0]])
        p_bop, _ = cv2.projectPoints(X, cv2.Rodrigues(a.R_w2c)[0], a.t_w2c, a.K, None)
        im = model.image_by_name(f"{a.im_id:06d}.png")
        cam = pycolmap.Camera(model=cameras[0].model, width=640, height=480, params=cameras[0].params)
        p_colmap = np.array(cam.img_from_cam((im.R_w2c @ X.T).T + im.t_w2c))
        np.testing.assert_allclose(points_colmap_to_opencv(p_colmap), p_bop.reshape(-1, 2), atol=1e-6)


def test_distorted_colmap_camera_is_refused_for_bop(tmp_path):
    cameras = [camera_from_opencv(K, [0.1, 0, 0, 0], 640, 480)]
    _, images = colmap_from_bop_frames(_frames(1), (640, 480))
    write_text_model(tmp_path, cameras, images)
    with pytest.raises(InputError, match="distortion"):
        bop_frames_from_colmap(read_model(tmp_path), tmp_path)
    with pytest.raises(InputError, match="no camera pose"):
        colmap_from_bop_frames([BopFrame(0, "a.png", K, 1.0)], (640, 480))


def test_bop_frames_follow_the_colmap_units_header(tmp_path):
    """A model whose header says metres gives BOP translations in mm (it was taken as mm: 1000x off)."""
    cameras, images = colmap_from_bop_frames(_frames(2), (640, 480))
    for im in images:
        im.t_w2c = im.t_w2c / 1000.0
    write_text_model(tmp_path / "m", cameras, images, units="m")
    back = bop_frames_from_colmap(read_model(tmp_path / "m"), tmp_path)
    for f, g in zip(_frames(2), back):
        np.testing.assert_allclose(g.t_w2c, f.t_w2c, atol=1e-9)
    # An explicit factor still wins; an unknown unit needs one.
    np.testing.assert_allclose(
        bop_frames_from_colmap(read_model(tmp_path / "m"), tmp_path, unit_to_mm=1.0)[0].t_w2c, images[0].t_w2c
    )
    write_text_model(tmp_path / "ft", cameras, images, units="ft")
    with pytest.raises(InputError, match="unit_to_mm"):
        bop_frames_from_colmap(read_model(tmp_path / "ft"), tmp_path)
