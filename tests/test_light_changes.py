"""The light-change generator (alcn_cv.data.light_changes) and its permissive photographs
(alcn_cv.data.permissive_images)."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from alcn_cv.data.light_changes import (
    LIGHTS,
    LightChangeConfig,
    random_homography,
    relief_shading,
    relight,
    relit_frames,
    sensor_noise,
    shading_field,
    shadow_mask,
)
from alcn_cv.data.permissive_images import (
    PERMISSIVE_LICENCES,
    SHARED_PHOTOGRAPHS,
    Photograph,
    relit_scenes,
    shared_photographs,
    skimage_photographs,
)
from alcn_cv.data.textures import SKIMAGE_PHOTOGRAPHS
from alcn_cv.errors import InputError
from alcn_cv.shared_data import shared_data_dir

NONE = LightChangeConfig.identity()


def _texture(h: int = 96, w: int = 128, colour: bool = False, seed: int = 0) -> np.ndarray:
    """A smooth random texture (smooth enough for bilinear resampling to be accurate)."""
    noise = np.random.default_rng(seed).uniform(0, 255, (h, w, 3) if colour else (h, w)).astype(np.float32)
    return np.clip(cv2.GaussianBlur(noise, (0, 0), 2.0) * 3 - 255, 0, 255).astype(np.uint8)


def test_frames_are_deterministic_by_seed():
    image = _texture(colour=True)
    a, b = (relit_frames(image, 2, np.random.default_rng(5), jitter=2.0) for _ in range(2))
    c = relit_frames(image, 2, np.random.default_rng(6), jitter=2.0)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@pytest.mark.parametrize("colour", [False, True])
def test_shapes_dtypes_and_ranges(colour):
    image = _texture(colour=colour)
    frames = relit_frames(image, 3, np.random.default_rng(0))
    assert frames.shape == (3, *image.shape) and frames.dtype == np.uint8


def test_bad_input_raises():
    with pytest.raises(InputError):
        relight(np.zeros((8, 8), np.float32), np.random.default_rng(0))
    with pytest.raises(InputError):
        relight(np.zeros((8, 8, 4), np.uint8), np.random.default_rng(0))


def test_identity_config_keeps_the_photograph():
    image = _texture(colour=True)
    out = relight(image, np.random.default_rng(0), NONE)
    assert np.abs(out.astype(int) - image).max() <= 1


def test_shadow_darkens_its_region_only():
    mask = shadow_mask((128, 128), np.random.default_rng(0), 1, light=(0.2, 0.2), penumbra=(1, 1), kinds=("polygon",))
    assert mask.dtype == np.float32 and mask.min() == pytest.approx(0.2, abs=0.02) and mask.max() == 1.0
    assert 0.02 < (mask < 0.5).mean() < 0.98
    assert np.array_equal(shadow_mask((32, 32), np.random.default_rng(0), 0), np.ones((32, 32), np.float32))
    several = shadow_mask((128, 128), np.random.default_rng(0), 4, light=(0.5, 0.5), penumbra=(1, 1))
    assert several.min() < 0.3  # where shadows overlap, they multiply
    image = np.full((128, 128), 160, np.uint8)
    out = relight(
        image, np.random.default_rng(2), replace(NONE, shadows=(1, 1), shadow_light=(0.2, 0.2), penumbra=(1.0, 1.0))
    )
    umbra = round(255 * 0.2 ** (1 / 2.2) * 160 / 255)  # a fifth of the linear light
    assert out.max() == 160 and (out == 160).mean() > 0.02  # lit pixels keep their value, none brightens
    assert abs(int(out.min()) - umbra) <= 1 and (out <= umbra + 1).mean() > 0.02


def test_penumbra_widens_the_edge():
    def edge_width(sigma: float) -> int:
        mask = shadow_mask(
            (128, 128), np.random.default_rng(4), 1, light=(0.0, 0.0), penumbra=(sigma, sigma), kinds=("edge",)
        )
        return int(((mask > 0.05) & (mask < 0.95)).sum())

    assert edge_width(8.0) > 3 * edge_width(0.5)


def test_shading_field():
    flat = shading_field((40, 50), np.random.default_rng(0), 0.0, 0.0)
    assert np.allclose(flat, 1.0)
    ramp = shading_field((40, 50), np.random.default_rng(0), 0.0, 1.0)
    assert 1.0 < ramp.max() / ramp.min() <= np.e + 1e-3
    smooth = shading_field((40, 50), np.random.default_rng(0), 0.7, 0.0)
    assert np.exp(-0.7) - 1e-4 <= smooth.min() < smooth.max() <= np.exp(0.7) + 1e-4


def test_noise_grows_relative_to_a_darker_signal():
    rng = np.random.default_rng(0)
    for bright, dark in [(0.5, 0.05), (0.05, 0.005)]:
        rel = [np.std(sensor_noise(np.full(20000, s, np.float32), rng, 1000.0, 3.0) - s) / s for s in (bright, dark)]
        assert rel[1] > 2 * rel[0]
    assert np.std(sensor_noise(np.full(20000, 0.5, np.float32), rng, 1000.0, 3.0)) == pytest.approx(
        np.sqrt(500 + 9) / 1000, rel=0.05
    )
    # through the camera: a darker light, brought back by exposure and ISO, is noisier
    image = np.full((64, 64), 128, np.uint8)
    noisy = replace(NONE, target=0.18, full_well=(2000.0, 2000.0), read_noise=(4.0, 4.0))
    stds = [relight(image, np.random.default_rng(1), replace(noisy, gain=(g, g))).std() for g in (1.0, 0.1, 0.01)]
    assert stds[0] < stds[1] < stds[2]


def test_light_colour_exposure_clipping_and_jpeg():
    image = _texture(colour=True)
    tinted = relight(image, np.random.default_rng(2), replace(NONE, colour=0.5))
    ratios = tinted.reshape(-1, 3).mean(0) / image.reshape(-1, 3).mean(0)
    assert ratios.max() / ratios.min() > 1.1
    bright = relight(image, np.random.default_rng(0), replace(NONE, gain=(8.0, 8.0)))
    assert (bright == 255).mean() > 0.5 > (image == 255).mean()
    darker = relight(image, np.random.default_rng(0), replace(NONE, gamma=(1.5, 1.5)))
    assert darker.mean() < image.mean()
    gray = _texture()
    jpeg = relight(gray, np.random.default_rng(0), replace(NONE, jpeg_probability=1.0, jpeg_quality=(30, 30)))
    assert 0.5 < np.abs(jpeg.astype(int) - gray).mean() < 8


def test_permissive_licences_only():
    assert SKIMAGE_PHOTOGRAPHS and SHARED_PHOTOGRAPHS
    assert all(licence in PERMISSIVE_LICENCES for licence, _ in SKIMAGE_PHOTOGRAPHS.values())
    assert set(SHARED_PHOTOGRAPHS.values()) <= set(PERMISSIVE_LICENCES)
    assert not any(p.startswith(("webcam", "psm", "middlebury", "lumia_box")) for p in SHARED_PHOTOGRAPHS)


def test_skimage_photographs_load_offline_with_their_licence():
    pytest.importorskip("skimage")
    photos = skimage_photographs(max_side=256)
    assert len(photos) == len(SKIMAGE_PHOTOGRAPHS)
    for p in photos:
        assert p.image.dtype == np.uint8 and max(p.image.shape[:2]) <= 256 and p.licence in PERMISSIVE_LICENCES


def test_shared_photographs():
    root = shared_data_dir()
    if not (root / "chessboard").is_dir():
        pytest.skip(f"the shared data is not at {root}")
    photos = shared_photographs(root, video_frames=2)
    assert any(p.name.startswith("chessboard/") for p in photos) and all(p.licence == "Apache-2.0" for p in photos)


def test_relief_shading_follows_the_light_direction():
    flat = relief_shading(np.full((32, 32), 0.4, np.float32), np.random.default_rng(0), 20.0)
    assert np.allclose(flat, 1.0, atol=1e-5)
    bumps = _texture().astype(np.float32) / 255
    a = relief_shading(bumps, np.random.default_rng(0), 20.0, elevation=30.0, ambient=0.2)
    b = relief_shading(bumps, np.random.default_rng(1), 20.0, elevation=30.0, ambient=0.2)
    assert a.dtype == np.float32 and a.min() >= 0.2 - 1e-5 and a.max() <= 2.0 + 1e-5 and a.std() > 0.05
    assert np.corrcoef(a.ravel(), b.ravel())[0, 1] < 0.9  # another azimuth, another shading
    image = (bumps * 255).astype(np.uint8)
    relit = relight(image, np.random.default_rng(0), replace(NONE, relief=(20.0, 20.0)))
    assert np.abs(relit.astype(int) - image).mean() > 3


def test_relit_frames_jitter_stays_within_its_pixels():
    image = _texture(128, 160, seed=2)
    still = relit_frames(image, 2, np.random.default_rng(0), NONE)
    assert all(np.abs(f.astype(int) - image).max() <= 1 for f in still)
    moved = relit_frames(image, 4, np.random.default_rng(0), NONE, jitter=2.0)
    shifts = [np.hypot(*cv2.phaseCorrelate(image.astype(np.float64), f.astype(np.float64))[0]) for f in moved]
    assert max(shifts) <= 2.0 * np.sqrt(2) + 0.5 and any(np.abs(f.astype(int) - image).mean() > 2 for f in moved)


def test_relit_scenes_are_registered_gray_scenes_drawn_by_seed():
    photos = [
        Photograph("a/b.png", _texture(64, 80, colour=True), "CC0", "test"),
        Photograph("c", _texture(), "CC0", "t"),
    ]
    scenes = relit_scenes(photos, 3, seed=5, light="relief")
    assert [s.name for s in scenes] == ["00_a_b_png", "01_c"] and {s.group for s in scenes} == {"relit"}
    assert scenes[0].frames.shape == (3, 64, 80) and scenes[0].frames.dtype == np.uint8
    assert scenes[1].frames.shape == (3, 96, 128) and len(scenes[1].files) == 3
    assert not np.array_equal(scenes[1].frames[0], scenes[1].frames[1])  # each frame under its own light
    again = relit_scenes(photos, 3, seed=5, light="relief")
    assert all(np.array_equal(a.frames, b.frames) for a, b in zip(scenes, again))
    assert not np.array_equal(relit_scenes(photos, 3, seed=6)[1].frames, scenes[1].frames)
    assert set(LIGHTS) >= {"default", "hard", "relief"}
    with pytest.raises(InputError, match="at least 2"):
        relit_scenes(photos, 1)
    with pytest.raises(InputError, match="unknown light"):
        relit_scenes(photos, 2, light="moonlight")


def test_read_noise_is_in_electrons_and_alone_in_the_dark():
    dark = sensor_noise(np.zeros(40000, np.float32), np.random.default_rng(0), 1000.0, 6.0)
    assert np.std(dark) == pytest.approx(6.0 / 1000, rel=0.03)


def test_auto_exposure_cannot_darken_beyond_its_range():
    """ISO is a digital gain of at least 1: a light brighter than the exposure's range makes up for saturates."""
    image = np.full((32, 32), 200, np.uint8)
    out = relight(image, np.random.default_rng(0), replace(NONE, gain=(50.0, 50.0), target=0.18, max_exposure=4.0))
    assert (out == 255).all()
    dim = relight(image, np.random.default_rng(0), replace(NONE, gain=(0.001, 0.001), target=0.18, max_iso=16.0))
    assert 0 < dim.mean() < 200


