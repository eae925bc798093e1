"""pose.build: triangulation with fixed poses (pycolmap), box fit (open3d), CLI, bad input."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from alcn_cv.errors import DatasetError, InputError
from box_points import box_faces
from pose import box_fit, build, plots, sequence, triangulate
from pose import model as pm
from pose.evaluate import relight
from pose.triangulate import MIN_TRACK, Features, collect_points


def _box_surface(rng, size=(140.0, 95.0, 55.0), n=600):
    """Points on the 5 visible faces of a box standing on a plane, plus a large support plane."""
    size = np.asarray(size)
    p = box_faces(rng, size, n)
    plane = np.c_[rng.uniform(-400, 500, (700, 2)), np.zeros(700)]
    under = (plane[:, 0] > -5) & (plane[:, 0] < size[0] + 5) & (plane[:, 1] > -5) & (plane[:, 1] < size[1] + 5)
    plane = plane[~under]
    far = rng.uniform(-2000, 2000, (8, 3))
    return np.vstack([p, plane, far])


def test_fit_box_removes_plane_and_outliers():
    rng = np.random.default_rng(0)
    pts = _box_surface(rng)
    a = np.radians(30)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    world = pts @ R.T + [10, 20, 30]
    fit = box_fit.fit_box(world, known_size=[55, 140, 95])
    assert fit.stats.get("support_plane_points", 0) > 300
    # the points within the plane's RANSAC band are lost with it: the fitted height is a bit short
    assert sorted(fit.stats["fitted_size"]) == pytest.approx([55, 95, 140], abs=7.0)
    assert fit.stats["mean_abs_relative_size_error"] < 0.05
    assert sorted(fit.size) == pytest.approx([55, 95, 140])
    # the fitted corners are the true ones (up to their order)
    true = pm.box_corners([140, 95, 55]) @ R.T + [10, 20, 30]
    d = np.linalg.norm(fit.corners[:, None] - true[None], axis=2).min(1)
    assert d.max() < 8.0
    # scale-free: an unknown scale is fixed by the known size
    fit2 = box_fit.fit_box(world * 0.01, known_size=[55, 140, 95], scale_free=True)
    assert fit2.stats["scale"] == pytest.approx(100, rel=0.05)


def _lid(rng, n=1500, noise=0.8):
    """A 140 x 95 x 55 box seen from above: points on its lid (z = 55) only, with noise."""
    return np.c_[rng.uniform(0, 140, n), rng.uniform(0, 95, n), 55 + rng.normal(0, noise, n)]


def test_fit_box_lid_only_extends_away_from_the_cameras():
    """Only the lid was reconstructed: the known height must hang below it (away from the
    cameras, here above the box), whichever way the noise leans."""
    rng = np.random.default_rng(3)
    lid = _lid(rng)
    above = np.array([[70.0, 40.0, 600.0], [0.0, -300.0, 500.0]])
    for cams, z in ((above, (0.0, 55.0)), (above * [1, 1, -1] + [0, 0, 110], (55.0, 110.0))):
        fit = box_fit.fit_box(lid, known_size=[55, 140, 95], viewpoints=cams)
        assert (fit.corners[:, 2].min(), fit.corners[:, 2].max()) == pytest.approx(z, abs=1.5)
        assert np.ptp(fit.corners[:, 0]) == pytest.approx(140, abs=3) and np.ptp(fit.corners[:, 1]) == pytest.approx(
            95, abs=3
        )


def test_fit_box_frame_from_the_lid_when_a_side_is_badly_triangulated():
    """A side face folded 40 degrees towards the lid (a flattened reconstruction) tilts the
    minimal bounding box; the frame of the best-seen face stays aligned with the box."""
    rng = np.random.default_rng(4)
    lid = _lid(rng, 2000, 0.3)
    s = rng.uniform(0, 1, (500, 2))
    a = np.radians(40)
    side = np.c_[s[:, 0] * 140, -s[:, 1] * 55 * np.cos(a), 55 - s[:, 1] * 55 * np.sin(a)]
    fit = box_fit.fit_box(np.vstack([lid, side]), known_size=[140, 95, 55], viewpoints=np.array([[70, -200, 500.0]]))
    axes = np.abs(fit.R)
    assert axes.max(0) == pytest.approx(1, abs=np.sin(np.radians(2)))  # each axis along x, y or z
    assert sorted(fit.size) == [55, 95, 140]
    assert fit.size[np.argmax(axes[2])] == 55  # the height is the lid's normal


def test_match_known_size_by_the_face_aspect():
    # a 25.8 x 18.9 lid seen in full, its 7.5 height only in part (2 of 7.5): sorting the three
    # lengths would give 7.5 to the lid's shorter edge's partner; the aspect ratio decides
    matched, s = box_fit.match_known_size([4.0, 2.93, 0.3], [18.9, 25.8, 7.5], scale_free=True)
    assert matched.tolist() == [25.8, 18.9, 7.5] and s == pytest.approx(6.45, rel=0.01)
    matched, s = box_fit.match_known_size([95.0, 55.0, 139.0], [140, 95, 55])
    assert matched.tolist() == [95, 55, 140] and s == 1.0


def test_a_partly_seen_height_longer_than_a_face_edge_keeps_the_faces_edges():
    """A 100 x 60 lid measured 100 x 61 with 5 of the 70 mm height seen: the lid's edges get 100 and 60, the height
    70 (a shortfall of the normal costs nothing; charging it would swap 60 and 70)."""
    matched, scale = box_fit.match_known_size(np.array([100.0, 61.0, 5.0]), np.array([70.0, 60.0, 100.0]))
    np.testing.assert_array_equal(matched, [100.0, 60.0, 70.0])
    assert scale == 1.0


def test_a_tilted_box_is_moved_to_touch_its_support_plane():
    """The box's half-extent along the plane's normal is that of the box turned by R: its lowest corner ends on the
    plane z = 0, none below."""
    R = Rotation.from_rotvec(np.radians(40) * np.array([1.0, 2.0, 3.0]) / np.sqrt(14)).as_matrix()
    known = np.array([30.0, 20.0, 10.0])
    center = np.array([5.0, -3.0, 100.0])
    points = center + (np.random.default_rng(0).uniform(-0.5, 0.5, (200, 3)) * known) @ R.T
    size, moved = box_fit.place_known_box(
        points, R, center, np.ones(200, bool), -known / 2, known / 2, known, False, None, np.array([0, 0, 1.0, 0]), {}
    )
    signs = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    corners = moved + (signs * size) @ R.T
    assert corners[:, 2].min() == pytest.approx(0.0, abs=1e-9)


def test_representatives_medoid_then_farthest():
    d = np.array([[0.0, 0], [1, 0], [0, 1], [10, 10], [0.5, 0.5]], np.float32)
    idx = triangulate.representatives(d, cv2.NORM_L2, 2)
    assert idx[0] == 4 and idx[1] == 3  # the medoid, then the most different view
    assert len(triangulate.representatives(d, cv2.NORM_L2, 8)) == 5
    assert triangulate.representatives(d[:1], cv2.NORM_L2, 8).tolist() == [0]
    bits = np.array([[0], [1], [255]], np.uint8)
    assert triangulate.representatives(bits, cv2.NORM_HAMMING, 1).tolist() == [1]


def test_fit_box_degenerate():
    with pytest.raises(DatasetError):
        box_fit.fit_box(np.zeros((5, 3)))
    rng = np.random.default_rng(1)
    flat = np.c_[rng.uniform(0, 10, (200, 2)), np.zeros(200)]
    with pytest.raises(DatasetError, match="flat"):
        box_fit.fit_box(flat)


def test_image_pairs_and_relight():
    assert triangulate.image_pairs(4) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    assert triangulate.image_pairs(4, window=1) == [(0, 1), (1, 2), (2, 3)]
    img = np.full((20, 30, 3), 128, np.uint8)
    out = relight(img)
    assert out.shape == img.shape and out.dtype == np.uint8 and out.std() > 5


def test_bad_inputs(tmp_path):
    with pytest.raises(DatasetError, match="not a BOP scene"):
        sequence.load_sequence(tmp_path)
    with pytest.raises(DatasetError, match="no such file or folder"):
        sequence.load_sequence(tmp_path / "missing.mp4")
    with pytest.raises(InputError, match="intrinsics"):
        build.main(tmp_path / "v.mp4", tmp_path / "m.npz") if (tmp_path / "v.mp4").write_bytes(b"x") else None
    (tmp_path / "photo.jpg").write_bytes(b"x")
    with pytest.raises(InputError, match="build from a video"):
        build.main(tmp_path / "photo.jpg", tmp_path / "m.npz")


def test_triangulation_with_fixed_poses_on_middlebury(shared_data, tmp_path):
    """Real calibrated views: 8 views, known poses held fixed, points must lie on the object."""
    from alcn_cv.formats.middlebury import read_middlebury

    src = shared_data / "middlebury" / "templeSparseRing"
    seq = sequence.load_sequence(src)
    assert seq.registered and seq.units == "m" and len(seq.views) == 16
    views = {v.name: v for v in read_middlebury(src)}
    seq.views = seq.views[:8]  # 8 consecutive views 22.5 deg apart
    model, cams = build.build(seq, feature="SIFT", n_features=4000, work_dir=tmp_path)
    assert len(model.points3d) >= 20
    # the poses were held fixed: the camera centres are the calibrated ones
    centers = np.array([views[v.name].center for v in seq.views])
    assert np.abs(np.sort(cams, 0) - np.sort(centers, 0)).max() < 1e-6
    # points inside the set's published bounding box (README.txt), with a 1 cm margin
    lo, hi = np.array([-0.073568, 0.021728, -0.012445]), np.array([0.028855, 0.181892, 0.062736])
    inside = np.all((model.points3d > lo - 0.01) & (model.points3d < hi + 0.01), axis=1)
    assert inside.mean() > 0.9
    # the views share one camera: the model keeps it, and the size of the frames it is for, for `pose track`
    np.testing.assert_allclose(model.extra["K"], views[seq.views[0].name].K)
    assert model.extra["image_size"] == list(cv2.imread(str(src / seq.views[0].name)).shape[1::-1])
    # seeded RANSAC and mapping: the same model every time
    again, _ = build.build(seq, feature="SIFT", n_features=4000, work_dir=tmp_path)
    np.testing.assert_array_equal(again.points3d, model.points3d)
    np.testing.assert_array_equal(again.corners, model.corners)
    path = pm.save(model, tmp_path / "temple.npz")
    plots.plot_model(model, cams, tmp_path / "temple_cameras.png")
    assert (tmp_path / "temple_cameras.png").stat().st_size > 1000 and path.is_file()


def test_pycolmap_log_goes_to_the_logger(tmp_path, capfd, caplog):
    """pycolmap (glog) wrote about 400 lines to stderr per build; they go to the logger (debug) instead."""
    import pycolmap

    (tmp_path / "images").mkdir()
    from calib.colmap_log import pycolmap_log

    with caplog.at_level("DEBUG", logger="pose.triangulate"), pycolmap_log(triangulate.logger):
        pycolmap.Database.open(tmp_path / "db.db").close()
        pycolmap.incremental_mapping(tmp_path / "db.db", tmp_path / "images", tmp_path)
    assert "pycolmap: " in caplog.text and "Loading database" in caplog.text
    assert "Loading database" not in capfd.readouterr().err


def test_a_build_without_the_pose_extra_says_so_before_the_work(run_python, tmp_path):
    """Without pycolmap, a build from Python (the examples) computed every frame's features, then ended in a
    traceback: one line names the extra first, and nothing is written."""
    proc = run_python(
        """
        import sys
        from alcn_cv.errors import MissingDependencyError
        from pose import build
        try:
            build.main(sys.argv[1], sys.argv[2])
        except MissingDependencyError as exc:
            print(exc)
        """,
        tmp_path / "box.mp4",
        tmp_path / "out" / "model.npz",
        blocked=("pycolmap",),
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == (
        'pose.build.main: needs the [pose] extra (pycolmap is not installed): pip install "alcn-cv[pose]"'
    )
    assert not (tmp_path / "out").exists()


class StopError(Exception):
    """Raised by :func:`pose.build.build` under the fixture ``build_stops``."""


@pytest.fixture
def build_stops(monkeypatch):
    """``pose.build.build`` raising :class:`StopError`: a test stops there, once ``main`` has checked and logged its
    options (the ``[pose]`` extra needed to get there, else skipped)."""
    for module in ("pycolmap", "open3d", "matplotlib"):
        pytest.importorskip(module)

    def stop(*args, **kwargs):
        raise StopError

    monkeypatch.setattr(build, "build", stop)


def test_options_of_a_video_given_for_a_registered_sequence_are_said_to_be_ignored(
    shared_data, tmp_path, caplog, build_stops
):
    """--K, --motion-mask and --refine-focal were silently ignored for a registered sequence."""
    src = shared_data / "middlebury" / "templeSparseRing"
    with caplog.at_level("WARNING", logger="pose.build"), pytest.raises(StopError):
        build.main(src, tmp_path / "m.npz", K=np.eye(3), motion_mask=True, refine_focal=True)
    assert "K, motion_mask, refine_focal apply to a video only, ignored" in caplog.text


def test_a_video_option_is_said_to_be_ignored_exactly_when_given(shared_data, tmp_path, caplog, build_stops):
    """`alcn pose build` passed its defaults of --step and --max-frames on as given: a registered sequence could not
    tell `--step 5` (the default's value, ignored) from no option."""
    from alcn_cv.cli import main

    src = shared_data / "middlebury" / "templeSparseRing"
    for options, ignored in (
        ([], None),
        (["--step", str(sequence.VIDEO_STEP)], "step"),
        (["--max-frames", str(sequence.VIDEO_MAX_FRAMES), "--motion-mask"], "max_frames, motion_mask"),
    ):
        caplog.clear()
        with caplog.at_level("WARNING", logger="pose.build"), pytest.raises(StopError):
            main(["pose", "build", str(src), str(tmp_path / "m.npz"), *options])
        if ignored is None:
            assert "ignored" not in caplog.text
        else:
            assert f"a registered sequence; {ignored} apply to a video only, ignored" in caplog.text


def test_a_presets_video_settings_stay_off_a_registered_sequence(shared_data, tmp_path, caplog, monkeypatch):
    """main(registered, conf="cookie-box", box_size=...) passed the preset's box_units="cm" on (the user's --box-size
    rescaled from cm to the sequence's m) and warned of the preset's K, step, ... as options given: a preset's values
    of a video apply to a video only, the warning names the caller's, and the model records the units its box was
    read in."""
    for module in ("pycolmap", "open3d", "matplotlib"):
        pytest.importorskip(module)
    seen = []

    def record(seq, **kwargs):
        seen.append(kwargs)
        return pm.PartModel(corners=pm.box_corners(np.array([0.1, 0.1, 0.1])), units=seq.units), np.zeros((0, 3))

    monkeypatch.setattr(build, "build", record)
    monkeypatch.setattr(build, "plot_model", lambda *args: None)
    src = shared_data / "middlebury" / "templeSparseRing"  # in m
    with caplog.at_level("WARNING", logger="pose.build"):
        build.main(src, tmp_path / "m.npz", conf="cookie-box", box_size=(0.1, 0.1, 0.1), progress=False)
    assert seen[-1]["box_units"] is None and "ignored" not in caplog.text
    assert (seen[-1]["feature"], seen[-1]["n_features"]) == ("ORB", 3000)  # the preset's settings of any sequence
    recorded = pm.load(tmp_path / "m.npz").extra["build"]
    assert recorded == {
        "conf": "cookie-box",
        "feature": "ORB",
        "n_features": 3000,
        "normalization": "none",
        "box_units": "m",
    }
    with caplog.at_level("WARNING", logger="pose.build"):
        build.main(
            src, tmp_path / "m.npz", conf="cookie-box", step=5, box_size=(10, 10, 10), box_units="cm", overwrite=True
        )
    assert "a registered sequence; step apply to a video only, ignored" in caplog.text
    assert seen[-1]["box_units"] == "cm" and pm.load(tmp_path / "m.npz").extra["build"]["box_units"] == "cm"
    build.main(src, tmp_path / "m.npz", progress=False, overwrite=True)  # no box: no units it was read in
    assert "box_units" not in pm.load(tmp_path / "m.npz").extra["build"]


def test_the_cookie_box_preset_is_the_tutorials_camera_and_alcn_pose_builds_from_it(monkeypatch):
    """The cookie box's settings were written out three times (its two examples and calibration.py, there with the
    focal lengths rounded): one preset, the same values as `alcn pose build` options (build_options, in full)."""
    from alcn_cv.cli import main as alcn

    conf = build.COOKIE_BOX
    assert np.array_equal(conf["K"], [[640 * 55 / 22.3, 0, 320], [0, 480 * 55 / 14.9, 240], [0, 0, 1]])
    assert not conf["K"].flags.writeable  # shared by every build that uses it
    assert {k: v for k, v in conf.items() if k != "K"} == {
        "step": 10,
        "max_frames": 46,
        "motion_mask": True,
        "feature": "ORB",
        "n_features": 3000,
        "box_units": "cm",
        "refine_focal": True,
    }
    calls = []
    monkeypatch.setattr(build, "main", lambda *args, **kwargs: calls.append(kwargs) or Path("model.npz"))
    assert alcn(["pose", "build", "box.mp4", "model.npz", *build.build_options(conf)]) == 0
    # a switch off is written --no-X: it overrides a preset's True (build_options left a False out)
    assert build.build_options({"motion_mask": False, "refine_focal": True}) == ["--no-motion-mask", "--refine-focal"]
    given = {k: calls[0][k] for k in conf}
    assert np.array_equal(given.pop("K"), conf["K"])  # bit for bit: the floats written with repr
    assert given == {k: v for k, v in conf.items() if k != "K"}


class ReconstructionReachedError(Exception):
    """Raised by ``pycolmap.incremental_mapping`` under a test: what reached the reconstruction was recorded."""


def test_a_video_builds_from_a_camera_yaml_with_its_distortion_and_focal_length(
    shared_data, tmp_path, monkeypatch, capsys
):
    """`pose build` had --K but not the --camera that `pose track` takes: K from camera.yaml and its distortion reach
    pycolmap's reconstruction (its database's OPENCV camera), its focal length held fixed even under a preset that
    refines a guessed one (--refine-focal, given, refines it); frames of another size refused from the video's first
    frame, before any frame is extracted; --K with --camera refused."""
    pycolmap = pytest.importorskip("pycolmap")
    from alcn_cv.cli import main
    from calib.camera import write_camera_yaml

    video = shared_data / "cookie_box" / "box.mp4"
    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    dist = np.array([-0.1, 0.02, 0.0, 0.0, 0.0])
    camera = write_camera_yaml(tmp_path / "camera.yaml", K, dist, (640, 480))
    reached = []

    def mapping(db_path, image_dir, out_dir, options, **callbacks):  # the call site of the reconstruction
        db = pycolmap.Database.open(db_path)
        try:
            cameras = [(c.model.name, np.asarray(c.params)) for c in db.read_all_cameras()]
        finally:
            db.close()
        reached.append((cameras, options.ba_refine_focal_length))
        raise ReconstructionReachedError

    monkeypatch.setattr(pycolmap, "incremental_mapping", mapping)
    argv = ["pose", "build", str(video), str(tmp_path / "m.npz"), "--camera", str(camera), "--no-progress"]
    argv += ["--step", "200", "--max-frames", "3", "--box-size", "18.9", "25.8", "7.5"]
    for options, refined in (([], False), (["--conf", "static-camera"], False), (["--refine-focal"], True)):
        with pytest.raises(ReconstructionReachedError):
            main([*argv, *options])
        (model, params), *others = reached[-1][0]
        assert model == "OPENCV" and not others  # one camera for the video's frames
        # fx, fy, cx, cy in COLMAP's pixel convention (+0.5), then k1, k2, p1, p2
        np.testing.assert_allclose(params, [600, 600, 320.5, 240.5, -0.1, 0.02, 0, 0])
        assert reached[-1][1] is refined, options
    monkeypatch.setattr(build, "video_sequence", _no_frames)  # the size is checked before the frames are extracted
    write_camera_yaml(tmp_path / "small.yaml", K, dist, (320, 240))
    with pytest.raises(InputError, match="640x480 but .*small.yaml is for 320x240"):
        build.main(video, tmp_path / "m.npz", camera=tmp_path / "small.yaml", step=200, max_frames=3)
    with pytest.raises(InputError, match="--K or --camera, not both"):
        build.main(video, tmp_path / "m.npz", K=K, camera=camera)
    with pytest.raises(SystemExit) as exc:
        main(["pose", "build", str(video), str(tmp_path / "m.npz"), "--K", "1", "1", "1", "1", "--camera", str(camera)])
    assert exc.value.code == 2 and "not allowed with argument" in capsys.readouterr().err


def _no_frames(*args, **kwargs):
    raise AssertionError("the frames were extracted before the check")


def test_a_calibration_reaches_the_model_and_what_tracks_with_it(tmp_path, monkeypatch):
    """docs/pose.md's build --conf static-camera --camera cam.yaml, then track --camera cam.yaml: the preset refined the
    focal length (the model's K no longer the calibration's) and the model dropped the distortion (tracking without
    --camera undistorted nothing). The model stores K, the distortion and the size; the build records the camera."""
    for module in ("pycolmap", "open3d", "matplotlib"):
        pytest.importorskip(module)
    from calib.camera import write_camera_yaml

    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    dist = np.array([-0.1, 0.02, 0.0, 0.0, 0.0])
    camera = write_camera_yaml(tmp_path / "camera.yaml", K, dist, (640, 480))
    seen = []

    def record(seq, **kwargs):  # the pipeline, replaced: a model of the sequence's camera, as build() stores it
        seen.append(kwargs)
        points = np.random.default_rng(0).uniform(0, 7.5, (10, 3))
        descriptors = np.random.default_rng(0).integers(0, 256, (10, 32), dtype=np.uint8)
        corners = pm.box_corners(np.array([25.8, 18.9, 7.5]))
        model = pm.PartModel(corners=corners, points3d=points, descriptors=descriptors, units="cm")
        model.extra.update(K=seq.views[0].K.tolist(), image_size=[640, 480])
        if seq.views[0].dist is not None:
            model.extra["dist"] = seq.views[0].dist.tolist()
        return model, np.zeros((0, 3))

    monkeypatch.setattr(build, "build", record)
    monkeypatch.setattr(build, "plot_model", lambda *args: None)
    video = tmp_path / "box.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (640, 480))
    for i in range(3):
        writer.write(np.full((480, 640, 3), 40 * i, np.uint8))
    writer.release()
    build.main(video, tmp_path / "m.npz", conf="static-camera", camera=camera, box_size=(18.9, 25.8, 7.5), step=1)
    assert seen[-1]["refine_focal"] is False
    model = pm.load(tmp_path / "m.npz")
    assert model.extra["build"]["camera"] == str(camera) and model.extra["build"]["distortion"] is True
    assert model.extra["build"]["refine_focal"] is False and model.extra["build"]["box_units"] == "cm"
    from pose import track

    box = track.open_tracker(tmp_path / "m.npz")  # the model's camera: K and its distortion
    assert box.camera == "model" and np.allclose(box.K, K) and np.allclose(box.dist, dist)
    assert np.allclose(box.tracker.solver.dist, dist) and box.image_size == (640, 480)
    given = track.open_tracker(tmp_path / "m.npz", camera=camera)
    assert np.allclose(given.K, box.K) and np.allclose(given.dist, box.dist)
    assert track.open_tracker(tmp_path / "m.npz", K).dist is None  # intrinsics given: theirs, without distortion
    build.main(video, tmp_path / "k.npz", conf="static-camera", K=K, box_size=(18.9, 25.8, 7.5), step=1)
    assert seen[-1]["refine_focal"] is True  # a guessed K: the preset refines it
    assert pm.load(tmp_path / "k.npz").extra["build"]["camera"] == "K"


def test_the_cookie_box_preset_refuses_a_video_of_another_size(tmp_path, monkeypatch):
    """examples/track_cookie_box.py --data lumia_box built with the cookie box's 640x480 intrinsics from a 960x544
    video, warned only of a poor box fit, and tracked it as a success: the preset's camera is checked against the
    first frame before the work; intrinsics given replace it, and so pass."""
    for module in ("pycolmap", "open3d", "matplotlib"):
        pytest.importorskip(module)
    video = tmp_path / "box.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (96, 64))
    for i in range(3):
        writer.write(np.full((64, 96, 3), 40 * i, np.uint8))
    writer.release()
    monkeypatch.setattr(build, "video_sequence", _no_frames)  # the size is checked before the frames are extracted
    with pytest.raises(InputError, match="its frames are 96x64 but the preset 'cookie-box''s camera is for 640x480"):
        build.main(video, tmp_path / "m.npz", conf="cookie-box", box_size=(1, 1, 1))
    assert not (tmp_path / "m.npz").exists()
    K = np.array([[90.0, 0, 48], [0, 90.0, 32], [0, 0, 1]])
    with pytest.raises(AssertionError, match="extracted before the check"):  # past the check: the frames' turn
        build.main(video, tmp_path / "m.npz", conf="cookie-box", K=K, box_size=(1, 1, 1))


def test_a_camera_given_for_a_registered_sequence_is_said_to_be_ignored(shared_data, tmp_path, caplog, build_stops):
    from calib.camera import write_camera_yaml

    camera = write_camera_yaml(tmp_path / "camera.yaml", np.eye(3), np.zeros(5), (640, 480))
    with caplog.at_level("WARNING", logger="pose.build"), pytest.raises(StopError):
        build.main(shared_data / "middlebury" / "templeSparseRing", tmp_path / "m.npz", camera=camera)
    assert "a registered sequence; camera apply to a video only, ignored" in caplog.text


def test_the_command_prints_where_the_cameras_plot_is(tmp_path, monkeypatch, capsys):
    """The last line gave the cameras' plot as `model_cameras.png`, without its folder."""
    from alcn_cv.cli import main

    out = tmp_path / "models" / "box.npz"
    monkeypatch.setattr(build, "main", lambda *args, **kwargs: out)
    assert main(["pose", "build", "box.mp4", str(out), "--K", "1", "1", "1", "1", "--box-size", "1", "2", "3"]) == 0
    assert f"its cameras: {tmp_path / 'models' / 'box_cameras.png'})" in capsys.readouterr().out


def test_a_preset_reaches_the_build_and_an_option_given_overrides_it(shared_data, tmp_path, monkeypatch, capsys):
    """The settings that build a hand-held object before a static camera were only in pose.build.COOKIE_BOX and the
    examples, while `alcn pose build`'s defaults fold the box: --conf NAME gives them, an option given overrides the
    preset's value (a switch with --no-...), --K or --camera its camera; the model records the preset and the
    settings used."""
    for module in ("pycolmap", "open3d", "matplotlib"):
        pytest.importorskip(module)
    from alcn_cv.cli import main
    from calib.camera import write_camera_yaml

    video, ply = shared_data / "cookie_box" / "box.mp4", shared_data / "cookie_box" / "box.ply"
    seen = []

    def record(seq, **kwargs):  # the pipeline, replaced by a model that says what reached it
        seen.append((seq, kwargs))
        return pm.PartModel(corners=pm.box_corners(np.array([25.8, 18.9, 7.5])), units="cm"), np.zeros((0, 3))

    monkeypatch.setattr(build, "build", record)
    monkeypatch.setattr(build, "plot_model", lambda *args: None)
    # every run after the first replaces its model
    argv = ["pose", "build", str(video), str(tmp_path / "m.npz"), "--box-ply", str(ply), "--no-progress", "--overwrite"]
    assert main([*argv, "--conf", "cookie-box", "--max-frames", "3"]) == 0
    seq, kwargs = seen[-1]
    assert len(seq.views) == 3 and seq.info["step"] == build.COOKIE_BOX["step"] == 10  # --max-frames overrides 46
    np.testing.assert_array_equal(seq.views[0].K, build.COOKIE_BOX["K"])
    assert kwargs["masks"] is not None and kwargs["refine_focal"] and kwargs["box_units"] == "cm"
    assert (kwargs["feature"], kwargs["n_features"], kwargs["normalization"]) == ("ORB", 3000, "none")
    recorded = pm.load(tmp_path / "m.npz").extra["build"]
    assert recorded == {
        "conf": "cookie-box",
        "feature": "ORB",
        "n_features": 3000,
        "normalization": "none",
        "step": 10,
        "max_frames": 3,
        "motion_mask": True,
        "refine_focal": True,
        "camera": "K",
        "distortion": False,
        "box_units": "cm",
    }
    options = ["--K", "600", "600", "320", "240", "--n-features", "500", "--no-motion-mask", "--max-frames", "3"]
    assert main([*argv, "--conf", "static-camera", *options]) == 0
    seq, kwargs = seen[-1]
    K = np.array([[600.0, 0, 320], [0, 600.0, 240], [0, 0, 1]])
    np.testing.assert_array_equal(seq.views[0].K, K)
    assert kwargs["masks"] is None and kwargs["n_features"] == 500 and kwargs["refine_focal"]
    assert seq.info["step"] == 10 and kwargs["box_units"] == "cm"  # the preset's step; a video's units
    camera = write_camera_yaml(tmp_path / "camera.yaml", K, np.zeros(5), (640, 480))
    assert main([*argv, "--conf", "cookie-box", "--camera", str(camera), "--max-frames", "3"]) == 0  # not "not both"
    np.testing.assert_array_equal(seen[-1][0].views[0].K, K)
    assert not seen[-1][1]["refine_focal"]  # a calibration's focal length is held fixed, whatever the preset
    assert (
        main(
            [
                *argv,
                "--conf",
                "static-camera",
                "--K",
                "600",
                "600",
                "320",
                "240",
                "--max-frames",
                "3",
                *build.build_options({"motion_mask": False}),
            ]
        )
        == 0
    )  # a switch off, given as the command's option
    assert seen[-1][1]["masks"] is None and seen[-1][1]["refine_focal"]
    assert main([*argv, "--K", "600", "600", "320", "240", "--max-frames", "3"]) == 0  # no preset: the defaults
    seq, kwargs = seen[-1]
    assert seq.info["step"] == sequence.VIDEO_STEP and kwargs["masks"] is None and not kwargs["refine_focal"]
    assert kwargs["n_features"] == build.DEFAULTS["n_features"] == 4000
    assert pm.load(tmp_path / "m.npz").extra["build"]["conf"] is None
    capsys.readouterr()
    assert main([*argv, "--conf", "cookie_box"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "alcn pose build: error: unknown preset 'cookie_box'; choose one of static-camera, cookie-box"


def test_presets_are_read_only_settings_of_main():
    """Every preset's keys are keywords of build.main, that no preset can change, COOKIE_BOX is the cookie-box preset,
    and conf_settings lets a value given override the preset's."""
    import inspect

    keywords = set(inspect.signature(build.main).parameters)
    assert set(build.CONFS) == set(build.CONF_SUMMARIES) == {"static-camera", "cookie-box"}
    for name, settings in build.CONFS.items():
        assert set(settings) <= keywords - {"input_path", "output", "box_ply", "box_size", "conf"}, name
        with pytest.raises(TypeError):
            settings["step"] = 5  # type: ignore[index]
    assert build.COOKIE_BOX is build.CONFS["cookie-box"]
    static = dict(build.CONFS["static-camera"])
    assert static == {"step": 10, "motion_mask": True, "feature": "ORB", "n_features": 3000, "refine_focal": True}
    assert {k: v for k, v in build.COOKIE_BOX.items() if k not in ("K", "max_frames", "box_units")} == static
    assert build.conf_settings("cookie-box", step=None, n_features=1000)["n_features"] == 1000
    assert build.conf_settings("cookie-box", motion_mask=False)["motion_mask"] is False
    assert "K" not in build.conf_settings("cookie-box", camera="camera.yaml")
    # a calibration's focal length is measured: held fixed unless refine_focal is given
    assert build.conf_settings("static-camera", camera="camera.yaml")["refine_focal"] is False
    assert build.conf_settings("static-camera", camera="camera.yaml", refine_focal=True)["refine_focal"] is True
    assert build.conf_settings("static-camera", K=np.eye(3))["refine_focal"] is True  # a guessed K: refined
    # a registered sequence: the preset's values of a video left out, the caller's kept
    assert build.conf_settings("cookie-box", video=False) == {"feature": "ORB", "n_features": 3000}
    assert build.conf_settings("cookie-box", video=False, step=3)["step"] == 3
    assert build.conf_settings(None, step=None) == {}
    with pytest.raises(InputError, match="unknown preset 'x'; choose one of static-camera, cookie-box"):
        build.conf_settings("x")


def test_a_degenerate_reconstruction_writes_no_model(shared_data, tmp_path):
    """The cookie box from its first 12 frames of every 10th: 3 images registered, the bundle adjustment pulls fx and
    fy apart (9x) and the box fit is 49% off, yet such a model "tracks" every frame; the build fails instead."""
    from alcn_cv.cli import main

    video, ply = shared_data / "cookie_box" / "box.mp4", shared_data / "cookie_box" / "box.ply"
    argv = ["pose", "build", str(video), str(tmp_path / "m.npz"), "--box-ply", str(ply), "--conf", "cookie-box"]
    assert main([*argv, "--max-frames", "12", "--no-progress"]) == 2
    assert not (tmp_path / "m.npz").exists()


def test_a_point_seen_in_min_track_images_is_kept_one_seen_in_fewer_is_not():
    assert MIN_TRACK == 2
    names = ["a.png", "b.png", "c.png"]
    feats = {
        n: Features(np.zeros((2, 2), np.float32), np.full((2, 32), i, np.uint8), np.full((2, 3), 10 * i, np.uint8))
        for i, n in enumerate(names)
    }

    def point(xyz: list[float], *image_ids: int) -> SimpleNamespace:
        seen = [SimpleNamespace(image_id=i, point2D_idx=0) for i in image_ids]
        return SimpleNamespace(xyz=np.array(xyz), track=SimpleNamespace(elements=seen))

    rec = SimpleNamespace(
        images={i + 1: SimpleNamespace(name=n) for i, n in enumerate(names)},
        points3D={7: point([1.0, 2.0, 3.0], 1, 2), 8: point([4.0, 5.0, 6.0], 3)},
    )
    xyz, desc, owner, lengths, rgb = collect_points(rec, feats, cv2.NORM_HAMMING)
    np.testing.assert_array_equal(xyz, [[1.0, 2.0, 3.0]])
    assert lengths.tolist() == [2] and set(owner.tolist()) == {0} and len(desc) == 2
