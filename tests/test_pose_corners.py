"""pose.corners: corner labels, ONNX/torch agreement, the torch-free runtime, train -> track end to end."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
import torch

from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.nets.detector import Detector
from pose import corner_data, corner_train
from pose import corners as pc
from pose import track
from pose.sequence import load_sequence
from pose.cli import add_parser
from pose.evaluate import projection_error
from pose.model import box_corners, read_box_corners
from pose.solver import camera_matrix


@pytest.fixture(scope="module")
def posedata(tmp_path_factory):
    """Four registered 320x240 training frames of the data engine's box, one test sequence."""
    from alcn_cv.data import pose

    return pose.generate(tmp_path_factory.mktemp("corners") / "data", size="small", n_frames=4, n_test=1,
                         clutter=False, progress=False)


@pytest.fixture(scope="module")
def random_net(tmp_path_factory):
    torch.manual_seed(0)
    net = Detector(pc.NUM_CORNERS + 1, channels=(4, 8), hidden=16).eval()
    meta = {"format": pc.FORMAT_NAME, "version": pc.FORMAT_VERSION, "normalizer": "none", "scale": 0.5,
            "input_mean": 0.5, "input_std": 0.25,
            "corners": box_corners([140, 95, 55]).tolist(), "units": "mm", "window": pc.WINDOW,
            "stride": pc.STRIDE, "pad": pc.PAD}
    path = corner_train.export_onnx(net, tmp_path_factory.mktemp("onnx") / "c.onnx", meta)
    return net, path


def test_constants_match_the_detector():
    assert (pc.WINDOW, pc.STRIDE) == (Detector.input_size, Detector.stride)


def test_visibility_of_a_box_seen_from_above():
    corners = box_corners([100, 60, 40], [-50, -30, -20])
    K = camera_matrix(500, 500, 319.5, 239.5)
    R = np.diag([1.0, -1.0, -1.0])  # camera on the +z side of the box, looking down -z
    t = np.array([0.0, 0.0, 600.0])
    uv, vis = corner_data.corner_visibility(corners, R, t, K, (480, 640))
    np.testing.assert_array_equal(vis, [False, True] * 4)  # the top face (z bit set) only
    assert np.allclose(uv[1], [319.5 - 500 * 50 / 580, 239.5 + 500 * 30 / 580])
    mask = np.zeros((480, 640), np.uint8)  # an occluder hides everything but corner 7
    mask[int(uv[7, 1]) - 1 : int(uv[7, 1]) + 2, int(uv[7, 0]) - 1 : int(uv[7, 0]) + 2] = 255
    _, vis = corner_data.corner_visibility(corners, R, t, K, (480, 640), mask)
    assert np.flatnonzero(vis).tolist() == [7]
    _, vis = corner_data.corner_visibility(corners, R, t + [2000, 0, 0], K, (480, 640))  # out of the image
    assert not vis.any()


def test_dataset_labels_are_the_projected_corners(posedata):
    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    data = corner_data.build_dataset(seq, corners, "none", scale=1.0, negatives_per_frame=30, augment_per_corner=2,
                            backgrounds=0)
    assert len(data.normalized) == len(seq.views)
    assert data.windows.shape[1:] == (32, 32) and data.windows.dtype == np.float32
    assert np.isfinite(data.windows).all()
    assert set(np.unique(data.labels)) > {0} and data.labels.max() <= 8
    for f, view in enumerate(seq.views):
        uv, vis = corner_data.corner_visibility(corners, view.R_w2c, view.t_w2c, view.K, (240, 320))
        sel = (data.frames == f) & ~data.augmented
        pos = sel & (data.labels > 0)
        d = np.linalg.norm(data.centers[pos] - uv[data.labels[pos] - 1], axis=1)
        assert len(d) and d.max() <= 1.0 + 1e-9  # positives within pos_radius of their own corner
        assert set(data.labels[pos] - 1) == set(np.flatnonzero(vis))
        neg = data.centers[sel & (data.labels == 0)]
        assert np.linalg.norm(neg[:, None] - uv[vis][None], axis=2).min() > 5.0
        # the window's centre pixel is the normalized frame's pixel at the label's position
        i = np.flatnonzero(pos)[0]
        np.testing.assert_allclose(data.windows[i][15:17, 15:17].mean(),
                                   cv2.getRectSubPix(data.normalized[f], (2, 2), tuple(data.centers[i])).mean(),
                                   atol=1e-5)


