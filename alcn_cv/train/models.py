r"""The models of the joint training (Rad, Roth & Lepetit, BMVC 2017, Eq. 2).

:class:`JointModel` is the Normalizer ``f`` (or a fixed filter), the Gaussian mixture and the
detector ``g`` of::

    min_{Theta, Phi}  sum_j  -log p( y_j | g_Phi( ALCN(I_j; f_Theta(I_j)) ) )         (Eq. 2)

where ``ALCN(I; w) = (sum_i w_i G_{sigma_i}) * I`` (Eq. 1) is differentiable in ``w``, so the
gradient reaches ``Theta``. Only the centre 32x32 of the mixture is needed and the image needs no
gradient, so :class:`CentreMixture` blurs just that centre with each kernel's own width (no
padding: the 64x64 window holds every tap) and weighs the blurs; it equals the centre of
:class:`~alcn_cv.filters.kornia_mixture.GaussianMixture2d` on the window (a test checks it to
1e-5) at a fraction of its cost.
Each 64x64 training window (:mod:`alcn_cv.data.phos`) is used as in the paper: the Normalizer
sees its centre 48x48, the mixture filters the whole 64x64 and the detector gets the centre
32x32 (free of border effects for sigmas up to 5), after the detector input policy
(``model.detector_input``, per-window standardization by default).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from torch import nn

from alcn_cv.data.phos import WINDOW
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d, gaussian_sigmas, kernel_radius
from alcn_cv.filters.standardize import standardize_windows
from alcn_cv.nets.detector import INPUT, Detector
from alcn_cv.nets.gain import dog_weights
from alcn_cv.nets.normalizer import Normalizer

__all__ = ["CentreMixture", "JointModel", "measure_output_range"]

_NORMALIZER_CROP = (WINDOW - Normalizer.window) // 2  # 8: the Normalizer sees the centre 48x48
_DETECTOR_CROP = (WINDOW - INPUT) // 2  # 16: the detector sees the centre 32x32


class CentreMixture(nn.Module):
    """Eq. 1 on the centre ``size x size`` of ``(B, 1, H, W)`` windows, one weight vector per window.

    The kernels are :func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d` (the library's
    definition), applied as banded matrices ``K_i`` (``size x H``): the centre of ``G_i * I`` is
    ``K_i I K_i^T``, two batched matrix products. Every tap must fall inside the window
    (``(H - size) / 2 >= radius``), so no border rule is involved.

    Shape:
        windows ``(B, 1, H, W)``, weights ``(B, N)`` -> ``(B, 1, size, size)``
    """

    def __init__(self, sigmas: tuple[float, ...], window: int = WINDOW, size: int = INPUT) -> None:
        super().__init__()
        self.sigmas, self.window, self.size = sigmas, window, size
        top = (window - size) // 2
        bands = np.zeros((len(sigmas), size, window), np.float32)
        for i, s in enumerate(sigmas):
            r = kernel_radius(s)
            if top < r:
                raise InputError(f"{window}x{window} windows are too small for sigma {s} around a {size}x{size} centre")
            k = gaussian_kernel1d(s)
            for y in range(size):
                bands[i, y, top + y - r : top + y + r + 1] = k
        self.register_buffer("bands", torch.from_numpy(bands), persistent=False)

    def blurs(self, windows: torch.Tensor) -> torch.Tensor:
        """``(B, N, size, size)``: the centre of the window blurred by each kernel."""
        if windows.shape[-2:] != (self.window, self.window):
            raise InputError(f"windows must be {self.window}x{self.window}, got {tuple(windows.shape[-2:])}")
        return self.bands @ windows @ self.bands.transpose(1, 2)

    def forward(self, windows: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            blurs = self.blurs(windows)
        return torch.einsum("bnhw,bn->bhw", blurs, weights).unsqueeze(1)

    def dense(self, windows: torch.Tensor, maps: torch.Tensor) -> torch.Tensor:
        """Eq. 3 on the centre: ``sum_i G_i * (F_i o I)`` with per-pixel weight maps.

        Shape:
            windows ``(B, 1, H, W)``, maps ``(B, N, H, W)`` -> ``(B, 1, size, size)``
        """
        if windows.shape[-2:] != (self.window, self.window) or maps.shape[-2:] != windows.shape[-2:]:
            raise InputError(
                f"windows and maps must be {self.window}x{self.window}, got "
                f"{tuple(windows.shape[-2:])} and {tuple(maps.shape[-2:])}"
            )
        return (self.bands @ (maps * windows) @ self.bands.transpose(1, 2)).sum(1, keepdim=True)


class JointModel(nn.Module):
    """Normalizer (or a fixed filter) + Gaussian mixture + detector input policy + detector.

    Args:
        cfg: the ``[model]`` section of a :class:`~alcn_cv.train.config.TrainConfig`.
        num_classes: background + objects.

    Shape:
        ``(B, 1, 64, 64)`` windows, float intensities in [0, 1] -> ``(B, num_classes)`` logits.
    """

    def __init__(self, cfg: Any, num_classes: int) -> None:
        super().__init__()
        self.method = cfg.method
        self.policy = cfg.detector_input
        sigmas = gaussian_sigmas(cfg.num_kernels, cfg.sigma_step)
        dog = dog_weights(sigmas, *cfg.dog)
        self.mixture = CentreMixture(sigmas)
        self.normalizer: Normalizer | None = None
        if self.method == "alcn":
            self.normalizer = Normalizer(
                cfg.num_kernels,
                tuple(cfg.channels),
                cfg.hidden,
                cfg.output_scale,
                init_weights=dog,
            )
        self.register_buffer("fixed_weights", torch.tensor(dog, dtype=torch.float32))
        self.detector = Detector(num_classes, tuple(cfg.detector_channels), cfg.detector_hidden, cfg.detector_dropout)

    def weights(self, windows: torch.Tensor) -> torch.Tensor:
        """Mixture weights ``(B, N)`` of each window: the Normalizer's, or the fixed DoG."""
        if self.normalizer is None:
            return self.fixed_weights.expand(len(windows), -1)
        c = _NORMALIZER_CROP
        return self.normalizer(windows[..., c : c + Normalizer.window, c : c + Normalizer.window])

    def normalized(self, windows: torch.Tensor) -> torch.Tensor:
        """The detector's input ``(B, 1, 32, 32)``: mixture output (or raw) centre, after the policy."""
        c = _DETECTOR_CROP
        out = windows[..., c : c + INPUT, c : c + INPUT] if self.method == "none" else self.response(windows)
        return standardize_windows(out) if self.policy == "standardize" else out

    def response(self, windows: torch.Tensor) -> torch.Tensor:
        """The raw mixture output ``(B, 1, 32, 32)`` on the centre (before the input policy): Eq. 1
        with one weight vector per window."""
        return self.mixture(windows, self.weights(windows))

    def forward(self, windows: torch.Tensor, anchor: torch.Tensor | None = None) -> torch.Tensor:
        """Logits ``(B, num_classes)``. With a boolean ``anchor`` mask (the ``"meta"`` objective),
        the detector's parameters are seen as constants for the windows outside the mask: their
        loss trains the Normalizer only."""
        z = self.normalized(windows)
        if anchor is None:
            return self.detector(z)
        fixed = {k: v.detach() for k, v in self.detector.named_parameters()}
        logits = torch.empty(len(z), self.detector.num_classes, dtype=z.dtype, device=z.device)
        logits[anchor] = self.detector(z[anchor])
        logits[~anchor] = torch.func.functional_call(self.detector, fixed, (z[~anchor],))
        return logits


@torch.no_grad()
def measure_output_range(
    model: JointModel, windows: np.ndarray, percentiles: tuple[float, float] = (0.5, 99.5)
) -> list[float]:
    """The ``percentiles`` of the raw mixture responses (before the detector input policy) of ``model``, on whatever
    device it is, to ``(n, 64, 64)`` uint8 ``windows``: ``[low, high]``."""
    device = model.fixed_weights.device
    values = []
    for i in range(0, len(windows), 512):
        x = torch.from_numpy(windows[i : i + 512]).unsqueeze(1).to(device).float() / 255.0
        values.append(model.response(x).flatten().cpu().numpy())
    lo, hi = np.percentile(np.concatenate(values), percentiles)
    return [float(lo), float(hi)]
