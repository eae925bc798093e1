"""The data engine's textures (alcn_cv.data.textures): photographs only from the permissive list."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.data.textures import (
    SKIMAGE_PHOTOGRAPHS,
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
