"""Every method's output reaches the detector the same way: the input policies and the window agreement."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.bench import detect as D
from alcn_cv.bench import policies
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import from_spec


@pytest.mark.parametrize("policy", ["raw", "local"])
@pytest.mark.parametrize(("gain", "offset"), [(0.05, 0.0), (20.0, -3.0)])
def test_policies_ignore_the_responses_affine_range(policy, gain, offset):
    # A method's declared output range (tanh's [-1, 1], DoG's +-0.1, ...) is an affine map of its
    # response: under either policy the detector gets the same input whatever that map is.
    rng = np.random.default_rng(0)
    train = rng.normal(size=(12, 64, 64)).astype(np.float32)
    image = rng.normal(size=(50, 70)).astype(np.float32)
    reference = policies.InputPolicy(policy, train)
    mapped = policies.InputPolicy(policy, gain * train + offset)
    np.testing.assert_allclose(mapped.windows(gain * train + offset), reference.windows(train), atol=1e-3)
    np.testing.assert_allclose(mapped.image(gain * image + offset), reference.image(image), atol=1e-3)


@pytest.mark.parametrize("policy", ["raw", "local"])
def test_window_and_image_inputs_agree(policy):
    # The detector is trained on windows and scores images: at a window's centre both forms give
    # the same input for a method that looks no further than the window.
    rng = np.random.default_rng(1)
    train = rng.normal(size=(6, 64, 64)).astype(np.float32)
    pol = policies.InputPolicy(policy, train)
    image = rng.normal(size=(80, 90)).astype(np.float32)
    window = image[10:74, 20:84]
    np.testing.assert_allclose(pol.windows(window[None])[0], pol.image(image)[26:58, 36:68], atol=1e-4)


class _MinusImageMean(Normalization):
    """Subtracts the mean of whatever it is given: a global statistic, wider than any window."""

    name = "minus_image_mean"

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return gray - gray.mean()


def test_window_agreement():
    rng = np.random.default_rng(2)
    x = np.linspace(0, 1, 200, dtype=np.float32)
    images = [
        np.clip(0.5 * x[None, :] + 0.4 * x[:150, None] + 0.1 * rng.random((150, 200)), 0, 1).astype(np.float32)
        for _ in range(2)
    ]
    dog = from_spec("dog")
    assert D.window_agreement(dog, images, [dog.normalize(im) for im in images]) == pytest.approx(1.0, abs=1e-5)
    wide = _MinusImageMean()
    assert D.window_agreement(wide, images, [wide.normalize(im) for im in images]) < 0.9
    assert D.window_agreement(dog, [images[0][:40, :40]], [images[0][:40, :40]]) is None
