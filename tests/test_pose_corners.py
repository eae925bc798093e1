"""The learned corner detector of pose/: labels, sub-stride peaks, gating, ONNX, training, Table 1."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import onnx
import pytest
import torch

from alcn_cv.errors import DatasetError, InputError, WeightFileError
from alcn_cv.nets.detector import Detector
from alcn_cv.weight_file import ONNX_METADATA_KEY
from pose import box, corner_data, corner_train, track
from pose import corners as pc
from pose.corner_net import CornerNet
from pose.model import box_corners, read_box_corners
from pose.sequence import load_sequence
from pose.solver import camera_matrix, rotation_error_deg


@pytest.fixture(scope="module")
def posedata(tmp_path_factory):
    """Four registered 320x240 training frames of the data engine's box, one test sequence."""
    from alcn_cv.data import pose

    return pose.generate(
        tmp_path_factory.mktemp("corners") / "data",
        conf="small",
        n_frames=4,
        n_test=1,
        clutter=False,
        train_sweeps=(1,),
        progress=False,
    )


@pytest.fixture(scope="module")
def random_net(tmp_path_factory):
    """A detector of the 8 box corners (``divisions=1``), untrained."""
    torch.manual_seed(0)
    net = CornerNet(8, channels=(4, 8), hidden=16).eval()
    path = corner_train.export_onnx(net, tmp_path_factory.mktemp("onnx") / "c.onnx", _box_corners_meta(net.config))
    return net, path


def _box_corners_meta(config: dict) -> dict:
    """The metadata of a detector of the 8 corners of a 140x95x55 mm box, its network's ``config`` given."""
    corners = box_corners([140, 95, 55]).tolist()
    return {
        "format": pc.FORMAT_NAME,
        "version": pc.FORMAT_VERSION,
        "normalization": "none",
        "scale": 0.5,
        "input_mean": 0.5,
        "input_std": 0.25,
        "parts": corners,
        "corners": corners,
        "units": "mm",
        "window": pc.WINDOW,
        "stride": pc.STRIDE,
        "pad": pc.PAD,
        "config": config,
    }


def test_constants_match_the_detector():
    assert (pc.WINDOW, pc.STRIDE) == (Detector.input_size, Detector.stride) == (CornerNet.input_size, CornerNet.stride)
    net = CornerNet(channels=(4, 8), hidden=16).eval()
    with torch.no_grad():  # one output cell per 32x32 window, one more per 4 pixels; 1 + 26 logits, 26 offsets
        assert net(torch.zeros(1, 1, 32, 32)).shape == (1, 79, 1, 1)
        assert net(torch.zeros(1, 1, 32 + 8, 32 + 12)).shape == (1, 79, 3, 4)
    assert pc.grid_shape(240, 320) == (61, 81)
    np.testing.assert_allclose(pc.grid_centres((2, 3))[1, 2], [7.5, 3.5])


def test_scaled_camera_follows_the_resize():
    """The intrinsics of a resized frame project where ``cv2.resize`` moves the pixels (OpenCV pixel
    centres: ``(x + 0.5) s - 0.5``), for one scale and for one per axis."""
    K = camera_matrix(300.0, 280.0, 39.5, 29.5)
    rng = np.random.default_rng(0)
    pts = rng.uniform([-20, -15, 200], [20, 15, 300], (20, 3))
    uv = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, None)[0].reshape(-1, 2)
    for sx, sy in ((0.75, 0.75), (2.0, 0.5)):
        moved = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), pc.scaled_camera(K, sx, sy), None)[0].reshape(-1, 2)
        np.testing.assert_allclose(moved, (uv + 0.5) * [sx, sy] - 0.5, atol=1e-9)
    np.testing.assert_array_equal(pc.scaled_camera(K, 0.75), pc.scaled_camera(K, 0.75, 0.75))
    # the principal point of an 80x60 frame doubled in size: where a blob at it lands
    K = camera_matrix(300.0, 280.0, 39.0, 29.0)
    blob = np.zeros((60, 80), np.float32)
    blob[29, 39] = 1.0
    big = cv2.resize(cv2.GaussianBlur(blob, (0, 0), 3.0), (160, 120), interpolation=cv2.INTER_LINEAR)
    yy, xx = np.mgrid[:120, :160]
    centroid = [(xx * big).sum() / big.sum(), (yy * big).sum() / big.sum()]
    np.testing.assert_allclose(centroid, pc.scaled_camera(K, 2.0)[:2, 2], atol=0.02)


def test_grid_cell_is_the_cell_centred_nearest():
    centres = pc.grid_centres((5, 7))
    uv = np.random.default_rng(1).uniform([0, 0], [23, 15], (200, 2))
    j, i = pc.grid_cell(uv).T
    d = np.linalg.norm(centres[None] - uv[:, None, None], axis=3).reshape(len(uv), -1)
    np.testing.assert_allclose(d[np.arange(len(uv)), i * 7 + j], d.min(1))
    np.testing.assert_array_equal(
        pc.grid_cell(centres.reshape(-1, 2)), np.c_[np.tile(np.arange(7), 5), np.repeat(np.arange(5), 7)]
    )


def test_label_grid_offsets_point_at_the_corner():
    shape = pc.grid_shape(60, 80)
    uv = np.array([[21.3, 30.8], [60.0, 10.0]])
    labels, offsets, owner = corner_data.label_grid(uv, np.array([2, 5]), np.array([[40.0, 50.0]]), shape)
    centres = pc.grid_centres(shape)
    d = np.linalg.norm(centres[None] - uv[:, None, None], axis=3)
    assert set(np.unique(labels[d[0] <= 4.0])) == {3} and set(np.unique(labels[d[1] <= 4.0])) == {6}
    assert (labels[(d.min(0) > 4.0) & (d.min(0) <= 7.0)] == -1).all()
    hidden = np.linalg.norm(centres - [40.0, 50.0], axis=2)
    assert (labels[hidden <= 7.0] == -1).all() and (labels[(d.min(0) > 7.0) & (hidden > 7.0)] == 0).all()
    # every owned cell's offset points at its corner, to the stride's fraction
    for k, corner in zip([2, 5], uv):
        cells = owner == k
        assert cells.sum() >= 4
        np.testing.assert_allclose(
            centres[cells] + pc.STRIDE * offsets[:, cells].T, np.tile(corner, (cells.sum(), 1)), atol=1e-5
        )
    assert (owner[d.min(0) > 7.0] == -1).all()


