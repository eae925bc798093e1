"""pose.overlay (the drawn box against the image's edges) and the face frame of pose.box_fit."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pose import box_fit, overlay
from pose.box import facing_faces
from pose.model import box_corners
from pose.solver import camera_matrix, project

K = camera_matrix(600.0, 600.0, 320.0, 240.0)
SIZE = np.array([20.0, 14.0, 6.0])


def _pose() -> tuple[np.ndarray, np.ndarray]:
    """The box seen from above and in front, its lid (z = 0 face) turned to the camera."""
    # the box's +z (its height) points away from the camera: its z = 0 face is turned to it
    return np.array([[np.radians(-35.0)], [np.radians(10.0)], [0.0]]), np.array([[-10.0], [-4.0], [60.0]])


def _render(corners: np.ndarray, rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """A grey frame with each face of the box turned to the camera filled with its own grey level
    on a dark background (a convex box: those faces do not overlap)."""
    img = np.full((480, 640), 40, np.uint8)
    uv = project(corners, rvec, tvec, K)
    levels = iter((110, 180, 250))
    for quad in facing_faces(corners, cv2.Rodrigues(rvec)[0], tvec.ravel()):
        hull = cv2.convexHull(np.round(uv[list(quad)] * 16).astype(np.int32))
        cv2.fillConvexPoly(img, hull, next(levels), cv2.LINE_AA, 4)
    return img


def test_visible_edges_of_a_box_seen_from_one_side():
    rvec, tvec = _pose()
    edges = overlay.visible_edges(box_corners(SIZE), rvec, tvec)
    # three faces at most are turned to a camera outside the box: at most 9 of the 12 edges
    assert 4 <= len(edges) <= 9
    assert {(0, 2), (0, 4), (2, 6), (4, 6)} <= set(edges)  # the lid (z = 0), turned to the camera
    assert not {(1, 3), (1, 5), (3, 7), (5, 7)} <= set(edges)  # not the bottom


def test_frame_error_zero_when_aligned_and_the_offset_when_shifted():
    rvec, tvec = _pose()
    corners = box_corners(SIZE)
    gray = _render(corners, rvec, tvec)
    aligned = overlay.frame_error(gray, corners, rvec, tvec, K)
    assert aligned.mean_px < 1.5 and aligned.found > 0.5
    # the box drawn about 10 px to the right: each edge is off by the shift along its normal
    shift = 10.0
    moved = tvec + np.array([[shift * tvec[2, 0] / K[0, 0]], [0.0], [0.0]])
    off = overlay.frame_error(gray, corners, rvec, moved, K)
    assert off.mean_px > aligned.mean_px + 3
    uv = project(corners, rvec, moved, K)
    for (i, j), signed in off.edges.items():
        d = (uv[j] - uv[i]) / np.linalg.norm(uv[j] - uv[i])
        assert signed == pytest.approx(-shift * -d[1], abs=1.5), (i, j)  # the normal is (-dy, dx)


def test_edge_offsets_signed_along_the_normal():
    edges = np.zeros((100, 100), bool)
    edges[60, :] = True  # a horizontal image edge at y = 60
    angle = np.full((100, 100), np.pi / 2)  # its gradient points along +y
    s = overlay.EdgeSettings()
    # a drawn edge from left to right at y = 50: normal (-dy, dx) = (0, 1), the image edge is 10 px along it
    assert np.allclose(overlay.edge_offsets(edges, angle, (10, 50), (90, 50), s), 10)
    assert np.allclose(overlay.edge_offsets(edges, angle, (90, 50), (10, 50), s), -10)
    # an image edge across the drawn one does not count
    across = np.zeros((100, 100), bool)
    across[:, 50] = True
    assert np.isnan(overlay.edge_offsets(across, np.zeros((100, 100)), (10, 50), (90, 50), s)).all()


def _thick_lid_box(rng: np.random.Generator, noise: float) -> np.ndarray:
    """A box 140 x 95 x 55 seen from above: a noisy lid (z = 55) with many points, two sides with fewer."""
    lid = np.c_[rng.uniform(0, 140, 1500), rng.uniform(0, 95, 1500), 55 + rng.normal(0, noise, 1500)]
    s = rng.uniform(0, 1, (600, 2))
    front = np.c_[s[:, 0] * 140, rng.normal(0, noise, 600), s[:, 1] * 55]
    side = np.c_[140 + rng.normal(0, noise, 600), s[:, 0] * 95, s[:, 1] * 55]
    return np.vstack([lid, front, side])


def test_face_frame_normal_of_a_noisy_lid():
    """A lid twice as thick (noise) as RANSAC's threshold: the face must not grow into the sides,
    whose points would tilt its normal (the cookie box's lid: 13 degrees before)."""
    rng = np.random.default_rng(0)
    pts = _thick_lid_box(rng, noise=2.0)
    extent = float(np.linalg.norm(np.percentile(pts, 95, 0) - np.percentile(pts, 5, 0)))
    R, center, on_face = box_fit.face_frame(pts, 0.005 * extent)
    tilt = np.degrees(np.arccos(abs(R[2, 2])))
    assert tilt < 1.0
    assert center[2] == pytest.approx(55, abs=0.5)
    assert on_face[:1500].mean() > 0.9 and on_face[1500:].mean() < 0.15


def test_image_edges_of_a_yellow_box_on_white_need_colour():
    """The cookie box is yellow on a white tablecloth: hardly a grey-level edge, a strong blue-channel one."""
    img = np.full((120, 160, 3), (235, 240, 240), np.uint8)
    img[40:80, 50:110] = (40, 215, 245)  # BGR yellow
    s = overlay.EdgeSettings()
    colour, angle = overlay.image_edges(img, s)
    grey, _ = overlay.image_edges(cv2.cvtColor(img, cv2.COLOR_BGR2GRAY), s)
    assert colour[38:42, 60:100].any(axis=0).all()  # the top edge, all along
    assert not grey.any()
    # the top edge's gradient is vertical
    rows = colour[38:42, 60:100]
    assert np.allclose(np.abs(np.sin(angle[38:42, 60:100][rows])), 1, atol=0.1)


def test_known_box_flush_with_the_lid_when_points_rise_above_it():
    """The lid (z = 55), a side down to the bottom and a hand's points up to 20 above the lid: the
    points span more than the box's height, yet the box must hang from the lid (it was centred on
    the points' extent, 10 higher)."""
    rng = np.random.default_rng(5)
    lid = np.c_[rng.uniform(0, 140, 2000), rng.uniform(0, 95, 2000), 55 + rng.normal(0, 0.5, 2000)]
    s = rng.uniform(0, 1, (1500, 2))
    front = np.c_[s[:, 0] * 140, rng.normal(0, 0.5, 1500), s[:, 1] * 55]
    hand = np.c_[rng.uniform(0, 30, 500), rng.uniform(0, 25, 500), rng.uniform(55, 75, 500)]
    cams = np.array([[70.0, -150.0, 400.0], [20.0, -100.0, 300.0]])
    fit = box_fit.fit_box(np.vstack([lid, front, hand]), known_size=[140, 95, 55], viewpoints=cams)
    assert (fit.corners[:, 2].min(), fit.corners[:, 2].max()) == pytest.approx((0.0, 55.0), abs=1.0)


def test_a_run_without_a_posed_frame_is_an_error_before_anything_is_written(tmp_path):
    import json

    from alcn_cv.errors import InputError
    from pose import model as part_model

    model = part_model.PartModel(
        corners=box_corners([100, 80, 40]), points3d=np.zeros((1, 3)), descriptors=np.zeros((1, 32), np.uint8)
    )
    model.extra["K"] = camera_matrix(600.0, 600.0, 160.0, 120.0).tolist()
    part_model.save(model, tmp_path / "m.npz")
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10, (320, 240))
    for _ in range(3):
        writer.write(np.full((240, 320, 3), 128, np.uint8))
    writer.release()
    (tmp_path / "lost.json").write_text(json.dumps({f"frame_{i:06d}": [] for i in range(3)}))
    with pytest.raises(InputError, match="run lost: no frame"):
        overlay.main(video, [("lost", tmp_path / "m.npz", tmp_path / "lost.json")], tmp_path / "out")
    assert not (tmp_path / "out").exists()
    (tmp_path / "file").write_text("")
    with pytest.raises(InputError, match="is a file"):
        overlay.main(video, [("lost", tmp_path / "m.npz", tmp_path / "lost.json")], tmp_path / "file")


