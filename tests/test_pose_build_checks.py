"""pose.build's checks of its inputs and of the box fit, on synthetic points (the features, matches and triangulation
replaced: no pycolmap), and the units of a registration read by pose.sequence."""

from __future__ import annotations

import json
import logging
from pathlib import Path
from types import SimpleNamespace

import cv2
import numpy as np
import pytest

from alcn_cv.errors import DatasetError, InputError
from alcn_cv.formats import bop
from box_points import box_faces
from pose import build, sequence
from pose import model as pm

pytest.importorskip("open3d")  # the box fit

BOX = np.array([140.0, 95.0, 55.0])  # x, y, z of the synthetic box, mm
K = np.array([[500.0, 0, 320], [0, 500.0, 240], [0, 0, 1]])


def _box_points(size=BOX, n=3000, seed=0) -> np.ndarray:
    """Points on the 5 visible faces of an axis-aligned box [0, size] (the bottom unseen)."""
    return box_faces(np.random.default_rng(seed), size, n)


def _cameras(n=6) -> list[tuple[np.ndarray, np.ndarray]]:
    """World-to-camera poses of ``n`` cameras around and above the box, looking at its centre."""
    poses = []
    centre = BOX / 2
    for a in np.linspace(0, 2 * np.pi, n, endpoint=False):
        c = centre + 600 * np.array([np.cos(a), np.sin(a), 0.8])
        z = (centre - c) / np.linalg.norm(centre - c)
        x = np.cross(z, [0, 0, 1.0])
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(z, x), z])
        poses.append((R, -R @ c))
    return poses


def _sequence(units="mm") -> sequence.TrainingSequence:
    views = [sequence.TrainingView(f"{i:06d}.png", K, None, R, t) for i, (R, t) in enumerate(_cameras())]
    return sequence.TrainingSequence(Path("."), views, units, (640, 480), info={"path": "seq"})


@pytest.fixture
def triangulated(monkeypatch):
    """pose.build's features, matches and triangulation replaced: the triangulation gives ``points["xyz"]`` (set by
    the test) seen by the cameras of :func:`_sequence`."""
    points = {"xyz": _box_points()}

    def rec(seq, *args):
        images = {
            i: SimpleNamespace(
                name=v.name,
                camera_id=1,
                has_pose=True,
                projection_center=lambda v=v: -v.R_w2c.T @ v.t_w2c,
                cam_from_world=lambda v=v: SimpleNamespace(matrix=lambda: np.hstack([v.R_w2c, v.t_w2c[:, None]])),
            )
            for i, v in enumerate(seq.views)
        }
        return SimpleNamespace(cameras={}, images=images)  # a registered sequence: its cameras are not read back

    def collect(*args, **kwargs):
        xyz = points["xyz"]
        n = len(xyz)
        return xyz, np.zeros((n, 32), np.uint8), np.arange(n), np.full(n, 3), np.zeros((n, 3), np.uint8)

    monkeypatch.setattr(build, "extract_features", lambda *a, **k: {})
    monkeypatch.setattr(build, "write_database", lambda *a, **k: None)
    monkeypatch.setattr(build, "triangulate_fixed_poses", rec)
    monkeypatch.setattr(build, "collect_points", collect)
    return points


def _box_ply(path: Path, size=BOX, origin=(0.0, 0.0, 0.0)) -> Path:
    corners = pm.box_corners(np.asarray(size, np.float64), np.asarray(origin, np.float64))
    bop.write_ply(path, bop.PlyModel(corners, np.zeros((0, 3), np.int64)))
    return path


def test_a_known_box_the_points_miss_suggests_box_size(triangulated, tmp_path):
    """A --box-ply placed elsewhere than the sequence's points (its poses not in the box's frame) failed with no hint
    that --box-size, the size alone, works."""
    ply = _box_ply(tmp_path / "box.ply", origin=(5000.0, 0.0, 0.0))
    with pytest.raises(DatasetError, match=r"only 0 triangulated points lie on the known box.*--box-size W H D"):
        build.build(_sequence(), box_ply=ply, work_dir=tmp_path)
    model, _ = build.build(_sequence(), box_size=BOX[[2, 0, 1]], work_dir=tmp_path)  # any order
    assert model.box_fit["mean_abs_relative_size_error"] < 0.05


