"""The gain Normalizer (alcn_cv.nets.gain): shapes, its untrained form, gradients, weight files."""

import numpy as np
import pytest
import torch

from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters import gaussian_blur_stack
from alcn_cv.filters.divisive import divisive_normalization
from alcn_cv.filters.gaussian_mixture import gaussian_sigmas
from alcn_cv.nets.gain import ARCHITECTURE, GainNormalizer, contrast_equalization, dog_weights
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file


def _lit_texture(h=72, w=88, seed=0):
    """A fine texture under a smooth light falling off by 10x across the image: (1, 1, h, w)."""
    rng = np.random.default_rng(seed)
    texture = 0.5 + 0.4 * rng.random((h, w))
    light = np.exp(np.linspace(0.0, np.log(0.1), w))[None, :] * np.ones((h, 1))
    return torch.from_numpy((texture * light).astype(np.float32))[None, None]


def test_shapes_follow_alcn_grid_convention():
    net = GainNormalizer(num_kernels=10, sigma_step=0.5)
    image = torch.rand(2, 1, 37, 53)
    assert net.dense_grid(image).shape == (2, 10, 6, 8)  # ceil(36/8)+1, ceil(52/8)+1
    assert net.dense_grid(image, 16).shape == (2, 10, 4, 5)
    fits = torch.rand(1, 1, 33, 49)  # both grids end on the last pixel: the coarse one is every other point
    torch.testing.assert_close(net.dense_grid(fits, 16), net.dense_grid(fits)[..., ::2, ::2])
    assert net.dense(image).shape == (2, 10, 37, 53)
    out = net(image)
    assert out.shape == (2, 1, 37, 53) and out.abs().max() < 1
    assert net.features(image).shape == (2, 4, 6, 8)
    tiny = net.dense_grid(torch.rand(1, 1, 3, 2))  # smaller than the cells and the blurs
    assert tiny.shape == (1, 10, 2, 2) and torch.isfinite(tiny).all()


def test_maps_on_the_grid_equal_dense_there():
    net = GainNormalizer()
    image = torch.rand(1, 1, 33, 41)
    torch.testing.assert_close(net.dense(image)[..., ::8, ::8], net.dense_grid(image))


def test_bad_inputs_are_rejected():
    net = GainNormalizer()
    with pytest.raises(InputError):
        net.dense_grid(torch.rand(1, 2, 16, 16))
    with pytest.raises(InputError):
        net.dense_grid(torch.rand(1, 1, 16, 16), 12)
    with pytest.raises(InputError):
        GainNormalizer(num_kernels=2, sigma_step=0.5)  # the DoG 1/2 needs sigma 2 in the basis
    with pytest.raises(InputError):
        dog_weights((0.5, 1.0))
    assert dog_weights(gaussian_sigmas(4, 0.1), 0.1, 0.3) == [1.0, 0.0, -1.0, 0.0]  # 3 * 0.1 is not 0.3


@pytest.mark.parametrize("num_kernels, sigma_step", [(2, 1.0), (10, 0.5)])
def test_untrained_model_is_the_dog(num_kernels, sigma_step):
    net = GainNormalizer(num_kernels=num_kernels, sigma_step=sigma_step).eval()
    image = _lit_texture()
    with torch.no_grad():
        grid = net.dense_grid(image)
        response = net.response(image)[0, 0].numpy()
    torch.testing.assert_close(grid, torch.tensor(dog_weights(net.sigmas)).view(1, -1, 1, 1).expand_as(grid))
    centre, surround = gaussian_blur_stack(np.ascontiguousarray(image[0, 0].numpy()), (1.0, 2.0))
    np.testing.assert_allclose(response, centre - surround, atol=1e-5)


def test_local_mean_of_a_constant_image_is_the_constant():
    net = GainNormalizer()
    local = net.features(torch.full((1, 1, 40, 56), 0.3))[:, 1].exp() - net.eps
    torch.testing.assert_close(local, torch.full_like(local, 0.3))


def test_untrained_response_ignores_the_light_strength():
    net = GainNormalizer(eps=1e-6).eval()
    image = _lit_texture()
    with torch.no_grad():
        torch.testing.assert_close(net(0.05 * image), net(image), atol=1e-2, rtol=0)  # but for the absolute floor