def test_the_overlay_error_draws_with_the_models_distortion(tmp_path):
    """A model built with a calibration (`alcn pose build --camera`) stores its distortion, which `alcn pose track`
    tracks with: the overlay error drew its box without it, off the distorted object's edges."""
    import json

    from pose import model as part_model

    dist = np.array([-0.4, 0.1, 0.0, 0.0, 0.0])
    rvec, tvec = _pose()
    tvec = tvec + np.array([[-14.0], [-9.0], [0.0]])  # towards the corner of the frame, where distortion is largest
    corners = box_corners(SIZE)
    img = np.full((480, 640), 40, np.uint8)
    uv = project(corners, rvec, tvec, K, dist)
    for quad, level in zip(facing_faces(corners, cv2.Rodrigues(rvec)[0], tvec.ravel()), (110, 180, 250)):
        cv2.fillConvexPoly(img, cv2.convexHull(np.round(uv[list(quad)] * 16).astype(np.int32)), level, cv2.LINE_AA, 4)
    (tmp_path / "frames").mkdir()
    cv2.imwrite(str(tmp_path / "frames" / "0000.png"), img)
    R = cv2.Rodrigues(rvec)[0]
    pose = [{"obj_id": 1, "cam_R_m2c": R.ravel().tolist(), "cam_t_m2c": tvec.ravel().tolist()}]
    (tmp_path / "p.json").write_text(json.dumps({"0000": pose}))  # mm, the model's units
    model = part_model.PartModel(corners=corners, points3d=np.zeros((1, 3)), descriptors=np.zeros((1, 32), np.uint8))
    model.extra["K"] = K.tolist()
    part_model.save(model, tmp_path / "pinhole.npz")  # a model of before: no distortion
    model.extra["dist"] = dist.tolist()
    part_model.save(model, tmp_path / "m.npz")
    with_dist = overlay.measure(tmp_path / "m.npz", tmp_path / "p.json", tmp_path / "frames", progress=False)
    without = overlay.measure(tmp_path / "pinhole.npz", tmp_path / "p.json", tmp_path / "frames", progress=False)
    assert with_dist["0000"].matched_px < 1.0 and without["0000"].matched_px > 4.0


