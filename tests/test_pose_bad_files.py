"""`alcn pose ...` given bad files: poses of the wrong shape (or their _info.json), corrupt part models, a truncated
video and a --box-ply that is not a box, each refused or told in one line naming the file (the bad-file sweep's
findings)."""

from __future__ import annotations

import json
import logging
import zipfile

import numpy as np
import pytest

from alcn_cv.errors import DatasetError, WeightFileError
from alcn_cv.formats import bop
from alcn_cv.io import open_video_writer
from pose import model as part_model
from pose import track
from pose.model import box_corners
from pose.solver import camera_matrix


def _model() -> part_model.PartModel:
    """A small part model: a box and the 4 points a tracker needs at least."""
    corners = box_corners([20.0, 14.0, 6.0])
    return part_model.PartModel(corners=corners, points3d=corners[:4], descriptors=np.zeros((4, 32), np.uint8))


@pytest.mark.parametrize(
    ("poses", "message"),
    [
        ({"summary": {"frames": 3, "poses": "p.json"}, "frames": {}}, "the _info.json that `alcn pose track` writes"),
        ([1, 2], "not a poses file of `alcn pose track` (frame -> [{cam_R_m2c, cam_t_m2c}]): a JSON list"),
        ({"a": 1}, "frame 'a' is no list of poses"),
        ({"0": [{"cam_R_m2c": [1, 0], "cam_t_m2c": [0, 0, 0]}]}, "frame '0': cam_R_m2c is not 9 finite numbers"),
        ({"0": [{"cam_R_m2c": np.eye(3).ravel().tolist(), "cam_t_m2c": ["a", 0, 0]}]}, "cam_t_m2c is not 3 finite"),
        ({"0": [{"obj_id": 1}]}, "frame '0': cam_R_m2c is missing"),
    ],
)
def test_poses_of_the_wrong_shape_name_the_file_and_field(poses, message, tmp_path):
    """The _info.json given as the poses ended in a traceback (KeyError: 0), other JSON in messages naming neither
    the file nor the field ("'int' object is not subscriptable", "cannot reshape array of size 2")."""
    path = tmp_path / "p6.json"
    path.write_text(json.dumps(poses))
    with pytest.raises(DatasetError) as err:
        track.read_poses(path, "mm")
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value)
    assert "\n" not in str(err.value)


def test_a_corrupt_or_pickled_part_model_is_one_line(tmp_path):
    """A part model with a bad CRC ended in a traceback (zipfile.BadZipFile); one with an object array got numpy's
    advice to load it with allow_pickle."""
    model = _model()
    model.descriptors[:] = 7
    path = part_model.save(model, tmp_path / "m.npz")
    raw = path.read_bytes()  # numpy.savez stores its members: the descriptors' bytes are in the file as they are
    assert zipfile.ZipFile(path).getinfo("descriptors.npy").compress_type == zipfile.ZIP_STORED
    path.write_bytes(raw.replace(bytes([7] * 128), bytes([8] * 128)))
    with pytest.raises(WeightFileError, match=r"m\.npz: corrupt or truncated part model \(Bad CRC-32"):
        part_model.load(path)
    objects = tmp_path / "o.npz"
    np.savez(objects, header=np.array("{}"), corners=np.array([None] * 3, dtype=object))
    with pytest.raises(WeightFileError) as err:
        part_model.load(objects)
    assert (
        str(err.value)
        == f"{objects}: array 'corners' holds pickled Python objects, which are not read: not a part model"
    )


def test_a_truncated_video_is_tracked_with_a_warning(tmp_path, caplog):
    """`pose track` tracked the frames of a truncated video in silence ("tracked 0 of 11 frames") where `normalize`
    refuses it."""
    video = tmp_path / "v.avi"
    writer = open_video_writer(video, 10.0, (64, 48))
    rng = np.random.default_rng(0)
    for _ in range(20):
        writer.write(rng.integers(0, 256, (48, 64, 3), np.uint8))
    writer.release()
    truncated = tmp_path / "t.avi"
    truncated.write_bytes(video.read_bytes()[: video.stat().st_size // 3])
    model = part_model.save(_model(), tmp_path / "m.npz")
    with caplog.at_level(logging.WARNING, logger="pose.track"):
        summary = track.main(
            model, truncated, tmp_path / "p.json", K=camera_matrix(60.0, 60.0, 32.0, 24.0), progress=False
        )
    decoded = summary["frames"]
    assert 0 < decoded < 19
    assert f"{truncated}: decoded {decoded} of the 20 frames its header counts (truncated or corrupt video)" in (
        caplog.text
    )


def _box_ply(path, vertices: np.ndarray) -> None:
    faces = np.array([[0, 1, 2]] * max(1, len(vertices) - 2), np.int64)
    bop.write_ply(path, bop.PlyModel(vertices=vertices, faces=faces, colors=None))


def test_box_ply_that_is_not_a_box_or_not_finite(tmp_path):
    """A tetrahedron's PLY became its bounding box in silence; a box with a NaN vertex failed with "corners must be
    a finite (8, 3) array, got shape (8, 3)", naming no file."""
    box = box_corners([20.0, 14.0, 6.0])
    _box_ply(tmp_path / "box.ply", np.concatenate([box, box[::-1]]))  # a corner repeated, as once per face
    np.testing.assert_allclose(part_model.read_box_corners(tmp_path / "box.ply"), box)
    _box_ply(tmp_path / "tetra.ply", np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], np.float64))
    with pytest.raises(DatasetError) as err:
        part_model.read_box_corners(tmp_path / "tetra.ply")
    assert str(err.value) == (
        f"{tmp_path / 'tetra.ply'}: field 'vertex': its 4 vertices are not the 8 corners of a box (a cuboid mesh)"
    )
    nan = box.copy()
    nan[3] = np.nan
    _box_ply(tmp_path / "nan.ply", nan)
    with pytest.raises(DatasetError, match=r"nan\.ply: field 'vertex': 1 of its vertices are not finite"):
        part_model.read_box_corners(tmp_path / "nan.ply")