def test_gradients_reach_every_parameter():
    net = GainNormalizer(learn_scales=True)
    with torch.no_grad():
        net.head.weight.normal_(0.0, 0.01)  # a zero last layer blocks the gradient to the layers below it
    net(_lit_texture()).square().mean().backward()
    for name, p in net.named_parameters():
        assert p.grad is not None and torch.isfinite(p.grad).all() and p.grad.abs().sum() > 0, name


def test_weight_file_round_trip(tmp_path):
    net = GainNormalizer(channels=8, dilations=(1, 2))
    with torch.no_grad():
        for p in net.parameters():
            p.add_(0.01 * torch.randn_like(p))
    path = save_normalizer_file(tmp_path / "gain.npz", net.state_arrays(), net.file_meta(trained=True))
    weight_file = load_normalizer_file(path)
    assert weight_file.meta["architecture"] == ARCHITECTURE and weight_file.meta["output_range"] == [-1.15, 1.15]
    loaded = GainNormalizer.from_file(weight_file)
    image = _lit_texture()
    with torch.no_grad():
        torch.testing.assert_close(loaded(image), net(image))


def test_contrast_equalization_numpy_and_torch_agree():
    x = np.linspace(-5, 5, 11, dtype=np.float32)
    out = contrast_equalization(x, 2.0)
    assert out.dtype == np.float32 and np.all(np.abs(out) < 1)
    np.testing.assert_allclose(out, contrast_equalization(torch.from_numpy(x), 2.0).numpy(), atol=1e-6)


def test_shipped_gain_model_through_create_alcn():
    """``createALCN(model="gain")``: the shipped weights, the exact mixture equal to the torch
    model's equalized output plus its wide band, outputs in (-1.15, 1.15) whatever the light's strength, and the
    cv2.dnn backend (its ONNX export) equal to the fast one."""
    import alcn_cv

    alcn = alcn_cv.createALCN(model="gain", mixture="exact", backend="fast")  # .net: the torch model
    assert alcn.trained and alcn.equalization_tau is not None and alcn.output_range == (-1.15, 1.15)
    image = _lit_texture(96, 120)
    out = alcn.normalize(image[0, 0].numpy())
    with torch.inference_mode():
        expected = alcn.net(image)[0, 0].numpy()
    np.testing.assert_allclose(out, expected, atol=2e-3)
    assert np.abs(out).max() < alcn.output_range[1]
    # The gain follows the light down to a few grey levels (the darkest pixels here are 0.025,
    # 6 levels); below that the trained model no longer amplifies what is mostly noise.
    darker = alcn.normalize(image[0, 0].numpy() * 0.5)
    assert np.corrcoef(out.ravel(), darker.ravel())[0, 1] > 0.9
    windows = alcn.normalize_windows(np.clip(image[0, :, :64, :64].numpy(), 0, 1))
    assert windows.shape == (1, 64, 64) and np.abs(windows).max() < alcn.output_range[1]
    fast = alcn_cv.createALCN(model="gain", backend="fast").normalize(image[0, 0].numpy())
    np.testing.assert_allclose(
        alcn_cv.createALCN(model="gain", backend="opencv").normalize(image[0, 0].numpy()), fast, atol=1e-4, rtol=0
    )


def test_gain_windows_are_normalized_as_small_images_and_the_lite_ones_by_eq1():
    import alcn_cv

    windows = np.clip(
        _lit_texture(64, 64)[0].numpy().repeat(2, axis=0) * np.array([1.0, 0.3], np.float32)[:, None, None], 0, 1
    )
    gain = alcn_cv.createALCN(model="gain")
    assert gain.spec.per_pixel and not alcn_cv.createALCN(model="lite").spec.per_pixel
    np.testing.assert_array_equal(gain.normalize_windows(windows), np.stack([gain.normalize(w) for w in windows]))
    # Eq. 1: the weights the torch network predicts for each window's central 48x48 (at the working scale), applied
    # to the whole window; the runtime under test runs the network by cv2.dnn
    from alcn_cv.filters.gaussian_mixture import alcn_filter
    from alcn_cv.nn import ALCN2d

    lite = alcn_cv.createALCN(model="lite")
    windows = np.clip(
        _lit_texture(96, 96)[0].numpy().repeat(2, axis=0) * np.array([1.0, 0.3], np.float32)[:, None, None], 0, 1
    )
    net = ALCN2d(model="lite").net
    centre = net.window // 2 // net.stride
    for window, out in zip(windows, lite.normalize_windows(windows)):
        small = lite.spec.working_image(window)
        o = (small.shape[0] - net.window) // 2
        with torch.no_grad():
            crop = torch.from_numpy(np.ascontiguousarray(small[o : o + net.window, o : o + net.window]))[None, None]
            weights = net.dense_grid(crop)[0, :, centre, centre].numpy()
        np.testing.assert_allclose(out, alcn_filter(window, weights, lite.spec.full_res_sigmas), atol=1e-4, rtol=0)
        assert np.abs(out - lite.normalize(window)).max() > 3e-4  # not the per-pixel Eq. 3 of the window