def test_a_shown_frame_without_a_pose_is_labelled_and_said(tmp_path, caplog):
    """`alcn pose overlay-error` after `alcn pose track --max-frames 60` drew its default frame (frame_000300) without a
    box and without a word: it looked like a tracking failure. A run without a pose for a shown frame is labelled
    so on it and logged."""
    rvec, tvec = _pose()
    corners = box_corners(SIZE)
    (tmp_path / "frames").mkdir()
    for name in ("0000", "0001"):
        cv2.imwrite(str(tmp_path / "frames" / f"{name}.png"), _render(corners, rvec, tvec))
    drawn = {"track": (corners, K, None, {"0000": (rvec, tvec)})}
    with caplog.at_level("WARNING", logger="pose.overlay"):
        sheet = overlay.plot_frames(tmp_path / "frames", drawn, ["0000", "0001"], tmp_path / "sheet.png")
    assert "0001: the run 'track' has no pose for it" in caplog.text and "0000:" not in caplog.text
    tiles = cv2.imread(str(sheet), cv2.IMREAD_GRAYSCALE)
    posed, unposed = tiles[:, :640], tiles[:, 640:]
    box = cv2.absdiff(posed, cv2.cvtColor(_render(corners, rvec, tvec), cv2.COLOR_GRAY2BGR)[..., 0]) > 0
    assert box[40:-40].any() and (unposed[:30, 120:240] > 0).any()  # a box on the first; a longer label on the second
