from __future__ import annotations

import cv2
import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from alcn_cv.errors import DatasetError
from calib.conventions import (
    bop_camera_entry,
    camera_from_opencv,
    points_colmap_to_opencv,
    points_opencv_to_colmap,
    read_scene_camera,
    write_scene_camera,
)


def test_same_point_in_three_conventions(tmp_path):
    """A world point projects to u_opencv in OpenCV, u_opencv + 0.5 in COLMAP, and BOP's stored
    pose in mm reproduces the OpenCV projection."""
    K = np.array([[610.0, 0, 322.4], [0, 605.0, 238.9], [0, 0, 1]])
    R = Rotation.from_euler("xyz", [20, -10, 5], degrees=True).as_matrix()
    t_m = np.array([0.05, -0.02, 0.7])
    X_m = np.array([[0.01, 0.02, 0.03], [-0.05, 0.04, 0.0]])
    uv, _ = cv2.projectPoints(X_m, cv2.Rodrigues(R)[0], t_m, K, None)
    uv = uv.reshape(-1, 2)

    cam = camera_from_opencv(K, None, 640, 480)
    rec_cam = pycolmap.Camera(model=cam.model, width=640, height=480, params=cam.params)
    uv_colmap = np.array(rec_cam.img_from_cam((R @ X_m.T).T + t_m))
    np.testing.assert_allclose(uv_colmap, points_opencv_to_colmap(uv), atol=1e-9)
    np.testing.assert_allclose(points_colmap_to_opencv(uv_colmap), uv, atol=1e-9)

    write_scene_camera(tmp_path / "scene_camera.json", {0: bop_camera_entry(K, R, t_m, unit_to_mm=1000.0)})
    K2, R2, t_mm = read_scene_camera(tmp_path / "scene_camera.json")[0]
    uv_bop, _ = cv2.projectPoints(X_m * 1000.0, cv2.Rodrigues(R2)[0], t_mm, K2, None)
    np.testing.assert_allclose(uv_bop.reshape(-1, 2), uv, atol=1e-9)


def test_scene_camera_errors(tmp_path):
    p = tmp_path / "scene_camera.json"
    p.write_text('{"0": {"cam_K": [1, 2, 3]}}')
    with pytest.raises(DatasetError, match="cam_K"):
        read_scene_camera(p)
    p.write_text('{"x": {"cam_K": [1, 0, 0, 0, 1, 0, 0, 0, 1]}}')
    with pytest.raises(DatasetError, match="image id"):
        read_scene_camera(p)
    p.write_text('{"0": ')
    with pytest.raises(DatasetError, match="JSON"):
        read_scene_camera(p)
    entry = bop_camera_entry(np.eye(3))
    assert "cam_R_w2c" not in entry
    write_scene_camera(p, {3: entry})
    K, R, t = read_scene_camera(p)[3]
    assert R is None and t is None