def test_random_homography_moves_corners_by_a_share_of_width_in_x_and_height_in_y():
    h, w, shift = 100, 400, 0.1
    corners = np.float32([[[0, 0]], [[w - 1, 0]], [[w - 1, h - 1]], [[0, h - 1]]])
    moves = np.concatenate(
        [
            cv2.perspectiveTransform(corners, random_homography((h, w), np.random.default_rng(s), shift))[:, 0]
            - corners[:, 0]
            for s in range(20)
        ]
    )
    assert np.abs(moves[:, 0]).max() <= shift * w + 1e-3 and np.abs(moves[:, 0]).max() > shift * h
    assert np.abs(moves[:, 1]).max() <= shift * h + 1e-3


def test_auto_exposure_and_iso_bring_the_mean_to_the_target_once():
    """Exposure and ISO together make up ``target / mean``: ISO is only the part the exposure could not reach. An ISO
    computed from the mean alone (``target / mean``, the exposure forgotten) amplified a dim scene's signal by the
    exposure twice, so a relit frame came out far brighter than the target (255 where 117 is right)."""
    image = np.full((32, 32), 128, np.uint8)
    on_target = round(255 * 0.18 ** (1 / 2.2))  # the target mean 0.18 through the tone curve: 117
    for gain in (2.0, 0.5, 0.1):  # exposure 0.41 and 1.64 within [1/4, 4]; 4 and then ISO 2.05
        out = relight(image, np.random.default_rng(0), replace(NONE, gain=(gain, gain), target=0.18))
        assert abs(float(out.mean()) - on_target) <= 1, gain
    # beyond max_exposure * max_iso (64): the signal stays below the target, by that product
    dim = relight(image, np.random.default_rng(0), replace(NONE, gain=(0.01, 0.01), target=0.18))
    expected = 255 * ((128 / 255) ** 2.2 * 0.01 * 64) ** (1 / 2.2)
    assert abs(float(dim.mean()) - expected) <= 1


