"""The colour path of ``Normalization.apply`` (OpenCV passes) against the plain float Lab round trip
(:func:`alcn_cv.bench.speed.lab_round_trip`): within one level of the output type."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.bench.speed import lab_round_trip, synthetic_frame
from alcn_cv.enhance.registry import from_spec

METHODS = ["alcn", "dog", "ns", "clahe", "alcn:model=gain"]


def _images() -> list[np.ndarray]:
    images = [synthetic_frame(200, 150, True, seed=3), np.random.default_rng(0).integers(0, 256, (90, 120, 3), dtype=np.uint8)]
    saturated = np.zeros((64, 96, 3), np.uint8)
    saturated[:, :32, 2] = 255  # pure red, green and blue blocks next to black: out-of-gamut lightness
    saturated[:, 32:64, 1] = 255
    saturated[:, 64:, 0] = np.linspace(0, 255, 64, dtype=np.uint8)[:, None]
    return images + [saturated]


@pytest.mark.parametrize("name", METHODS)
def test_colour_within_one_level_of_the_lab_round_trip(name):
    method = from_spec(name)
    for img in _images():
        for source, out_dtype in ((img, np.uint8), (img.astype(np.uint16) * 257, np.uint16),
                                  (img.astype(np.float32) / np.float32(255), np.float32)):
            out = method.apply(source, out_dtype=out_dtype)
            reference = lab_round_trip(method, source, np.dtype(out_dtype))
            assert out.dtype == reference.dtype and out.shape == reference.shape
            level = 1 if out_dtype != np.float32 else 1 / 65535
            assert np.abs(out.astype(np.float64) - reference).max() <= level, (name, out_dtype)


def test_colour_within_one_level_on_a_photograph(shared_data):
    photo = cv2.imread(str(shared_data / "cookie_box" / "resized_IMG_3875.JPG"), cv2.IMREAD_COLOR)
    if photo is None:
        pytest.skip("the cookie-box photograph is not in the shared data")
    photo = cv2.resize(photo, (480, 360), interpolation=cv2.INTER_AREA)
    for name in ("alcn", "alcn:model=gain"):
        method = from_spec(name)
        diff = np.abs(method.apply(photo).astype(int) - lab_round_trip(method, photo, np.dtype(np.uint8)))
        assert diff.max() <= 1, name
