"""The Gaussian mixture (Eq. 1 and Eq. 3): OpenCV and kornia versions against scipy."""

import numpy as np
import pytest
import scipy.ndimage as ndi
import torch

from alcn_cv import InputError, alcn_filter, gaussian_sigmas
from alcn_cv.filters import GaussianMixture2d, gaussian_blur_stack, gaussian_kernel1d, gaussian_mixture2d, kernel_radius

SIGMAS = gaussian_sigmas()


def reference(image: np.ndarray, weights: np.ndarray, sigmas=SIGMAS) -> np.ndarray:
    """Independent computation with scipy (float64, 'mirror' = reflect-101, truncate 3)."""
    img = image.astype(np.float64)
    if weights.ndim == 1:
        return sum(w * ndi.gaussian_filter(img, s, mode="mirror", truncate=3.0) for w, s in zip(weights, sigmas))
    return sum(ndi.gaussian_filter(f * img, s, mode="mirror", truncate=3.0) for f, s in zip(weights, sigmas))


@pytest.fixture
def rng():
    return np.random.default_rng(0)


def test_basis_is_the_papers():
    assert tuple(i / 2 for i in range(1, 11)) == SIGMAS
    assert gaussian_sigmas(4, 1.0) == (1.0, 2.0, 3.0, 4.0)
    for s in SIGMAS:
        k = gaussian_kernel1d(s)
        assert len(k) == 2 * kernel_radius(s) + 1 and abs(k.sum() - 1) < 1e-12


@pytest.mark.parametrize("shape", [(48, 48), (37, 61), (120, 90)])
def test_eq1_matches_scipy(rng, shape):
    image = rng.random(shape, dtype=np.float32)
    weights = rng.normal(size=10)
    np.testing.assert_allclose(alcn_filter(image, weights), reference(image, weights), atol=1e-5)


@pytest.mark.parametrize("shape", [(48, 48), (53, 70)])
def test_eq3_matches_scipy(rng, shape):
    image = rng.random(shape, dtype=np.float32)
    maps = rng.normal(size=(10,) + shape).astype(np.float32)
    np.testing.assert_allclose(alcn_filter(image, maps), reference(image, maps), atol=1e-4)


def test_constant_maps_equal_eq1(rng):
    image = rng.random((40, 50), dtype=np.float32)
    w = rng.normal(size=10)
    maps = np.broadcast_to(w[:, None, None], (10, 40, 50))
    np.testing.assert_allclose(alcn_filter(image, maps), alcn_filter(image, w), atol=1e-5)


def test_blur_stack_matches_scipy(rng):
    image = rng.random((33, 45), dtype=np.float32)
    stack = gaussian_blur_stack(image, SIGMAS)
    for s, b in zip(SIGMAS, stack):
        np.testing.assert_allclose(
            b, ndi.gaussian_filter(image.astype(np.float64), s, mode="mirror", truncate=3.0), atol=1e-6
        )


@pytest.mark.parametrize("per_pixel", [False, True])
def test_kornia_matches_opencv_and_scipy(rng, per_pixel):
    images = rng.random((3, 1, 50, 64), dtype=np.float32)
    weights = rng.normal(size=(3, 10, 50, 64) if per_pixel else (3, 10)).astype(np.float32)
    out = gaussian_mixture2d(torch.from_numpy(images), torch.from_numpy(weights)).numpy()
    module = GaussianMixture2d()(torch.from_numpy(images), torch.from_numpy(weights)).numpy()
    np.testing.assert_array_equal(out, module)
    for b in range(3):
        fast = alcn_filter(images[b, 0], weights[b])
        np.testing.assert_allclose(out[b, 0], fast, atol=1e-4)
        np.testing.assert_allclose(out[b, 0], reference(images[b, 0], weights[b].astype(np.float64)), atol=1e-4)


