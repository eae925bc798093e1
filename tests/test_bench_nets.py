"""The deep baselines of the detection benchmark (alcn_cv.bench.deep_baselines): plain CNN and CIFAR-style ResNets."""

from __future__ import annotations

import pytest

torch = pytest.importorskip("torch")

from alcn_cv.bench.deep_baselines import CifarResNet, PlainCNN, resnet20, resnet56  # noqa: E402
from alcn_cv.errors import InputError  # noqa: E402


@pytest.mark.parametrize("depth", [1, 2, 3, 4])
def test_plain_cnn_dense_equals_windows(depth):
    torch.manual_seed(0)
    net = PlainCNN(3, depth=depth, width=4).eval()
    image = torch.rand(1, 1, 44, 52)
    with torch.no_grad():
        dense = net.dense(image)
        assert dense.shape == (1, 3, (44 - 32) // 4 + 1, (52 - 32) // 4 + 1)
        for i in range(dense.shape[2]):
            for j in range(dense.shape[3]):
                window = image[..., 4 * i : 4 * i + 32, 4 * j : 4 * j + 32]
                torch.testing.assert_close(net(window)[0], dense[0, :, i, j], atol=1e-5, rtol=1e-5)


def test_resnet_depths_and_shapes():
    def convs(net):
        return sum(isinstance(m, torch.nn.Conv2d) and m.kernel_size == (3, 3) for m in net.modules())

    # 6n + 2 weighted layers: 6n + 1 3x3 convolutions plus the linear layer
    assert convs(resnet20(2)) + 1 == 20
    assert convs(resnet56(2)) + 1 == 56
    net = resnet20(4).eval()
    with torch.no_grad():
        assert net(torch.zeros(3, 1, 32, 32)).shape == (3, 4)
        assert net.dense(torch.zeros(1, 1, 64, 72)).shape == (1, 4, 9, 11)


def test_resnet_dense_matches_window_inside():
    """On a 32x32 image (a single window) the dense score is the window score."""
    torch.manual_seed(1)
    net = CifarResNet(2, blocks=1).eval()
    image = torch.rand(1, 1, 32, 32)
    with torch.no_grad():
        torch.testing.assert_close(net.dense(image)[0, :, 0, 0], net(image)[0], atol=1e-5, rtol=1e-5)


def test_resnet_with_context_classifies_the_centre_as_dense_pools_it():
    """Trained with context, forward on a 64x64 input scores its central 32x32 window exactly as
    the dense run over that input scores the window at (16, 16); the context changes the score."""
    torch.manual_seed(2)
    net = CifarResNet(3, blocks=1, context=16).eval()
    assert net.input_size == 64 and net.config["context"] == 16
    image = torch.rand(2, 1, 64, 64)
    with torch.no_grad():
        dense = net.dense(image)
        assert dense.shape == (2, 3, 9, 9)
        torch.testing.assert_close(dense[:, :, 4, 4], net(image), atol=1e-5, rtol=1e-5)
        other = image.clone()
        other[..., :8, :] = 0  # outside the centre 32x32
        assert not torch.allclose(net(other), net(image))
    with pytest.raises(InputError, match="64"):
        net(torch.zeros(1, 1, 32, 32))
    with pytest.raises(InputError, match="multiple of 4"):
        CifarResNet(3, context=6)


def test_bad_arguments():
    with pytest.raises(InputError):
        PlainCNN(1)
    with pytest.raises(InputError):
        PlainCNN(3, depth=5)
    with pytest.raises(InputError):
        CifarResNet(3, blocks=0)
    with pytest.raises(InputError):
        resnet20(3)(torch.zeros(1, 1, 28, 28))
