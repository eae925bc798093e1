from __future__ import annotations

import cv2
import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats import bop
from alcn_cv.formats.bop import BopFrame
from alcn_cv.formats.colmap import (
    camera_from_opencv,
    points_colmap_to_opencv,
    points_opencv_to_colmap,
    read_model,
    write_text_model,
)
from calib.conventions import (
    ARBITRARY_UNITS,
    colmap_from_bop_frames,
    colmap_model_units,
    colmap_unit_to_mm,
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
    assert model.units == "mm" and colmap_unit_to_mm(model, tmp_path / "colmap") == 1.0
    for a in frames:
        im = model.image_by_name(f"{a.im_id:06d}.png")
        assert im.image_id == a.im_id + 1
        np.testing.assert_allclose(model.cameras[im.camera_id].to_opencv()[0], K, atol=1e-9)
        np.testing.assert_allclose(im.R_w2c, a.R_w2c, atol=1e-9)
        np.testing.assert_allclose(im.t_w2c, a.t_w2c, atol=1e-6)
        # Both conventions project a point to the same OpenCV pixel.
        X = np.array([[5.0, -3.0, 2.0]])
        p_bop, _ = cv2.projectPoints(X, cv2.Rodrigues(a.R_w2c)[0], a.t_w2c, a.K, None)
        cam = pycolmap.Camera(model=cameras[0].model, width=640, height=480, params=cameras[0].params)
        p_colmap = np.array(cam.img_from_cam((im.R_w2c @ X.T).T + im.t_w2c))
        np.testing.assert_allclose(points_colmap_to_opencv(p_colmap), p_bop.reshape(-1, 2), atol=1e-6)


def test_a_frame_without_a_camera_pose_is_refused():
    with pytest.raises(InputError, match="no camera pose"):
        colmap_from_bop_frames([BopFrame(0, "a.png", K, 1.0)], (640, 480))


def test_the_units_of_a_colmap_model_follow_its_header(tmp_path):
    """A model whose header says metres is 1000 mm per unit (it was taken as mm: 1000x off); an explicit factor
    still wins; a unit other than mm, cm or m needs one."""
    cameras, images = colmap_from_bop_frames(_frames(2), (640, 480))
    write_text_model(tmp_path / "m", cameras, images, units="m")
    model = read_model(tmp_path / "m")
    assert colmap_model_units(model, tmp_path / "m") == "m" and colmap_unit_to_mm(model, tmp_path / "m") == 1000.0
    assert colmap_unit_to_mm(model, tmp_path / "m", unit_to_mm=1.0) == 1.0
    write_text_model(tmp_path / "ft", cameras, images, units="ft")
    with pytest.raises(InputError, match="units are 'ft'; pass unit_to_mm"):
        colmap_unit_to_mm(read_model(tmp_path / "ft"), tmp_path / "ft")


def test_a_colmap_model_without_a_header_is_in_arbitrary_units_unless_its_registration_says(tmp_path):
    """One rule for `alcn pose` and `alcn calib` (pose read a header-less model as metres, calib as mm, 1000x apart):
    the header, else the registration.json of `alcn calib register` beside the model folder, else arbitrary units,
    which no length is read in."""
    cameras, images = colmap_from_bop_frames(_frames(2), (640, 480))
    folder = tmp_path / "reg" / "colmap"
    write_text_model(folder, cameras, images)
    model = read_model(folder)
    assert model.units is None
    assert colmap_model_units(model) == colmap_model_units(model, folder) == ARBITRARY_UNITS
    with pytest.raises(InputError, match=r"units are arbitrary \(no '# Units:' header.*; pass --unit"):
        colmap_unit_to_mm(model, folder, option="--unit")
    assert colmap_unit_to_mm(model, folder, unit_to_mm=10.0) == 10.0
    (tmp_path / "reg" / "registration.json").write_text('{"units": "arbitrary"}')
    assert colmap_model_units(model, folder) == ARBITRARY_UNITS
    (tmp_path / "reg" / "registration.json").write_text('{"units": "mm"}')
    assert colmap_model_units(model, folder) == "mm" and colmap_unit_to_mm(model, folder) == 1.0
    (tmp_path / "reg" / "registration.json").write_text('{"units": 3}')
    with pytest.raises(DatasetError, match="field 'units'"):
        colmap_model_units(model, folder)
