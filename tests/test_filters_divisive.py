"""The divisive normalization's two forms: NumPy/OpenCV (alcn_cv.filters.divisive) and torch (torch_divisive)."""

import cv2
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from alcn_cv.filters import (
    divisive,
    torch_divisive,
)


def _response(h=57, w=83, seed=0):
    rng = np.random.default_rng(seed)
    return (rng.standard_normal((h, w)) * np.linspace(0.01, 1.0, w)[None, :]).astype(np.float32)


def test_gaussian_energy_numpy_and_torch_agree():
    r = _response()
    expected = divisive.gaussian_energy(r, 2.0)
    np.testing.assert_allclose(
        torch_divisive.gaussian_energy(torch.from_numpy(r)[None, None], 2.0)[0, 0].numpy(),
        expected,
        rtol=1e-5,
        atol=1e-7,
    )


@pytest.mark.parametrize("floor, multiplier", [(None, 1.0), (0.05, 1.0), (None, 1 / 3)])
def test_divisive_normalization_numpy_and_torch_agree(floor, multiplier):
    r = _response(seed=1)
    expected = divisive.divisive_normalization(r, 2.0, 0.7, floor=floor, multiplier=multiplier)
    floor_tensor = None if floor is None else torch.full((1, 1, 1, 1), floor)
    got = torch_divisive.divisive_normalization(torch.from_numpy(r)[None, None], 2.0, 0.7, floor_tensor, multiplier)
    np.testing.assert_allclose(got[0, 0].numpy(), expected, rtol=1e-5, atol=1e-6)
    module = torch_divisive.DivisiveNormalization2d(2.0, 0.7)
    if multiplier == 1.0:
        torch.testing.assert_close(module(torch.from_numpy(r)[None, None], floor_tensor), got)


def test_torch_with_and_without_a_gradient_agree():
    """Without a gradient asked for, the divisor is computed in place: the same numbers, the response untouched."""
    r = torch.from_numpy(_response(seed=3))[None, None]
    before = r.clone()
    with torch.no_grad():
        in_place = torch_divisive.divisive_normalization(r, 2.0, 0.7, multiplier=1 / 3)
    assert torch.equal(r, before)
    leaf = r.clone().requires_grad_(True)
    with_graph = torch_divisive.divisive_normalization(leaf, 2.0, 0.7, multiplier=1 / 3)
    assert with_graph.requires_grad
    torch.testing.assert_close(with_graph.detach(), in_place, atol=0, rtol=0)
    scale = torch.tensor(0.7, requires_grad=True)  # a learnable floor scale asks for the graph too
    with_graph = torch_divisive.divisive_normalization(r, 2.0, scale, multiplier=1 / 3)
    with_graph.sum().backward()
    assert scale.grad is not None


def test_invariant_to_a_gain_of_the_response():
    r = _response(seed=2)
    np.testing.assert_allclose(
        divisive.divisive_normalization(8 * r, 2.0, 1.0), divisive.divisive_normalization(r, 2.0, 1.0), atol=1e-3
    )


def test_blur_pads_reflect_101_for_any_size():
    """The pad of one pass (smaller than the side) and the ONNX-friendly index form give the same values."""
    x = torch.rand(1, 1, 3, 5)
    small = torch_divisive.reflect101_pad(x, 2, 2, 2, 2)
    torch.testing.assert_close(small, torch.nn.functional.pad(x, (2, 2, 2, 2), mode="reflect"))
    tiny = torch_divisive.reflect101_pad(x, 4, 4, 4, 4)  # the reflection repeats
    assert tiny.shape == (1, 1, 11, 13)
    torch.testing.assert_close(tiny[..., 4:7, 4:9], x)
    # the repeated reflection itself, as OpenCV pads (not edge replication, not one reflection)
    np.testing.assert_array_equal(
        tiny[0, 0].numpy(), cv2.copyMakeBorder(x[0, 0].numpy(), 4, 4, 4, 4, cv2.BORDER_REFLECT_101)
    )
    r = _response(2, 3, seed=3)
    blurred = torch_divisive.gaussian_blur(torch.from_numpy(r)[None, None], 2.0)[0, 0].numpy()
    assert blurred.shape == (2, 3) and np.isfinite(blurred).all()
    # a blur longer than the 2x3 side: the torch energy is the NumPy/OpenCV one
    np.testing.assert_allclose(
        torch_divisive.gaussian_energy(torch.from_numpy(r)[None, None], 2.0)[0, 0].numpy(),
        divisive.gaussian_energy(r, 2.0),
        atol=1e-6,
    )
