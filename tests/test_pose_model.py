"""pose.model: the part-model file format."""

from __future__ import annotations

import json

import numpy as np
import pytest

from alcn_cv.errors import InputError, WeightFileError
from pose import model as pm


def _model(n=50):
    rng = np.random.default_rng(0)
    return pm.PartModel(
        corners=pm.box_corners([140, 95, 55]),
        points3d=rng.uniform(0, 100, (n, 3)),
        descriptors=rng.integers(0, 256, (n, 32), dtype=np.uint8),
        units="mm",
        box_fit={"object_points": n},
    )


def test_box_corners_and_edges():
    c = pm.box_corners([2, 3, 4], [1, 1, 1])
    assert c.shape == (8, 3)
    assert np.allclose(c.min(0), 1) and np.allclose(c.max(0), [3, 4, 5])
    assert len(pm.BOX_EDGES) == 12
    m = pm.PartModel(corners=c)
    assert np.allclose(m.box_size, [2, 3, 4])
    assert m.diameter == pytest.approx(np.sqrt(4 + 9 + 16))


def test_roundtrip_writes_ply(tmp_path):
    m = _model()
    path = pm.save(m, tmp_path / "box")
    assert path.suffix == ".npz" and path.with_suffix(".ply").is_file()
    back = pm.load(path)
    assert np.allclose(back.corners, m.corners)
    assert np.array_equal(back.descriptors, m.descriptors)
    assert np.allclose(back.points3d, m.points3d, atol=1e-4)
    assert back.units == "mm" and back.box_fit == {"object_points": 50}
    assert back.box_size == pytest.approx([140, 95, 55])
    ply = path.with_suffix(".ply").read_bytes()
    assert ply.startswith(b"ply") and b"element vertex 50" in ply


def test_other_version_and_corrupt_files(tmp_path):
    path = pm.save(_model(), tmp_path / "m.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"]))
    header["version"] = pm.FORMAT_VERSION + 1
    arrays["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "v2.npz", **arrays)
    with pytest.raises(WeightFileError, match=rf"version {pm.FORMAT_VERSION + 1}.*versions 1, 2"):
        pm.load(tmp_path / "v2.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(WeightFileError, match=r"bad.npz: no .npz archive, not a part model \(the .npz of"):
        pm.load(tmp_path / "bad.npz")
    # a video given where the model goes (the commands order their paths differently): not numpy's pickle advice
    (tmp_path / "box.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(64))
    with pytest.raises(WeightFileError, match=r"box.mp4: a video, not a part model") as refused:
        pm.load(tmp_path / "box.mp4")
    assert "pickle" not in str(refused.value)
    with pytest.raises(WeightFileError, match="not found"):
        pm.load(tmp_path / "missing.npz")
    (tmp_path / "m.ply").write_text("ply\n")  # the point cloud save writes beside the model
    with pytest.raises(WeightFileError, match="the model is .*m.npz"):
        pm.load(tmp_path / "m.ply")


def test_several_descriptors_per_point_and_version_1(tmp_path):
    rng = np.random.default_rng(1)
    owner = np.array([0, 0, 1, 2, 2, 2], np.int32)
    m = pm.PartModel(
        corners=pm.box_corners([1, 1, 1]),
        points3d=rng.uniform(0, 1, (3, 3)),
        descriptors=rng.integers(0, 256, (6, 32), dtype=np.uint8),
        descriptor_point=owner,
    )
    back = pm.load(pm.save(m, tmp_path / "m.npz"))
    assert np.array_equal(back.descriptor_point, owner) and np.array_equal(back.descriptors, m.descriptors)
    # a version-1 file (one descriptor per point, no descriptor_point) is still read
    path = pm.save(_model(), tmp_path / "v1.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != "descriptor_point"}
    header = json.loads(str(arrays["header"]))
    header["version"] = 1
    arrays["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "v1.npz", **arrays)
    assert np.array_equal(pm.load(tmp_path / "v1.npz").descriptor_point, np.arange(50))
    del arrays["descriptors"]
    header["version"] = 2
    arrays["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "v2.npz", **arrays)
    with pytest.raises(WeightFileError, match="descriptor"):
        pm.load(tmp_path / "v2.npz")
    with pytest.raises(InputError, match="index the 3 points"):
        pm.PartModel(
            corners=pm.box_corners([1, 1, 1]),
            points3d=np.zeros((3, 3)),
            descriptors=np.zeros((2, 32), np.uint8),
            descriptor_point=[0, 3],
        )


def test_bad_models():
    with pytest.raises(InputError):
        pm.PartModel(corners=np.zeros((4, 3)))
    with pytest.raises(InputError):
        pm.PartModel(
            corners=pm.box_corners([1, 1, 1]), points3d=np.zeros((3, 3)), descriptors=np.zeros((2, 32), np.uint8)
        )
    with pytest.raises(InputError):
        pm.PartModel(corners=pm.box_corners([1, 1, 1]), units="inch")


def test_the_cookie_box_ply_is_read_as_its_cuboid(shared_data):
    corners = pm.read_box_corners(shared_data / "cookie_box" / "box.ply")
    assert sorted(np.round(pm.PartModel(corners=corners).box_size, 1)) == [7.5, 18.9, 25.8]


def test_files_have_normal_permissions(tmp_path):
    """model.npz was written with mode 0600 (the temporary file's): others could not read it."""
    import os

    umask = os.umask(0)
    os.umask(umask)
    path = pm.save(_model(), tmp_path / "box.npz")
    for p in (path, path.with_suffix(".ply")):
        assert p.stat().st_mode & 0o777 == 0o666 & ~umask
    assert not [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temporary file left


def test_version_2_names_the_normalization_normalizer(tmp_path):
    model = _model()
    model.normalization = "clahe"
    path = pm.save(model, tmp_path / "m.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(str(arrays["header"]))
    header["version"] = 2
    header["normalizer"] = header.pop("normalization")
    arrays["header"] = np.array(json.dumps(header))
    np.savez(tmp_path / "v2.npz", **arrays)
    assert pm.load(tmp_path / "v2.npz").normalization == "clahe"


def test_a_header_that_is_not_an_object_is_one_line(tmp_path):
    path = pm.save(_model(), tmp_path / "m.npz")
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["header"] = np.array("[1]")
    np.savez(tmp_path / "list.npz", **arrays)
    with pytest.raises(WeightFileError, match=r"list.npz: the header is not a JSON object; not a part model"):
        pm.load(tmp_path / "list.npz")


def test_a_box_ply_off_the_origin_keeps_its_place(tmp_path):
    """A BOP model is centred on its origin: the corners read from its PLY are at ``[lo, hi]``, not moved to start
    at 0 (which shifted the box the pose is measured on by half its size)."""
    from alcn_cv.formats import bop

    box = pm.box_corners([20.0, 14.0, 6.0], [-10.0, -7.0, -3.0])
    faces = np.array([[0, 1, 2]] * 6, np.int64)
    bop.write_ply(tmp_path / "box.ply", bop.PlyModel(vertices=box, faces=faces, colors=None))
    np.testing.assert_allclose(pm.read_box_corners(tmp_path / "box.ply"), box, atol=1e-6)
