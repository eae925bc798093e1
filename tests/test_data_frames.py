"""The synthetic frames of the speed benchmark and the runtime's tests (alcn_cv.data.frames)."""

import numpy as np

from alcn_cv.data.frames import synthetic_frame


def test_synthetic_frames():
    gray, bgr = synthetic_frame(64, 48, False), synthetic_frame(64, 48, True)
    assert gray.shape == (48, 64) and bgr.shape == (48, 64, 3) and gray.dtype == bgr.dtype == np.uint8
    assert gray.std() > 10
    np.testing.assert_array_equal(gray, synthetic_frame(64, 48, False))
    assert not np.array_equal(gray, synthetic_frame(64, 48, False, t=1.0))
