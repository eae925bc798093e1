"""Parameter search of DoG, SLCN and DLCN on training windows."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.bench import tuning
from alcn_cv.errors import InputError
from alcn_cv.filters.standardize import standardize_windows


def _windows(n_per_class: int = 12, seed: int = 0):
    """Two textured classes and a background class, 64x64 float windows in [0, 1]."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:64, 0:64]
    stripes = 0.5 + 0.3 * np.sin(x / 2.0)
    rings = 0.5 + 0.3 * np.sin(np.hypot(x - 32, y - 32) / 1.5)
    out, labels = [], []
    for label, base in enumerate([None, stripes, rings]):
        for _ in range(n_per_class):
            w = rng.random((64, 64)) if base is None else base + 0.05 * rng.standard_normal((64, 64))
            out.append(np.clip(w, 0, 1))
            labels.append(label)
    return np.asarray(out, np.float32), np.asarray(labels)


def test_relight_is_deterministic_and_in_range():
    w, _ = _windows(2)
    a = tuning.relight_windows(w, np.random.default_rng(3))
    b = tuning.relight_windows(w, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert a.dtype == np.float32 and a.min() >= 0 and a.max() <= 1
    assert not np.allclose(a, w)


def test_standardize_windows():
    w, _ = _windows(2)
    s = standardize_windows(w * 3 + 1, eps=tuning.BENCH_STANDARDIZE_EPS)
    np.testing.assert_allclose(s.mean((1, 2)), 0, atol=1e-4)
    np.testing.assert_allclose(s.std((1, 2)), 1, atol=1e-3)


def test_tune_scores_every_setting_and_picks_the_best():
    w, labels = _windows()
    grid = [{"sigma1": 0.5, "sigma2": 1.5}, {"sigma1": 6.0, "sigma2": 8.0}]
    best, trials = tuning.tune("dog", w, labels, np.random.default_rng(0), grid)
    assert [t["params"] for t in trials] == grid
    assert best == max(trials, key=lambda t: t["score"])["params"]
    # 8 px blurs erase 2-3 px stripes and rings: the fine band-pass must separate the classes better
    assert best == grid[0] and trials[0]["score"] > trials[1]["score"]
    assert all(0 <= t["score"] <= 1 for t in trials)


def test_tune_all_and_bad_input():
    w, labels = _windows(4)
    out = tuning.tune_all((w * 255).astype(np.uint8), labels, seed=0, methods=["slcn"])
    assert set(out) == {"slcn"} and len(out["slcn"]["trials"]) == len(tuning.GRIDS["slcn"])
    with pytest.raises(InputError):
        tuning.tune("clahe", w, labels, np.random.default_rng(0))
    with pytest.raises(InputError):
        tuning.tune("dog", w[:, :16, :16], labels, np.random.default_rng(0))
