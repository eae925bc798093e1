"""The helpers of benchmark reports (alcn_cv.report)."""

import json

import numpy as np

from alcn_cv.report import nan_to_none


def test_nan_to_none_makes_reports_json():
    report = {"a": [1.0, np.nan], "b": np.float32(2), "c": {"d": float("inf"), "e": "text", "f": 3}}
    assert nan_to_none(report) == {"a": [1.0, None], "b": 2.0, "c": {"d": None, "e": "text", "f": 3}}
    json.dumps(nan_to_none(report), allow_nan=False)
    assert report["a"][1] != report["a"][1]  # the input is left as it was (NaN)
