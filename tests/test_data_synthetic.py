"""Tests of the paper's simple synthetic images (augmentation of a few real images)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.data.synthetic import augment, object_box, sample_negatives
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


def _still_negatives(img, box, n, seed, off_centre_fraction):
    """Negatives of the object's own image only, without noise or intensity changes."""
    kwargs = dict(natural_fraction=0.0, noise=0, intensity_scale=(1, 1), intensity_offset=0)
    rng = np.random.default_rng(seed)
    return sample_negatives([img], [box], n, rng, off_centre_fraction=off_centre_fraction, **kwargs)


def test_negatives_avoid_the_object():
    img, box = _image()
    neg = _still_negatives(img, box, 50, seed=3, off_centre_fraction=0.0)
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


_STILL = {
    "max_shift": 0,
    "max_rotation_deg": 0,
    "max_scale_change": 0,
    "noise": 0,
    "intensity_scale": (1, 1),
    "intensity_offset": 0,
    "replace_background": 0,
}


def test_augment_maps_the_boxs_centre_to_the_windows_centre_exactly():
    """The box's centre ``x + (w - 1) / 2`` lands on the window's ``(64 - 1) / 2``: at the image's scale and without
    jitter a window is a crop of the image, pixel for pixel. A centre ``x + w / 2`` (half a pixel off) passed the
    test above, whose tolerance is a pixel, and interpolated every window between pixels."""
    img, box = _image()  # the centre (84.5, 59.5): the crop [28:92, 53:117]
    win = augment(img, box, 3, np.random.default_rng(0), extent=None, **_STILL)
    gray = cv2.cvtColor(img.astype(np.float32) / np.float32(255), cv2.COLOR_BGR2GRAY)
    expected = np.rint(np.clip(gray[28:92, 53:117], 0, 1) * 255).astype(np.uint8)
    for w in win:
        np.testing.assert_array_equal(w, expected)


def test_the_intensity_offset_is_drawn_on_both_sides_of_zero():
    """``|b|`` at most ``intensity_offset``: b is drawn in [-offset, offset], darkening as often as lightening (an
    offset drawn in [0, offset] only made every window brighter)."""
    flat = np.full((100, 100), 128, np.uint8)
    win = augment(flat, [30, 30, 40, 40], 200, np.random.default_rng(5), **{**_STILL, "intensity_offset": 0.05})
    levels = win.reshape(200, -1)
    assert (levels == levels[:, :1]).all()  # a uniform image stays uniform: a, b, no noise
    b = levels[:, 0].astype(int) - 128
    assert b.min() < -8 and b.max() > 8 and np.abs(b).max() <= 13  # 0.05 * 255 = 12.75 levels


def test_off_centre_negatives_show_the_object_14_to_26_output_pixels_off_the_centre():
    """The off-centre distance is in output pixels: ``d / s`` input pixels at the scale ``s``; ``d * s`` (at s = 2
    here) put the object 56 to 104 pixels off, out of the window."""
    img = np.zeros((120, 200), np.uint8)
    img[59:61, 99:101] = 255  # a dot at the centre (99.5, 59.5) of the box below
    box = [90, 50, 20, 20]  # extent 40: the scale s = 2
    neg = _still_negatives(img, box, 30, seed=6, off_centre_fraction=1.0)
    ys, xs = np.mgrid[0:64, 0:64]
    for w in neg.astype(np.float64):
        assert w.sum() > 0, "the object left the window"
        y, x = (ys * w).sum() / w.sum(), (xs * w).sum() / w.sum()
        assert 13.5 <= np.hypot(x - 31.5, y - 31.5) <= 26.5


def test_a_sixteen_bit_image_gives_the_windows_of_its_eight_bits():
    """A uint16 image is read in [0, 1] as ``x / 65535``: dividing it by 255 (as uint8) saturated it to white."""
    img, box = _image()
    a = augment(img, box, 6, np.random.default_rng(9))
    b = augment(img.astype(np.uint16) * 257, box, 6, np.random.default_rng(9))
    assert np.abs(a.astype(int) - b).max() <= 1


def test_a_0_255_masks_object_is_what_lies_above_127():
    """A 0..255 mask (a PNG with anti-aliased edges) is the object above 127, as io.read_mask reads one: its faint
    fringe is not the object. Counting every nonzero pixel grew the box by the fringe; a 0/1 or boolean mask is the
    object where nonzero."""
    mask = np.zeros((60, 80), np.uint8)
    mask[10:50, 20:70] = 100  # the fringe
    mask[20:40, 30:60] = 255
    box, kept = object_box(mask.shape, mask)
    assert box.tolist() == [30, 20, 30, 20] and kept.sum() == 600
    for core in ((mask == 255).astype(np.uint8), mask == 255):
        assert object_box(mask.shape, core)[0].tolist() == [30, 20, 30, 20]
