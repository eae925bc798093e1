"""The free-form baseline as a normalization method: a trained :class:`~alcn_cv.train.unet_normalizer.UNetNormalizer`
behind :class:`~alcn_cv.enhance.base.Normalization`'s ``apply``.

A lab baseline for the benchmarks (``alcn bench relight --methods unet:weights=PATH``,
:func:`alcn_cv.bench.relight.build_method`), not a method of the runtime's registry.
"""

from __future__ import annotations

import os

import numpy as np
import torch

from alcn_cv.enhance.base import Normalization
from alcn_cv.nn import read_only_tensor
from alcn_cv.train.unet_normalizer import UNetNormalizer
from alcn_cv.weight_file import load_normalizer_file

__all__ = ["UNetNormalization"]


class UNetNormalization(Normalization):
    """A U-Net trained to output the normalized image (Jenicek & Chum's jointly trained U-Net).

    Args:
        weights: a weight file of ``architecture: "unet"`` (:func:`alcn_cv.train.unet.train_unet`); its
            ``output_range`` is the fixed map of the responses to the image's range.

    Example:
        >>> import numpy as np
        >>> from alcn_cv.train.unet_normalizer import UNetNormalizer
        >>> from alcn_cv.weight_file import save_normalizer_file
        >>> net = UNetNormalizer()
        >>> path = save_normalizer_file("/tmp/unet_doc.npz", net.state_arrays(), net.file_meta(trained=False))
        >>> UNetNormalization(path).apply(np.zeros((48, 64), np.uint8)).shape
        (48, 64)
    """

    name = "unet"
    reference = "Jenicek & Chum, No Fear of the Dark, ICCV 2019"
    output_range = (-1.0, 1.0)

    def __init__(self, weights: str | os.PathLike) -> None:
        weight_file = load_normalizer_file(weights)
        self.net = UNetNormalizer.from_file(weight_file)
        self.output_range = tuple(weight_file.meta["output_range"])
        #: The weight file's header, as :attr:`ALCN.weights_meta <alcn_cv.enhance.alcn.ALCN>` keeps its own.
        self.weights_meta = weight_file.meta

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        with torch.inference_mode():
            return self.net(read_only_tensor(gray)[None, None])[0, 0].numpy()