def test_divisive_floor_keeps_a_flat_region_flat():
    image = np.full((64, 128), 0.5, np.float32)
    image[:, :64] += 0.2 * np.random.default_rng(0).standard_normal((64, 64)).astype(np.float32)
    image[:, 64:] += 0.002 * np.random.default_rng(1).standard_normal((64, 64)).astype(np.float32)
    net = GainNormalizer()
    with torch.no_grad():
        out = net(torch.from_numpy(image)[None, None])[0, 0].numpy()
    assert out[8:-8, 80:-8].std() < 0.1 * out[8:-8, 8:56].std()  # without the floor: about equal


def test_per_pixel_divisive_numpy_and_torch_agree_and_ignore_the_light_strength():
    rng = np.random.default_rng(5)
    image = gaussian_blur_stack(rng.random((75, 93)).astype(np.float32), (1.5,))[0]
    net = GainNormalizer(floor_scale=0.5)
    with torch.no_grad():
        response = net.response(torch.from_numpy(image)[None, None])
        divided = net.divide(response)[0, 0].numpy()
        brighter = net.divide(10.0 * response)[0, 0].numpy()
        darker = net.divide(net.response(torch.from_numpy(0.1 * image)[None, None]))[0, 0].numpy()
    np.testing.assert_allclose(divisive_normalization(response[0, 0].numpy(), 2.0, 0.5), divided, atol=1e-5)
    np.testing.assert_allclose(brighter, divided, atol=1e-3)  # a gain of the response: exact but for the absolute floor
    np.testing.assert_allclose(darker, divided, atol=1e-2)
    assert np.abs(divided).max() > 0.5


def test_a_config_the_network_refuses_is_a_weight_file_error(tmp_path):
    import alcn_cv

    with pytest.raises(InputError):
        GainNormalizer(divisive_sigma=0.0)
    net = GainNormalizer()
    for name, config in (("unknown", {"gain": "weber"}), ("refused", {"divisive_sigma": 0.0})):
        meta = net.file_meta(trained=True)
        meta["config"] = {**meta["config"], **config}
        path = save_normalizer_file(tmp_path / f"{name}.npz", net.state_arrays(), meta)
        with pytest.raises(WeightFileError, match="weights do not fit"):
            GainNormalizer.from_file(load_normalizer_file(path))
        for backend in ("fast", "torch"):
            with pytest.raises(WeightFileError, match="weights do not fit"):
                alcn_cv.createALCN(weights=path, backend=backend)


def test_defaults_are_the_shipped_model():
    from alcn_cv.runtime import MODELS

    assert GainNormalizer().config == load_normalizer_file(MODELS["gain"]).meta["config"]


def test_per_pixel_divisive_weight_file_round_trip_through_create_alcn(tmp_path):
    from alcn_cv.enhance.alcn import ALCN

    net = GainNormalizer(floor_scale=0.8, tau=2.0)
    path = save_normalizer_file(tmp_path / "d.npz", net.state_arrays(), net.file_meta(trained=True))
    weight_file = load_normalizer_file(path)
    assert weight_file.meta["divisive"] == {"scale": pytest.approx(0.8), "sigma": 2.0}
    assert weight_file.meta["equalization"] == {"tau": pytest.approx(2.0)}
    assert GainNormalizer.from_file(weight_file).divisive_sigma == 2.0
    image = gaussian_blur_stack(np.random.default_rng(4).random((90, 110)).astype(np.float32), (1.0,))[0]
    with torch.no_grad():
        expected = net(torch.from_numpy(image)[None, None])[0, 0].numpy()
    for backend in ("torch", "fast"):
        np.testing.assert_allclose(ALCN(weights=path, backend=backend).normalize(image), expected, atol=1e-4)
    assert ALCN(weights=path, scale=0.5).spec.divisive == (4.0, pytest.approx(0.8))
    assert ALCN(model="gain").spec.divisive == (2.0, 1.0)  # the shipped file: the per-pixel energy
