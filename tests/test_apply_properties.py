"""Property-based test of ``apply()`` for every registered method: any array ends in a clean
InputError or an output of the input's shape and dtype without NaN, and the input is untouched."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import alcn_cv
from alcn_cv.enhance.base import Normalization
from alcn_cv.errors import InputError

DTYPES = (np.uint8, np.uint16, np.float32)


@cache
def _method(name: str) -> Normalization:
    return alcn_cv.create(name)


@st.composite
def images(draw: st.DrawFn) -> np.ndarray:
    """Arrays of 1..300 px a side, 1 to 4 channels, random, constant or binary content, in
    native or swapped byte order, as contiguous arrays or as strided views (every other pixel,
    flipped, transposed)."""
    h, w = draw(st.integers(1, 300)), draw(st.integers(1, 300))
    channels = draw(st.sampled_from([None, 1, 2, 3, 4]))
    dtype = draw(st.sampled_from(DTYPES))
    content = draw(st.sampled_from(["random", "constant", "binary"]))
    view = draw(st.sampled_from(["contiguous", "every other", "flipped", "transposed"]))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    shape = (2 * h if view == "every other" else h, w) + (() if channels is None else (channels,))
    if view == "transposed":
        shape = (w, h) + shape[2:]
    unit = {
        "random": lambda: rng.random(shape),
        "constant": lambda: np.full(shape, draw(st.sampled_from([0.0, 0.5, 1.0]))),
        "binary": lambda: (rng.random(shape) > 0.5).astype(np.float64),
    }[content]()
    base = unit.astype(np.float32) if dtype == np.float32 else np.rint(unit * np.iinfo(dtype).max).astype(dtype)
    if draw(st.booleans()):
        base = base.astype(base.dtype.newbyteorder("S"))  # e.g. big-endian >u2 on a little-endian machine
    if view == "every other":
        return base[::2]
    if view == "flipped":
        return base[::-1, ::-1]
    if view == "transposed":
        return base.swapaxes(0, 1)
    return base


@pytest.mark.parametrize("name", alcn_cv.available())
def test_apply_never_fails_unclearly(name):
    method = _method(name)

    @settings(max_examples=30, deadline=None, derandomize=True, database=None)
    @given(img=images(), out_dtype=st.sampled_from([None, *DTYPES]))
    def check(img: np.ndarray, out_dtype: type | None) -> None:
        before = img.copy()
        try:
            out = method.apply(img, out_dtype=out_dtype)
        except InputError:
            return
        finally:
            np.testing.assert_array_equal(img, before)
        assert out.shape == img.shape
        assert out.dtype == (img.dtype.newbyteorder("=") if out_dtype is None else out_dtype)
        if out.dtype == np.float32:
            assert np.isfinite(out).all() and out.min() >= 0 and out.max() <= 1

    check()