def test_the_box_fit_is_logged_in_the_order_of_the_models_box(triangulated, tmp_path, caplog):
    """One build logged the box as [189, 75, 258] (the fit's axes: face edges, normal) and [189, 258, 75] (the model's
    box, the .ply's x, y, z): the fit's sizes are reordered to the model's."""
    with caplog.at_level(logging.INFO):
        model, _ = build.build(_sequence(), box_ply=_box_ply(tmp_path / "box.ply"), work_dir=tmp_path)
        pm.save(model, tmp_path / "m.npz")
    assert model.box_size.tolist() == BOX.tolist()
    assert model.box_fit["known_size"] == BOX.tolist()
    assert np.allclose(model.box_fit["fitted_size"], BOX, rtol=0.05)
    assert "box fit error vs the known size" in caplog.text and "per edge x, y, z" in caplog.text
    assert "[55.0, 140.0, 95.0]" not in caplog.text  # the fit's order (face edges, normal) is not logged
    assert "[140.0, 95.0, 55.0] mm" in caplog.text  # the model's, as `wrote part model` gives it


def test_a_poor_box_fit_warns_in_every_branch(triangulated, tmp_path, caplog):
    """A fit 8-10% off the known size was logged at INFO (warned over 10%, and never with --box-ply)."""
    triangulated["xyz"] = _box_points(BOX * 0.92)
    for given in ({"box_ply": _box_ply(tmp_path / "box.ply")}, {"box_size": BOX}):
        caplog.clear()
        with caplog.at_level(logging.INFO, logger="pose.build"):
            build.build(_sequence(), work_dir=tmp_path, **given)
        (record,) = [r for r in caplog.records if "box fit error" in r.getMessage()]
        assert record.levelno == logging.WARNING and "fit the box poorly" in record.getMessage(), given


def test_a_box_fit_far_off_the_known_size_fails(triangulated, tmp_path):
    """Points in other units than the box (arbitrary units read as mm: 95% off) built a model that tracked nothing."""
    triangulated["xyz"] = _box_points(BOX / 20)
    for given in ({"box_size": BOX}, {"box_size": BOX / 10, "box_units": "cm"}):
        with pytest.raises(DatasetError, match=r"off the known size on the edges its points cover.*over 20%"):
            build.build(_sequence(), work_dir=tmp_path, **given)
    triangulated["xyz"] = _box_points()
    with pytest.raises(DatasetError, match="--box-units"):  # a box of 140 cm for points of 140 mm
        build.build(_sequence(), box_size=BOX, box_units="cm", work_dir=tmp_path)


def test_the_box_fit_against_a_box_ply_is_measured_along_its_edges(triangulated, tmp_path):
    """A box turned against its --box-ply (its points those of a 55 x 95 x 140 box, the .ply 140 x 95 x 55) had the
    known lengths matched to its axes in another order: it built, 23% off, logged "per edge x, y, z" with the known
    size [55, 140, 95], while the model's box is the .ply's. The fit is measured against the .ply along its x, y, z:
    55 along the .ply's 140."""
    triangulated["xyz"] = _box_points(BOX[[2, 1, 0]])
    with pytest.raises(DatasetError) as exc:
        build.build(_sequence(), box_ply=_box_ply(tmp_path / "box.ply"), work_dir=tmp_path)
    message = str(exc.value)
    assert "known [140.0, 95.0, 55.0] mm, off by [-8" in message and "along the edges x, y, z" in message


def test_a_box_fit_failure_names_what_can_be_off_in_its_branch():
    """A video's fit is scaled to the box's size, so its units cannot be off: the failure said "not in these units;
    check --box-units" there too."""
    stats = {
        "known_size": BOX.tolist(),
        "size_error": (BOX * [0.5, -0.3, 0.0]).tolist(),
        "mean_abs_relative_size_error": 0.27,
        "seen_relative_size_error": 0.27,
    }
    with pytest.raises(DatasetError) as video:
        build.check_box_fit(stats, "cm", scale_free=True)
    assert "units" not in str(video.value).split(":", 1)[1] and "--refine-focal" in str(video.value)
    with pytest.raises(DatasetError, match="not in these units; check --box-size/--box-ply and --box-units"):
        build.check_box_fit(stats, "mm")


def test_a_registered_sequences_camera_is_stored_with_its_distortion(triangulated, tmp_path):
    """The model stored K alone: frames of a distorted camera were tracked as undistorted."""
    dist = np.array([-0.1, 0.02, 0.0, 0.0, 0.0])
    seq = _sequence()
    for view in seq.views:
        view.dist = dist
    model, _ = build.build(seq, box_size=BOX, work_dir=tmp_path)
    assert model.extra["K"] == K.tolist() and model.extra["dist"] == dist.tolist()
    model, _ = build.build(_sequence(), box_size=BOX, work_dir=tmp_path)
    assert "K" in model.extra and "dist" not in model.extra


