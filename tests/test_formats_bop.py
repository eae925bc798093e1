"""Tests of the BOP scene and PLY model readers and writers."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from alcn_cv.errors import DatasetError
from alcn_cv.formats.bop import (
    BopFrame,
    BopObjectPose,
    PlyModel,
    load_scene,
    models_info,
    read_ply,
    write_camera,
    write_ply,
    write_scene,
)

K = np.array([[500.0, 0, 319.5], [0, 500.0, 239.5], [0, 0, 1]])


def _frames(n=3):
    out = []
    for i in range(n):
        R = Rotation.from_euler("xyz", [10 * i, 5, -20], degrees=True).as_matrix()
        t = np.array([1.0 * i, -20.0, 600.0])
        out.append(
            BopFrame(
                i,
                None,
                K,
                1.0,
                [BopObjectPose(1, R, t), BopObjectPose(2, R.T, t + 50)],
                R if i else None,
                t if i else None,
            )
        )
    return out


def test_scene_roundtrip(tmp_path):
    write_scene(tmp_path, _frames())
    scene = load_scene(tmp_path)
    assert [f.im_id for f in scene.frames] == [0, 1, 2]
    for a, b in zip(_frames(), scene.frames):
        np.testing.assert_allclose(b.K, K)
        np.testing.assert_allclose(b.pose(2).R, a.objects[1].R, atol=1e-9)
        np.testing.assert_allclose(b.pose(1).t, a.objects[0].t)
        assert b.rgb_path == tmp_path / "rgb" / f"{a.im_id:06d}.png" and b.depth_scale == 1.0
    assert scene.frame(0).R_w2c is None and scene.frame(1).R_w2c is not None
    with pytest.raises(KeyError):
        scene.frame(0).pose(7)
    with pytest.raises(DatasetError, match=r"000000\.png"):
        load_scene(tmp_path, check_images=True)


def test_object_index_is_the_mask_index_of_an_annotated_object():
    frame = _frames(1)[0]
    frame.objects.append(BopObjectPose(1, np.eye(3), np.zeros(3)))  # a second instance: the first one's index
    assert (frame.object_index(1), frame.object_index(2), frame.object_index(7)) == (0, 1, None)
    assert frame.pose(2) is frame.objects[1]


def _edit(path, fn):
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


@pytest.mark.parametrize(
    "file, edit, match",
    [
        ("scene_gt.json", lambda d: d["1"][0].update(cam_t_m2c=[0.001, 0.02, 0.6]), r"1\[0\]\.cam_t_m2c.*wrong unit"),
        ("scene_gt.json", lambda d: d["1"][0].update(cam_R_m2c=[2, 0, 0, 0, 1, 0, 0, 0, 1]), r"cam_R_m2c.*rotation"),
        ("scene_gt.json", lambda d: d["1"][0].update(cam_R_m2c=[1, 0, 0]), r"field 1\[0\]\.cam_R_m2c"),
        ("scene_gt.json", lambda d: d.update({"9": []}), r"field 9.*scene_camera"),
        ("scene_camera.json", lambda d: d["2"].pop("cam_K"), r"field 2.*cam_K"),
        ("scene_camera.json", lambda d: d["2"].pop("cam_t_w2c"), r"field 2.*together"),
        ("scene_camera.json", lambda d: d["0"].update(cam_K=[0, 0, 0, 0, 1, 0, 0, 0, 1]), r"0\.cam_K"),
    ],
)
def test_bad_scene_files_name_file_and_field(tmp_path, file, edit, match):
    write_scene(tmp_path, _frames())
    _edit(tmp_path / file, edit)
    with pytest.raises(DatasetError, match=match) as info:
        load_scene(tmp_path)
    assert file in str(info.value)


def test_missing_and_truncated_scene_files(tmp_path):
    with pytest.raises(DatasetError, match="scene_camera.json: file not found"):
        load_scene(tmp_path)
    write_scene(tmp_path, _frames())
    text = (tmp_path / "scene_gt.json").read_text()
    (tmp_path / "scene_gt.json").write_text(text[:-10])
    with pytest.raises(DatasetError, match="scene_gt.json: malformed or truncated"):
        load_scene(tmp_path)


def _cube(scale=50.0):
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float) * scale
    f = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ]
    )
    return v, f


@pytest.mark.parametrize("binary", [True, False])
def test_ply_roundtrip(tmp_path, binary):
    v, f = _cube()
    m = PlyModel(
        v,
        f,
        v / np.linalg.norm(v, axis=1, keepdims=True),
        np.full((8, 3), 200, np.uint8),
        np.linspace(0, 1, 16).reshape(8, 2),
        "tex.png",
    )
    write_ply(tmp_path / "m.ply", m, binary=binary)
    r = read_ply(tmp_path / "m.ply")
    np.testing.assert_allclose(r.vertices, v, atol=1e-4)
    np.testing.assert_array_equal(r.faces, f)
    np.testing.assert_allclose(r.normals, m.normals, atol=1e-5)
    np.testing.assert_array_equal(r.colors, m.colors)
    np.testing.assert_allclose(r.texcoords, m.texcoords, atol=1e-5)
    assert r.texture_file == "tex.png"
    info = models_info({1: r})["1"]
    assert info["diameter"] == pytest.approx(100 * np.sqrt(3), rel=1e-5) and info["size_x"] == pytest.approx(100)


def test_bad_ply_files(tmp_path):
    v, f = _cube()
    p = write_ply(tmp_path / "m.ply", PlyModel(v, f))
    data = p.read_bytes()
    p.write_bytes(data[:-20])
    with pytest.raises(DatasetError, match="truncated"):
        read_ply(p)
    write_ply(p, PlyModel(v / 1000.0, f))
    with pytest.raises(DatasetError, match="wrong unit"):
        read_ply(p)
    assert read_ply(p, unit_check=False).vertices.max() == pytest.approx(0.05)
    p.write_text("not a ply")
    with pytest.raises(DatasetError, match="not a PLY"):
        read_ply(p)
    with pytest.raises(DatasetError, match="not found"):
        read_ply(tmp_path / "none.ply")
    p.write_text(
        "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\nend_header\n"
        "0 0 0\n10 0 0\n10 10 0\n0 10 0\n4 0 1 2 3\n"
    )
    with pytest.raises(DatasetError, match="triangles"):
        read_ply(p)


def test_image_size_is_checked_against_camera_json(tmp_path):
    scene_dir = tmp_path / "test" / "000001"
    write_scene(scene_dir, _frames(2))
    (scene_dir / "rgb").mkdir()
    for i in range(2):
        cv2.imwrite(str(scene_dir / "rgb" / f"{i:06d}.png"), np.zeros((480, 640, 3), np.uint8))
    write_camera(tmp_path, K, 640, 480)
    assert len(load_scene(scene_dir, check_images=True)) == 2
    cv2.imwrite(str(scene_dir / "rgb" / "000001.png"), np.zeros((240, 320, 3), np.uint8))
    with pytest.raises(DatasetError, match=r"camera.json: fields width/height: 640x480 but .*000001.png is 320x240"):
        load_scene(scene_dir, check_images=True)


def test_a_truncated_jpeg_is_a_dataset_error_naming_the_file(tmp_path):
    scene_dir = tmp_path / "test" / "000001"
    write_scene(scene_dir, _frames(2))
    (scene_dir / "rgb").mkdir()
    image = np.random.default_rng(0).integers(0, 256, (480, 640, 3), np.uint8)
    data = cv2.imencode(".jpg", image)[1].tobytes()
    for i in range(2):
        (scene_dir / "rgb" / f"{i:06d}.jpg").write_bytes(data)
    assert len(load_scene(scene_dir, check_images=True)) == 2
    (scene_dir / "rgb" / "000001.jpg").write_bytes(data[: len(data) // 2])
    with pytest.raises(DatasetError, match=r"scene_camera.json: field 1: .*000001.jpg: truncated or corrupt JPEG"):
        load_scene(scene_dir, check_images=True)


_PLY_HEAD = "ply\nformat ascii 1.0\nelement vertex 3\n{vprops}element face {nf}\n{fprop}end_header\n"
_XYZ = "property float x\nproperty float y\nproperty float z\n"
_FACE = "property list uchar int vertex_indices\n"


@pytest.mark.parametrize(
    "header, body, match",
    [
        (_PLY_HEAD.format(vprops=_XYZ.replace("float x", "foo x"), nf=1, fprop=_FACE), "", "bad property"),
        (_PLY_HEAD.format(vprops=_XYZ, nf=1, fprop=_FACE.replace(" int ", " foo ")), "", "bad property"),
        (_PLY_HEAD.format(vprops=_XYZ, nf=1, fprop="property list uchar vertex_indices\n"), "", "bad property"),
        (_PLY_HEAD.format(vprops=_XYZ, nf=2, fprop=_FACE), "0 0 0\n10 0 0\n0 10 0\n3 0 1 2\n", "truncated"),
        (_PLY_HEAD.format(vprops=_XYZ, nf=1, fprop=_FACE), "0 0 a\n10 0 0\n0 10 0\n3 0 1 2\n", "element vertex"),
        (_PLY_HEAD.format(vprops=_XYZ, nf=1, fprop=_FACE), "0 0 0\n10 0 0\n0 10 0\n3 0 1 x\n", "element face"),
        (_PLY_HEAD.format(vprops=_XYZ, nf=1, fprop=_FACE).replace("vertex 3", "vertex x"), "", "element NAME COUNT"),
    ],
)
def test_malformed_ply_raises_dataset_error(tmp_path, header, body, match):
    """Malformed headers and bodies raise DatasetError, not a bare KeyError/IndexError/ValueError."""
    p = tmp_path / "m.ply"
    p.write_text(header + body)
    with pytest.raises(DatasetError, match=match):
        read_ply(p)
    p.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 0\nend_header")  # no newline after the header
    with pytest.raises(DatasetError):
        read_ply(p)


def test_models_info_sizes_are_per_axis():
    """BOP's models_info.json: size_x, size_y, size_z the extents along x, y, z; diameter the largest distance."""
    corners = np.array([[x, y, z] for x in (-50, 50) for y in (-20, 20) for z in (0, 30)], np.float64)
    info = models_info({3: PlyModel(corners + [1.0, 2.0, 3.0], np.zeros((0, 3), np.int64))})["3"]
    assert (info["size_x"], info["size_y"], info["size_z"]) == (100.0, 40.0, 30.0)
    assert (info["min_x"], info["min_y"], info["min_z"]) == (-49.0, -18.0, 3.0)
    assert info["diameter"] == pytest.approx(np.sqrt(100**2 + 40**2 + 30**2))


def test_the_principal_point_is_checked_against_width_and_height_each(tmp_path):
    """A landscape image: cx may exceed the height (it lies in [0, width)), cy may not exceed the height."""
    R = np.eye(3)

    def scene(cx, cy):
        K = np.array([[500.0, 0, cx], [0, 500.0, cy], [0, 0, 1]])
        folder = tmp_path / f"{cx}_{cy}"
        write_scene(folder, [BopFrame(0, None, K, 1.0, [BopObjectPose(1, R, np.array([0, 0, 600.0]))])])
        (folder / "rgb").mkdir()
        cv2.imwrite(str(folder / "rgb" / "000000.png"), np.zeros((480, 640, 3), np.uint8))
        return folder

    assert len(load_scene(scene(600.0, 100.0), check_images=True)) == 1  # cx beyond the height, inside the width
    with pytest.raises(DatasetError, match="principal point outside"):
        load_scene(scene(100.0, 600.0), check_images=True)  # cy beyond the height
