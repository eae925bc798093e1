"""The input checks of alcn_cv.checks that no normalization's tests cover."""

import cv2
import numpy as np
import pytest

import alcn_cv
from alcn_cv.checks import check_gray, check_out_dtype, check_positive, check_seeds, from_unit_float
from alcn_cv.errors import InputError


def test_check_seeds_takes_distinct_non_negative_integers_and_names_the_bad_ones():
    assert check_seeds((2, np.int64(0), 1)) == [2, 0, 1]
    assert all(type(s) is int for s in check_seeds([np.int64(3)]))
    for seeds, named in (
        ([], r"got \[\]$"),
        ([0, 1, 1, 0], r"repeated: \[0, 1\]"),
        ([0, -1], r"not a non-negative integer: \[-1\]"),
        ([0, 1.5, True], r"not a non-negative integer: \[1\.5, True\]"),
    ):
        with pytest.raises(
            InputError, match=r"^seeds must be distinct non-negative integers, at least one; .*" + named
        ):
            check_seeds(seeds)


def test_a_stack_of_frames_given_to_apply_is_pointed_to_apply_batch():
    from alcn_cv.checks import check_image

    with pytest.raises(InputError, match=r"got shape \(5, 48, 64\) \(frames stacked\? .*apply_batch\)$"):
        check_image(np.zeros((5, 48, 64), np.uint8))
    # three or four: a torch image's channels as well
    message = r"got shape \(3, 48, 64\) \(channels first, as in torch\? img.transpose\(1, 2, 0\); frames stacked\? "
    with pytest.raises(InputError, match=message):
        check_image(np.zeros((3, 48, 64), np.uint8))
    with pytest.raises(InputError, match=r"got shape \(48, 64, 5\)$"):  # five channels, not a stack
        check_image(np.zeros((48, 64, 5), np.uint8))


def test_the_mistakes_of_an_opencv_loop_are_named():
    """cv2.imread's None for a bad path (or the end of a video), a cv2.UMat, and a float image that a cubic resize
    took a little out of [0, 1]: each error says what was likely meant."""
    from alcn_cv.checks import check_image

    with pytest.raises(InputError, match=r"got NoneType \(cv2.imread could not read the file, or VideoCapture"):
        check_image(None)
    with pytest.raises(InputError, match=r"got UMat \(a cv2.UMat: umat.get\(\)\)$"):
        check_image(cv2.UMat(np.zeros((4, 4), np.uint8)))
    with pytest.raises(
        InputError, match=r"got \[-0.08, 1.07\] \(an interpolation's overshoot\? np.clip\(img, 0, 1\)\)$"
    ):
        check_image(np.array([[-0.08, 1.07]], np.float32))
    with pytest.raises(InputError, match=r"got \[0, 200\] \(divide by 255 first\)$"):
        check_image(np.array([[0, 200]], np.float32))


def test_check_out_dtype_defaults_to_the_input_and_names_a_bad_one():
    assert check_out_dtype(None, np.dtype(np.uint16)) == np.uint16
    assert check_out_dtype("float32", np.dtype(np.uint8)) == np.float32
    with pytest.raises(InputError, match="^unknown out_dtype 'pixels'"):
        check_out_dtype("pixels", np.dtype(np.uint8))
    with pytest.raises(InputError, match="^unsupported out_dtype float64"):
        check_out_dtype(np.float64, np.dtype(np.uint8))


def test_check_gray_checks_finiteness_only_when_asked():
    plane = np.full((4, 5), np.nan, np.float32)
    assert check_gray(plane, finite=False) is plane
    with pytest.raises(InputError, match="NaN or inf"):
        check_gray(plane)
    with pytest.raises(InputError, match="HxW"):
        check_gray(np.zeros((4, 5, 1), np.float32), finite=False)
    with pytest.raises(InputError, match="float32"):
        check_gray(np.zeros((4, 5)), finite=False)


@pytest.mark.parametrize("value", [0.0, -1.0, float("inf"), float("nan")])
def test_baseline_parameters_name_what_is_wrong(value):
    from alcn_cv.enhance.histogram import CLAHE
    from alcn_cv.enhance.retinex import IntrinsicImage, SelfQuotientImage

    with pytest.raises(InputError, match="^eps must be positive and finite"):
        IntrinsicImage(eps=value)
    with pytest.raises(InputError, match="^eps must be positive and finite"):
        SelfQuotientImage(eps=value)
    with pytest.raises(InputError, match="^clipLimit must be positive and finite"):
        CLAHE(clipLimit=value)
    assert check_positive("eps", 0.5) == 0.5


def test_uint16_is_rounded_and_round_trips_exactly():
    assert from_unit_float(np.array([[0.6, 1.4, 65534.6]], np.float32) / 65535, np.dtype(np.uint16)).tolist() == [
        [1, 1, 65535]
    ]
    img = np.random.default_rng(0).integers(0, 65536, (64, 80), dtype=np.uint16)
    np.testing.assert_array_equal(alcn_cv.create("none").apply(img), img)


def test_float_images_get_exactly_the_documented_rounding_tolerance():
    """A float32 image may lie FLOAT_TOLERANCE (1e-3) outside [0, 1], no more: a looser bound would let a bicubic
    resize's overshoot (1.005) through unnoticed, which apply() then clips silently."""
    from alcn_cv.checks import FLOAT_TOLERANCE, check_image

    assert FLOAT_TOLERANCE == 1e-3
    for inside in (1.0009, -0.0009):
        check_image(np.full((4, 5), inside, np.float32))
    for outside in (1.0011, 1.005, -0.0011):
        with pytest.raises(InputError, match=r"float32 intensities must be in \[0, 1\]"):
            check_image(np.full((4, 5), outside, np.float32))
