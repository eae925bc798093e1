"""alcn_cv.filters.torch_resize: the grid's and the blocks' bilinear upsampling against F.interpolate, the area
downsampling against cv2.INTER_AREA."""

import pytest

torch = pytest.importorskip("torch")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import torch.nn.functional as F  # noqa: E402

from alcn_cv.errors import InputError  # noqa: E402
from alcn_cv.filters.torch_resize import area_downsample, interpolate_grid, upsample_blocks  # noqa: E402


def _same_values_and_gradients(ours, reference, source):
    torch.testing.assert_close(ours, reference, atol=1e-12, rtol=0)
    (grad,) = torch.autograd.grad(ours.sum(), source)
    (expected,) = torch.autograd.grad(reference.sum(), source)
    torch.testing.assert_close(grad, expected)


@pytest.mark.parametrize(
    "grid_shape, stride, shape",
    [((101, 161), 8, (800, 1280)), ((5, 6), 8, (33, 40)), ((7, 9), 4, (25, 30)), ((2, 2), 8, (8, 9))],
)
def test_interpolate_grid_is_bilinear_with_the_grid_on_pixels(grid_shape, stride, shape):
    """torch's bilinear interpolation with aligned corners, cropped (a last row or column where the grid ends
    on the image's last pixel); differentiable, in the grid's dtype."""
    grid = torch.rand(2, 3, *grid_shape, dtype=torch.float64, requires_grad=True)
    size = tuple(stride * (g - 1) + 1 for g in grid_shape)
    reference = F.interpolate(grid, size=size, mode="bilinear", align_corners=True)[..., : shape[0], : shape[1]]
    out = interpolate_grid(grid, stride, shape)
    assert out.shape == (2, 3, *shape)
    _same_values_and_gradients(out, reference, grid)
    assert interpolate_grid(grid.detach().to(torch.bfloat16), stride, shape).dtype == torch.bfloat16


@pytest.mark.parametrize("small_shape, shape", [((200, 320), (800, 1280)), ((5, 7), (18, 27)), ((1, 3), (4, 9))])
def test_upsample_blocks_is_bilinear_with_pixel_centres(small_shape, shape):
    """torch's bilinear interpolation without aligned corners (the edges held), cropped."""
    small = torch.rand(2, 1, *small_shape, dtype=torch.float64, requires_grad=True)
    reference = F.interpolate(small, scale_factor=4, mode="bilinear", align_corners=False)[..., : shape[0], : shape[1]]
    out = upsample_blocks(small, 4, shape)
    assert out.shape == (2, 1, *shape)
    _same_values_and_gradients(out, reference, small)


@pytest.mark.parametrize(
    "shape, size",
    [((187, 253), (94, 126)), ((37, 53), (18, 26)), ((31, 31), (16, 16)), ((101, 99), (37, 37)), ((64, 80), (32, 40))],
)
def test_area_downsample_is_opencvs_inter_area(shape, size):
    """OpenCV's weights for any factor (torch's mode="area" differs where the sides are not multiples of it);
    differentiable: the gradient of the sum is each source pixel's total weight."""
    image = np.random.default_rng(0).random(shape).astype(np.float32)
    reference = cv2.resize(image, size[::-1], interpolation=cv2.INTER_AREA)
    x = torch.from_numpy(image)[None, None].requires_grad_()
    out = area_downsample(x, size)
    assert out.shape == (1, 1, *size) and out.dtype == torch.float32
    np.testing.assert_allclose(out.detach()[0, 0].numpy(), reference, atol=3e-7, rtol=0)
    if size[0] * 2 != shape[0] or size[1] * 2 != shape[1]:
        assert np.abs(F.interpolate(x, size=size, mode="area").detach()[0, 0].numpy() - reference).max() > 1e-3
    (grad,) = torch.autograd.grad(out.sum(), x)
    ones = cv2.resize(np.ones(shape, np.float32), size[::-1], interpolation=cv2.INTER_AREA)
    np.testing.assert_allclose(grad.sum().item(), ones.sum(), rtol=1e-5)


def test_too_small_inputs_are_clear_errors():
    with pytest.raises(InputError, match="does not cover"):
        interpolate_grid(torch.rand(1, 1, 3, 3), 4, (10, 8))
    with pytest.raises(InputError, match="do not cover"):
        upsample_blocks(torch.rand(1, 1, 3, 3), 4, (13, 8))
    with pytest.raises(InputError, match="makes images smaller"):
        area_downsample(torch.rand(1, 1, 3, 3), (4, 2))