def test_copies_with_new_backgrounds(posedata):
    seq = load_sequence(posedata / "train" / "000001", obj_id=1)
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    data = corner_data.build_dataset(seq, corners, "none", scale=1.0, negatives_per_frame=10, augment_per_corner=0,
                            backgrounds=2)
    assert len(data.normalized) == 3 * len(seq.views) and len(data.visible) == len(data.normalized)
    first = seq.views[0]
    mask = cv2.imread(str(posedata / "train" / "000001" / "mask_visib" / f"{first.name[:-4]}_000000.png"), 0)
    assert mask is not None and mask.shape == data.normalized[0].shape
    # the view's frames: the original, then its two copies (same corners, same object pixels)
    np.testing.assert_array_equal(data.visible[1], data.visible[0])
    inside, outside = mask == 255, mask == 0
    for copy in data.normalized[1:3]:
        assert np.abs(copy - data.normalized[0])[outside].mean() > 0.1 * data.normalized[0].std()
    gray = pc.to_gray(cv2.imread(str(seq.image_dir / first.name)))
    composite = corner_data.replace_background(gray, mask, np.random.default_rng(0))
    np.testing.assert_array_equal(composite[inside], gray[inside])
    assert np.abs(composite[outside].astype(int) - gray[outside]).mean() > 5
    pos = (data.labels > 0) & np.isin(data.frames, [1, 2])
    assert pos.any() and set(data.labels[pos]) == set(data.labels[(data.labels > 0) & (data.frames == 0)])


def test_onnx_matches_torch(random_net):
    net, path = random_net
    det = pc.CornerDetector(path)
    image = np.random.default_rng(0).random((45, 61), dtype=np.float32)
    with torch.no_grad():
        padded = cv2.copyMakeBorder(image, pc.PAD, pc.PAD, pc.PAD, pc.PAD, cv2.BORDER_REFLECT_101)
        ref = net.dense(torch.from_numpy(padded)[None, None])[0].numpy()
    got = det.logits(image)
    assert got.shape == ref.shape == (9, 12, 16) and np.ptp(ref) > 1e-3
    np.testing.assert_allclose(got, ref, atol=1e-4)
    assert det.corners.shape == (8, 3) and det.scale == 0.5 and det.normalizer_name == "none"


def test_finer_score_grid_scores_the_windows_it_names(random_net):
    net, path = random_net
    frame = np.random.default_rng(3).integers(0, 256, (120, 160), dtype=np.uint8)
    coarse = pc.CornerDetector(path, subdivide=1).scores(frame)
    fine = pc.CornerDetector(path, subdivide=2).scores(frame)
    assert fine.shape == (9, 2 * coarse.shape[1], 2 * coarse.shape[2])
    np.testing.assert_allclose(fine[:, ::2, ::2], coarse, atol=1e-5)
    normalized = pc.CornerDetector(path).normalize(frame)
    for i, j in [(9, 11), (10, 13), (17, 20)]:  # grid point (i, j): window centred on (2j - 0.5, 2i - 0.5)
        window = normalized[2 * i - 16 : 2 * i + 16, 2 * j - 16 : 2 * j + 16]
        with torch.no_grad():
            ref = torch.softmax(net.dense(torch.from_numpy(np.ascontiguousarray(window))[None, None]), 1)
        np.testing.assert_allclose(fine[:, i, j], ref[0, :, 0, 0].numpy(), atol=1e-4)
    with pytest.raises(InputError, match="subdivide"):
        pc.CornerDetector(path, subdivide=3)


