"""Tuning a method on a rendering of hard directional light (``alcn_cv.bench.directional``)."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.bench.directional import identify, score, tune
from alcn_cv.data.relief_scenes import render_scenes
from alcn_cv.enhance.registry import format_spec, from_spec


@pytest.fixture(scope="module")
def scenes() -> np.ndarray:
    """A tiny validation rendering: 6 identities of 48 px."""
    return np.stack([frames for frames, _ in render_scenes(6, side=48, seed=3, lighting="directional", progress=False)])


def test_tuning_chooses_the_best_scoring_setting_and_applies_it(scenes: np.ndarray) -> None:
    # the best setting neither first nor last: a rule that picks either one fails
    grid = [{"sigma1": 4.0, "sigma2": 12.0}, {"sigma1": 0.5, "sigma2": 1.5}, {"sigma1": 8.0, "sigma2": 16.0}]
    result = tune("dog", scenes, grid)
    specs = [format_spec("dog", params) for params in grid]
    # each score is its own setting's identification: the parameters are applied (the scores differ by setting)
    assert result["scores"] == {spec: score(identify(spec, scenes)) for spec in specs}
    assert len(set(result["scores"].values())) == len(grid)
    assert result["chosen"] == max(specs, key=result["scores"].get) == specs[1]
    chosen = from_spec(result["chosen"])
    assert (chosen.sigma1, chosen.sigma2) == (0.5, 1.5)


def test_a_tie_keeps_the_first_setting(scenes: np.ndarray) -> None:
    """DLCN's default ``eps`` given or not: the same normalization, the same score; the first (the grid's default)
    wins."""
    result = tune("dlcn", scenes, [{"sigma": 2.0}, {"sigma": 2.0, "eps": 0.001}])
    assert len(set(result["scores"].values())) == 1
    assert result["chosen"] == "dlcn:sigma=2.0"


def test_score_is_the_mean_over_sides_and_elevations() -> None:
    assert (
        score({32: {"elevation 75": 100.0, "elevation 12": 50.0}, 64: {"elevation 75": 100.0, "elevation 12": 70.0}})
        == 80.0
    )
