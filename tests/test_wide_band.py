"""The wide band added to the gain Normalizer's output (:mod:`alcn_cv.filters.wide_band`): NumPy and torch
agree, it ignores the light's strength, strips of an image give the whole image's band, and weight files
record it."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from alcn_cv.data.frames import synthetic_frame  # noqa: E402
from alcn_cv.errors import WeightFileError  # noqa: E402
from alcn_cv.filters import torch_wide_band  # noqa: E402
from alcn_cv.filters.wide_band import (  # noqa: E402
    BLOCK,
    band_meta,
    band_reach,
    block_means,
    check_band_meta,
    wide_band,
    wide_band_floor,
)


def _gray(h: int, w: int, seed: int = 3) -> np.ndarray:
    return synthetic_frame(w, h, False, seed=seed).astype(np.float32) / np.float32(255)


@pytest.mark.parametrize("shape", [(64, 80), (67, 81), (120, 97), (9, 13)])
def test_numpy_and_torch_agree(shape):
    gray = _gray(*shape)
    band = wide_band(gray, tau=3.0)
    assert band.shape == shape and band.dtype == np.float32 and np.abs(band).max() < 1
    with torch.inference_mode():
        expected = torch_wide_band.wide_band(torch.from_numpy(gray)[None, None], tau=3.0)[0, 0].numpy()
    np.testing.assert_allclose(band, expected, atol=2e-5, rtol=0)


def test_block_means_are_the_means_of_whole_blocks():
    gray = _gray(10, 7)
    small = block_means(gray)
    assert small.shape == (3, 2)
    np.testing.assert_allclose(small[0, 0], gray[:BLOCK, :BLOCK].mean(), rtol=1e-6)
    reflected = np.pad(gray, ((0, 2), (0, 1)), mode="reflect")  # reflect-101 to whole blocks
    np.testing.assert_allclose(small[-1, -1], reflected[-BLOCK:, -BLOCK:].mean(), rtol=1e-6)


def test_the_band_ignores_the_strength_of_the_light():
    gray = _gray(96, 128)
    np.testing.assert_allclose(wide_band(gray * np.float32(0.2), 3.0), wide_band(gray, 3.0), atol=1e-4, rtol=0)


def test_a_strip_with_its_reach_and_the_whole_floor_gives_the_whole_band():
    gray = _gray(4 * band_reach(), 40)
    whole = wide_band(gray, 3.0)
    floor = wide_band_floor(block_means(gray), 1.0)
    start = stop = 2 * band_reach()
    stop += 8 * BLOCK
    lo, hi = start - band_reach(), stop + band_reach()
    strip = wide_band(gray[lo:hi], 3.0, floor=floor)
    np.testing.assert_allclose(strip[start - lo : stop - lo], whole[start:stop], atol=1e-6, rtol=0)


def test_weight_files_record_the_band_they_were_made_with():
    assert check_band_meta(band_meta(0.3)) == 0.3
    with pytest.raises(WeightFileError, match="wide band"):
        check_band_meta({**band_meta(0.3), "sigmas": [4.0, 16.0]})


def test_strips_of_alcn_give_the_whole_band_down_to_a_last_strip_of_one_row(monkeypatch):
    from alcn_cv import createALCN
    from alcn_cv.enhance import base

    alcn = createALCN()
    assert alcn.spec.band == 0.15
    frame = synthetic_frame(416, 289, False, seed=4)
    whole = alcn.apply(frame, out_dtype=np.float32)
    monkeypatch.setattr(base, "TILE_PIXELS", 20_000)
    strips = alcn._strips(frame.shape[:2])
    assert strips is not None and strips[-1][1] - strips[-1][0] == 1
    np.testing.assert_allclose(alcn.apply(frame, out_dtype=np.float32), whole, atol=1e-5, rtol=0)


@pytest.mark.parametrize("rows", [289, 290])
def test_the_strips_floors_are_the_whole_images(monkeypatch, rows):
    """The divisive floors the strips are normalized with are the whole image's, the band's included: its last
    strip's blocks reflected below the image's last row as the whole's are (not the strip's few rows reflected on
    their own: a floor 3e-4 off, which the output shows only at 5e-6)."""
    from alcn_cv import createALCN
    from alcn_cv.enhance import base
    from alcn_cv.enhance.alcn import _DIVISIVE_FLOORS
    from alcn_cv.filters.divisive import divisive_floor, gaussian_energy

    alcn = createALCN()
    frame = synthetic_frame(416, rows, False, seed=4)
    gray = frame.astype(np.float32) * np.float32(1 / 255)
    sigma, c = alcn.spec.divisive
    monkeypatch.setattr(base, "TILE_PIXELS", 20_000)
    strips = alcn._strips(frame.shape[:2])
    assert strips is not None and (strips[-1][1] - strips[-1][0]) % 4  # a last strip of part of a block
    with alcn._strip_context(frame, strips):
        floor, band_floor = _DIVISIVE_FLOORS.get()
    assert band_floor == pytest.approx(wide_band_floor(block_means(gray), c), rel=1e-6, abs=0)
    assert floor == pytest.approx(divisive_floor(gaussian_energy(alcn.runtime.mixture(gray), sigma), c), rel=1e-5)


@pytest.mark.parametrize("meta", [{k: v for k, v in band_meta(0.3).items() if k != "weight"}, [0.3], None])
def test_a_band_entry_without_a_weight_is_a_weight_file_error(meta):
    """It was a KeyError (or an AttributeError) from the runtime's loader."""
    with pytest.raises(WeightFileError):
        check_band_meta(meta)
    with pytest.raises(WeightFileError, match="weight"):
        check_band_meta({**band_meta(0.3), "weight": "heavy"})
