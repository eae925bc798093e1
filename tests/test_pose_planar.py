"""pose.planar: a planar target's part model from one frame, posed under light changes (``alcn pose planar``)."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from alcn_cv.errors import DatasetError, InputError
from pose import planar
from pose.corner_train import CONFS as CORNER_CONFS
from pose.planar import select_region
from pose.solver import PoseSolver, project


def _texture(seed: int = 0, size: tuple[int, int] = (360, 480)) -> np.ndarray:
    """A grey frame: a flat left third, blobs of random texture elsewhere."""
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, size).astype(np.float32), (0, 0), 2.5)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX)
    img[:, : size[1] // 3] = 128
    return img.astype(np.uint8)


def _solve(target: planar.PlanarTarget, image: np.ndarray, normalization: str = "none"):
    det = planar.feature_detector(target, normalization)
    corr = det.detect(image)
    return PoseSolver(target.K, min_inliers=12, iterations=2000, outline=target.model.corners).solve(
        corr.object_points, corr.image_points
    )


def test_pinhole_camera_and_reference():
    K = planar.pinhole_camera(640, 480, 90.0)
    assert K[0, 0] == pytest.approx(320.0) and K[1, 1] == K[0, 0]
    assert (K[0, 2], K[1, 2]) == (319.5, 239.5)
    with pytest.raises(InputError):
        planar.pinhole_camera(640, 480, 180.0)
    frames = np.stack([np.full((4, 4), v, np.uint8) for v in (10, 200, 90, 120, 30)])
    assert planar.reference_index(frames) == 2  # median brightness


def test_select_region_avoids_the_flat_part():
    img = _texture()
    x, y, w, h = planar.select_region(img, 0.5)
    assert (w, h) == (240, 180)
    assert x >= img.shape[1] // 3 - 20  # the textured two thirds, not the flat third


def test_target_posed_under_a_light_change_and_a_camera_rotation():
    img = _texture(1)
    K = planar.pinhole_camera(img.shape[1], img.shape[0])
    target = planar.build_target(img, (200, 90, 220, 180), K)
    assert target.model.units == "mm" and len(target.model.points3d) > 50
    assert np.allclose(target.image_corners(), [[200, 90], [200, 270], [420, 90], [420, 270]], atol=1e-6)
    # the same view under another light (gain and gamma): the reference pose
    relit = np.clip(255 * (0.6 * img / 255.0) ** 1.4, 0, 255).astype(np.uint8)
    est = _solve(target, relit)
    assert est.ok
    assert np.abs(project(target.corners, est.rvec, est.tvec, K) - target.image_corners()).max() < 1.0
    # the camera turned by 4 and 3 degrees: the image moves by the homography K R K^-1 and the pose by R
    R = cv2.Rodrigues(np.radians([3.0, 4.0, 0.0]))[0]
    warped = cv2.warpPerspective(img, K @ R @ np.linalg.inv(K), img.shape[::-1], flags=cv2.INTER_LINEAR)
    est = _solve(target, warped)
    truth = project(target.corners, cv2.Rodrigues(R)[0], R @ target.tvec, K)
    assert est.ok
    assert np.abs(project(target.corners, est.rvec, est.tvec, K) - truth).max() < 1.0
    assert np.abs(truth - target.image_corners()).max() > 20  # the test can fail: the corners moved


def test_build_target_bad_region():
    img = _texture()
    K = planar.pinhole_camera(img.shape[1], img.shape[0])
    with pytest.raises(InputError):
        planar.build_target(img, (400, 300, 200, 200), K)
    with pytest.raises(DatasetError, match="keypoints"):
        planar.build_target(img, (10, 10, 60, 60), K)  # the flat third


def test_target_parts_are_its_corners_and_side_middles():
    img = _texture(1)
    K = planar.pinhole_camera(img.shape[1], img.shape[0])
    target = planar.build_target(img, (200, 90, 220, 180), K)
    parts, uv = planar.target_parts(target)
    assert parts.shape == (8, 3) and np.all(parts[:, 2] == 0)
    np.testing.assert_allclose(
        uv, [[200, 90], [310, 90], [420, 90], [420, 180], [420, 270], [310, 270], [200, 270], [200, 180]], atol=1e-6
    )
    assert {tuple(p) for p in uv[::2].round(6)} == {tuple(p) for p in target.image_corners().round(6)}


def test_corner_detector_is_trained_on_the_reference_frame(tmp_path):
    img = _texture(1)
    K = planar.pinhole_camera(img.shape[1], img.shape[0])
    target = planar.build_target(img, (200, 90, 220, 180), K, reference="ref.png")
    recipe = dataclasses.replace(CORNER_CONFS["planar"], iterations=3, copies=1)
    det = planar.DETECTORS["corners"](target, "none", 0, tmp_path, recipe)
    np.testing.assert_allclose(det.parts, planar.target_parts(target)[0])
    np.testing.assert_allclose(det.corners, target.model.corners)
    assert det.path == tmp_path / "corners_ref_none.onnx" and det.meta["source"] == "ref.png"
    assert det.meta["fit"]["views"] == 1 and det.meta["fit"]["frames"] == 2
    assert det.meta["recipe"] == json.loads(json.dumps(dataclasses.asdict(recipe))) and det.meta["scale"] == 0.5
    corr = det.detect(img)
    assert corr.object_points.shape[1] == 3 and len(corr.object_points) == len(corr.image_points)
    target.image = None
    with pytest.raises(InputError, match="reference image"):
        planar.corner_detector(target, "none")


def test_planar_on_a_webcam_scene(shared_data, tmp_path):
    """Smoke test on real frames: 3 frames of one scene, no normalization, both detectors (a few
    training steps of the learned one)."""
    root = shared_data / "webcam"
    if not (root / "mexico").is_dir():
        pytest.skip(f"the webcam scenes are not in {root}")
    recipe = dataclasses.replace(CORNER_CONFS["planar"], iterations=3, copies=1)
    result = planar.main(
        tmp_path,
        root,
        scenes=["mexico"],
        normalizations=["none"],
        detectors=["features", "corners"],
        max_frames=3,
        recipe=recipe,
        command="test",
    )
    assert set(result["table"]) == {"none / sift features", "none / corner CNN"}
    assert len(list(tmp_path.glob("corners_*_none.onnx"))) == 1
    row = "none / sift features"
    assert set(result["table"][row]) == {"mexico", "mean"}
    assert 0 <= result["table"][row]["mexico"] <= 100
    for name in ("planar_pose.md", "planar_pose.json", "planar_pose.png", "targets.png"):
        assert (tmp_path / name).is_file()
    report = json.loads((tmp_path / "planar_pose.json").read_text())
    assert report["command"] == "test" and len(report["details"][row]["mexico"]["per_frame"]) == 2


def test_planar_command_takes_the_recipe_and_the_normalizations(tmp_path, monkeypatch):
    from alcn_cv.cli import build_parser

    parser = build_parser()
    seen = []
    report = tmp_path / "planar_pose.md"
    monkeypatch.setattr(planar, "main", lambda *a, **kw: seen.append(kw) or report.write_text(""))
    args = parser.parse_args(
        [
            "pose",
            "planar",
            "--out",
            str(tmp_path),
            "--normalizations",
            "none",
            "dog",
            "--detectors",
            "corners",
            "--set",
            "iterations=3",
        ]
    )
    assert args.func(args) == 0
    assert seen[0]["normalizations"] == ["none", "dog"]
    assert seen[0]["recipe"] == dataclasses.replace(CORNER_CONFS["planar"], iterations=3)


def test_planar_refuses_an_earlier_report_and_a_folder_another_run_writes(tmp_path, capsys):
    from alcn_cv.cli import main
    from alcn_cv.errors import InputError
    from alcn_cv.io import held_folder

    (tmp_path / "planar_pose.json").write_text("{}")
    assert main(["pose", "planar", "--out", str(tmp_path), "--data", str(tmp_path / "none")]) == 2
    assert capsys.readouterr().err.strip().endswith("planar_pose.json exists (--overwrite replaces it)")
    with held_folder(tmp_path / "busy"), pytest.raises(InputError, match="is in use by another run"):
        planar.main(tmp_path / "busy", tmp_path / "none", progress=False)


@pytest.mark.parametrize("corner", ["top left", "bottom right"])
def test_select_region_counts_the_keypoints_inside_each_window(corner):
    """A large textured patch in one corner and smaller ones elsewhere: the window holding the large one wins. In the
    top left (smaller patches in the three other corners), a count that took in what lies above, left or above-left
    of a window would favour the others; in the bottom right (one smaller patch in the top left), a count that left
    out the integral image's fourth corner would."""
    rng = np.random.default_rng(0)
    img = np.full((240, 320), 128, np.uint8)

    def texture(cells: int, side: int) -> np.ndarray:
        noise = rng.integers(0, 256, (cells, cells), dtype=np.uint8)
        return cv2.resize(noise, (side, side), interpolation=cv2.INTER_NEAREST)

    if corner == "top left":
        top, left, side = 10, 10, 100
        img[10:110, 10:110] = texture(25, side)
        for y, x in [(10, 250), (170, 10), (170, 250)]:
            img[y : y + 60, x : x + 60] = texture(15, 60)
    else:
        top, left, side = 130, 210, 100
        img[10:90, 10:90] = texture(20, 80)
        img[130:230, 210:310] = texture(25, side)
    x, y, w, h = select_region(img, 0.5)
    assert (w, h) == (160, 120) and x <= left and x + w >= left + side and y <= top and y + h >= top + side