def test_check_box_fit_thresholds(caplog):
    def stats(rel):
        rel = np.asarray(rel, np.float64)
        return {
            "known_size": BOX.tolist(),
            "size_error": (rel * BOX).tolist(),
            "mean_abs_relative_size_error": float(np.abs(rel).mean()),
            "seen_relative_size_error": float(np.r_[np.abs(rel[:2]), max(rel[2], 0)].mean()),
        }

    with caplog.at_level(logging.INFO, logger="pose.build"):
        build.check_box_fit(stats([0.014, -0.014, 0.054]), "cm")  # the cookie box's recipe: 2.7%
        build.check_box_fit(stats([0.082, -0.076, 0.057]), "cm")  # the tutorial's focal length not refined: 7.2%
        build.check_box_fit(stats([0.02, 0.01, -0.9]), "cm")  # only the lid seen: its normal short, as expected
    assert [r.levelno for r in caplog.records] == [logging.INFO, logging.WARNING, logging.WARNING]
    with pytest.raises(DatasetError, match="62% off"):
        build.check_box_fit(stats([-0.951, -0.908, -0.989]), "mm")  # the walk's arbitrary units read as mm
    build.check_box_fit({}, "mm")  # no known size: nothing to say


def test_fit_box_reports_the_error_on_what_its_points_cover():
    """Only the lid seen: the box's height is not measured, and does not count in ``seen_relative_size_error``."""
    from pose.box_fit import fit_box

    rng = np.random.default_rng(3)
    lid = np.c_[rng.uniform(0, 140, 1500), rng.uniform(0, 95, 1500), 55 + rng.normal(0, 0.8, 1500)]
    fit = fit_box(lid, known_size=[55, 140, 95], viewpoints=np.array([[70.0, 40.0, 600.0]]))
    assert fit.stats["mean_abs_relative_size_error"] > 0.3
    assert fit.stats["seen_relative_size_error"] < 0.05


def _registration(root: Path, units: str) -> Path:
    """A registration folder as `alcn calib register` writes it: BOP scene, colmap/ and registration.json."""
    from alcn_cv.formats.colmap import write_text_model
    from calib.conventions import colmap_from_bop_frames

    (root / "rgb").mkdir(parents=True)
    frames = []
    for i, (R, t) in enumerate(_cameras(3)):
        path = root / "rgb" / f"{i:06d}.png"
        cv2.imwrite(str(path), np.zeros((480, 640, 3), np.uint8))
        frames.append(bop.BopFrame(i, path, K, 1.0, [], R, t / (100 if units == "arbitrary" else 1)))
    bop.write_scene(root, frames)
    cameras, images = colmap_from_bop_frames(frames, (640, 480))
    write_text_model(root / "colmap", cameras, images, None, units=None if units == "arbitrary" else units)
    (root / "registration.json").write_text(json.dumps({"units": units, "frames": []}))
    return root


def test_a_registration_without_a_known_length_is_read_in_arbitrary_units(tmp_path):
    """`alcn calib register --method sfm` without --known-distance records "units": "arbitrary"; its BOP scene was read
    as millimetres and its COLMAP model as metres."""
    reg = _registration(tmp_path / "reg", "arbitrary")
    assert sequence.load_sequence(reg).units == "arbitrary"
    assert sequence.load_sequence(reg / "colmap").units == "arbitrary"
    mm = _registration(tmp_path / "mm", "mm")
    assert sequence.load_sequence(mm).units == "mm" and sequence.load_sequence(mm / "colmap").units == "mm"
    (mm / "registration.json").unlink()  # a BOP scene of its own, a COLMAP model without a header: as before
    assert sequence.load_sequence(mm).units == "mm"
    assert sequence.load_sequence(mm).size == sequence.load_sequence(mm / "colmap").size == (640, 480)


