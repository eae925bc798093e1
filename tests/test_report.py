"""The helpers of benchmark reports (alcn_cv.report)."""

import json

import numpy as np
import pytest

from alcn_cv.report import nan_to_none


def test_nan_to_none_makes_reports_json():
    report = {"a": [1.0, np.nan], "b": np.float32(2), "c": {"d": float("inf"), "e": "text", "f": 3}}
    assert nan_to_none(report) == {"a": [1.0, None], "b": 2.0, "c": {"d": None, "e": "text", "f": 3}}
    json.dumps(nan_to_none(report), allow_nan=False)
    assert report["a"][1] != report["a"][1]  # the input is left as it was (NaN)


def test_save_figure_closes_the_figure_when_the_write_fails(tmp_path):
    """A failed write left the figure open in pyplot (its memory kept until the process ends)."""
    from alcn_cv.report import new_figure, save_figure

    plt, fig, _ = new_figure()
    before = len(plt.get_fignums())
    (tmp_path / "f.png").mkdir()  # a folder where the file goes: the rename fails
    with pytest.raises(OSError):
        save_figure(plt, fig, tmp_path / "f.png")
    assert len(plt.get_fignums()) == before - 1