def test_the_gain_ramp_is_scaled_by_the_longer_side():
    """``ramp`` is the largest log-ratio of the ramp across the frame's longer side: ``t`` is 1 per ``max(H, W)``
    pixels. Dividing by the shorter side made a wide frame's ramp many times ``ramp`` (e^10 across 20 x 200)."""
    fields = [shading_field((20, 200), np.random.default_rng(seed), 0.0, 1.0) for seed in range(20)]
    ratios = [float(np.log(f.max() / f.min())) for f in fields]
    assert max(ratios) <= 1.0 + 1e-3 and max(ratios) > 0.3


def test_relight_takes_the_penumbra_of_its_config():
    """``relight`` draws each shadow's penumbra from ``config.penumbra``: a soft shadow leaves many pixels between the
    umbra and the lit level, a hard one few. Passing ``shadow_light`` (0.2 here) as the penumbra gave every shadow a
    hard edge whatever the config said."""
    image = np.full((128, 128), 160, np.uint8)
    umbra = round(255 * 0.2 ** (1 / 2.2) * 160 / 255)

    def edge_pixels(sigma: float) -> int:
        config = replace(NONE, shadows=(1, 1), shadow_light=(0.2, 0.2), penumbra=(sigma, sigma))
        out = relight(image, np.random.default_rng(2), config)
        return int(((out > umbra + 1) & (out < 159)).sum())

    hard, soft = edge_pixels(0.5), edge_pixels(8.0)
    assert hard > 0 and soft > 5 * hard