def test_a_colmap_model_without_units_is_in_arbitrary_units_as_calib_reads_it(tmp_path):
    """A COLMAP model without a "# Units:" line and without a registration beside it was read as metres by pose and
    as millimetres by calib; both now read it by calib.conventions.colmap_model_units: arbitrary, refused."""
    from alcn_cv.formats.colmap import read_model
    from calib.conventions import colmap_model_units

    reg = _registration(tmp_path / "reg", "arbitrary")
    (reg / "registration.json").unlink()
    seq = sequence.load_sequence(reg / "colmap")
    assert seq.units == colmap_model_units(read_model(reg / "colmap"), reg / "colmap") == "arbitrary"
    with pytest.raises(InputError, match=r"arbitrary units .*'# Units: mm'"):
        sequence.check_known_units(seq, "a part model")


def test_a_build_in_arbitrary_units_is_refused_in_one_line(tmp_path, capsys):
    """The walk's build from such a registration succeeded with a model 95% off its box that tracked no frame."""
    from alcn_cv.cli import main

    with pytest.raises(InputError, match="arbitrary units.*--known-distance"):
        build.build(_sequence("arbitrary"), box_size=BOX)
    reg = _registration(tmp_path / "reg", "arbitrary")
    for source in (reg, reg / "colmap"):
        assert main(["pose", "build", str(source), str(tmp_path / "m.npz"), "--box-size", "14", "9.5", "5.5"]) == 2
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err
        assert "arbitrary units" in err and "--known-distance FRAME_A FRAME_B MM" in err and "--box-size" in err
    assert not (tmp_path / "m.npz").exists()
    assert main(["pose", "build", str(reg), str(tmp_path / "new" / "m.npz"), "--box-size", "14", "9.5", "5.5"]) == 2
    assert not (tmp_path / "new").exists()  # the failed build left an empty folder
    capsys.readouterr()


def test_train_corners_and_eval_refuse_arbitrary_units_as_build_does(tmp_path, capsys, monkeypatch):
    """`alcn pose train-corners` and `alcn pose eval` read a registration in arbitrary units as millimetres (the box
    projected at the wrong depth): all three commands refuse it through one check, pose.sequence.check_known_units,
    before any work."""
    from alcn_cv.cli import main
    from pose import corner_train, evaluate

    assert build.check_known_units is sequence.check_known_units is evaluate.check_known_units
    monkeypatch.setattr(evaluate, "build_model", _no_work)  # nothing past the check runs
    monkeypatch.setattr(corner_train, "build_frames", _no_work)
    reg = _registration(tmp_path / "reg", "arbitrary")
    ply = _box_ply(tmp_path / "box.ply")
    data = tmp_path / "data"  # an `alcn pose eval` data set whose training sequence is that registration
    (data / "train").mkdir(parents=True)
    reg.rename(data / "train" / "000001")
    _registration(data / "test" / "000001", "mm")
    (data / "models").mkdir()
    ply.rename(data / "models" / "obj_000001.ply")
    ply = data / "models" / "obj_000001.ply"
    for argv in (
        ["pose", "train-corners", str(data / "train" / "000001"), str(tmp_path / "c.onnx"), "--box-ply", str(ply)],
        ["pose", "eval", "--data", str(data), "--out", str(tmp_path / "r"), "--detectors", "features", "corners"],
    ):
        assert main([*argv, "--no-progress"]) == 2, argv
        err = capsys.readouterr().err.strip()
        assert len(err.splitlines()) == 1 and "Traceback" not in err, err
        assert "arbitrary units" in err and "--known-distance FRAME_A FRAME_B MM" in err, err
    assert not (tmp_path / "c.onnx").exists()
    with pytest.raises(InputError, match="a corner detector .*needs known units"):
        corner_train.train_corners(data / "train" / "000001", pm.read_box_corners(ply), tmp_path / "c.onnx")
    sequence.check_known_units(_sequence("mm"), "anything")  # known units: nothing to say
    checked = []  # train_corners runs the one check, pose.sequence's, where it runs (imported at the call)
    monkeypatch.setattr(sequence, "check_known_units", lambda seq, what, *a: checked.append(what) or _no_work())
    with pytest.raises(AssertionError, match="the work began"):
        corner_train.train_corners(data / "test" / "000001", pm.read_box_corners(ply), tmp_path / "c.onnx")
    assert checked == ["a corner detector (its box projected by the poses)"]


def _no_work(*args, **kwargs):
    raise AssertionError("the work began before the check")


