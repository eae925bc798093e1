"""The contrast equalization's tanh through OpenCV's exp (alcn_cv.filters.equalization)."""

import numpy as np
import pytest

from alcn_cv.filters.equalization import TANH_TOLERANCE, tanh


@pytest.mark.parametrize("scale", [1e-30, 1e-6, 1e-3, 0.1, 1.0, 3.0, 30.0, 1e4, 1e30])
def test_tanh_within_its_tolerance_at_every_magnitude(scale):
    x = (np.random.default_rng(0).standard_normal(200_000) * scale).astype(np.float32)
    exact = np.tanh(x.astype(np.float64))
    assert np.abs(tanh(x).astype(np.float64) - exact).max() <= TANH_TOLERANCE


def test_tanh_limits_nan_and_monotony():
    special = np.array([np.nan, np.inf, -np.inf, 89.0, -89.0, 1e38, -1e38, 0.0], np.float32)
    got = tanh(special)
    assert np.isnan(got[0])
    np.testing.assert_array_equal(got[1:], [1, -1, 1, -1, 1, -1, 0])
    x = np.linspace(-12, 12, 200_001, dtype=np.float32)
    assert (np.diff(tanh(x)) >= 0).all()


def test_tanh_of_the_largest_floats_warns_nothing():
    with np.errstate(all="raise"):
        np.testing.assert_array_equal(tanh(np.array([3e38, -3e38], np.float32)), [1, -1])


def test_tanh_in_place_any_shape():
    x = np.random.default_rng(1).standard_normal((2, 3, 5, 7)).astype(np.float32)
    expected = tanh(x)
    assert tanh(x, out=x) is x
    np.testing.assert_array_equal(x, expected)


@pytest.mark.parametrize(
    "x, out",
    [
        (np.zeros((4, 4)), None),  # float64
        (np.zeros((4, 4), np.float32)[:, ::2], None),  # not contiguous
        (np.zeros((4, 4), np.float32), np.zeros((4, 3), np.float32)),
        # as many values in another shape: refused by the shape check itself, not by NumPy's broadcasting
        (np.zeros((4, 4), np.float32), np.zeros((2, 8), np.float32)),
        (np.zeros((4, 4), np.float32), np.zeros((4, 4))),
    ],
)
def test_tanh_refuses_what_it_cannot_compute_in_place(x, out):
    with pytest.raises(ValueError):
        tanh(x, out=out)
