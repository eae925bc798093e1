"""Property-based tests of ``apply()`` for every registered method: any array of the documented contract gives an
output of the input's shape and dtype without NaN, its alpha channel kept, and the input is untouched; any array
outside it ends in a clean InputError."""

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


def _expected_alpha(alpha: np.ndarray, dtype: np.dtype) -> np.ndarray:
    """The input's alpha channel in ``dtype``: the same values, scaled to its full scale (float64, to compare)."""
    unit = alpha.astype(np.float64) / (1.0 if alpha.dtype == np.float32 else np.iinfo(alpha.dtype).max)
    return unit if dtype == np.float32 else np.rint(unit * np.iinfo(dtype).max)


@pytest.mark.parametrize("name", alcn_cv.available())
def test_apply_never_fails_unclearly(name):
    """Every array :func:`images` draws meets apply()'s contract (1 to 4 channels, uint8, uint16 or float32 in
    [0, 1], any byte order and layout): apply must succeed on it, never refuse it."""
    method = _method(name)

    @settings(max_examples=30, deadline=None, derandomize=True, database=None)
    @given(img=images(), out_dtype=st.sampled_from([None, *DTYPES]))
    def check(img: np.ndarray, out_dtype: type | None) -> None:
        before = img.copy()
        out = method.apply(img, out_dtype=out_dtype)  # any InputError here fails: the input is valid
        np.testing.assert_array_equal(img, before)
        assert out.shape == img.shape
        assert out.dtype == (img.dtype.newbyteorder("=") if out_dtype is None else out_dtype)
        assert out.dtype.isnative
        if out.dtype == np.float32:
            assert np.isfinite(out).all() and out.min() >= 0 and out.max() <= 1
        if img.ndim == 3 and img.shape[2] in (2, 4):  # gray or BGR and alpha: the alpha passed through
            expected = _expected_alpha(img[..., -1], out.dtype)
            if out.dtype == img.dtype.newbyteorder("="):
                np.testing.assert_array_equal(out[..., -1], img[..., -1])
            else:
                atol = 1e-6 if out.dtype == np.float32 else 1
                np.testing.assert_allclose(out[..., -1].astype(np.float64), expected, rtol=0, atol=atol)

    check()


@st.composite
def invalid_inputs(draw: st.DrawFn) -> tuple[object, object]:
    """``(image, out_dtype)`` pairs that break apply()'s contract, one way each: an empty array, 1 or 4 dimensions,
    5 or more channels, an unsupported dtype, NaN, inf or out-of-range float32 values, not an array, or an
    unsupported out_dtype."""
    h, w = draw(st.integers(1, 40)), draw(st.integers(1, 40))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    valid = (rng.random((h, w)) * 255).astype(np.uint8)
    fault = draw(
        st.sampled_from(
            ["empty", "1-d", "4-d", "channels", "dtype", "nan", "inf", "range", "not an array", "out_dtype"]
        )
    )
    if fault == "empty":
        return np.zeros(draw(st.sampled_from([(0, w), (h, 0), (0, 0, 3)])), np.uint8), None
    if fault == "1-d":
        return valid.ravel(), None
    if fault == "4-d":
        return np.stack([valid[..., None]] * 2), None
    if fault == "channels":
        return np.dstack([valid] * draw(st.integers(5, 8))), None
    if fault == "dtype":
        bad = draw(st.sampled_from([np.float64, np.float16, np.int8, np.int16, np.int32, np.uint32, np.bool_]))
        return valid.astype(bad), None
    if fault in ("nan", "inf", "range"):
        img = rng.random((h, w), dtype=np.float32)
        value = {"nan": np.nan, "inf": np.inf, "range": draw(st.sampled_from([-0.5, 1.5, 255.0]))}[fault]
        img[draw(st.integers(0, h - 1)), draw(st.integers(0, w - 1))] = value
        return img, None
    if fault == "not an array":
        return draw(st.sampled_from([None, 3, "image.png", valid.tolist()])), None
    return valid, draw(st.sampled_from([np.float64, np.int32, "int8", "not a dtype"]))


@pytest.mark.parametrize("name", alcn_cv.available())
def test_apply_refuses_invalid_inputs_clearly(name):
    """Any input outside the contract ends in an InputError of one line, never another exception or an output."""
    method = _method(name)

    @settings(max_examples=20, deadline=None, derandomize=True, database=None)
    @given(case=invalid_inputs())
    def check(case: tuple[object, object]) -> None:
        img, out_dtype = case
        with pytest.raises(InputError) as error:
            method.apply(img, out_dtype=out_dtype)
        assert str(error.value) and "\n" not in str(error.value)

    check()
