"""The data engine's textures (alcn_cv.data.textures): photographs only from the permissive list."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.data.textures import (
    SKIMAGE_PHOTOGRAPHS,
    colour_jitter,
    display_texture,
    photo_crop,
    photos,
    procedural_texture,
    random_texture,
    skimage_photograph,
)
from alcn_cv.errors import DatasetError, InputError

skimage_data = pytest.importorskip("skimage.data")


def test_photos_are_the_permissive_photographs_as_linear_rgb():
    pool = photos()
    assert len(pool) == len(SKIMAGE_PHOTOGRAPHS)
    for name, photo in zip(SKIMAGE_PHOTOGRAPHS, pool, strict=True):
        raw = skimage_photograph(name)
        assert photo.shape == (*raw.shape[:2], 3) and photo.dtype == np.float32
        assert photo.min() >= 0.0 and photo.max() <= 1.0
        expected = (raw.astype(np.float32) / 255) ** 2.2
        if raw.ndim == 2:  # a gray photograph is replicated to three channels
            expected = np.repeat(expected[..., None], 3, axis=2)
        assert np.allclose(photo, expected)
    assert any(skimage_photograph(name).ndim == 2 for name in SKIMAGE_PHOTOGRAPHS)


def test_a_photograph_without_a_permissive_licence_is_refused():
    for name in ("moon", "page", "colorwheel", "stereo_motorcycle"):
        with pytest.raises(InputError, match=name):
            skimage_photograph(name)


def test_a_photograph_whose_docstring_lost_its_licence_is_refused(monkeypatch):
    def camera() -> np.ndarray:
        """A camera man."""
        return np.zeros((8, 8), np.uint8)

    monkeypatch.setattr(skimage_data, "camera", camera)
    with pytest.raises(DatasetError, match="licence"):
        skimage_photograph("camera")


def test_crops_and_textures_are_linear_rgb_and_deterministic():
    crop = photo_crop(np.random.default_rng(0), (40, 56))
    assert crop.shape == (40, 56, 3) and crop.dtype == np.float32 and 0 <= crop.min() <= crop.max() <= 1
    a = random_texture(np.random.default_rng(1), 32, p_photo=1.0)
    assert np.array_equal(a, random_texture(np.random.default_rng(1), 32, p_photo=1.0)) and a.std() > 0


def test_procedural_texture_kinds_and_sizes():
    """An unknown kind was a ValueError raised after drawing; a NumPy integer side could not be unpacked."""
    with pytest.raises(InputError, match="unknown procedural texture"):
        procedural_texture(np.random.default_rng(0), 16, "plaid")
    a = procedural_texture(np.random.default_rng(3), np.int64(24), "blobs")
    assert a.shape == (24, 24, 3) and np.array_equal(a, procedural_texture(np.random.default_rng(3), 24, "blobs"))
    assert photo_crop(np.random.default_rng(0), np.int32(20)).shape == (20, 20, 3)


def test_p_photo_one_always_gives_a_jittered_photograph_crop():
    """``p_photo`` is the probability of a photograph: at 1 every texture is a colour-jittered :func:`photo_crop` drawn
    after the choice (an inverted comparison gave procedural textures only, which the determinism test let pass)."""
    for seed in range(4):
        rng = np.random.default_rng(seed)
        rng.random()  # the choice
        expected = colour_jitter(rng, photo_crop(rng, 24), 0.6)
        np.testing.assert_array_equal(random_texture(np.random.default_rng(seed), 24, p_photo=1.0), expected)


def test_colour_jitter_stays_in_the_unit_range():
    """Gains above 1, a saturation boost and the inversion would leave [0, 1] unclipped (a reflectance above 1)."""
    img = np.random.default_rng(0).random((16, 16, 3), dtype=np.float32)
    for seed in range(20):
        out = colour_jitter(np.random.default_rng(seed), img, 1.0)
        assert out.dtype == np.float32 and out.min() >= 0.0 and out.max() <= 1.0
    assert max(float(colour_jitter(np.random.default_rng(s), img, 1.0).max()) for s in range(20)) == 1.0  # clipped


def test_display_texture_is_the_gamma_encoded_luma_of_the_linear_texture():
    """A background as a photograph stores it: the linear texture raised to 1/2.2, then luma. Without the encoding
    the backgrounds were the darker linear values."""
    linear = random_texture(np.random.default_rng(3), 20, p_photo=0.5)
    expected = cv2.cvtColor(np.ascontiguousarray(linear[..., ::-1] ** (1 / 2.2), dtype=np.float32), cv2.COLOR_BGR2GRAY)
    shown = display_texture(np.random.default_rng(3), 20, p_photo=0.5)
    assert shown.shape == (20, 20) and shown.dtype == np.float32
    np.testing.assert_allclose(shown, expected, atol=1e-6)