def test_runs_where_torch_cannot_be_imported(random_net, run_without_torch):
    _, path = random_net
    frame = np.random.default_rng(2).integers(0, 256, (120, 160, 3), dtype=np.uint8)
    ref = pc.CornerDetector(path, min_score=0.0).detect(frame)
    out = path.parent / "points.npy"
    run_without_torch(f"""
        import numpy as np
        from pose.corners import CornerDetector
        frame = np.random.default_rng(2).integers(0, 256, (120, 160, 3), dtype=np.uint8)
        np.save(sys.argv[1], CornerDetector({str(path)!r}, min_score=0.0).detect(frame).image_points)
    """, out)
    assert len(ref.image_points) == 32  # top_k=4 candidates for each of the 8 corners
    np.testing.assert_allclose(np.load(out), ref.image_points, atol=1e-3)


def test_alcn_runs_at_the_detector_resolution_torch_free_where_it_can(tmp_path):
    import shutil

    from alcn_cv.enhance.alcn import MODELS

    paper = pc.normalization_for("alcn:model=paper")
    assert paper.scale == 1.0 and paper.backend == "opencv"
    assert pc.normalization_for("alcn:model=paper:backend=fast").backend == "fast"
    weights = shutil.copy(MODELS["lite"], tmp_path / "lite.npz")  # weights without an ONNX twin
    lite = pc.normalization_for(f"alcn:weights={weights}:mixture=pyramid")
    assert lite.scale == 1.0 and lite.backend == "fast" and lite.mixture == "pyramid"


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
    with pytest.raises(InputError, match="trained after the normalizer 'none'"):
        track.main(random_net[1], tmp_path, tmp_path / "p.json", np.eye(3), normalizer="alcn", detector="corners")


def test_train_then_track_end_to_end(posedata, tmp_path):
    """`alcn pose train-corners` on four frames, then `alcn pose track --detector corners` on them."""
    import argparse

    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    train = posedata / "train" / "000001"
    onnx = tmp_path / "corners.onnx"
    args = parser.parse_args(["pose", "train-corners", str(train), str(onnx), "--box-ply",
                              str(posedata / "models" / "obj_000001.ply"), "--scale", "1", "--epochs", "4",
                              "--rounds", "1"])
    assert args.func(args) == 0
    meta = pc.read_metadata(onnx)
    assert meta["normalizer"] == "none" and meta["fit"]["train_accuracy"] > 0.9
    cam = json.loads((train / "scene_camera.json").read_text())["0"]
    K = np.asarray(cam["cam_K"]).reshape(3, 3)
    out = tmp_path / "poses.json"
    args = parser.parse_args(["pose", "track", str(onnx), str(train / "rgb"), str(out), "--detector", "corners",
                              "--K", str(K[0, 0]), str(K[1, 1]), str(K[0, 2]), str(K[1, 2]),
                              "--overlay", str(tmp_path / "overlay")])
    assert args.func(args) == 0
    poses = json.loads(out.read_text())
    gt = json.loads((train / "scene_gt.json").read_text())
    corners = read_box_corners(posedata / "models" / "obj_000001.ply")
    errors = [projection_error(corners, np.reshape(p[0]["cam_R_m2c"], (3, 3)), p[0]["cam_t_m2c"],
                               np.reshape(gt[str(int(k))][0]["cam_R_m2c"], (3, 3)), gt[str(int(k))][0]["cam_t_m2c"], K)
              for k, p in poses.items() if p]
    assert len(poses) == 4 and len(errors) >= 3 and np.median(errors) < 5.0, errors
    info = json.loads((tmp_path / "poses_info.json").read_text())
    assert info["summary"]["detector"] == "corners" and len(list((tmp_path / "overlay").glob("*.png"))) == 4


def test_table1_rows_of_the_corner_detector(posedata, tmp_path):
    from pose import evaluate

    with pytest.raises(InputError, match="unknown detectors"):
        evaluate.main(posedata, tmp_path, normalizers=["none"], detectors=["cnn"])
    result = evaluate.main(posedata, tmp_path, normalizers=["none"], detectors=["corners"],
                           corner_kw={"scale": 1.0, "epochs": 2, "rounds": 1})
    row = result["table"]["none / corner CNN"]
    assert list(row) == ["#1"] and 0.0 <= row["#1"] <= 100.0
    assert (tmp_path / "corners_none.onnx").is_file() and "none / corner CNN" in (tmp_path / "table1.md").read_text()
    assert result["details"]["none / corner CNN"]["sequences"]["#1"]["frames"] == 4
