"""Tests of the pose sequences (BOP layout + COLMAP export)."""

from __future__ import annotations

import json

import cv2
import jsonschema
import numpy as np
import pytest
from scipy.spatial import ConvexHull

from alcn_cv.data import pose
from alcn_cv.data.manifest import MANIFEST_SCHEMA
from alcn_cv.errors import InputError
from alcn_cv.formats import schema
from alcn_cv.formats.bop import load_scene, read_ply
from alcn_cv.formats.colmap import read_text_model
from alcn_cv.io import read_json


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """Small sequences without clutter: the duck is the only possible occluder of the box."""
    return pose.generate(
        tmp_path_factory.mktemp("pose") / "plain", conf="small", n_frames=2, clutter=False, progress=False
    )


def _scenes(root):
    return sorted(p for p in root.glob("*/*") if (p / "scene_camera.json").exists())


def test_layout_and_schemas(plain):
    scenes = _scenes(plain)
    assert [s.relative_to(plain).as_posix() for s in scenes] == (
        [f"test/{k:06d}" for k in range(1, 9)] + ["train/000001"]
    )
    for s in scenes:
        jsonschema.validate(json.loads((s / "scene_camera.json").read_text()), schema("bop_scene_camera"))
        jsonschema.validate(json.loads((s / "scene_gt.json").read_text()), schema("bop_scene_gt"))
        scene = load_scene(s, check_images=True)
        assert len(scene) == (2 * len(pose.TRAIN_SWEEPS) if s.parent.name == "train" else 2)  # 2 views a loop
        for f in scene.frames:
            assert {o.obj_id for o in f.objects} == {1, 2}
            assert cv2.imread(str(f.rgb_path)).shape == (240, 320, 3)
    man = json.loads((plain / "manifest.json").read_text())
    jsonschema.validate(man, read_json(MANIFEST_SCHEMA))
    assert json.loads((plain / "camera.json").read_text())["width"] == 320
    assert [s["change"] for s in man["sequences"][1:]] == ["none"] + ["mild"] * 3 + ["drastic"] * 4
    box = read_ply(plain / "models" / "obj_000001.ply")
    np.testing.assert_allclose(np.ptp(box.vertices, axis=0), pose.BOX_SIZE_MM)
    assert box.texture_file == "obj_000001.png" and (plain / "models" / box.texture_file).exists()
    duck = read_ply(plain / "models" / "obj_000002.ply")
    assert duck.colors is not None and 80 < np.ptp(duck.vertices, axis=0).max() < 200


def _signed_distance(hull: np.ndarray, h: int, w: int) -> np.ndarray:
    """Distance of every pixel centre to a convex polygon's edges' lines, positive inside."""
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    p = hull.reshape(-1, 2)
    area = np.sum(p[:, 0] * np.roll(p[:, 1], -1) - np.roll(p[:, 0], -1) * p[:, 1])
    if area < 0:
        p = p[::-1]
    sd = np.full((h, w), np.inf)
    for a, b in zip(p, np.roll(p, -1, axis=0)):
        e = b - a
        n = np.array([-e[1], e[0]]) / np.linalg.norm(e)  # inward for this orientation in image coords
        sd = np.minimum(sd, (xx - a[0]) * n[0] + (yy - a[1]) * n[1])
    return sd


def test_gt_pose_projects_box_corners_onto_the_drawn_pixels(plain):
    """The box's silhouette is the hull of its projected corners to within 0.5 px."""
    verts = read_ply(plain / "models" / "obj_000001.ply").vertices
    corners = np.unique(verts, axis=0)
    assert len(corners) == 8
    checked = 0
    for s in _scenes(plain):
        for f in load_scene(s).frames:
            gt = f.pose(1)
            pts, _ = cv2.projectPoints(corners, cv2.Rodrigues(gt.R)[0], gt.t, f.K, None)
            pts = pts.reshape(-1, 2)
            hull = pts[ConvexHull(pts).vertices]
            box = cv2.imread(str(s / "mask_visib" / f"{f.im_id:06d}_000000.png"), cv2.IMREAD_GRAYSCALE) > 0
            duck = cv2.imread(str(s / "mask_visib" / f"{f.im_id:06d}_000001.png"), cv2.IMREAD_GRAYSCALE) > 0
            sd = _signed_distance(hull, *box.shape)
            assert not box[sd < -0.5].any()  # nothing drawn more than 0.5 px outside
            missing = (sd > 0.5) & ~box
            assert not (missing & ~duck).any()  # everything 0.5 px inside drawn, unless the duck hides it
            checked += 1
    assert checked == 8 * 2 + 2 * len(pose.TRAIN_SWEEPS)


def test_world_poses_and_colmap_export(plain):
    train = load_scene(plain / "train" / "000001")
    m2w = []
    for f in train.frames:
        o = f.pose(1)
        m2w.append((f.R_w2c.T @ o.R, f.R_w2c.T @ (o.t - f.t_w2c)))
    for R, t in m2w[1:]:  # the box does not move in the world
        np.testing.assert_allclose(R, m2w[0][0], atol=1e-9)
        np.testing.assert_allclose(t, m2w[0][1], atol=1e-6)
    model = read_text_model(plain / "train" / "000001" / "colmap")
    assert len(model.points3d) == 0 and len(model.images) == len(train)
    K, dist = model.cameras[1].to_opencv()
    np.testing.assert_allclose(K, train.frames[0].K, atol=1e-9)
    assert not np.any(dist)
    for f in train.frames:
        im = model.image_by_name(f"{f.im_id:06d}.png")
        np.testing.assert_allclose(im.R_w2c, f.R_w2c, atol=1e-9)
        np.testing.assert_allclose(im.t_w2c, f.t_w2c, atol=1e-6)
        assert (plain / "train" / "000001" / "rgb" / im.name).exists()


