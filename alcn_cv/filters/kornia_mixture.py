"""Differentiable form of ALCN's Gaussian mixture, on kornia's Gaussian kernels.

Same definition as :mod:`alcn_cv.filters.gaussian_mixture` (kernels, truncation, reflect-101
borders), so both agree to 1e-5; this one lets gradients flow to the weights (and thus to the
Normalizer) during the joint training of Eq. 2. Each kernel runs at its own width, in two passes of
:mod:`alcn_cv.filters.torch_separable` (on the CPU, faster than kornia's ``filter2d_separable``, torch's
convolution).
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from kornia.filters import get_gaussian_kernel1d

from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import check_sigmas, gaussian_sigmas, kernel_radius
from alcn_cv.filters.torch_pad import reflect101_pad
from alcn_cv.filters.torch_precision import ExactBuffers
from alcn_cv.filters.torch_separable import filter_columns, filter_rows

__all__ = ["GaussianMixture2d", "gaussian_mixture2d"]


def _kernel_bank(sigmas: Sequence[float], device: torch.device, dtype: torch.dtype) -> torch.Tensor:
    """``(N, K)`` kornia Gaussian kernels, zero-padded to the widest one (``K`` odd)."""
    radii = [kernel_radius(s) for s in sigmas]
    width = 2 * max(radii) + 1
    bank = torch.zeros(len(sigmas), width, device=device, dtype=dtype)
    for i, (s, r) in enumerate(zip(sigmas, radii)):
        k = get_gaussian_kernel1d(2 * r + 1, s, device=device, dtype=dtype)
        offset = (width - (2 * r + 1)) // 2
        bank[i, offset : offset + 2 * r + 1] = k[0]
    return bank


def _blurs(x: torch.Tensor, bank: torch.Tensor, sigmas: Sequence[float]) -> list[torch.Tensor]:
    """Channel ``i`` of ``x`` ``(B, N, H, W)`` (or its one channel, for every kernel) blurred with kernel ``bank[i]``
    of ``sigmas[i]`` (reflect-101), each at its own width (the bank's zeros left out): ``N`` tensors
    ``(B, 1, H, W)``. One pad of the widest radius serves every kernel, each reading its own margin of it."""
    h, w = x.shape[-2:]
    widest = bank.shape[1] // 2
    padded = reflect101_pad(x, widest, widest, widest, widest)  # a side shorter than the kernel: as OpenCV's
    blurred = []
    for i, sigma in enumerate(sigmas):
        r = kernel_radius(sigma)
        o = widest - r
        taps = bank[i, o : o + 2 * r + 1]
        channel = padded[:, i : i + 1] if x.shape[1] > 1 else padded
        blurred.append(filter_columns(filter_rows(channel[..., o : o + h + 2 * r, o : o + w + 2 * r], taps), taps))
    return blurred


def gaussian_mixture2d(
    image: torch.Tensor, weights: torch.Tensor, sigmas: Sequence[float] | None = None
) -> torch.Tensor:
    """Differentiable ALCN Gaussian mixture on kornia's Gaussian filtering.

    Args:
        image: ``(B, 1, H, W)`` float tensor, intensities nominally in [0, 1].
        weights: ``(B, N)`` -- one weight vector per image (Eq. 1), or ``(B, N, H, W)`` --
            per-pixel maps (Eq. 3).
        sigmas: ``N`` standard deviations in pixels; default :func:`gaussian_sigmas` of ``N``.

    Returns:
        ``(B, 1, H, W)`` normalized image, same dtype and device as ``image`` (``weights`` of that dtype too).

    Example:
        >>> image, maps = torch.rand(2, 1, 32, 40), torch.rand(2, 10, 32, 40)
        >>> gaussian_mixture2d(image, maps).shape
        torch.Size([2, 1, 32, 40])
    """
    _check_shapes(image, weights)
    n = weights.shape[1]
    sigmas = gaussian_sigmas(n) if sigmas is None else check_sigmas(sigmas)
    if len(sigmas) != n:
        raise InputError(f"{n} weights for {len(sigmas)} sigmas")
    bank = _kernel_bank(sigmas, image.device, image.dtype)
    return _mix(image, weights, bank, sigmas)


def _check_shapes(image: torch.Tensor, weights: torch.Tensor) -> None:
    """An image ``(B, 1, H, W)`` and weights of the same batch, ``(B, N)`` or ``(B, N, H, W)``: a colour image would
    otherwise be blurred channel by kernel, and a batch of one broadcast, without a word."""
    if image.ndim != 4 or image.shape[1] != 1:
        raise InputError(f"image must have shape (B, 1, H, W), got {tuple(image.shape)}")
    if weights.ndim not in (2, 4) or weights.shape[0] != image.shape[0]:
        raise InputError(f"weights must have shape (B, N) or (B, N, H, W), got {tuple(weights.shape)}")


def _mix(image: torch.Tensor, weights: torch.Tensor, bank: torch.Tensor, sigmas: Sequence[float]) -> torch.Tensor:
    if weights.ndim == 2:  # Eq. 1: blur the image with every kernel once, then weigh.
        return torch.einsum("bnhw,bn->bhw", torch.cat(_blurs(image, bank, sigmas), dim=1), weights).unsqueeze(1)
    if weights.shape[2:] != image.shape[2:]:
        raise InputError(f"weight maps {tuple(weights.shape[2:])} do not match the image {tuple(image.shape[2:])}")
    return torch.cat(_blurs(weights * image, bank, sigmas), dim=1).sum(dim=1, keepdim=True)  # Eq. 3


class GaussianMixture2d(ExactBuffers):
    """Module form of :func:`gaussian_mixture2d`, with the kernel bank built once (float32, which a cast of the module
    to float16 does not round: rounded, the two kernels of a DoG move ALCN's output by 2e-3).

    Args:
        sigmas: standard deviations in pixels; default :func:`gaussian_sigmas` ``(i / 2, i = 1..10)``.

    Shape:
        - image: ``(B, 1, H, W)``; weights: ``(B, N)`` or ``(B, N, H, W)``, both of one float dtype
        - output: ``(B, 1, H, W)``, that dtype

    Example:
        >>> mixture = GaussianMixture2d([1.0, 2.0])
        >>> mixture(torch.rand(1, 1, 16, 16), torch.tensor([[1.0, -1.0]])).shape  # a DoG
        torch.Size([1, 1, 16, 16])
    """

    exact_buffers = ("bank",)

    def __init__(self, sigmas: Sequence[float] | None = None) -> None:
        super().__init__()
        self.sigmas = gaussian_sigmas() if sigmas is None else check_sigmas(sigmas)
        self.register_buffer("bank", _kernel_bank(self.sigmas, torch.device("cpu"), torch.float32), persistent=False)

    @property
    def num_kernels(self) -> int:
        return len(self.sigmas)

    def _bank(self, x: torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
        """The kernels in ``dtype`` on ``x``'s device, made again for a dtype of more precision than the bank's
        (float64)."""
        if torch.finfo(self.bank.dtype).eps <= torch.finfo(dtype).eps:
            return self.bank.to(dtype)
        with torch.inference_mode(False):  # as gaussian_blur's cached kernels: a backward may follow
            return _kernel_bank(self.sigmas, x.device, dtype)

    def forward(self, image: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        _check_shapes(image, weights)
        if weights.shape[1] != self.num_kernels:
            raise InputError(f"{weights.shape[1]} weights for {self.num_kernels} kernels")
        return _mix(image, weights, self._bank(image, torch.promote_types(image.dtype, weights.dtype)), self.sigmas)

    def difference(self, product: torch.Tensor) -> torch.Tensor:
        """Eq. 3 of two kernels whose maps are ``F`` and ``-F`` (the gain Normalizer's, :mod:`alcn_cv.nets.gain`):
        ``G_1 * P - G_2 * P`` of the one product ``P = F o I`` ``(B, 1, H, W)`` -> ``(B, 1, H, W)``, half the
        products and pads of :meth:`forward` with both maps.

        Example:
            >>> mixture, image, f = GaussianMixture2d((1.0, 2.0)), torch.rand(1, 1, 32, 32), torch.rand(1, 1, 32, 32)
            >>> torch.allclose(mixture.difference(f * image), mixture(image, torch.cat([f, -f], dim=1)))
            True
        """
        if self.num_kernels != 2 or product.ndim != 4 or product.shape[1] != 1:
            raise InputError(
                f"difference takes a (B, 1, H, W) product and a mixture of two kernels, got {tuple(product.shape)} "
                f"and {self.num_kernels} kernels"
            )
        first, second = _blurs(product, self._bank(product, product.dtype), self.sigmas)
        return first - second

    def extra_repr(self) -> str:
        return f"sigmas={self.sigmas}"
