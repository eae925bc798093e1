"""The input checks of alcn_cv.checks that no normalization's tests cover."""

import numpy as np
import pytest

from alcn_cv.checks import check_seeds
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

    with pytest.raises(InputError, match=r"got shape \(4, 48, 64\) \(frames stacked\? .*apply_batch\)"):
        check_image(np.zeros((4, 48, 64), np.uint8))
    with pytest.raises(InputError, match=r"got shape \(48, 64, 5\)$"):  # five channels, not a stack
        check_image(np.zeros((48, 64, 5), np.uint8))
