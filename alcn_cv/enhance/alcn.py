"""ALCN as an OpenCV-style preprocessing step: ``alcn_cv.createALCN().apply(img)``.

The Normalizer runs fully-convolutionally at the *working scale* (the resolution at which its
48x48 window was trained), giving per-pixel weight maps F_k; these are upsampled to the input
resolution and the Gaussian mixture of Eq. 3 is applied there with the sigmas scaled by
``1 / working_scale``, so the output keeps the input's size and detail:
``ALCN(I) = sum_k G_{sigma_k / s} * (F_k(I) o I)``.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import alcn_filter
from alcn_cv.weight_file import DEFAULT_WEIGHTS, load_normalizer_file

if TYPE_CHECKING:
    import torch

__all__ = ["ALCN", "createALCN"]

logger = logging.getLogger(__name__)

BACKENDS = ("fast", "torch")


@register
class ALCN(Normalization):
    """Adaptive Local Contrast Normalization (Rad, Roth & Lepetit, BMVC 2017).

    Args:
        weights: a Normalizer weight file (``.npz``, see :mod:`alcn_cv.weight_file`); default:
            the file shipped in the package, ``alcn_cv/weights/alcn_normalizer.npz``.
        scale: working scale, the factor from the input resolution to the one the Normalizer
            sees (its 48x48 window and sigmas are in working-scale pixels). Default: the
            weight file's ``working_scale`` (0.5 for the shipped file: a 640x480 frame is
            seen at 320x240, where a 48-pixel window spans 15% of the width).
        backend: ``"fast"`` (Normalizer in torch on the CPU, Gaussian mixture in OpenCV) or
            ``"torch"`` (everything in torch/kornia, on ``device``).
        device: torch device for ``backend="torch"`` (``"cpu"`` or ``"cuda"``).
    """

    name = "alcn"

    def __init__(
        self,
        weights: str | Path | None = None,
        scale: float | None = None,
        backend: str = "fast",
        device: str = "cpu",
    ) -> None:
        if backend not in BACKENDS:
            raise InputError(f"unknown backend {backend!r}; choose one of {', '.join(BACKENDS)}")
        weight_file = load_normalizer_file(weights)
        meta = weight_file.meta
        self.weights_path = Path(weights) if weights is not None else DEFAULT_WEIGHTS
        self.sigmas = tuple(float(s) for s in meta["sigmas"])
        self.scale = float(meta["working_scale"] if scale is None else scale)
        if not 0 < self.scale <= 4:
            raise InputError(f"scale must be in (0, 4], got {self.scale}")
        self.output_range = tuple(float(v) for v in meta["output_range"])
        self.trained = bool(meta["trained"])
        if not self.trained:
            logger.warning("%s holds UNTRAINED Normalizer weights (%s)", self.weights_path.name, meta.get("description", ""))
        self.backend = backend
        self.device = device

        import torch  # deferred: importing alcn_cv must not need torch

        from alcn_cv.nets.normalizer import Normalizer

        if backend == "torch" and device.startswith("cuda") and not torch.cuda.is_available():
            raise InputError("device 'cuda' requested but torch sees no CUDA device")
        self.net = Normalizer.from_file(weight_file).to(device if backend == "torch" else "cpu")
        if len(self.sigmas) != self.net.num_kernels:
            raise InputError(f"weight file has {len(self.sigmas)} sigmas for {self.net.num_kernels} outputs")

    @property
    def full_res_sigmas(self) -> tuple[float, ...]:
        """The mixture's sigmas in input pixels: ``sigma_k / scale``."""
        return tuple(s / self.scale for s in self.sigmas)

    def _working_image(self, gray: np.ndarray) -> np.ndarray:
        if self.scale == 1:
            return gray
        h, w = gray.shape
        size = (max(1, round(w * self.scale)), max(1, round(h * self.scale)))
        return cv2.resize(gray, size, interpolation=cv2.INTER_AREA if self.scale < 1 else cv2.INTER_LINEAR)

    def _dense(self, gray: np.ndarray) -> torch.Tensor:
        import torch

        small = torch.from_numpy(self._working_image(gray)).to(next(self.net.parameters()).device)
        with torch.inference_mode():
            return self.net.dense(small[None, None])[0]

    def weight_maps(self, gray: np.ndarray) -> np.ndarray:
        """The per-pixel mixture weights F_k at the input resolution.

        Args:
            gray: ``(H, W)`` float32 intensities in [0, 1].

        Returns:
            ``(N, H, W)`` float32.
        """
        maps = self._dense(gray).cpu().numpy()
        h, w = gray.shape
        if maps.shape[1:] == (h, w):
            return maps
        return np.stack([cv2.resize(m, (w, h), interpolation=cv2.INTER_LINEAR) for m in maps])

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        if self.backend == "fast":
            return alcn_filter(gray, self.weight_maps(gray), self.full_res_sigmas)
        import torch
        import torch.nn.functional as F

        from alcn_cv.filters.kornia_mixture import gaussian_mixture2d

        maps = self._dense(gray)[None]
        with torch.inference_mode():
            image = torch.from_numpy(gray).to(maps.device)[None, None]
            if maps.shape[-2:] != image.shape[-2:]:
                maps = F.interpolate(maps, size=image.shape[-2:], mode="bilinear", align_corners=False)
            return gaussian_mixture2d(image, maps, self.full_res_sigmas)[0, 0].cpu().numpy()

    def __repr__(self) -> str:
        return (
            f"ALCN(weights={self.weights_path.name!r}, scale={self.scale}, backend={self.backend!r}, "
            f"trained={self.trained})"
        )


def createALCN(**params: object) -> ALCN:  # noqa: N802 -- OpenCV naming, like cv2.createCLAHE
    """Create an :class:`ALCN` normalization; ``createALCN().apply(img)`` normalizes an image.

    Example:
        >>> import alcn_cv, numpy as np
        >>> frame = (np.random.rand(480, 640) * 255).astype(np.uint8)
        >>> alcn_cv.createALCN().apply(frame).shape
        (480, 640)
    """
    return ALCN(**params)
