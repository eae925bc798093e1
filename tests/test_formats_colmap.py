from __future__ import annotations

import numpy as np
import pycolmap
import pytest
from scipy.spatial.transform import Rotation

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats.colmap import (
    ColmapCamera,
    ColmapImage,
    ColmapPoint3D,
    camera_from_opencv,
    camera_from_pycolmap,
    points_colmap_to_opencv,
    points_opencv_to_colmap,
    qvec_from_rotmat,
    read_model,
    rotmat_from_qvec,
    write_text_model,
)


def _images(n: int = 3, seed: int = 0) -> list[ColmapImage]:
    rng = np.random.default_rng(seed)
    R = Rotation.random(n, random_state=seed).as_matrix()
    return [ColmapImage(i + 1, f"{i:06d}.png", 1, R[i], rng.normal(size=3)) for i in range(n)]


def test_qvec_round_trip_and_sign():
    R = Rotation.random(50, random_state=1).as_matrix()
    for r in R:
        q = qvec_from_rotmat(r)
        assert q[0] >= 0 and np.isclose(np.linalg.norm(q), 1)
        np.testing.assert_allclose(rotmat_from_qvec(q), r, atol=1e-12)
    # COLMAP's convention: identity is (1, 0, 0, 0); 90 degrees about z is (c, 0, 0, s).
    np.testing.assert_allclose(qvec_from_rotmat(np.eye(3)), [1, 0, 0, 0])
    Rz = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    np.testing.assert_allclose(qvec_from_rotmat(Rz), [np.sqrt(0.5), 0, 0, np.sqrt(0.5)], atol=1e-12)


def test_opencv_camera_conversion_half_pixel():
    K = np.array([[500.0, 0, 319.5], [0, 510.0, 239.5], [0, 0, 1]])
    cam = camera_from_opencv(K, None, 640, 480)
    assert cam.model == "PINHOLE"
    np.testing.assert_allclose(cam.params, [500, 510, 320, 240])
    K2, d2 = cam.to_opencv()
    np.testing.assert_allclose(K2, K)
    assert not np.any(d2)

    cam = camera_from_opencv(K, [0.1, -0.2, 0.001, 0.002], 640, 480)
    assert cam.model == "OPENCV"
    cam = camera_from_opencv(K, [0.1, -0.2, 0.001, 0.002, 0.05], 640, 480)
    assert cam.model == "FULL_OPENCV"
    K2, d2 = cam.to_opencv()
    np.testing.assert_allclose(d2[:5], [0.1, -0.2, 0.001, 0.002, 0.05])
    with pytest.raises(InputError, match="skew"):
        camera_from_opencv(np.array([[500.0, 1, 320], [0, 500, 240], [0, 0, 1]]), None, 640, 480)


def test_projection_agrees_with_pycolmap():
    """Same 3D point, OpenCV projection + 0.5 == pycolmap's projection of the converted camera."""
    K = np.array([[520.0, 0, 300.2], [0, 515.0, 250.7], [0, 0, 1]])
    dist = np.array([-0.2, 0.05, 0.001, -0.002, 0.01])
    cam = camera_from_opencv(K, dist, 640, 480)
    pc = pycolmap.Camera(model=cam.model, width=640, height=480, params=cam.params)
    X = np.array([[0.1, -0.05, 1.0], [-0.2, 0.1, 2.0]])
    import cv2

    uv_cv, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), K, dist)
    uv_colmap = np.array(pc.img_from_cam(X))
    np.testing.assert_allclose(uv_colmap, uv_cv.reshape(-1, 2) + 0.5, atol=1e-6)


def test_text_round_trip_and_pycolmap_reads_it(tmp_path):
    cam = camera_from_opencv(np.array([[500.0, 0, 320], [0, 500, 240], [0, 0, 1]]), None, 640, 480)
    images = _images()
    images[0].points2d = np.array([[10.5, 20.25], [30.0, 40.0]])
    images[0].point3d_ids = np.array([7, -1])
    points = [ColmapPoint3D(7, [0.1, 0.2, 0.3], [255, 0, 10], 0.5, [[1, 0]])]
    write_text_model(tmp_path / "m", [cam], images, points)
    assert not list((tmp_path / "m").glob("*.tmp"))

    model = read_model(tmp_path / "m")
    assert set(model.images) == {1, 2, 3}
    for im in images:
        got = model.images[im.image_id]
        np.testing.assert_allclose(got.R_w2c, im.R_w2c, atol=1e-12)
        np.testing.assert_allclose(got.t_w2c, im.t_w2c)
    np.testing.assert_allclose(model.images[1].points2d, images[0].points2d)
    assert model.points3d[7].track.tolist() == [[1, 0]]

    # pycolmap reads our text model, and our reader reads its binary export.
    rec = pycolmap.Reconstruction(str(tmp_path / "m"))
    assert rec.num_images() == 3
    pose = rec.images[2].cam_from_world()
    np.testing.assert_allclose(pose.rotation.matrix(), images[1].R_w2c, atol=1e-9)
    (tmp_path / "b").mkdir()
    rec.write_binary(str(tmp_path / "b"))
    binary = read_model(tmp_path / "b")
    np.testing.assert_allclose(binary.images[3].t_w2c, images[2].t_w2c)
    np.testing.assert_allclose(binary.cameras[1].params, cam.params)
    assert binary.images[1].point3d_ids.tolist() == [7, -1]


def test_empty_points_file(tmp_path):
    cam = ColmapCamera(1, "SIMPLE_PINHOLE", 64, 48, [50.0, 32.0, 24.0])
    write_text_model(tmp_path, [cam], _images(2))
    lines = [line for line in (tmp_path / "points3D.txt").read_text().splitlines() if not line.startswith("#")]
    assert lines == []
    assert read_model(tmp_path).points3d == {}