def _fake_maps(shape: tuple[int, int], peaks: dict[int, list[tuple[float, float, float]]]):
    """Scores and votes of a detector that sees corner k at each (x, y, score) of ``peaks[k]``
    (downscaled pixels): a 3x3 blob of scores, every cell voting for the exact position."""
    prob = np.zeros((9, *shape), np.float32)
    prob[0] = 1.0
    votes = np.zeros((8, *shape, 2))
    centres = pc.grid_centres(shape)
    for k, points in peaks.items():
        for x, y, s in points:
            d = np.linalg.norm(centres - [x, y], axis=2)
            i, j = np.unravel_index(d.argmin(), shape)
            blob = np.zeros(shape, np.float32)
            blob[i - 1 : i + 2, j - 1 : j + 2] = s / 2
            blob[i, j] = s
            prob[k + 1] = np.maximum(prob[k + 1], blob)
            votes[k][blob > 0] = [x, y]
    return prob, votes


def test_peaks_are_placed_finer_than_the_stride(random_net, monkeypatch):
    det = pc.CornerDetector(random_net[1])
    shape = pc.grid_shape(120, 160)
    truth = {0: [(37.3, 21.7, 0.9)], 4: [(101.9, 80.2, 0.6)], 7: [(12.6, 90.1, 0.03)]}
    monkeypatch.setattr(det, "maps", lambda image: _fake_maps(shape, truth))
    peaks = det.peaks(None)
    for k in range(8):
        xy, scores = peaks[k]
        if k in (0, 4):  # full-image pixels of the downscaled position, to a small fraction of a pixel
            np.testing.assert_allclose(xy, pc.from_scaled(np.array([truth[k][0][:2]]), det.scale), atol=1e-6)
            assert scores[0] == pytest.approx(truth[k][0][2])
        else:  # nothing or below min_score
            assert len(xy) == 0


def test_vote_positions_are_the_weighted_mean_of_the_neighbourhood():
    rng = np.random.default_rng(0)
    score, votes = rng.random((6, 7)).astype(np.float32), rng.random((6, 7, 2)) * 50
    ii, jj = np.array([0, 2, 5]), np.array([0, 3, 6])  # a corner, an inner cell, the opposite corner
    for i, j, got in zip(ii, jj, pc.vote_positions(score, votes, ii, jj)):
        rows, cols = slice(max(i - 1, 0), i + 2), slice(max(j - 1, 0), j + 2)
        w = score[rows, cols].astype(np.float64)
        np.testing.assert_allclose(got, (w[..., None] * votes[rows, cols]).sum((0, 1)) / w.sum(), rtol=1e-9)
    assert pc.vote_positions(score, votes, ii[:0], jj[:0]).shape == (0, 2)


def test_candidates_are_gated_by_the_predicted_pose(random_net, monkeypatch):
    det = pc.CornerDetector(random_net[1], top_k=3, gate=20.0)
    shape = pc.grid_shape(120, 160)
    # corner 2: a strong wrong peak far away and the right one, weaker, near the prediction
    monkeypatch.setattr(det, "maps", lambda image: _fake_maps(shape, {2: [(120.0, 30.0, 0.9), (40.0, 60.0, 0.3)]}))
    right = pc.from_scaled(np.array([40.0, 60.0]), det.scale)
    wrong = pc.from_scaled(np.array([120.0, 30.0]), det.scale)
    everywhere = det.peaks(None)[2][0]
    np.testing.assert_allclose(everywhere, [wrong, right], atol=1e-6)
    predicted = np.tile(right + [8.0, -5.0], (8, 1))  # 9.4 px off
    np.testing.assert_allclose(det.peaks(None, predicted, 20.0)[2][0], [right], atol=1e-6)
    assert len(det.peaks(None, predicted, 5.0)[2][0]) == 0
    np.testing.assert_allclose(det.peaks(None, predicted)[2][0], [right], atol=1e-6)  # within the gate by default
    # detect() projects the corners with the prior and gates with gate * search_scale
    K = camera_matrix(300, 300, 159.5, 119.5)
    rvec, tvec = np.zeros(3), np.array([0.0, 0.0, 1000.0])
    uv = cv2.projectPoints(det.corners, rvec, tvec, K, None)[0].reshape(-1, 2)
    target = pc.to_scaled(uv[2], det.scale)
    monkeypatch.setattr(det, "maps", lambda image: _fake_maps(shape, {2: [(*target, 0.3), (120.0, 30.0, 0.9)]}))
    corr = det.detect(None, (rvec, tvec, K))
    assert corr.keypoints == 1 and np.allclose(corr.object_points[0], det.corners[2])
    np.testing.assert_array_equal(corr.directions, box.edge_directions(det.corners, det.parts)[[2]])
    assert det.detect(None).keypoints == 2


def test_support_is_the_score_where_the_pose_shows_its_parts(random_net, monkeypatch):
    det = pc.CornerDetector(random_net[1], min_support=0.5)
    image = np.zeros((240, 320), np.uint8)  # 120x160 at the detector's scale of 0.5
    K = camera_matrix(300, 300, 159.5, 119.5)
    rvec = cv2.Rodrigues(np.diag([1.0, -1.0, -1.0]))[0]  # looking down at the top face: corners 1, 3, 5, 7
    tvec = np.array([-70.0, 47.5, 800.0])
    uv = cv2.projectPoints(det.corners, rvec, tvec, K, None)[0].reshape(-1, 2)
    top = {k: [(*pc.to_scaled(uv[k], det.scale), 0.8)] for k in (1, 3, 5, 7)}
    shape = pc.grid_shape(120, 160)
    monkeypatch.setattr(det, "maps", lambda image: _fake_maps(shape, top))
    assert det.support(image, rvec, tvec, K) == pytest.approx(0.8)  # the hidden bottom corners do not count
    assert det.verify(image, rvec, tvec, K) == ""
    shifted = tvec + [30.0, 0.0, 0.0]  # 11 px of the full frame: the 3x3 cells reach the blobs' centres or edges
    assert 0.4 <= det.support(image, rvec, shifted, K) < 0.8
    far = tvec + [120.0, 0.0, 0.0]  # 45 px
    assert det.support(image, rvec, far, K) == 0.0
    assert "support 0.00" in det.verify(image, rvec, far, K)
    assert det.support(image, rvec, tvec + [0.0, 0.0, -2000.0], K) == 0.0  # behind the camera: nothing shown
    with pytest.raises(InputError, match="min_support"):
        pc.CornerDetector(random_net[1], min_support=1.0)


