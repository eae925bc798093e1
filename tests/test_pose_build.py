"""pose.build: triangulation with fixed poses (pycolmap), box fit (open3d), CLI, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.errors import DatasetError, InputError
from pose import build
from pose import model as pm
from pose.evaluate import relight


def _box_surface(rng, size=(140.0, 95.0, 55.0), n=600):
    """Points on the 5 visible faces of a box standing on a plane, plus a large support plane."""
    size = np.asarray(size)
    face = rng.integers(0, 5, n)
    p = rng.uniform(0, 1, (n, 3)) * size
    p[face == 0, 2] = size[2]
    p[face == 1, 0] = 0
    p[face == 2, 0] = size[0]
    p[face == 3, 1] = 0
    p[face == 4, 1] = size[1]
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
    fit = build.fit_box(world, known_size=[55, 140, 95])
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
    fit2 = build.fit_box(world * 0.01, known_size=[55, 140, 95], scale_free=True)
    assert fit2.stats["scale"] == pytest.approx(100, rel=0.05)


def test_fit_box_degenerate():
    with pytest.raises(DatasetError):
        build.fit_box(np.zeros((5, 3)))
    rng = np.random.default_rng(1)
    flat = np.c_[rng.uniform(0, 10, (200, 2)), np.zeros(200)]
    with pytest.raises(DatasetError, match="flat"):
        build.fit_box(flat)


def test_image_pairs_and_relight():
    assert build.image_pairs(4) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]
    assert build.image_pairs(4, window=1) == [(0, 1), (1, 2), (2, 3)]
    img = np.full((20, 30, 3), 128, np.uint8)
    out = relight(img)
    assert out.shape == img.shape and out.dtype == np.uint8 and out.std() > 5


def test_bad_inputs(tmp_path):
    with pytest.raises(DatasetError, match="not a BOP scene"):
        build.load_sequence(tmp_path)
    with pytest.raises(InputError, match="intrinsics"):
        build.main(tmp_path / "v.mp4", tmp_path / "m.npz") if (tmp_path / "v.mp4").write_bytes(b"x") else None


def test_triangulation_with_fixed_poses_on_middlebury(shared_data, tmp_path):
    """Real calibrated views: 8 views, known poses held fixed, points must lie on the object."""
    from alcn_cv.formats.middlebury import read_middlebury

    src = shared_data / "middlebury" / "templeSparseRing"
    seq = build.load_sequence(src)
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
    path = pm.save(model, tmp_path / "temple.npz")
    build.plot_model(model, cams, tmp_path / "temple_cameras.png")
    assert (tmp_path / "temple_cameras.png").stat().st_size > 1000 and path.is_file()