def test_bad_files(tmp_path):
    with pytest.raises(DatasetError, match="no COLMAP model"):
        read_model(tmp_path)
    cam = ColmapCamera(1, "PINHOLE", 64, 48, [50.0, 50.0, 32.0, 24.0])
    write_text_model(tmp_path, [cam], _images(2))
    text = (tmp_path / "images.txt").read_text().replace(" 1 000001.png", " 9 000001.png")
    (tmp_path / "images.txt").write_text(text)
    with pytest.raises(DatasetError, match="CAMERA_ID=9"):
        read_model(tmp_path)
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 64 48 50 50 32\n")
    with pytest.raises(DatasetError, match=r"cameras.txt:1"):
        read_model(tmp_path)
    (tmp_path / "cameras.txt").write_text("1 PINHOLE 64 48 50 50 32 abc\n")
    with pytest.raises(DatasetError, match="PARAMS"):
        read_model(tmp_path)
    with pytest.raises(InputError, match="camera_id 2"):
        write_text_model(tmp_path / "x", [cam], [ColmapImage(1, "a.png", 2, np.eye(3), np.zeros(3))])


@pytest.mark.parametrize("model", ["SIMPLE_DIVISION", "DIVISION", "SIMPLE_FISHEYE", "FISHEYE", "EUCM"])
def test_every_pycolmap_camera_model_is_read(tmp_path, model):
    """COLMAP's newer camera models are valid files: read them (to_opencv refuses them, as fisheyes)."""
    pc = pycolmap.Camera.create_from_model_id(1, getattr(pycolmap.CameraModelId, model), 100.0, 64, 48)
    cam = ColmapCamera(1, model, 64, 48, np.array(pc.params))
    write_text_model(tmp_path, [cam], _images(1))
    read = read_model(tmp_path).cameras[1]
    assert read.model == model and read.params.size == len(pc.params)
    with pytest.raises(InputError, match="no OpenCV pinhole equivalent"):
        read.to_opencv()


@pytest.mark.parametrize(
    "file, text, match",
    [
        ("cameras.txt", "1 PINHOLE 64 48 50 50 32 24\n1 PINHOLE 64 48 60 60 32 24\n", "duplicate id 1"),
        ("images.txt", "1 1 0 0 0 0 0 1 1 a.png\n\n1 1 0 0 0 0 0 1 1 b.png\n\n", "duplicate id 1"),
        ("images.txt", "1 1 0 0 0 0 0 1 1 a.png\n1.0 2.0 3.5\n", "POINT3D_ID"),
        ("points3D.txt", "1 0 0 1 300 0 0 0.5\n", "RGB"),
        ("points3D.txt", "1 0 0 1 3 0 0 0.5 1.5 0\n", "TRACK"),
        ("points3D.txt", "1 0 0 1 3 0 0 0.5\n1 0 0 2 3 0 0 0.5\n", "duplicate id 1"),
    ],
)
def test_malformed_values_are_refused_not_silently_changed(tmp_path, file, text, match):
    """Duplicate ids (one record lost), colours beyond 0..255 (wrapped) and fractional ids (truncated)."""
    cam = ColmapCamera(1, "PINHOLE", 64, 48, [50.0, 50.0, 32.0, 24.0])
    write_text_model(tmp_path, [cam], [])
    (tmp_path / file).write_text(text)
    with pytest.raises(DatasetError, match=match):
        read_model(tmp_path)


def test_a_pycolmap_camera_converts_to_opencv_by_the_modules_half_pixel():
    """pose.build converted a refined pycolmap camera by hand (``calibration_matrix()``, ``cx - 0.5``); the half pixel
    has one owner here (points_colmap_to_opencv), which camera_from_pycolmap's to_opencv goes through."""
    for model, params in (
        ("SIMPLE_PINHOLE", [650.3, 320.5, 240.5]),
        ("OPENCV", [640.2, 655.0, 321.1, 239.9, 0.1, 0, 0, 0]),
    ):
        cam = pycolmap.Camera(model=model, width=640, height=480, params=params)
        K, _ = camera_from_pycolmap(cam).to_opencv()
        expected = cam.calibration_matrix()
        expected[:2, 2] = points_colmap_to_opencv(expected[:2, 2])
        np.testing.assert_array_equal(K, expected)
    np.testing.assert_array_equal(points_opencv_to_colmap([[0.0, 0.0]]), [[0.5, 0.5]])


@pytest.mark.parametrize(
    "model, params, dist",
    [
        ("SIMPLE_RADIAL", [500.0, 320.5, 240.5, 0.1], [0.1, 0.0, 0.0, 0.0]),
        ("RADIAL", [500.0, 320.5, 240.5, 0.1, -0.02], [0.1, -0.02, 0.0, 0.0]),
    ],
)
def test_radial_cameras_keep_their_distortion_in_opencv(model, params, dist):
    """COLMAP's SIMPLE_RADIAL names its one coefficient ``k``: it is OpenCV's k1, not dropped."""
    K, d = ColmapCamera(1, model, 640, 480, params).to_opencv()
    np.testing.assert_allclose(d, dist)
    np.testing.assert_allclose(K, [[500.0, 0, 320.0], [0, 500.0, 240.0], [0, 0, 1]])


def test_image_center_is_the_point_the_camera_maps_to_its_origin():
    """``center`` is ``-R_w2c.T @ t_w2c``: the world point at the camera's origin, ``R_w2c @ C + t_w2c = 0``. With
    ``R_w2c`` for its transpose the centre was right only for symmetric rotations; only the shared-data
    registration test noticed."""
    for im in _images(5, seed=3):
        np.testing.assert_allclose(im.R_w2c @ im.center + im.t_w2c, 0.0, atol=1e-12)
