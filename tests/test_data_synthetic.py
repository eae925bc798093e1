"""Tests of the paper's simple synthetic images (augmentation of a few real images)."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.data.synthetic import augment, sample_negatives
from alcn_cv.errors import InputError


def _image():
    rng = np.random.default_rng(0)
    img = np.full((120, 160, 3), 90, np.uint8)
    img[40:80, 60:110] = rng.integers(150, 255, (40, 50, 3), dtype=np.uint8)  # the object
    return img, [60, 40, 50, 40]


def test_augment_centres_the_object_at_the_requested_extent():
    img, box = _image()
    win = augment(
        img,
        box,
        32,
        np.random.default_rng(1),
        extent=40,
        max_shift=0,
        max_rotation_deg=0,
        max_scale_change=0,
        noise=0,
        intensity_scale=(1, 1),
        intensity_offset=0,
        replace_background=0,
    )
    assert win.shape == (32, 64, 64) and win.dtype == np.uint8
    bright = win.mean(0) > 140
    ys, xs = np.nonzero(bright)
    assert abs(xs.min() - 12) <= 1 and abs(xs.max() - 51) <= 1  # 50 px wide -> 40 px, centred
    assert abs((ys.min() + ys.max()) / 2 - 31.5) <= 1


def test_augment_varies_intensity_background_and_noise():
    img, box = _image()
    mask = np.zeros(img.shape[:2], np.uint8)
    mask[40:80, 60:110] = 1
    rng = np.random.default_rng(2)
    win = augment(img, mask, 64, rng, backgrounds=[np.zeros((50, 50), np.uint8)])
    corners = win[:, :6, :6].reshape(64, -1).mean(1)
    assert corners.std() > 20  # backgrounds replaced (uniform colours, crops, textures)
    centre = win[:, 28:36, 28:36].reshape(64, -1).mean(1)
    assert centre.std() > 2  # I' = a I + b
    a = augment(img, box, 5, np.random.default_rng(7))
    b = augment(img, box, 5, np.random.default_rng(7))
    assert np.array_equal(a, b)


def test_negatives_avoid_the_object():
    img, box = _image()
    neg = sample_negatives(
        [img],
        [box],
        50,
        np.random.default_rng(3),
        natural_fraction=0.0,
        off_centre_fraction=0.0,
        noise=0,
        intensity_scale=(1, 1),
        intensity_offset=0,
    )
    assert neg.shape == (50, 64, 64)
    centre = neg[:, 16:48, 16:48].astype(np.float32)
    assert (centre.reshape(50, -1).mean(1) < 120).all()  # background is 90, the object >= 150
    mixed = sample_negatives([img], [box], 20, np.random.default_rng(4))
    assert mixed.shape == (20, 64, 64)


def test_bad_input():
    img, box = _image()
    rng = np.random.default_rng(0)
    with pytest.raises(InputError):
        augment(img, [0, 0, 0, 5], 2, rng)
    with pytest.raises(InputError):
        augment(img, np.zeros((3, 3)), 2, rng)
    with pytest.raises(InputError):
        augment(img.astype(np.float64), box, 2, rng)
    with pytest.raises(InputError):
        augment(np.zeros((0, 0), np.uint8), box, 2, rng)
    with pytest.raises(InputError):
        sample_negatives([img], [], 2, rng)
    with pytest.raises(InputError):
        sample_negatives([img], [box], -1, rng)


def test_a_box_past_the_top_left_corner_keeps_its_object():
    """A box starting at a negative coordinate sliced its background mask from the far side of the image: empty,
    so the whole window, object included, was replaced by background."""
    img = np.full((100, 100), 200, np.uint8)
    img[:30, :30] = 20  # the object, in the corner; its box runs 5 px past it
    kwargs = dict(replace_background=1.0, noise=0, intensity_offset=0, intensity_scale=(1, 1), max_shift=0)
    win = augment(img, [-5, -5, 35, 35], 8, np.random.default_rng(0), **kwargs)
    assert (win[:, 28:36, 28:36] == 20).all()  # the object's centre, whatever the background