def test_relief_shading_under_a_light_straight_above_is_the_cosine_of_the_slope():
    """``elevation`` is measured from the image plane: at 90 degrees the light is straight above, its azimuth does not
    matter, and a plane of slope ``s`` (height per pixel) gets ``ambient + (1 - ambient) / sqrt(1 + s^2)``. Taking the
    elevation from the normal (sin and cos swapped) divided by cos(90 degrees), about 6e-17: gains of 1e15."""
    ramp = np.tile(np.arange(64, dtype=np.float32) * np.float32(0.01), (48, 1))  # slope 1 at depth 100
    expected = 0.2 + 0.8 / np.sqrt(2.0)
    for seed in (0, 1):
        gain = relief_shading(ramp, np.random.default_rng(seed), 100.0, elevation=90.0, ambient=0.2)
        np.testing.assert_allclose(gain[8:-8, 8:-8], expected, atol=1e-4)  # away from the blur's border


def test_relit_frames_jitter_is_in_pixels_of_the_longer_side():
    """``jitter`` pixels are those of the longer side (x here): the homography's shift is ``jitter / max(H, W)`` of
    the width in x and of the height in y. Dividing by the shorter side moved a wide frame's corners by 15 px in x and
    3 px in y for a jitter of 3."""
    h, w, jitter = 48, 240, 3.0
    image = _texture(h, w, seed=3)
    moved = relit_frames(image, 8, np.random.default_rng(0), NONE, jitter=jitter)
    shifts = np.array([cv2.phaseCorrelate(image.astype(np.float64), f.astype(np.float64))[0] for f in moved])
    assert np.abs(shifts[:, 0]).max() <= jitter + 0.5 and np.abs(shifts[:, 1]).max() <= jitter * h / w + 0.5
    assert np.abs(shifts[:, 0]).max() > 1.0  # the frames do move


def test_shadow_mask_darkens_where_the_shape_is_shadow(monkeypatch):
    """``shadow_shape`` gives 1 where lit and 0 in the shadow: the mask keeps the light at 1 where the shape is lit
    and leaves ``light`` of it in the shadow, ``light^2`` where two shadows overlap. Weighing by ``lit`` instead of
    ``1 - lit`` cast each shadow on the lit part of its shape (a polygon's shadow became a hole in a shadow), which
    the random shapes of the other tests cannot tell apart."""
    from alcn_cv.data import light_changes

    half = np.ones((8, 16), np.float32)
    half[:, 8:] = 0.0  # the left half lit, the right half in shadow
    monkeypatch.setattr(light_changes, "shadow_shape", lambda rng, shape, kind, penumbra: half)
    one = shadow_mask((8, 16), np.random.default_rng(0), 1, light=(0.3, 0.3), penumbra=(1, 1))
    np.testing.assert_allclose(one[:, :8], 1.0)
    np.testing.assert_allclose(one[:, 8:], 0.3, rtol=1e-6)
    two = shadow_mask((8, 16), np.random.default_rng(0), 2, light=(0.3, 0.3), penumbra=(1, 1))
    np.testing.assert_allclose(two[:, 8:], 0.09, rtol=1e-5)