def test_a_corner_detectors_box_is_projected_in_its_sequences_units(tmp_path, monkeypatch):
    """``alcn pose train-corners --box-ply`` reads the cuboid in mm; a registration in cm is projected in cm: the box
    given to the frames is scaled to it, and the detector records cm."""
    from pose import corner_train

    reg = _registration(tmp_path / "reg", "cm")
    seen = {}

    def frames(seq, corners, *args, **kwargs):
        seen["corners"] = corners
        raise RuntimeError("stop")

    monkeypatch.setattr(corner_train, "build_frames", frames)
    corners = pm.box_corners(np.array([189.0, 258.0, 75.0]))  # mm
    with pytest.raises(RuntimeError, match="stop"):
        corner_train.train_corners(reg, corners, tmp_path / "c.onnx", units="mm")
    np.testing.assert_allclose(seen["corners"], corners / 10)


def test_a_corner_detectors_sequence_in_other_units_is_refused(tmp_path, monkeypatch):
    """A registration in units other than mm, cm or m projected the box unconverted (the conversion was skipped)."""
    from pose import corner_train

    reg = _registration(tmp_path / "reg", "in")
    monkeypatch.setattr(corner_train, "build_frames", _no_work)
    with pytest.raises(InputError, match="unknown unit 'in'"):
        corner_train.train_corners(reg, pm.box_corners(np.array([189.0, 258.0, 75.0])), tmp_path / "c.onnx")


def test_eval_scores_a_corner_detector_in_its_units(tmp_path, monkeypatch):
    """`alcn pose eval` scored a corner detector's poses as mm, while its units are its training sequence's (cm for a
    registration in cm): the detector's recorded units are those scored."""
    from pose import corner_train, corners, evaluate

    data = tmp_path / "data"
    _registration(data / "train" / "000001", "cm")
    _registration(data / "test" / "000001", "cm")
    (data / "models").mkdir()
    _box_ply(data / "models" / "obj_000001.ply", size=BOX / 10)
    detector = SimpleNamespace(units="cm", corners=pm.box_corners(BOX / 10))
    monkeypatch.setattr(corner_train, "train_corners", lambda *args, **kwargs: tmp_path / "c.onnx")
    monkeypatch.setattr(corners, "CornerDetector", lambda path: detector)
    scored = []

    def score(det, scene_dir, obj_id, vertices, units, *args):
        scored.append(units)
        raise RuntimeError("scored")

    monkeypatch.setattr(evaluate, "evaluate_sequence", score)
    with pytest.raises(RuntimeError, match="scored"):
        evaluate.main(data, tmp_path / "r", normalizations=["none"], detectors=["corners"], progress=False)
    assert scored == ["cm"]


def test_the_box_given_twice_is_refused_before_the_work(tmp_path, capsys):
    """``--box-ply`` and ``--box-size`` together: the .ply was taken silently."""
    from alcn_cv.cli import main

    ply = tmp_path / "box.ply"
    ply.write_text("ply\n")
    argv = ["pose", "build", str(tmp_path), str(tmp_path / "m.npz"), "--box-ply", str(ply), "--box-size", "1", "2", "3"]
    assert main([*argv, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [err] and "give the box once" in err, err


def test_a_focal_length_refined_to_square_pixels_is_not_a_warning():
    """The cookie box's documented build ended in a warning that its refined fx / fy had moved (from the tutorial's
    guess, 0.89, to 1.004: square pixels, a good result) with advice to add frames."""
    from pose.build import _focal_ratio_note

    assert _focal_ratio_note(0.89, 0.95) == (logging.INFO, "")  # within 10% of the given ratio
    assert _focal_ratio_note(0.89, 1.004) == (logging.INFO, "; their ratio moved from 0.89 to 1.00, square pixels")
    level, words = _focal_ratio_note(0.89, 0.79)  # the cookie box from its first 120 frames
    assert level == logging.WARNING and words.endswith("to 0.79: more frames or views from more directions")
    assert _focal_ratio_note(1.0, 1.25)[0] == logging.WARNING


def test_a_video_built_from_python_without_its_camera_names_the_keywords(tmp_path):
    """The message named only the command line's --K and --camera to a caller of pose.build.main."""
    video = tmp_path / "v.mp4"
    video.write_bytes(b"")
    with pytest.raises(InputError, match=r"needs the intrinsics .*in Python: K= or camera="):
        build.main(video, tmp_path / "m.npz", box_size=(1.0, 2.0, 3.0), progress=False)
    with pytest.raises(InputError, match=r"not both \(in Python: box_ply= or box_size=\)"):
        build.main(video, tmp_path / "m.npz", box_size=(1.0, 2.0, 3.0), box_ply=video, progress=False)
