"""pose.solver and pose.evaluate metrics on synthetic correspondences with known poses."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.errors import InputError
from pose.evaluate import add_error, projection_error, rotation_error_deg, score, summarize
from pose.solver import METHODS, PoseSolver, PoseTracker, camera_matrix, project

K = camera_matrix(600.0, 600.0, 320.0, 240.0)


def _scene(rng, n=200, outliers=0.4, noise=0.5):
    pts = rng.uniform([-50, -40, -30], [50, 40, 30], size=(n, 3))
    rvec = np.array([[0.3], [-0.4], [0.2]])
    tvec = np.array([[10.0], [-5.0], [400.0]])
    uv = project(pts, rvec, tvec, K) + rng.normal(0, noise, (n, 2))
    bad = rng.random(n) < outliers
    uv[bad] = rng.uniform([0, 0], [640, 480], size=(bad.sum(), 2))
    return pts, uv, rvec, tvec


@pytest.mark.parametrize("method", sorted(METHODS))
def test_solver_recovers_pose_with_outliers(method):
    rng = np.random.default_rng(0)
    pts, uv, rvec, tvec = _scene(rng)
    est = PoseSolver(K, method=method, iterations=2000).solve(pts, uv)
    assert est.ok, est.reason
    assert rotation_error_deg(est.R, cv2.Rodrigues(rvec)[0]) < 0.5
    assert np.linalg.norm(est.tvec - tvec) < 2.0
    assert est.reprojection_error < 1.5
    assert len(est.inliers) > 100


def test_too_few_or_random_matches_are_lost_not_wrong():
    rng = np.random.default_rng(1)
    solver = PoseSolver(K, min_inliers=12)
    pts, uv, *_ = _scene(rng, n=8, outliers=0.0)
    est = solver.solve(pts, uv)
    assert not est.ok and "matches" in est.reason and est.rvec is None
    # pure noise: no consistent pose
    pts = rng.uniform(-50, 50, (60, 3))
    uv = rng.uniform([0, 0], [640, 480], (60, 2))
    assert not solver.solve(pts, uv).ok
    with pytest.raises(InputError):
        est.R


def test_prior_is_used_and_tracker_logs_lost_and_recovered():
    rng = np.random.default_rng(2)
    pts, uv, rvec, tvec = _scene(rng, outliers=0.2)
    tracker = PoseTracker(PoseSolver(K))
    first = tracker.update(0, pts, uv)
    assert first.ok and not first.used_prior
    second = tracker.update(1, pts, uv)
    assert second.ok and second.used_prior
    assert not tracker.update(2, pts[:3], uv[:3]).ok
    assert tracker.update(3, pts, uv).ok
    assert [e[1] for e in tracker.events] == ["lost", "recovered"]
    assert [e[0] for e in tracker.events] == [2, 3]


def test_bad_arguments():
    with pytest.raises(InputError):
        PoseSolver(np.eye(2))
    with pytest.raises(InputError):
        PoseSolver(K, method="nope")
    with pytest.raises(InputError):
        PoseSolver(K).solve(np.zeros((10, 3)), np.zeros((9, 2)))


def test_metrics():
    v = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [0, 0, 100]], float)
    R = np.eye(3)
    t = np.array([0, 0, 500.0])
    assert projection_error(v, R, t, R, t, K) == 0 and add_error(v, R, t, R, t) == 0
    R5 = cv2.Rodrigues(np.array([0, np.radians(5.0), 0]))[0]
    assert rotation_error_deg(R5, R) == pytest.approx(5.0, abs=1e-6)
    assert add_error(v, R, t + [0, 0, 10], R, t) == pytest.approx(10.0)
    s = score(v, K, "mm", (R, t + [0, 0, 40.0]), (R, t))
    assert s.trans_cm == pytest.approx(4.0)
    lost = score(v, K, "mm", None, (R, t))
    res = summarize([s, lost], diameter=141.4)
    assert res["tracked"] == 50.0 and res["5cm5deg"] == 50.0 and res["add"] == 0.0