def test_propose_finds_the_pose_the_scores_show_and_only_a_unique_one(random_net, monkeypatch):
    det = pc.CornerDetector(random_net[1])
    image = np.zeros((240, 320), np.uint8)  # 120x160 at the detector's scale of 0.5
    K = camera_matrix(300, 300, 159.5, 119.5)
    R = cv2.Rodrigues(np.array([0.5, -0.4, 0.0]))[0] @ np.diag([1.0, -1.0, -1.0])  # the top and two sides
    tvec = np.array([-70.0, 47.5, 800.0])
    uv, vis = box.part_visibility(det.corners, R, tvec, K, image.shape)
    assert vis.sum() == 7
    shape = pc.grid_shape(120, 160)

    def blobs(score, shift=None):
        out = {k: [(*pc.to_scaled(uv[k], det.scale), score)] for k in np.flatnonzero(vis)}
        if shift is not None:  # the same box again, elsewhere
            for k in out:
                out[k].append((*pc.to_scaled(uv[k] + shift, det.scale), score))
        return _fake_maps(shape, out)

    monkeypatch.setattr(det, "maps", lambda image: blobs(0.8))
    rvec, t = det.propose(image, K)
    np.testing.assert_allclose(t.ravel(), tvec, atol=2.0)
    assert rotation_error_deg(cv2.Rodrigues(rvec)[0], R) < 1.0
    assert det.verify(image, rvec, t, K, proposed=True) == ""
    monkeypatch.setattr(det, "maps", lambda image: blobs(0.2))  # the pose, shown too weakly
    assert det.propose(image, K) is None
    monkeypatch.setattr(det, "maps", lambda image: blobs(0.8, shift=[0.0, 80.0]))  # two boxes: no unique pose
    assert det.propose(image, K) is None
    monkeypatch.setattr(det, "maps", lambda image: blobs(0.8))
    assert pc.CornerDetector(random_net[1], proposals=0).propose(image, K) is None
    with pytest.raises(InputError, match="proposals"):
        pc.CornerDetector(random_net[1], proposals=-1)
    with pytest.raises(InputError, match="refine_search_scale"):
        pc.CornerDetector(random_net[1], refine_search_scale=-0.5)


