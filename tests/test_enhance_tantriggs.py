"""Tan-Triggs (Tan & Triggs, IEEE TIP 2010): each step against an independent computation."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

import alcn_cv
from alcn_cv.enhance.tantriggs import TanTriggs, contrast_equalize
from alcn_cv.errors import InputError


def _scene(h: int = 30, w: int = 40) -> np.ndarray:
    rng = np.random.default_rng(1)
    texture = ndimage.gaussian_filter(rng.random((h, w)), 1.0)
    shading = np.linspace(0.2, 1.0, w)[None, :]
    return np.clip(shading * (0.2 + texture), 0.01, 1.0).astype(np.float32)


def test_registered_with_the_papers_defaults():
    norm = alcn_cv.create("tantriggs")
    assert isinstance(norm, TanTriggs) and "tantriggs" in alcn_cv.available()
    assert (norm.gamma, norm.sigma0, norm.sigma1, norm.alpha, norm.tau) == (0.2, 1.0, 2.0, 0.1, 10.0)
    assert norm.output_range == (-10.0, 10.0)
    assert alcn_cv.create("tantriggs", tau=5).output_range == (-5.0, 5.0)


def test_contrast_equalization_by_hand():
    x = np.array([[1.0, -4.0], [16.0, 64.0]], np.float32)
    alpha, tau = 0.5, 3.0
    step1 = x / np.mean(np.abs(x) ** alpha) ** (1 / alpha)  # mean of sqrt = (1+2+4+8)/4 = 3.75
    np.testing.assert_allclose(step1, x / 3.75**2, rtol=1e-6)
    step2 = step1 / np.mean(np.minimum(tau, np.abs(step1)) ** alpha) ** (1 / alpha)
    expected = tau * np.tanh(step2 / tau)
    out = contrast_equalize(x, alpha, tau)
    np.testing.assert_allclose(out, expected, rtol=1e-6)
    assert out.dtype == np.float32 and np.abs(out).max() < tau
    np.testing.assert_array_equal(contrast_equalize(np.zeros((3, 3), np.float32)), 0)  # flat: zeros, not NaN


@pytest.mark.parametrize(("alpha", "tau"), [(0.1, 10.0), (0.3, 3.0)])  # the defaults, and others: both are used
def test_steps_against_an_independent_chain(alpha, tau):
    """Gamma, DoG and the equalization (TIP 2010, Eqs. 1-3) written out here, not through the module's functions."""
    img = _scene()
    gamma, s0, s1 = 0.3, 1.0, 2.5
    corrected = img.astype(np.float64) ** gamma
    dog = ndimage.gaussian_filter(corrected, s0, mode="mirror", truncate=3) - ndimage.gaussian_filter(
        corrected, s1, mode="mirror", truncate=3
    )
    first = dog / np.mean(np.abs(dog) ** alpha) ** (1 / alpha)
    second = first / np.mean(np.minimum(tau, np.abs(first)) ** alpha) ** (1 / alpha)
    expected = tau * np.tanh(second / tau)
    out = TanTriggs(gamma=gamma, sigma0=s0, sigma1=s1, alpha=alpha, tau=tau).normalize(img)
    np.testing.assert_allclose(out, expected, atol=1e-3 * tau / 10)


def test_invariant_to_a_global_gain():
    # gamma turns a gain into another gain, the DoG is linear, the equalization removes the scale
    img = _scene()
    norm = TanTriggs()
    np.testing.assert_allclose(norm.normalize(img * 0.25), norm.normalize(img), atol=1e-3)


def test_apply_contract():
    img = np.rint(_scene() * 255).astype(np.uint8)
    out = alcn_cv.create("tantriggs").apply(img, out_dtype=np.float32)
    assert out.shape == img.shape and out.dtype == np.float32 and out.min() >= 0 and out.max() <= 1
    assert np.ptp(out) > 0
    np.testing.assert_array_equal(alcn_cv.create("tantriggs").apply(np.full((8, 9), 100, np.uint8)), 128)  # flat -> 0


@pytest.mark.parametrize("params", [{"gamma": 0}, {"sigma0": 2, "sigma1": 1}, {"tau": -1}, {"alpha": float("nan")}])
def test_bad_parameters(params):
    with pytest.raises(InputError):
        alcn_cv.create("tantriggs", **params)


def test_an_image_whose_largest_magnitude_is_eps_counts_as_flat():
    """``eps`` is "the largest magnitude at or below which the image counts as flat": a ``>=`` in the flatness check
    would blow an image of magnitude exactly ``eps`` up to full contrast instead of returning zeros."""
    x = np.array([[0.5, -0.5], [0.25, 0.0]], np.float32)
    np.testing.assert_array_equal(contrast_equalize(x, eps=0.5), np.zeros((2, 2), np.float32))
    assert np.abs(contrast_equalize(x, eps=0.4999)).max() > 1.0
