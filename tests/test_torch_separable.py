"""alcn_cv.filters.torch_separable: the grouped passes give torch's convolution, values and gradients."""

import pytest
import torch
import torch.nn.functional as F
from kornia.filters import filter2d_separable

from alcn_cv.filters import torch_separable
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d
from alcn_cv.filters.kornia_mixture import _blurs, _kernel_bank
from alcn_cv.filters.torch_separable import filter_columns, filter_rows


def _conv(x: torch.Tensor, kernel: torch.Tensor, shape: tuple[int, int]) -> torch.Tensor:
    b, c, h, w = x.shape
    out = F.conv2d(x.reshape(b * c, 1, h, w), kernel.view(1, 1, *shape))
    return out.view(b, c, *out.shape[-2:])


@pytest.mark.parametrize("shape", [(1, 1, 64, 96), (2, 3, 37, 53), (4, 2, 20, 17)])
@pytest.mark.parametrize("sigma", [0.5, 2.0])
def test_passes_equal_the_convolution_with_gradients(shape, sigma):
    torch.manual_seed(0)
    kernel = torch.as_tensor(gaussian_kernel1d(sigma), dtype=torch.float32)
    k = kernel.numel()
    x = torch.randn(*shape, requires_grad=True)
    for grouped, plain in (
        (filter_columns(x, kernel), _conv(x, kernel, (k, 1))),
        (filter_rows(x, kernel), _conv(x, kernel, (1, k))),
    ):
        assert grouped.shape == plain.shape
        torch.testing.assert_close(grouped, plain, atol=1e-6, rtol=0)
        seed = torch.randn_like(plain)
        (g_grouped,) = torch.autograd.grad((grouped * seed).sum(), x)
        (g_plain,) = torch.autograd.grad((plain * seed).sum(), x)
        torch.testing.assert_close(g_grouped, g_plain, atol=1e-6, rtol=0)


def test_float16_and_float64_take_their_own_paths():
    kernel = torch.as_tensor(gaussian_kernel1d(1.0))
    for dtype in (torch.float16, torch.float64, torch.bfloat16):
        x = torch.rand(1, 1, 40, 48, dtype=dtype)
        k = kernel.to(dtype)
        assert filter_rows(filter_columns(x, k), k).dtype == dtype
        torch.testing.assert_close(filter_columns(x, k), _conv(x, k, (k.numel(), 1)))


def test_mixture_blur_equals_kornias_filter():
    sigmas = (1.0, 2.0)
    bank = _kernel_bank(sigmas, torch.device("cpu"), torch.float32)
    x = torch.rand(2, 2, 50, 70)
    kernels = bank.repeat(2, 1)
    reference = filter2d_separable(x.reshape(4, 1, 50, 70), kernels, kernels, border_type="reflect")
    torch.testing.assert_close(torch.cat(_blurs(x, bank, sigmas), 1), reference.view(2, 2, 50, 70), atol=1e-6, rtol=0)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_without_a_gradient_the_passes_are_shifted_sums_equal_to_the_convolution(dtype, monkeypatch):
    kernel = torch.as_tensor(gaussian_kernel1d(2.0), dtype=dtype)
    k = kernel.numel()
    x = torch.randn(2, 3, 41, 57, dtype=dtype)[..., 1:-1, 2:]  # a strided view, as the mixture's padded margins
    expected = (_conv(x, kernel, (k, 1)), _conv(x, kernel, (1, k)))
    convolutions, conv2d = [], F.conv2d
    monkeypatch.setattr(torch_separable.F, "conv2d", lambda *a, **kw: convolutions.append(a) or conv2d(*a, **kw))
    with torch.no_grad():
        passes = (filter_columns(x, kernel), filter_rows(x, kernel))
    assert not convolutions
    for got, want in zip(passes, expected):
        assert got.shape == want.shape and got.is_contiguous()
        torch.testing.assert_close(got, want, atol=1e-6, rtol=0)
    filter_rows(x.requires_grad_(), kernel)  # a recorded gradient: the grouped convolution
    filter_rows(x.detach().bfloat16(), kernel.bfloat16())  # bfloat16: the convolution accumulates in float32
    assert len(convolutions) == 2
