"""pose.parts + pose.track end to end on a synthetic planar textured object with known poses."""

from __future__ import annotations

import inspect
import json
import logging
import os
import shutil
import subprocess
import sys
from pathlib import Path
from unittest.mock import ANY

import cv2
import numpy as np
import pytest

from alcn_cv import io
from alcn_cv.errors import InputError
from pose import model as pm
from pose import track
from pose.corners import scaled_camera
from pose.evaluate import rotation_error_deg
from pose.parts import FeaturePartDetector, create_feature
from pose.solver import camera_matrix, project

K = camera_matrix(500.0, 500.0, 159.5, 119.5)
SIZE = (320, 240)


def _texture(seed=0, n=256):
    rng = np.random.default_rng(seed)
    img = cv2.resize(rng.integers(0, 256, (n // 8, n // 8), dtype=np.uint8), (n, n), interpolation=cv2.INTER_NEAREST)
    for _ in range(60):
        c = tuple(int(v) for v in rng.integers(0, n, 2))
        cv2.circle(img, c, int(rng.integers(3, 20)), int(rng.integers(0, 256)), -1)
    return cv2.GaussianBlur(img, (3, 3), 0)


def _planar_model(tex, mm_per_px=0.5, units="mm"):
    """Top face z = 0 of a 128 x 128 x 20 mm box, textured with ``tex``, its lengths in ``units``."""
    kps, desc = create_feature("ORB", 1500).detectAndCompute(tex, None)
    uv = np.array([k.pt for k in kps])
    s = pm.unit_scale("mm", units)
    pts = np.c_[uv * mm_per_px, np.zeros(len(uv))] * s
    corners = pm.box_corners([128, 128, 20], [0, 0, -20]) * s
    return pm.PartModel(corners=corners, points3d=pts, descriptors=desc, units=units)


def _render(tex, rvec, tvec, mm_per_px=0.5):
    R = cv2.Rodrigues(rvec)[0]
    # texture pixel (u, v) -> object (u s, v s, 0) -> image: H = K [r1 r2 t] diag(s, s, 1)
    H = K @ np.c_[R[:, 0] * mm_per_px, R[:, 1] * mm_per_px, tvec.ravel()]
    bg = np.full((SIZE[1], SIZE[0]), 90, np.uint8)
    warped = cv2.warpPerspective(tex, H, SIZE)
    mask = cv2.warpPerspective(np.ones_like(tex), H, SIZE)
    return cv2.cvtColor(np.where(mask > 0, warped, bg), cv2.COLOR_GRAY2BGR)


def _poses(n=6):
    return [
        (np.array([[0.2 + 0.03 * i], [-0.1], [0.05 * i]]), np.array([[-60.0 + 2 * i], [-60.0], [330.0]]))
        for i in range(n)
    ]


def test_track_folder_writes_bop_json_and_overlay(tmp_path):
    tex = _texture()
    model = _planar_model(tex)
    pm.save(model, tmp_path / "m.npz")
    frames = tmp_path / "frames"
    frames.mkdir()
    poses = _poses()
    for i, (r, t) in enumerate(poses):
        cv2.imwrite(str(frames / f"{i:04d}.png"), _render(tex, r, t))
    black = np.zeros((SIZE[1], SIZE[0], 3), np.uint8)  # no object: lost, never a wrong pose
    cv2.imwrite(str(frames / f"{len(poses):04d}.png"), black)
    (tmp_path / "ov.v2").mkdir()  # an existing folder's name may hold a dot
    summary = track.main(
        tmp_path / "m.npz", frames, tmp_path / "out" / "poses.json", K, overlay=tmp_path / "ov.v2", n_features=800
    )
    assert summary["frames"] == len(poses) + 1 and summary["tracked"] == len(poses)
    assert summary["events"][-1]["event"] == "lost"
    gt = json.loads((tmp_path / "out" / "poses.json").read_text())
    for i, (r, t) in enumerate(poses):
        entry = gt[f"{i:04d}"][0]
        R = np.array(entry["cam_R_m2c"]).reshape(3, 3)
        assert rotation_error_deg(R, cv2.Rodrigues(r)[0]) < 2.5
        assert np.linalg.norm(np.array(entry["cam_t_m2c"]) - t.ravel()) < 6.0
    assert gt[f"{len(poses):04d}"] == []
    assert (tmp_path / "out" / "poses_info.json").is_file()
    assert len(list((tmp_path / "ov.v2").glob("*.png"))) == len(poses) + 1


def test_track_video_names_frames_in_order_and_uses_the_model_camera(tmp_path, caplog):
    """A video's overlay frames were named 0.png, 1.png, 10.png, ...; `track` needed --K although the
    model stores the camera it was built with (`pose build` from a video, --refine-focal)."""
    tex = _texture()
    model = _planar_model(tex)
    model.extra["K"] = K.tolist()
    pm.save(model, tmp_path / "m.npz")
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, SIZE)
    poses = _poses(3) * 4  # 12 frames: names past 10 sort in frame order only when zero-padded
    for r, t in poses:
        writer.write(_render(tex, r, t))
    writer.release()
    summary = track.main(tmp_path / "m.npz", video, tmp_path / "poses.json", overlay=tmp_path / "ov", n_features=800)
    assert summary["frames"] == len(poses) and summary["tracked"] >= len(poses) - 1
    names = [p.stem for p in sorted((tmp_path / "ov").glob("*.png"))]
    assert names == list(json.loads((tmp_path / "poses.json").read_text())) == [f"frame_{i:06d}" for i in range(12)]
    with caplog.at_level("WARNING", logger="pose.track"):
        track.main(tmp_path / "m.npz", video, tmp_path / "poses2.json", 1.5 * K, n_features=800)
    assert "differ from those" in caplog.text
    del model.extra["K"]
    pm.save(model, tmp_path / "m.npz")
    with pytest.raises(InputError, match="stores no camera"):
        track.main(tmp_path / "m.npz", video, tmp_path / "poses3.json")


def test_a_part_model_is_tracked_after_the_normalizer_it_was_built_after(tmp_path, caplog, monkeypatch):
    tex = _texture()
    model = _planar_model(tex)
    model.normalization = "clahe"
    pm.save(model, tmp_path / "m.npz")
    frames = tmp_path / "frames"
    frames.mkdir()
    r, t = _poses(1)[0]
    frame = _render(tex, r, t)
    cv2.imwrite(str(frames / "0.png"), frame)
    clahe_inputs = _spy_on_apply(monkeypatch, "clahe")
    assert track.main(tmp_path / "m.npz", frames, tmp_path / "a.json", K, n_features=800)["normalization"] == "clahe"
    # the detector normalized the frame with the model's CLAHE: once, on the frame's gray conversion
    assert len(clahe_inputs) == 1
    np.testing.assert_array_equal(clahe_inputs[0], cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))
    clahe_inputs.clear()
    with caplog.at_level("WARNING", logger="pose.track"):
        summary = track.main(tmp_path / "m.npz", frames, tmp_path / "b.json", K, normalization="none", n_features=800)
    assert summary["normalization"] == "none" and "built after the normalization 'clahe'" in caplog.text
    assert clahe_inputs == []  # the normalization given replaces the model's
    caplog.clear()
    with caplog.at_level("WARNING", logger="pose.track"):  # the same method, its default given
        track.main(
            tmp_path / "m.npz", frames, tmp_path / "d.json", K, normalization="clahe:clip_limit=2.0", n_features=800
        )
    assert "built after" not in caplog.text
    with pytest.raises(InputError, match=r"are 320x240 but the calibration is for 1280x960"):
        track.main(tmp_path / "m.npz", frames, tmp_path / "c.json", K, n_features=800, image_size=(1280, 960))


def _spy_on_apply(monkeypatch, name):
    """The images given to ``apply`` of the method ``name`` (its class), from now on."""
    import alcn_cv

    inputs = []
    cls = type(alcn_cv.create(name))
    apply = cls.apply

    def spy(self, src, *args, **kwargs):
        inputs.append(np.array(src, copy=True))
        return apply(self, src, *args, **kwargs)

    monkeypatch.setattr(cls, "apply", spy)
    return inputs


def test_detector_runs_after_any_normalizer(monkeypatch):
    """The features are computed on the normalized frame: the method's own apply() of its gray conversion, called
    once a frame; a real normalization (CLAHE) gives other correspondences than none."""
    import alcn_cv

    tex = _texture(1)
    model = _planar_model(tex)
    img = _render(tex, *_poses(1)[0])
    gray = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    found = {}
    for name in ("none", "clahe"):
        inputs = _spy_on_apply(monkeypatch, name)
        det = FeaturePartDetector(model, name, n_features=500)
        corr = det.detect(img)
        assert len(corr.image_points) == len(corr.object_points) > 20
        assert len(inputs) == 1, name  # the normalization ran on the frame's gray conversion, once
        np.testing.assert_array_equal(inputs[0], gray)
        monkeypatch.undo()
        np.testing.assert_array_equal(det.normalize(img), alcn_cv.create(name).apply(gray))
        found[name] = corr
    assert not np.array_equal(alcn_cv.create("clahe").apply(gray), gray)  # CLAHE changes the frame...
    clahe, none = found["clahe"].image_points, found["none"].image_points
    assert clahe.shape != none.shape or not np.array_equal(clahe, none)  # ... and so the keypoints matched


def test_a_frame_read_into_the_same_buffer_is_a_new_frame():
    """The detector keeps the last frame's work for the tracker's second search of it; an app that reads every frame
    into one buffer (``video.read(frame)``) must get the new frame's correspondences, not the kept ones."""
    tex = _texture(1)
    detector = FeaturePartDetector(_planar_model(tex), n_features=500)
    (r0, t0), (r1, t1) = _poses(6)[0], _poses(6)[5]
    buffer = _render(tex, r0, t0)
    first = detector.detect(buffer)
    assert detector.detect(buffer) is first  # the same frame again: kept
    buffer[:] = _render(tex, r1, t1)
    second = detector.detect(buffer)
    fresh = FeaturePartDetector(_planar_model(tex), n_features=500).detect(buffer.copy())
    assert np.array_equal(second.image_points, fresh.image_points)
    assert not np.array_equal(second.image_points, first.image_points)


def test_ratio_test_compares_distinct_points():
    """Each point described twice (the same descriptor): a plain 2-NN ratio test would reject every
    match (the runner-up is the same point); the detector compares the closest other point."""
    tex = _texture(2)
    one = _planar_model(tex)
    n = len(one.points3d)
    two = pm.PartModel(
        corners=one.corners,
        points3d=one.points3d,
        descriptors=np.vstack([one.descriptors] * 2),
        descriptor_point=np.r_[np.arange(n), np.arange(n)],
        units="mm",
    )
    r, t = _poses(1)[0]
    img = _render(tex, r, t)
    single = FeaturePartDetector(one, n_features=500).detect(img)
    double = FeaturePartDetector(two, n_features=500)
    glob = double.detect(img)
    assert len(glob.object_points) >= 0.9 * len(single.object_points) > 20
    prior = (r, t, K)  # guided matching around the prior
    single_guided = FeaturePartDetector(one, n_features=500).detect(img, prior)
    assert len(double.detect(img, prior).object_points) >= 0.9 * len(single_guided.object_points) > 20


def test_cross_check_keeps_mutual_nearest_neighbours():
    """A model with as many decoy points as real ones (descriptors of another texture at random
    positions): the mutual check keeps a strict subset of the matches, with a higher share of
    correct ones."""
    tex = _texture(4)
    real = _planar_model(tex)
    decoy = _planar_model(_texture(5))
    rng = np.random.default_rng(0)
    n = len(real.points3d)
    decoys = rng.uniform(-60, 60, decoy.points3d.shape)
    model = pm.PartModel(
        corners=real.corners,
        points3d=np.vstack([real.points3d, decoys]).astype(np.float32),
        descriptors=np.vstack([real.descriptors, decoy.descriptors]),
        descriptor_point=np.r_[real.descriptor_point, decoy.descriptor_point + n],
        units="mm",
    )
    r, t = _poses(1)[0]
    img = _render(tex, r, t)

    def pairs_and_correct(corr):
        err = np.linalg.norm(project(corr.object_points, r, t, K) - corr.image_points, axis=1)
        pairs = {(tuple(np.round(a, 2)), tuple(np.round(b, 2))) for a, b in zip(corr.image_points, corr.object_points)}
        return pairs, float(np.mean(err < 3))

    plain, plain_ok = pairs_and_correct(FeaturePartDetector(model, n_features=500).detect(img))
    mutual, mutual_ok = pairs_and_correct(FeaturePartDetector(model, n_features=500, cross_check=True).detect(img))
    assert 20 < len(mutual) < len(plain) and mutual <= plain
    assert mutual_ok > plain_ok


def test_keypoints_in_predicted_region_with_a_prior():
    """With a prior pose only the object's predicted region is searched (n_features there);
    without one, all keypoints of the frame."""
    tex = _texture(3)
    model = _planar_model(tex)
    r, t = _poses(1)[0][0], np.array([[-30.0], [-30.0], [600.0]])
    img = _render(tex, r, t)
    yy, xx = np.mgrid[: SIZE[1], : SIZE[0]]
    clutter = np.where(((xx + yy // 2) // 5 + yy // 5) % 2, 188, 68).astype(np.uint8)  # a fine checkerboard floor
    img = np.where(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)[..., None] == 90, clutter[..., None], img)
    det = FeaturePartDetector(model, n_features=150, min_guided=5)
    full = det.detect(img)
    assert full.keypoints > 150  # all keypoints without a prior
    tracked = det.detect(img, (r, t, K))
    region = det._region(img.shape, (r, t, K), det.search_radius)
    uv = np.round(tracked.image_points).astype(int)
    assert tracked.keypoints == 150 and len(uv) >= 5  # the cap applies inside the region, not before it
    assert region[uv[:, 1], uv[:, 0]].all()
    assert (region > 0).mean() < 0.8  # the region is not the whole frame


def test_bad_sources(tmp_path):
    with pytest.raises(InputError):
        list(io.iter_frames(tmp_path / "nope.mp4"))
    (tmp_path / "broken.mp4").write_bytes(b"\x00" * 100)
    with pytest.raises(InputError):
        list(io.iter_frames(tmp_path / "broken.mp4"))
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError):
        list(io.iter_frames(tmp_path / "empty"))


def test_track_command_prints_its_last_line_once(tmp_path, capsys, caplog):
    """Issue 41, part 4: `alcn pose track` printed "tracked N of M frames" twice (its print and the log)."""
    from alcn_cv.cli import main

    tex = _texture()
    pm.save(_planar_model(tex), tmp_path / "m.npz")
    frames = tmp_path / "frames"
    frames.mkdir()
    for i, (r, t) in enumerate(_poses(2)):
        cv2.imwrite(str(frames / f"{i:04d}.png"), _render(tex, r, t))
    caplog.set_level("INFO")
    assert (
        main(
            [
                "pose",
                "track",
                str(tmp_path / "m.npz"),
                str(frames),
                str(tmp_path / "poses.json"),
                "--K",
                "500",
                "500",
                "159.5",
                "119.5",
                "--n-features",
                "800",
            ]
        )
        == 0
    )
    captured = capsys.readouterr()
    text = captured.out + captured.err + caplog.text
    assert text.count("tracked 2 of 2 frames") == 1, text


def test_outputs_and_settings_are_checked_before_the_tracking(tmp_path):
    tex = _texture()
    model = _planar_model(tex)
    model.extra["K"], model.extra["image_size"] = K.tolist(), [640, 480]
    pm.save(model, tmp_path / "m.npz")
    frames = tmp_path / "frames"
    frames.mkdir()
    for i, (r, t) in enumerate(_poses(2)):
        cv2.imwrite(str(frames / f"{i:04d}.png"), _render(tex, r, t))
    before = sorted(p.read_bytes() for p in frames.iterdir())
    m = tmp_path / "m.npz"
    for kwargs, match in (
        ({"overlay": frames}, "is the input"),
        ({"overlay": tmp_path / "p.json"}, "a video .* or a folder"),
        ({"overlay": tmp_path / "ov.png"}, "a video .* or a folder"),
        ({"overlay": tmp_path / "ov.gif"}, "a video .* or a folder"),
        ({"reprojection_error": -1.0}, "reprojection_error must be > 0"),
        ({"min_inliers": 3}, "min_inliers >= 4"),
    ):
        with pytest.raises(InputError, match=match):
            track.main(m, frames, tmp_path / "p.json", K, **kwargs)
    with pytest.raises(InputError, match="must end in .json|suffix"):
        track.main(m, frames, tmp_path / "p.txt", K)
    with pytest.raises(InputError, match="--detector corners"):
        track.main(tmp_path / "c.onnx", frames, tmp_path / "p.json", K)
    with pytest.raises(InputError, match=r"are 320x240 but the camera of .*m.npz is for 640x480"):
        track.main(m, frames, tmp_path / "p.json")  # the model's camera, for frames of another size
    assert sorted(p.read_bytes() for p in frames.iterdir()) == before and not (tmp_path / "p.json").exists()


def test_the_summary_says_why_frames_were_lost(tmp_path):
    tex = _texture()
    pm.save(_planar_model(tex), tmp_path / "m.npz")
    frames = tmp_path / "frames"
    frames.mkdir()
    r, t = _poses(1)[0]
    cv2.imwrite(str(frames / "0.png"), _render(tex, r, t))
    for i in (1, 2):
        cv2.imwrite(str(frames / f"{i}.png"), np.full((SIZE[1], SIZE[0], 3), 90, np.uint8))
    summary = track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", K, n_features=800)
    assert summary["tracked"] == 1 and "match" in summary["lost_reason"]


def test_every_frame_of_a_folder_is_checked_against_the_camera_size(tmp_path):
    """Only the first frame was compared with the calibration's size: a later image of another size was
    tracked with intrinsics that do not hold for it."""
    tex = _texture()
    pm.save(_planar_model(tex), tmp_path / "m.npz")
    frames = tmp_path / "frames"
    frames.mkdir()
    (r0, t0), (r1, t1) = _poses(2)
    cv2.imwrite(str(frames / "0.png"), _render(tex, r0, t0))
    cv2.imwrite(str(frames / "1.png"), cv2.resize(_render(tex, r1, t1), (640, 480)))
    with pytest.raises(InputError, match=r"frame 1 of .* is 640x480 but the calibration is for 320x240"):
        track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", K, n_features=800, image_size=SIZE)
    assert not (tmp_path / "p.json").exists()


def test_a_nan_reprojection_error_is_refused(tmp_path):
    pm.save(_planar_model(_texture()), tmp_path / "m.npz")
    with pytest.raises(InputError, match="reprojection_error must be > 0"):
        track.main(tmp_path / "m.npz", tmp_path, tmp_path / "p.json", K, reprojection_error=float("nan"))


def test_the_overlay_video_keeps_the_frame_rate_of_the_input(tmp_path):
    """The overlay video was written at 30 fps whatever the input's: a 10 fps video played 3x too fast."""
    tex = _texture()
    pm.save(_planar_model(tex), tmp_path / "m.npz")
    video = tmp_path / "in.avi"
    writer = io.open_video_writer(video, 10.0, SIZE)
    for r, t in _poses(3):
        writer.write(_render(tex, r, t))
    writer.release()
    track.main(tmp_path / "m.npz", video, tmp_path / "p.json", K, n_features=800, overlay=tmp_path / "ov.avi")
    cap = cv2.VideoCapture(str(tmp_path / "ov.avi"))
    try:
        assert cap.get(cv2.CAP_PROP_FPS) == pytest.approx(10.0)
        assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    finally:
        cap.release()


def test_an_overlay_of_an_unknown_suffix_is_refused(tmp_path):
    """An overlay named ``out.gif`` (any suffix but a video's) was silently a folder of PNGs of that name."""
    frame = np.zeros((8, 8, 3), np.uint8)
    for name in ("out.gif", "out.png", "out.v2"):
        with pytest.raises(InputError, match=r"overlay .*out\.\w+: a video \(.*\.avi, .*\.mp4.*\) or a folder"):
            track.OverlayWriter(tmp_path / name)
        assert not (tmp_path / name).exists()
    (tmp_path / "run.v2").mkdir()
    for name in ("frames", "run.v2"):  # no suffix, or an existing folder whatever its name: a folder of PNGs
        with track.OverlayWriter(tmp_path / name) as writer:
            writer.write("a", frame)
        assert (tmp_path / name / "a.png").is_file()


def test_the_trackers_solver_takes_the_solvers_defaults_by_keyword():
    """make_solver copied PoseSolver's defaults ("usac_default", 4.0) and make_tracker passed its settings by position:
    they are keyword-only now, and what is not given is PoseSolver's own default."""
    import inspect

    from pose.solver import PoseSolver

    defaults = inspect.signature(PoseSolver).parameters
    solver = track.make_solver("features", K, None)
    assert solver.method == defaults["method"].default
    assert solver.reprojection_error == defaults["reprojection_error"].default
    assert solver.min_inliers == track.MIN_INLIERS["features"]
    tracker = track.make_tracker("corners", K, None, method="ransac_sqpnp", reprojection_error=6.0, min_inliers=8)
    assert (tracker.solver.method, tracker.solver.reprojection_error, tracker.solver.min_inliers) == (
        "ransac_sqpnp",
        6.0,
        8,
    )
    with pytest.raises(TypeError):
        track.make_tracker("features", K, None, None, "ransac_sqpnp")  # type: ignore[misc]


def _frames(tmp_path, n, name="frames", size=None):
    """A folder of ``n`` rendered frames of :func:`_texture`'s box (resized to ``size`` when given)."""
    tex = _texture()
    folder = tmp_path / name
    folder.mkdir()
    for i, (r, t) in enumerate(_poses(n)):
        frame = _render(tex, r, t)
        cv2.imwrite(str(folder / f"{i:04d}.png"), frame if size is None else cv2.resize(frame, size))
    return folder


def test_an_overlay_folder_is_never_mixed_with_an_earlier_runs_frames(tmp_path, monkeypatch):
    """A user's walk: a run on a 60-frame video into the overlay folder of a 110-frame run exited 0 with 110 PNGs in
    it, 50 of them stale. A folder of an earlier run is refused, replaced whole with overwrite, left as it was by an
    interrupted run, and a folder of other files is never replaced."""
    pm.save(_planar_model(_texture()), tmp_path / "m.npz")
    long, short = _frames(tmp_path, 4, "long"), _frames(tmp_path, 2, "short")
    ov = tmp_path / "ov"
    track.main(tmp_path / "m.npz", long, tmp_path / "a.json", K, overlay=ov, n_features=800, progress=False)
    assert len(list(ov.glob("*.png"))) == 4
    with pytest.raises(InputError, match=r"overlay .*ov exists \(--overwrite"):
        track.main(tmp_path / "m.npz", short, tmp_path / "b.json", K, overlay=ov, n_features=800, progress=False)
    assert len(list(ov.glob("*.png"))) == 4 and not (tmp_path / "b.json").exists()

    def interrupted(self, frame, *, name=None):
        if self.frames == 1:
            raise KeyboardInterrupt
        self.frames += 1
        return track.PoseEstimate(False, reason="test")

    before = sorted(p.name for p in tmp_path.iterdir())
    with monkeypatch.context() as m:
        m.setattr(track.BoxTracker, "step", interrupted)
        with pytest.raises(KeyboardInterrupt):
            track.main(tmp_path / "m.npz", short, tmp_path / "b.json", K, overlay=ov, overwrite=True, progress=False)
    assert sorted(p.name for p in ov.iterdir()) == [f"{i:04d}.png" for i in range(4)]  # as it was
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # no temporary folder or poses left
    track.main(tmp_path / "m.npz", short, tmp_path / "b.json", K, overlay=ov, overwrite=True, n_features=800)
    assert sorted(p.name for p in ov.iterdir()) == ["0000.png", "0001.png"]
    (ov / "notes.txt").write_text("mine")
    with pytest.raises(InputError, match="not an earlier overlay"):
        track.main(tmp_path / "m.npz", short, tmp_path / "c.json", K, overlay=ov, overwrite=True)
    assert (ov / "notes.txt").is_file()


def test_poses_are_written_in_mm_whatever_the_models_units(tmp_path):
    """poses.json called itself BOP scene_gt-style but held the model's units (cm for the cookie box); BOP's are mm.
    The overlay error reads them back in the model's units, and the poses of an earlier track in the model's units
    (an _info.json without translation_units) as they were."""
    from pose.overlay import _camera_and_poses

    model = _planar_model(_texture(), units="cm")
    model.extra["K"] = K.tolist()
    pm.save(model, tmp_path / "m.npz")
    frames = _frames(tmp_path, 3)
    summary = track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", K, n_features=800, progress=False)
    assert (summary["translation_units"], summary["units"]) == ("mm", "cm")  # "units": the model's, as before
    poses = json.loads((tmp_path / "p.json").read_text())
    for i, (_, t) in enumerate(_poses(3)):
        assert np.linalg.norm(np.array(poses[f"{i:04d}"][0]["cam_t_m2c"]) - t.ravel()) < 6.0  # mm, as rendered
    read = _camera_and_poses(tmp_path / "m.npz", tmp_path / "p.json")[3]
    assert np.allclose(read["0000"][1].ravel() * 10, poses["0000"][0]["cam_t_m2c"])  # cm, the model's
    info = json.loads((tmp_path / "p_info.json").read_text())
    del info["summary"]["translation_units"]  # an earlier track's: the model's units
    (tmp_path / "p_info.json").write_text(json.dumps(info))
    assert np.allclose(track.read_poses(tmp_path / "p.json", "cm")["0000"][1].ravel(), poses["0000"][0]["cam_t_m2c"])


def test_the_overlay_error_draws_with_the_camera_and_model_the_poses_were_tracked_with(tmp_path, monkeypatch):
    """`alcn pose overlay-error` drew every run with the model's camera: poses tracked with `--K` were measured 20 px
    off the box, and poses of another model were drawn with its box, without a word."""
    from alcn_cv.errors import DatasetError
    from pose.overlay import _camera_and_poses

    model = _planar_model(_texture())
    model_K = K * np.array([[0.5], [0.5], [1.0]])  # not the camera the frames were taken with
    model.extra["K"] = model_K.tolist()
    pm.save(model, tmp_path / "m.npz")
    frames = _frames(tmp_path, 2)
    track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", K, n_features=800, progress=False)
    np.testing.assert_array_equal(_camera_and_poses(tmp_path / "m.npz", tmp_path / "p.json")[1], K)  # --K's
    model.extra["K"] = K.tolist()
    pm.save(model, tmp_path / "other.npz")
    with pytest.raises(DatasetError, match="was tracked with .*m.npz, another file than .*other.npz"):
        _camera_and_poses(tmp_path / "other.npz", tmp_path / "p.json")
    shutil.copy(tmp_path / "m.npz", tmp_path / "kept.npz")
    shutil.copy(tmp_path / "other.npz", tmp_path / "m.npz")  # built again where it was
    with pytest.raises(DatasetError, match="was tracked with .*m.npz before it was built again: track again"):
        _camera_and_poses(tmp_path / "m.npz", tmp_path / "p.json")
    monkeypatch.chdir(tmp_path / "frames")  # the model named from another folder than the track's
    with pytest.raises(DatasetError, match="before it was built again"):
        _camera_and_poses("../m.npz", tmp_path / "p.json")
    shutil.copy(tmp_path / "kept.npz", tmp_path / "m.npz")
    info = json.loads((tmp_path / "p_info.json").read_text())
    corners = {**info, "summary": {**info["summary"], "detector": "corners"}, "model_digest": "0" * 64}
    (tmp_path / "p_info.json").write_text(json.dumps(corners))  # a corner CNN's run: its ONNX file is no part model
    np.testing.assert_array_equal(_camera_and_poses(tmp_path / "m.npz", tmp_path / "p.json")[1], K)
    for key in ("camera_matrix", "dist_coeffs", "model_digest", "model_file"):  # an earlier track's, with --K
        del info[key]
    (tmp_path / "p_info.json").write_text(json.dumps(info))
    with pytest.raises(DatasetError, match="camera given to `alcn pose track` that p_info.json does not record"):
        _camera_and_poses(tmp_path / "m.npz", tmp_path / "p.json")
    info["summary"]["camera"] = "model"  # an earlier track's with the model's camera: that camera, as before
    (tmp_path / "p_info.json").write_text(json.dumps(info))
    np.testing.assert_array_equal(_camera_and_poses(tmp_path / "m.npz", tmp_path / "p.json")[1], model_K)


def test_track_takes_max_frames_and_step(tmp_path, capsys):
    from alcn_cv.cli import main

    pm.save(_planar_model(_texture()), tmp_path / "m.npz")
    frames = _frames(tmp_path, 6)
    argv = ["pose", "track", str(tmp_path / "m.npz"), str(frames), str(tmp_path / "p.json"), "--no-progress"]
    argv += ["--K", "500", "500", "159.5", "119.5", "--n-features", "800"]
    assert main([*argv, "--max-frames", "2"]) == 0
    assert list(json.loads((tmp_path / "p.json").read_text())) == ["0000", "0001"]
    assert main([*argv, "--step", "2", "--max-frames", "2", "--overwrite"]) == 0
    assert list(json.loads((tmp_path / "p.json").read_text())) == ["0000", "0002"]
    capsys.readouterr()
    for option in ("--max-frames", "--step"):  # refused as they are parsed, naming the option
        with pytest.raises(SystemExit):
            main([*argv, option, "0"])
        assert capsys.readouterr().err.strip().endswith(f"argument {option}: an integer at least 1, got '0'")


def test_the_summary_names_the_outputs_the_units_and_the_next_step(tmp_path, capsys):
    from alcn_cv.cli import main

    model = _planar_model(_texture(), units="cm")
    model.extra["K"] = K.tolist()
    pm.save(model, tmp_path / "m.npz")
    frames = _frames(tmp_path, 2)
    out = tmp_path / "out" / "poses.json"
    argv = ["pose", "track", str(tmp_path / "m.npz"), str(frames), str(out), "--no-progress", "--n-features", "800"]
    assert main([*argv, "--overlay", str(tmp_path / "ov")]) == 0
    text = capsys.readouterr().out
    assert f"poses: {out}" in text and "cam_t_m2c in mm" in text and "the model is in cm" in text
    assert str(out.with_name("poses_info.json")) in text and f"overlay: {tmp_path / 'ov'}" in text
    assert "alcn pose overlay-error" in text and f"--run track {tmp_path / 'm.npz'} {out}" in text
    assert main([*argv, "--K", "500", "500", "159.5", "119.5", "--overwrite"]) == 0  # the poses record their camera
    assert "alcn pose overlay-error" in capsys.readouterr().out


def test_frames_of_another_size_than_the_models_name_the_camera_that_works(tmp_path, caplog):
    """Half-size frames tracked with --K warned "leave out --K/--camera to track with the model's", but leaving them
    out was an error: both name the model's camera resized to the frames."""
    model = _planar_model(_texture())
    model.extra["K"], model.extra["image_size"] = K.tolist(), list(SIZE)
    pm.save(model, tmp_path / "m.npz")
    frames = _frames(tmp_path, 2, size=(160, 120))
    half = "--K 250.00 250.00 79.50 59.50"
    with pytest.raises(InputError, match=f"the model's camera resized to them.*{half}"):
        track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", progress=False)
    with caplog.at_level("WARNING", logger="pose.track"):
        track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", 0.7 * K, progress=False, overwrite=True)
    assert "differ from those" in caplog.text and f"give {half}" in caplog.text and "leave out" not in caplog.text
    caplog.clear()
    from pose.corners import scaled_camera

    with caplog.at_level("WARNING", logger="pose.track"):
        track.main(
            tmp_path / "m.npz", frames, tmp_path / "p.json", scaled_camera(K, 0.5), progress=False, overwrite=True
        )
    assert "differ from those" not in caplog.text


def test_open_tracker_is_what_the_command_tracks_with(tmp_path):
    """FeaturePartDetector and PoseTracker built by hand had other defaults than the command (2000 keypoints, no
    check of the guided poses); open_tracker is the command's tracker, and gives its poses frame by frame."""
    from alcn_cv.cli import main

    model = _planar_model(_texture(), units="cm")
    model.extra["K"] = K.tolist()
    pm.save(model, tmp_path / "m.npz")
    frames = _frames(tmp_path, 4)
    assert main(["pose", "track", str(tmp_path / "m.npz"), str(frames), str(tmp_path / "p.json"), "--no-progress"]) == 0
    written = json.loads((tmp_path / "p.json").read_text())
    box = track.open_tracker(tmp_path / "m.npz")
    assert box.detector.n_features == 1000 and box.detector.n_features_global == 0
    assert (box.tracker.trusted_guided_ratio, box.tracker.min_guided_ratio) == (0.6, 0.3)
    assert box.camera == "model" and np.allclose(box.K, K) and box.units == "cm" and box.mm_per_unit == 10.0
    for name, frame in io.iter_frames(frames):
        est = box.step(frame)
        assert est.ok
        assert track.pose_to_bop(est, mm_per_unit=box.mm_per_unit) == written[name]
    assert track.open_tracker(model, n_features_global=3000).detector.n_features_global == 3000  # a PartModel too
    with pytest.raises(InputError, match="n_features_global >= 0"):
        track.open_tracker(model, n_features_global=-1)


def test_the_python_example_of_open_tracker_and_docs_pose_md_runs(tmp_path, capsys):
    """open_tracker's docstring example, on a synthetic model and video in place of the cookie box's: it runs, and
    docs/pose.md's Python example is the same code on the walkthrough's paths."""
    import re
    import textwrap

    text = (Path(__file__).resolve().parent.parent / "docs" / "pose.md").read_text(encoding="utf-8")
    walkthrough, stages = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    code = textwrap.dedent(track.open_tracker.__doc__.split("::\n", 1)[1])
    assert walkthrough.strip() == code.strip().replace("cb/model.npz", "out/cookie_box/model.npz")
    model = _planar_model(_texture(), units="cm")
    model.extra["K"] = K.tolist()
    pm.save(model, tmp_path / "model.npz")
    video = tmp_path / "box.avi"
    writer = io.open_video_writer(video, 10.0, SIZE)
    for r, t in _poses(3):
        writer.write(_render(_texture(), r, t))
    writer.release()
    assert "cb/model.npz" in code and "../shared/data/cookie_box/box.mp4" in code
    code = code.replace("cb/model.npz", str(tmp_path / "model.npz"))
    exec(code.replace("../shared/data/cookie_box/box.mp4", str(video)), {})
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == 3 and not any("lost" in line for line in lines)
    t_mm = json.loads("[" + lines[0].rsplit("[", 1)[1])  # the last list printed: t in mm
    assert np.linalg.norm(np.array(t_mm) - _poses(1)[0][1].ravel()) < 6.0  # mm, as rendered
    # the other stages' example (a build of minutes on the real data, run by hand): it names what exists, as called
    names: dict[str, object] = {}
    exec("\n".join(line for line in stages.splitlines() if line.startswith(("import ", "from "))), names)
    calls = {"build": ("box_ply", "conf"), "draw_box": ("dist",), "detect_in_images": ("progress",)}
    for name, keywords in calls.items():
        assert set(keywords) <= set(inspect.signature(names[name]).parameters), name
        assert all(f"{k}=" in stages for k in keywords), name
    compile(stages, "docs/pose.md", "exec")


def test_events_name_the_frames_of_the_source(tmp_path, caplog):
    """With --step, the events of _info.json and the log's "frame 3: tracking lost" gave the count of frames kept,
    which is frame 0006 of the folder: they name the frame."""
    folder = _frames(tmp_path, 6)
    black = np.zeros((SIZE[1], SIZE[0], 3), np.uint8)  # no object: lost
    for name in ("0004.png", "0005.png"):
        cv2.imwrite(str(folder / name), black)
    pm.save(_planar_model(_texture()), tmp_path / "m.npz")
    with caplog.at_level("INFO", logger="pose.solver"):
        summary = track.main(tmp_path / "m.npz", folder, tmp_path / "p.json", K, n_features=800, step=2)
    assert summary["frames"] == 3 and summary["events"] == [{"frame": "0004", "event": "lost", "reason": ANY}]
    info = json.loads((tmp_path / "p_info.json").read_text())
    assert info["summary"]["events"][0]["frame"] == "0004" and "0004" in info["frames"]
    assert "frame 0004: tracking lost" in caplog.text
    box = track.open_tracker(tmp_path / "m.npz", K)  # stepped without names: the index among the frames stepped
    for _, frame in io.iter_frames(folder, step=2):
        box.step(frame)
    assert [e[:2] for e in box.events] == [(2, "lost")]


def test_track_takes_its_settings_by_keyword(tmp_path):
    """track(frames, detector, tracker, total) became track(frames, tracker, total, ...): an old call would have
    taken its tracker as the total. Its settings are keywords."""
    box = track.open_tracker(_planar_model(_texture()), K)
    with pytest.raises(TypeError):
        next(track.track(iter([]), box, 3))  # type: ignore[misc]
    frames = io.iter_frames(_frames(tmp_path, 1))
    ((res, _),) = list(track.track(frames, tracker=box, total=1, progress=False))
    assert res.name == "0000" and res.estimate.ok


def test_an_interrupted_track_never_leaves_poses_read_in_the_wrong_units(tmp_path, monkeypatch):
    """poses.json was written before its _info.json: a Ctrl-C between them left new poses (mm) beside an earlier run's
    info without translation_units, and read_poses read them in the model's units (10 times too far, in cm). The info
    is written first, and the poses beside another run's info are refused."""
    from alcn_cv.errors import DatasetError
    from alcn_cv.io import write_json

    model = _planar_model(_texture(), units="cm")
    pm.save(model, tmp_path / "m.npz")
    frames = _frames(tmp_path, 2)
    track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", K, n_features=800, progress=False)
    truth = track.read_poses(tmp_path / "p.json", "cm")
    info = json.loads((tmp_path / "p_info.json").read_text())
    scene = json.loads((tmp_path / "p.json").read_text())
    earlier = {name: [{**e[0], "cam_t_m2c": [v / 10 for v in e[0]["cam_t_m2c"]]}] for name, e in scene.items()}
    (tmp_path / "p.json").write_text(json.dumps(earlier))  # an earlier track's: in the model's units (cm)
    del info["summary"]["translation_units"]
    info.pop("poses_digest", None)  # an info of before the digest
    (tmp_path / "p_info.json").write_text(json.dumps(info))
    np.testing.assert_allclose(track.read_poses(tmp_path / "p.json", "cm")["0000"][1], truth["0000"][1])
    written = []

    def interrupted(path, obj, **kwargs):
        if written:
            raise KeyboardInterrupt
        written.append(path)
        return write_json(path, obj, **kwargs)

    monkeypatch.setattr(track, "write_json", interrupted)
    with pytest.raises(KeyboardInterrupt):
        track.main(tmp_path / "m.npz", frames, tmp_path / "p.json", K, n_features=800, progress=False, overwrite=True)
    with pytest.raises(DatasetError, match="describes other poses than .*p.json .*track again"):
        track.read_poses(tmp_path / "p.json", "cm")  # never read in the wrong units
    assert written == [tmp_path / "p_info.json"]  # the info first: the earlier poses are left, never the new ones


def test_the_calibration_experiment_publishes_the_tracking_summary_without_paths(tmp_path, monkeypatch):
    """The track summary carries the paths of the model, the poses, their info and the overlay (the runs folder's,
    absolute), which experiments/calibration.py copied into the report it publishes: they stay out, and the model's
    units are the summary's "units" as before."""
    import importlib
    import sys

    from calib.camera import write_camera_yaml

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parent.parent / "experiments"))
    calibration = importlib.import_module("calibration")
    frames = _frames(tmp_path, 2)

    def alcn(*argv):  # the commands, on a synthetic camera, model and video
        assert argv[-1] == "--overwrite"  # a rerun of the experiment replaces its earlier run's files
        argv = argv[:-1]
        if argv[:2] == ("calib", "camera"):
            Path(argv[-1]).mkdir(parents=True)
            write_camera_yaml(Path(argv[-1]) / "camera.yaml", K, np.zeros(5), SIZE)
        elif argv[:2] == ("pose", "build"):
            model = _planar_model(_texture(), units="cm")
            model.extra.update(K=K.tolist(), registered_images=2)
            model.box_fit = {"mean_abs_relative_size_error": 0.02}
            pm.save(model, argv[3])
        else:
            track.main(argv[2], frames, argv[4], n_features=800, progress=False)

    kept = []
    monkeypatch.setattr(calibration, "RUNS", tmp_path / "runs")
    monkeypatch.setattr(calibration, "alcn", alcn)
    monkeypatch.setattr(calibration, "keep", lambda path, name: kept.append(json.loads(Path(path).read_text())))
    monkeypatch.setattr(sys, "argv", ["calibration.py"])
    calibration.main()
    tracking = kept[0]["tracking"]
    assert not set(track.SUMMARY_PATHS) & set(tracking) and str(tmp_path) not in json.dumps(tracking)
    assert (tracking["frames"], tracking["units"], tracking["translation_units"]) == (2, "cm", "mm")