def test_gradients_reach_weights_and_image():
    image = torch.rand(1, 1, 17, 18, dtype=torch.float64, requires_grad=True)
    weights = torch.randn(1, 10, 17, 18, dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(lambda i, w: gaussian_mixture2d(i, w[:, :, 8, 8]), (image, weights), fast_mode=True)
    assert torch.autograd.gradcheck(lambda i, w: gaussian_mixture2d(i, w), (image, weights), fast_mode=True)


def test_difference_is_eq3_of_opposite_maps_with_its_gradients():
    mixture = GaussianMixture2d((1.0, 2.0)).double()
    image = torch.rand(2, 1, 30, 41, dtype=torch.float64)
    f = torch.randn(2, 1, 30, 41, dtype=torch.float64, requires_grad=True)
    torch.testing.assert_close(mixture.difference(f * image), mixture(image, torch.cat([f, -f], dim=1)))
    assert torch.autograd.gradcheck(lambda m: mixture.difference(m * image), (f,), fast_mode=True)
    with pytest.raises(InputError, match="two kernels"):
        GaussianMixture2d((1.0, 2.0, 3.0)).difference(image.float())
    with pytest.raises(InputError, match="two kernels"):
        mixture.difference(torch.rand(1, 2, 30, 41, dtype=torch.float64))


def test_custom_sigmas(rng):
    image = rng.random((40, 40), dtype=np.float32)
    w = np.array([1.0, -1.0])
    np.testing.assert_allclose(alcn_filter(image, w, sigmas=(0.7, 2.2)), reference(image, w, (0.7, 2.2)), atol=1e-5)


@pytest.mark.parametrize(
    "image, weights",
    [
        (np.zeros((0, 4), np.float32), np.ones(10)),
        (np.zeros((8, 8), np.float64), np.ones(10)),
        (np.zeros((8, 8, 3), np.float32), np.ones(10)),
        (np.zeros((8, 8), np.float32), np.ones((10, 4, 4))),
        (np.zeros((8, 8), np.float32), np.array([np.nan] * 10)),
        (np.zeros((8, 8), np.float32), np.ones((2, 2))),
    ],
)
def test_bad_input(image, weights):
    with pytest.raises(InputError):
        alcn_filter(image, weights)


@pytest.mark.parametrize("shape", [(10, 10), (1, 40), (3, 2)])
def test_torch_small_images_are_mirrored_as_opencv_does(shape, rng):
    """A side shorter than the widest kernel (sigma 10 here: radius 30) repeats the reflection, as OpenCV's filters;
    it was an error."""
    image = rng.random(shape, dtype=np.float32)
    weights = rng.standard_normal(10)
    expected = alcn_filter(image, weights)
    got = gaussian_mixture2d(torch.from_numpy(image)[None, None], torch.from_numpy(weights)[None].float())
    np.testing.assert_allclose(got[0, 0].numpy(), expected, atol=1e-5)


def test_caller_array_untouched(rng):
    image = rng.random((30, 30), dtype=np.float32)
    maps = rng.normal(size=(10, 30, 30)).astype(np.float32)
    before = image.copy(), maps.copy()
    alcn_filter(image, maps)
    np.testing.assert_array_equal(image, before[0])
    np.testing.assert_array_equal(maps, before[1])


def test_module_checks_shapes_as_the_function_does():
    """GaussianMixture2d blurred channel i of a colour image with kernel i (and broadcast a batch of one) without a
    word, where gaussian_mixture2d refused."""
    mixture = GaussianMixture2d((1.0, 2.0, 3.0))
    with pytest.raises(InputError, match="image"):
        mixture(torch.rand(1, 3, 16, 16), torch.ones(1, 3))
    with pytest.raises(InputError, match="weights"):
        mixture(torch.rand(2, 1, 16, 16), torch.ones(1, 3, 16, 16))


def test_a_grid_that_does_not_cover_the_image_is_an_input_error(rng):
    """upsample_grid returned a smaller array (9x9 for 20x20), and alcn_filter_grid a cv2.error."""
    from alcn_cv.filters.gaussian_mixture import alcn_filter_grid, upsample_grid

    grid = rng.random((3, 3), dtype=np.float32)
    assert upsample_grid(grid, 4, (9, 9)).shape == (9, 9)
    with pytest.raises(InputError, match="cover"):
        upsample_grid(grid, 4, (20, 20))
    image = rng.random((20, 20), dtype=np.float32)
    with pytest.raises(InputError, match="cover"):
        alcn_filter_grid(image, np.stack([grid, -grid]), 4, (1.0, 2.0))
    maps = rng.random((2, 6, 6), dtype=np.float32)
    for rows in ((5, 3), (-1, 4), (0, 21)):
        with pytest.raises(InputError, match="rows"):
            alcn_filter_grid(image, maps, 4, (1.0, 2.0), rows=rows)


def test_a_cast_module_keeps_exact_kernels():
    """A mixture cast to float16 (with its module) keeps its float32 kernels, which a float32 image is blurred with
    and which a cast back to float32 finds unrounded: the two kernels of a DoG rounded to float16 moved ALCN's output
    by 2e-3."""
    image, maps = torch.rand(1, 1, 24, 32), torch.randn(1, 2, 24, 32)
    exact = GaussianMixture2d((1.0, 2.0))
    reference = exact(image, maps)
    mixture = GaussianMixture2d((1.0, 2.0)).half()
    assert mixture.bank.dtype == torch.float32
    torch.testing.assert_close(mixture(image, maps), reference, atol=0, rtol=0)
    torch.testing.assert_close(mixture.difference(image), exact.difference(image), atol=0, rtol=0)
    torch.testing.assert_close(mixture(image.half(), maps.half()), exact(image.half(), maps.half()), atol=0, rtol=0)
    torch.testing.assert_close(mixture.float().bank, exact.bank, atol=0, rtol=0)
