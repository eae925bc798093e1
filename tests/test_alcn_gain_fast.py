"""The gain Normalizer's OpenCV path in ALCN: ``createALCN(model="gain")`` against the torch model
(:meth:`GainNormalizer.forward <alcn_cv.nets.gain.GainNormalizer.forward>`), and its pieces."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")
import cv2  # noqa: E402
import torch.nn.functional as F  # noqa: E402

from alcn_cv.data.frames import synthetic_frame  # noqa: E402
from alcn_cv.enhance.alcn import ALCN  # noqa: E402
from alcn_cv.filters.gaussian_mixture import alcn_filter, alcn_filter_grid, upsample_grid  # noqa: E402
from alcn_cv.nets.gain import GainNormalizer  # noqa: E402
from alcn_cv.weight_file import save_normalizer_file  # noqa: E402


def _forward(net: torch.nn.Module, gray: np.ndarray) -> np.ndarray:
    with torch.inference_mode():
        return net(torch.from_numpy(gray)[None, None])[0, 0].numpy()


def _images() -> list[np.ndarray]:
    rng = np.random.default_rng(2)
    frames = [
        synthetic_frame(320, 200, False, seed=5),
        synthetic_frame(333, 251, False, seed=6),
        (rng.random((61, 47)) * 255).astype(np.uint8),
        np.full((40, 56), 90, np.uint8),
    ]
    return [f.astype(np.float32) / np.float32(255) for f in frames]


@pytest.mark.parametrize("backend", ["fast", "opencv"])
def test_shipped_gain_model_equals_the_torch_model(backend):
    alcn = ALCN(model="gain", backend=backend)
    assert alcn.mixture == "exact"
    reference = ALCN(model="gain", backend="fast").net  # the torch model of the same weight file
    for gray in _images():
        np.testing.assert_allclose(alcn.normalize(gray), _forward(reference, gray), atol=1e-3, rtol=0)


def test_gain_model_on_a_photograph(shared_data):
    photo = cv2.imread(str(shared_data / "cookie_box" / "resized_IMG_3875.JPG"), cv2.IMREAD_GRAYSCALE)
    if photo is None:
        pytest.skip("the cookie-box photograph is not in the shared data")
    gray = photo.astype(np.float32) / np.float32(255)
    alcn = ALCN(model="gain", backend="fast")  # .net: the torch model
    np.testing.assert_allclose(alcn.normalize(gray), _forward(alcn.net, gray), atol=1e-3, rtol=0)
    # apply's uint8 output: the forward's output range mapped to [0, 255] and rounded, within a level
    lo, hi = alcn.output_range
    expected = np.rint(np.clip((_forward(alcn.net, gray) - lo) / (hi - lo), 0, 1) * 255)
    assert np.abs(alcn.apply(photo).astype(np.float64) - expected).max() <= 1


@pytest.mark.parametrize("config", [{"stride": 4, "dilations": (1, 2)}, {"num_kernels": 4}, {"tau": 2.0}])
def test_other_gain_configurations_equal_the_torch_model(tmp_path, config):
    torch.manual_seed(0)
    net = GainNormalizer(**config)
    with torch.no_grad():
        for p in net.parameters():
            p.add_(0.1 * torch.randn_like(p))
    path = save_normalizer_file(tmp_path / "gain.npz", net.state_arrays(), net.file_meta(trained=True))
    alcn = ALCN(weights=path)
    for gray in _images()[:3]:
        np.testing.assert_allclose(alcn.normalize(gray), _forward(net, gray), atol=1e-3, rtol=0)


@pytest.mark.parametrize("stride", [3, 4, 8, 24])
# (9, 2**15 + 5): wider than OpenCV's warps take (NumPy's interpolation), as the strides 3 and 24 are
@pytest.mark.parametrize("shape", [(800, 1280), (17, 9), (1, 1), (8, 16), (9, 17), (9, 2**15 + 5)])
def test_upsample_grid_is_align_corners_bilinear(stride, shape):
    """torch's ``align_corners=True`` interpolation, computed exactly (in float64; torch's own float32 coordinates
    are off by up to 6e-4 on 2**15 columns)."""
    h, w = shape
    gh, gw = -(-(h - 1) // stride) + 1, -(-(w - 1) // stride) + 1
    grid = np.random.default_rng(0).random((gh, gw), dtype=np.float32)
    rows, cols = np.arange(h) / stride, np.arange(w) / stride
    along = np.stack([np.interp(cols, np.arange(gw), g) for g in grid.astype(np.float64)])
    expected = np.stack([np.interp(rows, np.arange(gh), c) for c in along.T], axis=1)
    np.testing.assert_allclose(upsample_grid(grid, stride, shape), expected, atol=1e-6, rtol=0)
    if shape == (17, 9):  # the reference is torch's
        size = (stride * (gh - 1) + 1, stride * (gw - 1) + 1)
        torch_grid = torch.from_numpy(grid)[None, None]
        by_torch = F.interpolate(torch_grid, size=size, mode="bilinear", align_corners=True)[0, 0, :h, :w]
        np.testing.assert_allclose(expected, by_torch.numpy(), atol=1e-6, rtol=0)


@pytest.mark.parametrize("stride", [4, 3])  # OpenCV's warp, and NumPy's interpolation
def test_upsample_grid_refuses_a_grid_one_point_short(stride):
    """A grid must reach the last row and column (``stride * (g - 1) >= side - 1``); one a point short was
    extended silently by the warp's replicated border, the maps' last pixels a copy instead of an error."""
    from alcn_cv import InputError

    grid = np.zeros((3, 3), np.float32)
    assert upsample_grid(grid, stride, (2 * stride + 1, 2 * stride + 1)).shape == (2 * stride + 1, 2 * stride + 1)
    for shape in [(2 * stride + 1, 2 * stride + 2), (2 * stride + 2, 2 * stride + 1)]:
        with pytest.raises(InputError, match="does not cover"):
            upsample_grid(grid, stride, shape)


@pytest.mark.parametrize("backend", ["fast", "opencv"])
def test_the_gain_model_at_another_scale_equals_the_torch_backend(backend):
    """At a working scale other than 1 the gain family runs the window runtime (its grid at the working scale,
    the maps resized to the input); the gain runtime, whose grid is the input's, put there gave outputs 0.01 off
    (three grey levels) with no error."""
    gray = synthetic_frame(128, 96, False, seed=1).astype(np.float32) * np.float32(1 / 255)
    expected = ALCN(model="gain", scale=0.5, backend="torch").normalize(gray)
    got = ALCN(model="gain", scale=0.5, backend=backend).normalize(gray)
    np.testing.assert_allclose(got, expected, atol=2e-5, rtol=0)


@pytest.mark.parametrize("proportional", [False, True])
def test_alcn_filter_grid_is_alcn_filter_of_the_upsampled_maps(proportional):
    image = np.random.default_rng(1).random((50, 70), dtype=np.float32)
    grid = np.random.default_rng(2).normal(size=(2, 8, 10)).astype(np.float32)
    if proportional:  # a band-pass of two kernels (F_2 = -F_1): one shared product
        grid[1] = -grid[0]
    maps = np.stack([upsample_grid(m, 8, image.shape) for m in grid])
    np.testing.assert_allclose(
        alcn_filter_grid(image, grid, 8, (1.0, 2.0)), alcn_filter(image, maps, (1.0, 2.0)), atol=1e-6
    )