def test_the_pose_extra_tracks_without_torch(tmp_path):
    """``[pose]`` installs no torch (nor kornia, scikit-image, onnx): ``alcn pose track`` runs without them, and without
    jsonschema (``pose build`` too: checked by hand on the cookie box, 2026-11-29; its reconstruction is slow for a
    test). It installs jsonschema, which reading a BOP scene (``alcn calib register``'s output) needs."""
    import tomllib

    pyproject = tomllib.loads((Path(__file__).parents[1] / "pyproject.toml").read_text())
    pose_extra = " ".join(pyproject["project"]["optional-dependencies"]["pose"])
    assert "torch" not in pose_extra and "[train" not in pose_extra and "[data" not in pose_extra, pose_extra
    assert "jsonschema" in pose_extra
    pm.save(_planar_model(_texture()), tmp_path / "m.npz")
    frames = _frames(tmp_path, 2)
    blocked = ("torch", "kornia", "skimage", "jsonschema", "onnx")
    (tmp_path / "sitecustomize.py").write_text(f"import sys\nfor m in {blocked!r}:\n    sys.modules[m] = None\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(tmp_path), os.environ.get("PYTHONPATH")]))}
    argv = ["pose", "track", str(tmp_path / "m.npz"), str(frames), str(tmp_path / "p.json"), "--no-progress"]
    argv += ["--K", "500", "500", "159.5", "119.5"]
    code = "import sys; from alcn_cv.cli import main; sys.exit(main(sys.argv[1:]))"
    proc = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    assert list(json.loads((tmp_path / "p.json").read_text())) == ["0000", "0001"]


@pytest.mark.parametrize(
    ("built", "given", "warns"),
    [
        ("alcn:model=gain", "alcn", False),
        ("alcn", "alcn:model=gain", False),
        ("alcn:model=gain", "alcn:model=lite", True),
    ],
)
def test_tracking_after_the_default_model_named_or_not_is_the_same_normalization(built, given, warns, caplog):
    """`createALCN`'s model defaults to None (the default model): tracking a model built after "alcn:model=gain"
    with "alcn" is the same normalization, not a mismatch to warn about."""
    model = _planar_model(_texture())
    model.normalization = built
    with caplog.at_level(logging.WARNING, logger="pose.track"):
        track.open_tracker(model, K, normalization=given)
    assert ("descriptors may not match" in caplog.text) == warns


def test_the_models_camera_is_resized_to_the_frames_along_each_axis(caplog):
    """Frames squeezed to half the width: the model's camera scaled in x only is the given one, no warning."""
    K = camera_matrix(500.0, 500.0, 319.5, 239.5)
    given = scaled_camera(K, 0.5, 1.0)
    with caplog.at_level("WARNING", logger="pose.track"):
        used = track.camera_matrix_for(K, given, "m.npz", model_size=(640, 480), frame_size=(320, 480))
    np.testing.assert_array_equal(used, given)
    assert "differ from those" not in caplog.text


@pytest.mark.parametrize("frame", [None, cv2.UMat(np.zeros((4, 4), np.uint8))])
def test_a_frame_that_is_no_array_is_named_with_the_way_out(frame):
    """`box.step(cap.read()[1])` past a video's end raised AttributeError ('NoneType' object has no attribute
    'shape') from the size check; it names the read, as `apply()` does."""
    box = track.open_tracker(_planar_model(_texture()), K)
    with pytest.raises(InputError, match=r"the frame must be a numpy array, got (NoneType \(cv2.imread|UMat \(a cv2)"):
        box.step(frame)
