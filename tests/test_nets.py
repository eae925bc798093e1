"""The Normalizer and Detector networks (Sec. 3.3, 4.2)."""

import numpy as np
import pytest
import torch

from alcn_cv import InputError, WeightFileError
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.nets import Detector, Normalizer
from alcn_cv.nets.normalizer import check_grid_stride
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file


@pytest.fixture(scope="module")
def net():
    torch.manual_seed(0)
    # Random, non-trivial head so that windows give different outputs.
    return Normalizer(output_scale=3.0).eval()


def test_window_shapes(net):
    assert net(torch.rand(5, 1, 48, 48)).shape == (5, 10)
    with pytest.raises(InputError):
        net(torch.rand(5, 1, 32, 32))


def test_reflect101_pad_matches_opencv():
    import cv2

    x = np.random.default_rng(1).random((7, 5), dtype=np.float32)
    for pads in [(2, 3, 1, 4), (10, 12, 9, 20)]:  # also pads larger than the image
        ours = reflect101_pad(torch.from_numpy(x), *pads).numpy()
        ref = cv2.copyMakeBorder(x, *pads, cv2.BORDER_REFLECT_101)
        np.testing.assert_array_equal(ours, ref)


@pytest.mark.parametrize("shape", [(70, 90), (61, 77)])
def test_dense_equals_window_at_grid_pixels(net, shape):
    rng = np.random.default_rng(2)
    image = torch.from_numpy(rng.random(shape, dtype=np.float32))[None, None]
    with torch.no_grad():
        dense = net.dense(image)[0]
        assert dense.shape == (10,) + shape
        padded = reflect101_pad(image, 24, 24, 24, 24)
        checked = 0
        for y in range(24, shape[0] - 24, 4):
            for x in range(24, shape[1] - 24, 4):
                window = padded[..., y : y + 48, x : x + 48]  # rows y-24..y+23 of the image
                np.testing.assert_allclose(dense[:, y, x], net(window)[0], atol=1e-4)
                checked += 1
    assert checked >= 4


def test_dense_interpolates_between_grid_pixels(net):
    image = torch.rand(1, 1, 40, 40)
    with torch.no_grad():
        dense = net.dense(image)[0]
    np.testing.assert_allclose(dense[:, 2, 0], (dense[:, 0, 0] + dense[:, 4, 0]) / 2, atol=1e-5)


def test_dense_tiny_image(net):
    assert net.dense(torch.rand(1, 1, 1, 3)).shape == (1, 10, 1, 3)


def test_init_weights_make_a_fixed_filter():
    w = [1.0, 0, -1.0] + [0] * 7
    net = Normalizer(init_weights=w, output_scale=5.0)
    out = net(torch.rand(3, 1, 48, 48))
    np.testing.assert_allclose(out.detach().numpy(), np.tile(w, (3, 1)), atol=1e-6)
    with pytest.raises(InputError):
        Normalizer(init_weights=[1.0, 2.0])


def test_detector_shapes():
    det = Detector(num_classes=4)
    assert det(torch.rand(6, 1, 32, 32)).shape == (6, 4)
    assert det.dense(torch.rand(1, 1, 64, 48)).shape == (1, 4, 9, 5)
    with pytest.raises(InputError):
        Detector(num_classes=1)
    with pytest.raises(InputError):
        det(torch.rand(2, 1, 48, 48))


def test_detector_dense_equals_windows():
    torch.manual_seed(0)
    det = Detector(num_classes=3).eval()
    image = torch.rand(1, 1, 44, 52)
    with torch.no_grad():
        dense = det.dense(image)[0]
        np.testing.assert_allclose(dense[:, 2, 3], det(image[..., 8:40, 12:44])[0], atol=1e-5)


def test_weight_file_round_trip(tmp_path, net):
    meta = {
        "config": net.config,
        "sigmas": [i / 2 for i in range(1, 11)],
        "working_scale": 0.5,
        "output_range": [-1.0, 1.0],
        "trained": False,
    }
    path = save_normalizer_file(tmp_path / "w.npz", net.state_arrays(), meta)
    again = Normalizer.from_file(load_normalizer_file(path))
    x = torch.rand(2, 1, 48, 48)
    np.testing.assert_array_equal(again(x).detach(), net(x).detach())


def test_weight_file_errors(tmp_path, net):
    with pytest.raises(WeightFileError, match="not found"):
        load_normalizer_file(tmp_path / "missing.npz")
    corrupt = tmp_path / "corrupt.npz"
    corrupt.write_bytes(b"PK\x03\x04 definitely not a zip")
    with pytest.raises(WeightFileError, match="corrupt"):
        load_normalizer_file(corrupt)
    plain = tmp_path / "plain.npz"
    np.savez(plain, a=np.zeros(3))
    with pytest.raises(WeightFileError, match="not an alcn-cv weight file"):
        load_normalizer_file(plain)
    meta = {"config": net.config, "sigmas": [0.5], "working_scale": 0.5, "output_range": [-1.0, 1.0], "trained": False}
    path = save_normalizer_file(tmp_path / "w.npz", net.state_arrays(), meta)
    import json

    header = json.loads(np.load(path)["__meta__"].item())
    header["version"] = 99
    np.savez(
        tmp_path / "v99.npz", **{k: v for k, v in net.state_arrays().items()}, __meta__=np.array(json.dumps(header))
    )
    with pytest.raises(WeightFileError, match="version 99"):
        load_normalizer_file(tmp_path / "v99.npz")
    bad_config = dict(meta, config=dict(net.config, hidden=7))
    path = save_normalizer_file(tmp_path / "bad.npz", net.state_arrays(), bad_config)
    with pytest.raises(WeightFileError, match="do not fit"):
        Normalizer.from_file(load_normalizer_file(path))


@pytest.mark.parametrize("bad", [True, 4.0, 2, 6, -4])
def test_grid_stride_must_be_a_multiple_of_the_network_stride(bad):
    with pytest.raises(InputError, match="grid_stride must be a positive multiple of 4"):
        check_grid_stride(bad, 4)


def test_grid_stride_defaults_to_the_network_stride():
    assert check_grid_stride(None, 8) == 8
    assert check_grid_stride(16, 8) == 16


def test_a_config_the_network_refuses_is_a_weight_file_error(tmp_path):
    """The constructor's InputError (a ValueError) and a malformed value (ValueError) name the weight file's fault."""
    net = Normalizer(num_kernels=1, channels=(2, 3), hidden=4)
    meta = {"config": net.config, "sigmas": [0.5], "working_scale": 0.5, "output_range": [-1.0, 1.0], "trained": False}
    for config in (dict(net.config, activation="sigmoid"), dict(net.config, channels=[2, 3, 4])):
        path = save_normalizer_file(tmp_path / "w.npz", net.state_arrays(), dict(meta, config=config))
        with pytest.raises(WeightFileError, match="do not fit"):
            Normalizer.from_file(load_normalizer_file(path))