def test_build_frames_labels_follow_the_corners(posedata):
    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    frames = corner_data.build_frames(seq, corners, "none", corner_train.CornerRecipe(scale=1.0, copies=2))
    parts = box.box_parts(corners)
    n = 3 * len(seq.views)
    assert frames.images.shape == (n, 240 + 2 * pc.PAD, 320 + 2 * pc.PAD) and frames.images.dtype == np.float32
    assert frames.labels.shape == frames.owner.shape == (n, 61, 81) and frames.offsets.shape == (n, 2, 61, 81)
    assert np.isfinite(frames.images).all() and frames.view.tolist() == np.repeat(np.arange(len(seq.views)), 3).tolist()
    centres = pc.grid_centres((61, 81))
    for f in range(n):
        visible = frames.corners[f]
        if f % 3 == 0:  # the view itself: the projected visible corners
            view = seq.views[f // 3]
            uv, vis = box.part_visibility(corners, view.R_w2c, view.t_w2c, view.K, (240, 320), parts=parts)
            assert sorted(visible[:, 2].astype(int)) == sorted(np.flatnonzero(vis))
            np.testing.assert_allclose(visible[:, :2], uv[visible[:, 2].astype(int)])
            assert vis[8:].any()  # parts besides the corners
        for x, y, k in visible:  # every visible part has its cells, whose votes hit it
            cells = (frames.labels[f] == k + 1) & (np.linalg.norm(centres - [x, y], axis=2) <= 4.0)
            assert cells.any()
            np.testing.assert_allclose(
                centres[cells] + pc.STRIDE * frames.offsets[f][:, cells].T, np.tile([x, y], (cells.sum(), 1)), atol=1e-4
            )
    # the copies differ from their view (warp, background, intensity)
    assert np.abs(frames.images[1] - frames.images[0]).mean() > 0.1


def test_the_training_frames_use_the_mask_of_the_sequences_object(posedata, tmp_path, monkeypatch):
    """A BOP frame's ``mask_visib`` is per object (``<image>_<annotation index>.png``): the sequence of
    object ``obj_id`` carries that object's masks, and the corner frames read them."""
    train = posedata / "train" / "000001"
    ids = [o["obj_id"] for o in json.loads((train / "scene_gt.json").read_text())["0"]]
    for index, obj_id in enumerate(ids):
        seq = load_sequence(train, obj_id=obj_id)
        assert all(v.mask.name == f"{int(v.name.split('.')[0]):06d}_{index:06d}.png" for v in seq.views)
        assert all(v.mask.is_file() for v in seq.views)
    with pytest.raises(DatasetError, match="no object 99"):
        load_sequence(train, obj_id=99)
    seq = load_sequence(train, obj_id=ids[0])
    for v in seq.views:
        v.mask = tmp_path / f"mask_of_{v.name}"
    read = []
    monkeypatch.setattr(corner_data, "_read_mask", lambda path, shape: read.append(path))
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    corner_data.build_frames(seq, corners, "none", corner_train.CornerRecipe(scale=0.5, copies=0))
    assert read == [v.mask for v in seq.views]


def test_a_sequence_or_camera_with_lens_distortion_is_refused_by_the_corner_detector(posedata, random_net):
    """The training labels (pinhole part_visibility, homography novel views) and the tracking's gates, support and
    P3P proposals ignore lens distortion, while the solver modelled it: a distorted sequence trained wrong labels with
    no error. Both now refuse it in one line that says to undistort first."""
    from pose.track import open_tracker

    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    seq.views[1].dist = np.array([0.1, 0.0, 0.0, 0.0])
    with pytest.raises(InputError, match=r"view .* has lens distortion.*alcn calib undistort"):
        corner_data.build_frames(seq, corners, "none", corner_train.CornerRecipe(scale=0.5, copies=0))
    seq.views[1].dist = np.zeros(4)  # no distortion: trained as before
    corner_data.build_frames(seq, corners, "none", corner_train.CornerRecipe(scale=0.5, copies=0))
    K = camera_matrix(300.0, 300.0, 159.5, 119.5)
    with pytest.raises(InputError, match=r"lens distortion.*alcn calib undistort"):
        open_tracker(random_net[1], K=K, dist=np.array([0.1, 0.0, 0.0, 0.0]), detector="corners")
    assert open_tracker(random_net[1], K=K, dist=np.zeros(5), detector="corners").kind == "corners"


def test_novel_view_moves_each_face_with_its_plane(posedata):
    from alcn_cv import io

    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    view = seq.views[0]
    gray = cv2.cvtColor(io.read_image(seq.image_dir / view.name), cv2.COLOR_BGR2GRAY)
    R, t, K = view.R_w2c, view.t_w2c, view.K
    uv, vis = box.part_visibility(corners, R, t, K, gray.shape)
    # no motion: the same frame and corners
    same, mask, uv0, vis0 = corner_data.novel_view(
        gray, corners, R, t, K, np.random.default_rng(0), azimuth_deg=0, elevation_deg=0, distance=(1, 1)
    )
    np.testing.assert_allclose(uv0, uv, atol=1e-6)
    assert (vis0 == vis).all() and mask.any()
    assert np.abs(same.astype(int) - gray)[cv2.erode(mask, np.ones((3, 3), np.uint8)) > 0].mean() < 2
    # another viewpoint: a pixel of every face it sees comes from that face's plane in the view
    img2, mask2, uv2, _ = corner_data.novel_view(gray, corners, R, t, K, np.random.default_rng(1), distance=(0.7, 1.2))
    assert np.abs(uv2 - uv).max() > 1
    checked = 0
    for quad in box.facing_faces(corners, R, t):
        q1, q2 = uv[list(quad)].astype(np.float32), uv2[list(quad)].astype(np.float32)
        if cv2.contourArea(q1, oriented=True) * cv2.contourArea(q2, oriented=True) <= 0:
            continue  # turned away in the new view
        x2, y2 = np.round(q2.mean(0)).astype(int)
        x1, y1 = cv2.perspectiveTransform(np.array([[[x2, y2]]], np.float32), cv2.getPerspectiveTransform(q2, q1))[0, 0]
        expected = cv2.getRectSubPix(gray.astype(np.float32), (1, 1), (float(x1), float(y1)))[0, 0]
        assert mask2[y2, x2] and abs(float(img2[y2, x2]) - expected) < 3
        checked += 1
    assert checked >= 2


def test_build_image_frames_labels_follow_the_parts():
    rng = np.random.default_rng(0)
    gray = cv2.GaussianBlur(rng.uniform(0, 255, (120, 160)).astype(np.float32), (0, 0), 2).astype(np.uint8)
    uv = np.array([[20, 15], [80, 15], [140, 15], [140, 60], [140, 100], [80, 100], [20, 100], [20, 60]], float)
    frames = corner_data.build_image_frames(gray, uv, "none", corner_train.CornerRecipe(scale=1.0, copies=3))
    assert frames.images.shape == (4, 120 + 2 * pc.PAD, 160 + 2 * pc.PAD) and frames.view.tolist() == [0] * 4
    np.testing.assert_allclose(frames.corners[0][:, :2], uv)
    assert frames.corners[0][:, 2].tolist() == list(range(8))
    centres = pc.grid_centres(frames.labels.shape[1:])
    for f in range(4):
        for x, y, k in frames.corners[f]:
            assert ((frames.labels[f] == k + 1) & (np.linalg.norm(centres - [x, y], axis=2) <= 4.0)).any()
    recipe = corner_train.CornerRecipe(scale=1.0, copies=0)
    assert corner_data.build_image_frames(gray, uv[:4], "none", recipe).corners[0][:, 2].tolist() == [
        0,
        1,
        2,
        3,
    ]  # any number of parts
    for bad in (uv[:, :1], uv[:0], np.full((8, 2), np.nan)):
        with pytest.raises(InputError, match="parts' pixels"):
            corner_data.build_image_frames(gray, bad, "none", recipe)


def test_mixing_layers_keep_the_geometry():
    net = CornerNet(channels=(4, 8), hidden=16, mixing=2).eval()
    with torch.no_grad():
        assert net(torch.zeros(1, 1, 32 + 8, 32 + 12)).shape == (1, 79, 3, 4)
    assert net.config == {"num_parts": 26, "channels": [4, 8], "hidden": 16, "mixing": 2}


def test_onnx_matches_torch(random_net):
    net, path = random_net
    det = pc.CornerDetector(path)
    image = np.random.default_rng(0).random((45, 61), dtype=np.float32)
    with torch.no_grad():
        padded = cv2.copyMakeBorder(image, pc.PAD, pc.PAD, pc.PAD, pc.PAD, cv2.BORDER_REFLECT_101)
        ref = net(torch.from_numpy(padded)[None, None])[0].numpy()
    got = det.outputs(image)
    assert got.shape == ref.shape == (25, 12, 16) and np.ptp(ref) > 1e-3
    np.testing.assert_allclose(got, ref, atol=1e-4)
    assert det.corners.shape == (8, 3) and det.scale == 0.5 and det.normalization_spec == "none"


def test_runs_where_torch_cannot_be_imported(random_net, run_without_torch):
    _, path = random_net
    frame = np.random.default_rng(2).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    ref = pc.CornerDetector(path, min_score=0.0).detect(frame)
    out = path.parent / "points.npy"
    run_without_torch(
        f"""
        import numpy as np
        from pose.corners import CornerDetector
        frame = np.random.default_rng(2).integers(0, 256, (120, 160, 3), dtype=np.uint8)
        np.save(sys.argv[1], CornerDetector({str(path)!r}, min_score=0.0).detect(frame).image_points)
    """,
        out,
    )
    assert len(ref.image_points) > 0
    np.testing.assert_allclose(np.load(out), ref.image_points, atol=1e-3)


def test_alcn_runs_at_the_detector_resolution_torch_free_where_it_can(tmp_path):
    import shutil

    from alcn_cv.runtime import MODELS

    paper = pc.normalization_for("alcn:model=paper")
    assert paper.scale == 1.0 and paper.backend == "opencv"
    assert pc.normalization_for("alcn:model=paper:backend=fast").backend == "fast"
    weights = shutil.copy(MODELS["lite"], tmp_path / "lite.npz")  # weights without an ONNX twin
    lite = pc.normalization_for(f"alcn:weights={weights}:mixture=pyramid")
    assert lite.scale == 1.0 and lite.backend == "fast" and lite.mixture == "pyramid"


def test_an_impossible_recipe_is_named():
    """Shares outside [0, 1], a negative noise, part cells beyond the ignored ring, an empty layer."""
    for conf in corner_train.CONFS.values():
        conf.check()
    bad = {"novel_views": 1.5, "backgrounds": -0.1, "noise": -0.01, "pos_radius": 8.0, "hidden": 0, "mixing": -1}
    for key, value in bad.items():
        with pytest.raises(InputError, match=f"'{key}'"):
            dataclasses.replace(corner_train.CONFS["box"], **{key: value}).check()


def test_bad_files(tmp_path, random_net):
    bad = tmp_path / "bad.onnx"
    bad.write_bytes(b"not a model")
    with pytest.raises(WeightFileError, match="bad.onnx"):
        pc.CornerDetector(bad)
    with pytest.raises(WeightFileError, match="not found"):
        pc.CornerDetector(tmp_path / "missing.onnx")
    with pytest.raises(InputError, match="top_k"):
        pc.CornerDetector(random_net[1], top_k=0)
    with pytest.raises(InputError, match=r"\.onnx"):
        corner_train.export_onnx(random_net[0], tmp_path / "x.pt", {})
    with pytest.raises(InputError, match="box_ply"):
        corner_train.main(tmp_path, tmp_path / "c.onnx")
    wrong = corner_train.export_onnx(
        random_net[0],
        tmp_path / "wrong.onnx",
        {**pc.read_metadata(random_net[1]), "parts": box_corners([1, 2, 3]).tolist() * 2},
    )  # 16 parts, 8 outputs
    with pytest.raises(WeightFileError, match="16 parts but a network for 8"):
        pc.CornerDetector(wrong)
    with pytest.raises(InputError, match="trained after the normalization 'none'"):
        track.main(random_net[1], tmp_path, tmp_path / "p.json", np.eye(3), normalization="alcn", detector="corners")


def _parser():
    """The ``alcn`` command's parser: its namespace has the words parsed, which the reports record."""
    from alcn_cv.cli import build_parser

    return build_parser()


def test_train_corners_lowers_the_loss(posedata, tmp_path):
    """`alcn pose train-corners`: a few steps on four frames."""
    onnx = tmp_path / "corners.onnx"
    args = _parser().parse_args(
        [
            "pose",
            "train-corners",
            str(posedata / "train" / "000001"),
            str(onnx),
            "--box-ply",
            str(posedata / "models" / "obj_000001.ply"),
            "--conf",
            "box",
            "--set",
            "iterations=12",
            "--set",
            "copies=0",
            "--set",
            "batch_size=24",
            "--device",
            "cpu",
        ]
    )
    assert args.func(args) == 0
    meta = pc.read_metadata(onnx)
    assert meta["normalization"] == "none" and meta["fit"]["final_loss"] < meta["fit"]["first_loss"]
    assert meta["fit"]["device"] == "cpu" and meta["conf"] == "box"
    # how it was made, as the Normalizers' weight files record it (it recorded the preset alone)
    assert meta["command"].startswith("alcn pose train-corners ") and "--set iterations=12" in meta["command"]
    assert meta["date"].endswith(" UTC") and meta["machine"]["cpu_count"] >= 1
    # the recipe is recorded whole: the preset with the settings
    expected = corner_train.CornerRecipe(iterations=12, copies=0, batch_size=24)
    assert meta["recipe"] == json.loads(json.dumps(dataclasses.asdict(expected)))
    assert meta["config"] == {"num_parts": 26, "channels": [16, 32], "hidden": 128, "mixing": 1}
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    np.testing.assert_allclose(meta["parts"], box.box_parts(corners))
    det = pc.CornerDetector(onnx)
    assert det.parts.shape == (26, 3) and det.outputs(np.zeros((40, 48), np.float32)).shape == (79, 11, 13)
    # the 8 corners only
    args = _parser().parse_args(
        [
            "pose",
            "train-corners",
            str(posedata / "train" / "000001"),
            str(onnx),
            "--box-ply",
            str(posedata / "models" / "obj_000001.ply"),
            "--set",
            "iterations=2",
            "--set",
            "copies=0",
            "--set",
            "divisions=1",
            "--overwrite",
        ]
    )
    assert args.func(args) == 0
    np.testing.assert_allclose(pc.read_metadata(onnx)["parts"], corners)


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error where torch sees no CUDA device")
def test_training_on_cuda_without_one_is_a_clear_error(posedata):
    recipe = corner_train.CornerRecipe(copies=0, iterations=1, batch_size=2, cells=4)
    frames = corner_data.build_frames(
        load_sequence(posedata / "train" / "000001"),
        read_box_corners(posedata / "models" / "obj_000001.ply"),
        "none",
        recipe,
    )
    with pytest.raises(InputError, match="no CUDA device"):
        corner_train.fit(CornerNet(), frames, recipe, device="cuda", progress=False)


def _recipes(posedata, tmp_path, monkeypatch, *extras: list[str]) -> list:
    """The recipes `alcn pose train-corners` and `alcn pose eval --detectors corners` pass on with each
    list of ``extras``."""
    from pose import evaluate

    seen = []
    monkeypatch.setattr(corner_train, "train_corners", lambda _s, _c, _o, recipe, **kw: seen.append(recipe))
    monkeypatch.setattr(evaluate, "main", lambda *a, **kw: seen.append(kw["corner_recipe"]))
    for extra in extras:
        for command in (
            [
                "train-corners",
                str(posedata / "train" / "000001"),
                str(tmp_path / "c.onnx"),
                "--box-ply",
                str(posedata / "models" / "obj_000001.ply"),
            ],
            ["eval", "--data", str(posedata), "--out", str(tmp_path / "t"), "--detectors", "corners"],
        ):
            args = _parser().parse_args(["pose", *command, *extra])
            args.func(args)
    return seen


def test_both_commands_take_the_recipe_as_a_preset_and_settings(posedata, tmp_path, monkeypatch, capsys):
    box_recipe = corner_train.CONFS["box"]
    seen = _recipes(
        posedata,
        tmp_path,
        monkeypatch,
        [],
        ["--set", "jitter=true", "--set", "novel_distance=[0.6, 1.1]"],
        ["--conf", "planar"],
    )
    assert seen[0] == seen[1] == box_recipe == corner_train.CornerRecipe()
    assert seen[2] == seen[3] == dataclasses.replace(box_recipe, jitter=True, novel_distance=[0.6, 1.1])
    assert seen[4] == seen[5] == corner_train.CONFS["planar"]
    for bad, key in (
        (["novel_distance=[1.2, 0.7]"], "novel_distance"),
        (["iterations=many"], "iterations"),
        (["iteration=3"], "iteration"),
    ):
        with pytest.raises(InputError, match=key):
            _recipes(posedata, tmp_path, monkeypatch, ["--set", *bad])


def test_no_intensity_trains_on_the_views_own_intensities(posedata):
    """``intensity_scale=[1, 1]``, ``intensity_offset=0``: the copies keep their view's intensities."""
    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    recipe = corner_train.CornerRecipe(scale=1.0, copies=3, backgrounds=0.0, noise=0.0, novel_views=0.0)
    frames = corner_data.build_frames(
        seq, corners, "none", dataclasses.replace(recipe, intensity_scale=[1.0, 1.0], intensity_offset=0.0)
    )
    changed = corner_data.build_frames(seq, corners, "none", recipe)
    shifts = [[abs(f.images[c].mean() - f.images[0].mean()) for c in (1, 2, 3)] for f in (frames, changed)]
    assert max(shifts[0]) < 0.3 * max(shifts[1])


def test_novel_distance_brings_the_novel_views_nearer(posedata):
    """``novel_distance``: the novel views' camera distance, so that the network sees the box larger
    than in any training view."""
    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")

    def box_size(distance):  # mean spread of the visible parts over the copies, pixels
        recipe = corner_train.CornerRecipe(
            scale=1.0, copies=6, backgrounds=0.0, noise=0.0, novel_views=1.0, novel_distance=list(distance)
        )
        frames = corner_data.build_frames(seq, corners, "none", recipe, seed=3)
        return np.mean([np.ptp(c[:, :2], 0).max() for c in frames.corners if len(c) >= 4])

    assert box_size((0.7, 0.7)) > 1.2 * box_size((1.2, 1.2))
    with pytest.raises(InputError, match="novel_distance"):
        corner_data.build_frames(seq, corners, "none", corner_train.CornerRecipe(novel_distance=[1.2, 0.7]))


def test_jitter_varies_each_crop_after_the_normalizer(posedata, monkeypatch):
    """:func:`pose.corner_train.jitter_crops` (the recipe's ``jitter``):
    each crop gets its own contrast, gain ramp, offset and noise within the bounds, in place."""
    rng = np.random.default_rng(0)
    crops = rng.normal(size=(64, 1, 40, 40)).astype(np.float32)
    jittered = corner_train.jitter_crops(crops.copy(), np.random.default_rng(1), noise=0.0)
    assert jittered.dtype == np.float32 and jittered.shape == crops.shape
    gain = jittered - jittered.mean((2, 3), keepdims=True)  # without noise: the gain field times the crop
    ratio = np.median(np.abs(gain) / (np.abs(crops - crops.mean((2, 3), keepdims=True)) + 1e-3), axis=(2, 3))
    assert ratio.min() < 0.85 and ratio.max() > 1.15  # contrasts differ from crop to crop
    assert ratio.min() > 1 / 1.5 / np.exp(0.8) and ratio.max() < 1.5 * np.exp(0.8)  # and stay within the bounds
    left, right = (
        np.abs(jittered[:, 0, :, :8]).mean((1, 2)) / np.abs(crops[:, 0, :, :8]).mean((1, 2)),
        np.abs(jittered[:, 0, :, -8:]).mean((1, 2)) / np.abs(crops[:, 0, :, -8:]).mean((1, 2)),
    )
    assert np.abs(np.log(right / left)).max() > 0.3  # a gain ramp across some crops
    same = crops.copy()
    corner_train.jitter_crops(same, np.random.default_rng(1), contrast=1.0, ramp=0.0, offset=0.0, noise=0.0)
    np.testing.assert_allclose(same, crops, atol=1e-6)
    # what fit does with it: the crops jittered where the recipe asks
    recipe = corner_train.CornerRecipe(copies=0, iterations=2, batch_size=2, cells=4)
    frames = corner_data.build_frames(
        load_sequence(posedata / "train" / "000001"),
        read_box_corners(posedata / "models" / "obj_000001.ply"),
        "none",
        recipe,
    )
    drawn = []
    monkeypatch.setattr(corner_train, "jitter_crops", lambda images, rng: drawn.append(images.copy()) or images)
    corner_train.fit(CornerNet(), frames, dataclasses.replace(recipe, jitter=True), device="cpu", progress=False)
    assert len(drawn) == 2  # one batch per iteration
    corner_train.fit(CornerNet(), frames, dataclasses.replace(recipe, jitter=False), device="cpu", progress=False)
    assert len(drawn) == 2


def test_track_and_bench_the_corner_detector(posedata, random_net, tmp_path):
    """`alcn pose track --detector corners` and `alcn pose bench-corners` (torch-free speed)."""
    train = posedata / "train" / "000001"
    cam = json.loads((train / "scene_camera.json").read_text())["0"]
    K = [str(v) for v in np.asarray(cam["cam_K"])[[0, 4, 2, 5]]]
    out = tmp_path / "poses.json"
    parser = _parser()
    args = parser.parse_args(
        [
            "pose",
            "track",
            str(random_net[1]),
            str(train / "rgb"),
            str(out),
            "--detector",
            "corners",
            "--K",
            *K,
            "--overlay",
            str(tmp_path / "overlay"),
        ]
    )
    assert args.func(args) == 0
    assert len(json.loads(out.read_text())) == 4
    info = json.loads((tmp_path / "poses_info.json").read_text())
    assert info["summary"]["detector"] == "corners" and len(list((tmp_path / "overlay").glob("*.png"))) == 4
    args = parser.parse_args(
        [
            "pose",
            "bench-corners",
            str(random_net[1]),
            str(train / "rgb"),
            "--K",
            *K,
            "--frame-size",
            "160",
            "120",
            "--repeats",
            "1",
            "--out",
            str(tmp_path / "bench"),
        ]
    )
    assert args.func(args) == 0
    bench = json.loads((tmp_path / "bench" / "bench_corners.json").read_text())
    assert bench["frames"] == 4 and bench["fps"] > 0 and set(bench["ms"]) == {"normalize", "network", "peaks_and_pose"}
    assert bench["cpu_ms_per_frame"] > 0 and "fps" in (tmp_path / "bench" / "bench_corners.md").read_text()


def test_bench_scales_the_camera_with_the_frames(posedata, random_net, monkeypatch):
    """`alcn pose bench-corners --frame-size`: the camera of the resized frames (pixel centres moved
    as ``cv2.resize`` moves them, :func:`pose.corners.scaled_camera`)."""
    from pose import corner_bench

    cameras = []
    make_tracker = track.make_tracker
    monkeypatch.setattr(track, "make_tracker", lambda kind, K, *a: cameras.append(K) or make_tracker(kind, K, *a))
    K = camera_matrix(300.0, 300.0, 159.5, 119.5)
    rgb = posedata / "train" / "000001" / "rgb"
    corner_bench.benchmark(random_net[1], rgb, K, size=(160, 120), max_frames=2, repeats=1)
    np.testing.assert_allclose(cameras[0], [[150.0, 0.0, 79.5], [0.0, 150.0, 59.5], [0.0, 0.0, 1.0]])


def test_corner_recall_against_the_true_corners(posedata, random_net, tmp_path, capsys):
    """`alcn pose corner-recall`: shares of the visible corners, as they are and on a grey background."""
    from pose import corner_bench

    scene = posedata / "test" / "000001"
    r = corner_bench.corner_recall(random_net[1], scene)
    assert r["frames"] == 4 and r["visible"] == sum(f["visible"] for f in r["per_frame"]) > 0
    assert 0 <= r["best"] <= r["candidates"] <= 1 and 0 <= r["gated"] <= 1 and 0 <= r["background_wins"] <= 1
    assert set(r["per_part"]) <= set(range(8))
    with pytest.raises(InputError, match="background"):
        corner_bench.corner_recall(random_net[1], scene, background="black")
    with pytest.raises(InputError, match="object 99 is not annotated"):
        corner_bench.corner_recall(random_net[1], scene, obj_id=99)
    args = _parser().parse_args(
        [
            "pose",
            "corner-recall",
            str(random_net[1]),
            str(scene),
            "--background",
            "keep",
            "grey",
            "--out",
            str(tmp_path),
        ]
    )
    assert args.func(args) == 0
    assert "grey background" in capsys.readouterr().out
    grey = json.loads((tmp_path / "corner_recall_grey.json").read_text())
    assert grey["background"] == "grey" and grey["visible"] == r["visible"]
    # what was measured, where: as every report records them (it recorded neither)
    assert grey["command"].startswith("alcn pose corner-recall ") and grey["machine"]["cpu_count"] >= 1


def test_table1_rows_of_the_corner_detector(posedata, tmp_path):
    from pose import evaluate

    with pytest.raises(InputError, match="unknown detectors"):
        evaluate.main(posedata, tmp_path, normalizations=["none"], detectors=["cnn"])
    result = evaluate.main(
        posedata,
        tmp_path,
        normalizations=["none"],
        detectors=["corners"],
        seeds=[0, 1],
        corner_recipe=corner_train.CornerRecipe(iterations=5, copies=0),
        corner_conf="box",
        command="alcn pose eval ...",
    )
    row = result["table"]["none / corner CNN"]
    assert list(row) == ["#1"] and 0.0 <= row["#1"] <= 100.0 and "#1" in result["spread"]["none / corner CNN"]
    assert (tmp_path / "corners_none_seed1.onnx").is_file()
    md = (tmp_path / "table1.md").read_text()
    assert "none / corner CNN" in md and "±" in md and "alcn pose eval ..." in md
    assert (tmp_path / "table1.png").is_file()
    details = result["details"]["none / corner CNN"]
    assert len(details["seeds"]) == 2 and details["seeds"][0]["sequences"]["#1"]["frames"] == 4


def test_eval_removes_an_earlier_runs_models_first(posedata, tmp_path, monkeypatch):
    from pose import evaluate

    out = tmp_path / "eval"
    out.mkdir()
    for name in ("model_dog.npz", "corners_dog_seed1.onnx", "notes.txt", "table1.json"):
        (out / name).write_bytes(b"earlier")

    def stop(*_args, **_kwargs):
        raise RuntimeError("stopped at the first model")

    monkeypatch.setattr(evaluate, "build_model", stop)
    with pytest.raises(RuntimeError, match="first model"):
        evaluate.main(posedata, out, normalizations=["none"], progress=False)
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt", "table1.json"]  # what it did not write stays
    (out / "table1.json").unlink()
    (out / "model_mine.npz").write_bytes(b"a user's")  # no earlier evaluation here: nothing is removed
    with pytest.raises(RuntimeError, match="first model"):
        evaluate.main(posedata, out, normalizations=["none"], progress=False)
    assert (out / "model_mine.npz").is_file()


def test_version_3_names_the_normalization_normalizer(random_net, tmp_path):
    meta = pc.read_metadata(random_net[1])
    meta["version"] = 3
    meta["normalizer"] = meta.pop("normalization")
    old = corner_train.export_onnx(random_net[0], tmp_path / "v3.onnx", meta)
    assert pc.read_metadata(old)["normalization"] == "none"
    assert pc.CornerDetector(old).normalization_spec == "none"


def test_the_maps_of_a_frame_read_into_the_same_buffer_are_new(random_net):
    """The maps of the last frame are kept for the tracker's second search; new pixels in the same array (an app's
    ``video.read(frame)``) are a new frame."""
    det = pc.CornerDetector(random_net[1])
    rng = np.random.default_rng(0)
    buffer = rng.integers(0, 256, (120, 160, 3), np.uint8)
    first = det.maps(buffer)
    assert det.maps(buffer)[0] is first[0]
    buffer[:] = rng.integers(0, 256, (120, 160, 3), np.uint8)
    second = det.maps(buffer)
    assert not np.array_equal(second[0], first[0])
    np.testing.assert_array_equal(second[0], pc.CornerDetector(random_net[1]).maps(buffer.copy())[0])


def test_each_call_compares_the_frame_with_the_last_once(random_net, monkeypatch):
    """Every internal use of the maps compared the whole frame with the last one again (twice per detect, three
    times per propose): the public call compares once and hands the maps on."""
    det = pc.CornerDetector(random_net[1])
    compared, same_frame = [], pc.same_frame

    def counted(kept, image):
        compared.append(1)
        return same_frame(kept, image)

    monkeypatch.setattr(pc, "same_frame", counted)
    image = np.random.default_rng(0).integers(0, 256, (240, 320, 3), np.uint8)
    K = camera_matrix(300, 300, 159.5, 119.5)
    rvec, tvec = cv2.Rodrigues(np.diag([1.0, -1.0, -1.0]))[0], np.array([-70.0, 47.5, 800.0])
    det.maps(image)  # the first frame: nothing kept to compare with
    for call in (
        lambda: det.detect(image),
        lambda: det.detect(image, (rvec, tvec, K)),
        lambda: det.verify(image, rvec, tvec, K),
        lambda: det.propose(image, K),
    ):
        compared.clear()
        call()
        assert len(compared) == 1


def test_a_detector_whose_graph_does_not_fit_its_metadata(tmp_path):
    """Metadata naming 8 parts over a network of 26 (a graph from another file): its maps were read as the wrong
    parts, or failed in numpy with no file named."""
    net = CornerNet(channels=(4, 8), hidden=16).eval()  # 26 parts: 79 maps
    path = corner_train.export_onnx(net, tmp_path / "c.onnx", _box_corners_meta({**net.config, "num_parts": 8}))
    detector = pc.CornerDetector(path)
    expected = r"c\.onnx: its network gives outputs of shape \(1, 79, .*\(1, 25, h, w\) maps of 8 parts"
    with pytest.raises(WeightFileError, match=expected):
        detector.maps(np.zeros((120, 160), np.uint8))


def test_metadata_that_is_not_an_object_is_one_line(random_net, tmp_path):
    model = onnx.load(random_net[1])
    next(p for p in model.metadata_props if p.key == ONNX_METADATA_KEY).value = "[1]"
    path = tmp_path / "list.onnx"
    onnx.save(model, path)
    with pytest.raises(WeightFileError, match=r"list.onnx: the header is not a JSON object; not a corner detector"):
        pc.read_metadata(path)


def test_gated_search_keeps_gated_top_k_down_to_gated_min_score(random_net, monkeypatch):
    """Around a prediction the detector keeps ``gated_top_k`` (not ``top_k``) candidates, and accepts scores down to
    ``gated_min_score``, below the whole frame's ``min_score``."""
    det = pc.CornerDetector(random_net[1], top_k=5, gated_top_k=2, min_score=0.05, gated_min_score=0.02, gate=40.0)
    shape = pc.grid_shape(120, 160)
    near = [(40.0, 60.0, 0.5), (52.0, 60.0, 0.4), (40.0, 72.0, 0.3)]  # downscaled pixels, 12 apart
    faint = (100.0, 30.0, 0.03)  # between gated_min_score and min_score
    monkeypatch.setattr(det, "maps", lambda image: _fake_maps(shape, {1: near, 3: [faint]}))
    everywhere = det.peaks(None)
    assert len(everywhere[1][0]) == 3 and len(everywhere[3][0]) == 0
    predicted = np.tile(pc.from_scaled(np.array([44.0, 62.0]), det.scale), (8, 1))
    predicted[3] = pc.from_scaled(np.array([faint[:2]]), det.scale)
    gated = det.peaks(None, predicted)
    np.testing.assert_allclose(gated[1][1], [0.5, 0.4], atol=1e-6)  # the best two, best first
    np.testing.assert_allclose(gated[3][1], [0.03], atol=1e-6)


def test_the_offsets_are_in_strides(random_net, monkeypatch):
    """The network's offsets are in units of the stride: each cell votes for its window centre plus
    ``STRIDE * (dx, dy)`` (downscaled pixels)."""
    det = pc.CornerDetector(random_net[1])
    image = np.zeros((120, 160), np.uint8)
    gh, gw = pc.grid_shape(60, 80)  # the detector's scale is 0.5
    n = len(det.parts)
    out = np.zeros((3 * n + 1, gh, gw), np.float32)
    out[n + 1 :: 2] = 0.5  # dx of every part
    out[n + 2 :: 2] = -0.25  # dy
    monkeypatch.setattr(det, "outputs", lambda normalized: out)
    _, votes = det.maps(image)
    np.testing.assert_allclose(votes, np.broadcast_to(pc.grid_centres((gh, gw)) + [2.0, -1.0], votes.shape))


def test_the_gate_is_a_circle(random_net, monkeypatch):
    """A candidate 15 px off the prediction in both x and y (21 px away) is outside a gate of 20 px: a circle, not a
    square."""
    det = pc.CornerDetector(random_net[1], gate=20.0)
    shape = pc.grid_shape(120, 160)
    monkeypatch.setattr(det, "maps", lambda image: _fake_maps(shape, {2: [(40.0, 60.0, 0.5)]}))
    at = pc.from_scaled(np.array([40.0, 60.0]), det.scale)
    assert len(det.peaks(None, np.tile(at + [15.0, 15.0], (8, 1)))[2][0]) == 0
    assert len(det.peaks(None, np.tile(at + [19.0, 0.0], (8, 1)))[2][0]) == 1