def test_same_seed_gives_identical_bytes(tmp_path):
    a = pose.generate(tmp_path / "a", conf="small", n_frames=2, n_test=1, seed=3, progress=False)
    b = pose.generate(tmp_path / "b", conf="small", n_frames=2, n_test=1, seed=3, progress=False, workers=2)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for f in files:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f


def test_training_light_control_changes_only_the_test_lighting(tmp_path):
    kw = dict(conf="small", n_frames=2, n_test=5, seed=3, clutter=False, progress=False)
    lit = pose.generate(tmp_path / "lit", **kw)
    control = pose.generate(tmp_path / "control", training_light=True, **kw)
    man = json.loads((control / "manifest.json").read_text())
    assert man["parameters"]["training_light"] is True
    assert [s["change"] for s in man["sequences"][1:]] == ["none"] * 5
    assert all(s["lighting"] == man["sequences"][0]["lighting"] for s in man["sequences"])
    for rel in ["train/000001", "test/000001"]:  # under the training light in both: the same bytes
        for f in sorted((lit / rel).rglob("*.png")):
            assert f.read_bytes() == (control / f.relative_to(lit)).read_bytes(), f
    # #5 (a grazing light): the same poses and masks, other pixels
    a, b = load_scene(lit / "test" / "000005"), load_scene(control / "test" / "000005")
    for fa, fb in zip(a.frames, b.frames):
        np.testing.assert_array_equal(fa.pose(1).R, fb.pose(1).R)
        np.testing.assert_array_equal(fa.pose(1).t, fb.pose(1).t)
        assert np.abs(cv2.imread(str(fa.rgb_path)).astype(int) - cv2.imread(str(fb.rgb_path))).mean() > 10
    masks = sorted((lit / "test" / "000005" / "mask_visib").glob("*.png"))
    assert masks and all(m.read_bytes() == (control / m.relative_to(lit)).read_bytes() for m in masks)


def _elevations_deg(poses) -> np.ndarray:
    eyes = np.array([-R.T @ t for R, t in poses])
    return np.degrees(np.arcsin(eyes[:, 2] / np.linalg.norm(eyes, axis=1)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_three_sweeps_see_every_stretch_of_azimuth_from_high_and_low(seed):
    """Every 11 consecutive views (about 120 deg of the 330 deg loop) span nearly the 30-60 deg band."""

    def narrowest_span(cycles):
        el = _elevations_deg(
            pose.trajectory(30, np.random.default_rng([seed, 20]), span_deg=330.0, elevation_cycles=cycles)
        )
        return min(np.ptp(el[i : i + 11]) for i in range(len(el) - 10))

    assert narrowest_span(3) > 25.0
    assert narrowest_span(1) < 12.0  # one sweep: a stretch of azimuth is seen from one height only


def test_training_loops_change_only_the_training_sequence(tmp_path):
    kw = dict(conf="small", n_frames=4, n_test=1, seed=3, clutter=False, progress=False)
    one = pose.generate(tmp_path / "one", train_sweeps=(1,), **kw)
    default = pose.generate(tmp_path / "default", **kw)
    assert (
        json.loads((default / "manifest.json").read_text())["parameters"]["train_sweeps"]
        == list(pose.TRAIN_SWEEPS)
        == [1, 3]
    )
    for f in sorted((one / "test").rglob("*.png")) + sorted((one / "test").rglob("*.json")):
        assert f.read_bytes() == (default / f.relative_to(one)).read_bytes(), f
    a, b = load_scene(one / "train" / "000001"), load_scene(default / "train" / "000001")
    assert len(a.frames) == 4 and len(b.frames) == 8
    for fa, fb in zip(a.frames, b.frames):  # the first loop is the single loop
        np.testing.assert_array_equal(fa.R_w2c, fb.R_w2c)
    np.testing.assert_allclose(b.frames[4].R_w2c, b.frames[0].R_w2c)  # the second starts where it starts
    assert not np.allclose(b.frames[5].R_w2c, b.frames[1].R_w2c)  # and then rises and falls faster
    assert len(read_text_model(default / "train" / "000001" / "colmap").images) == 8
    with pytest.raises(InputError, match="--train-sweeps"):
        pose.generate(tmp_path / "bad", train_sweeps=(1, -1), **kw)


def test_zero_frames_and_an_output_under_a_file_are_errors(tmp_path, monkeypatch):
    """--frames 0 is refused, not read as "the size's default" (3 frames, silently); an output under a file fails
    in one line before the rendering."""
    blocker = tmp_path / "file.json"
    blocker.write_text("mine")
    monkeypatch.setattr(pose, "parallel_map", lambda *args, **kwargs: pytest.fail("rendered"))
    with pytest.raises(InputError, match=r"frames >= 1 \(--frames\).*got 0"):
        pose.generate(tmp_path / "zero", conf="small", n_frames=0, progress=False)
    with pytest.raises(InputError, match="is a file"):
        pose.generate(blocker / "pose", conf="small", progress=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.json"]
