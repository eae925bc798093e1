"""The colour path of ``Normalization.apply`` (OpenCV passes) against the plain float Lab round trip
(:func:`alcn_cv.bench.speed.lab_round_trip`): within one level of the output type."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from alcn_cv.bench.speed import lab_round_trip
from alcn_cv.data.frames import synthetic_frame
from alcn_cv.enhance.registry import available, from_spec
from alcn_cv.io import iter_frames

#: Every registered method (they all share the colour path), and the gain Normalizer.
METHODS = [*available(), "alcn:model=lite"]


def _saturated_hues() -> np.ndarray:
    """Fully saturated hues at four brightnesses, in 8x8 blocks alternating with black and
    white ones: the normalized lightness lands far from the input's, out of the sRGB gamut."""
    hue = np.linspace(0, 179, 48).astype(np.uint8)
    rows = [
        cv2.cvtColor(
            np.stack([hue, np.full_like(hue, 255), np.full_like(hue, value)], axis=-1)[None], cv2.COLOR_HSV2BGR
        )[0]
        for value in (255, 192, 96, 32)
    ]
    blocks = np.repeat(np.repeat(np.stack(rows), 8, axis=0), 8, axis=1)
    blocks[::16, ::2] = 0
    blocks[8::16, 1::2] = 255
    return blocks


def _images() -> list[np.ndarray]:
    images = [
        synthetic_frame(200, 150, True, seed=3),
        np.random.default_rng(0).integers(0, 256, (90, 120, 3), dtype=np.uint8),
    ]
    saturated = np.zeros((64, 96, 3), np.uint8)
    saturated[:, :32, 2] = 255  # pure red, green and blue blocks next to black: out-of-gamut lightness
    saturated[:, 32:64, 1] = 255
    saturated[:, 64:, 0] = np.linspace(0, 255, 64, dtype=np.uint8)[:, None]
    return images + [saturated, _saturated_hues()]


@pytest.mark.parametrize("name", METHODS)
def test_colour_within_one_level_of_the_lab_round_trip(name):
    method = from_spec(name)
    for img in _images():
        for source, out_dtype in (
            (img, np.uint8),
            (img.astype(np.uint16) * 257, np.uint16),
            (img.astype(np.float32) / np.float32(255), np.float32),
        ):
            out = method.apply(source, out_dtype=out_dtype)
            reference = lab_round_trip(method, source, np.dtype(out_dtype))
            assert out.dtype == reference.dtype and out.shape == reference.shape
            level = 1 if out_dtype != np.float32 else 1 / 65535
            assert np.abs(out.astype(np.float64) - reference).max() <= level, (name, out_dtype)


def test_colour_within_one_level_on_a_photograph(shared_data):
    photo = cv2.imread(str(shared_data / "cookie_box" / "resized_IMG_3875.JPG"), cv2.IMREAD_COLOR)
    if photo is None:
        pytest.skip("the cookie-box photograph is not in the shared data")
    photo = cv2.resize(photo, (480, 360), interpolation=cv2.INTER_AREA)
    for name in ("alcn", "alcn:model=lite"):
        method = from_spec(name)
        diff = np.abs(method.apply(photo).astype(int) - lab_round_trip(method, photo, np.dtype(np.uint8)))
        assert diff.max() <= 1, name


def _real_frames(root) -> list[tuple[str, np.ndarray]]:
    """One outdoor webcam frame of each scene and two frames of the cookie-box video."""
    frames = []
    for scene in ("courbevoie", "frankfurt", "mexico", "panorama"):
        folder = root / "webcam" / scene
        if folder.is_dir():
            frames += [(f"webcam/{scene}/{name}", frame) for name, frame in iter_frames(folder, step=17, max_frames=1)]
    video = root / "cookie_box" / "box.mp4"
    if video.is_file():
        frames += [(f"cookie_box/{name}", frame) for name, frame in iter_frames(video, step=200, max_frames=2)]
    return frames


@pytest.mark.parametrize("name", ["alcn", "alcn:model=lite", "dog", "clahe"])
def test_colour_within_one_level_on_real_frames(shared_data, name):
    frames = _real_frames(shared_data)
    if not frames:
        pytest.skip("neither the webcam frames nor the cookie-box video are in the shared data")
    method = from_spec(name)
    for label, frame in frames:
        diff = np.abs(method.apply(frame).astype(int) - lab_round_trip(method, frame, np.dtype(np.uint8)))
        assert diff.max() <= 1, (name, label)


def test_colour_of_a_bgra_view_equals_the_bgr_image():
    bgr = synthetic_frame(120, 90, True, seed=5)
    bgra = np.dstack([bgr, np.full(bgr.shape[:2], 200, np.uint8)])
    method = from_spec("alcn")
    out = method.apply(bgra)
    np.testing.assert_array_equal(out[..., :3], method.apply(bgr))
    np.testing.assert_array_equal(out[..., 3], bgra[..., 3])
    np.testing.assert_array_equal(method.apply(bgr[:, ::-1]), method.apply(np.ascontiguousarray(bgr[:, ::-1])))
