"""Histogram equalizations (OpenCV): ``he`` and ``clahe``.

Both run OpenCV's uint8 implementations: the float32 image in [0, 1] is quantized to 8 bits
(``round(255 I)``), equalized, and returned as float32 in [0, 1].
"""

from __future__ import annotations

import cv2
import numpy as np

from alcn_cv.checks import check_positive, from_unit_float, to_unit_float
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError

__all__ = ["CLAHE", "HistogramEqualization"]


def _to_uint8(gray: np.ndarray) -> np.ndarray:
    """The caller's float32 plane quantized to uint8, ``rint(255 * clip(gray, 0, 1))``, left as it was."""
    return from_unit_float(gray.copy(), np.dtype(np.uint8))


@register
class HistogramEqualization(Normalization):
    """Global histogram equalization (``cv2.equalizeHist``).

    Maps intensities through the image's cumulative histogram so the output histogram is
    close to uniform (e.g. Gonzalez & Woods, "Digital Image Processing", Sec. 3.3). No
    parameters.
    """

    name = "he"
    summary = "global histogram equalization (cv2.equalizeHist)"
    reference = "Gonzalez & Woods, Digital Image Processing, Sec. 3.3"
    output_range = (0.0, 1.0)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return to_unit_float(cv2.equalizeHist(_to_uint8(gray)))

    def _apply_gray_uint8(self, gray8: np.ndarray) -> np.ndarray:
        return cv2.equalizeHist(gray8)  # output_range (0, 1): the fixed map is the identity


@register
class CLAHE(Normalization):
    """Contrast-limited adaptive histogram equalization (``cv2.createCLAHE``).

    Zuiderveld, "Contrast limited adaptive histogram equalization", Graphics Gems IV, 1994:
    histogram equalization per tile with the histogram clipped at ``clipLimit`` times its
    mean, bilinearly blended between tiles.

    Args:
        clipLimit: contrast limit (OpenCV's meaning). Default 2.0.
        tileGridSize: tiles per row and column ``(cols, rows)``. Default ``(8, 8)``.
    """

    name = "clahe"
    summary = "contrast-limited adaptive histogram equalization (cv2.createCLAHE)"
    reference = "Zuiderveld, Graphics Gems IV, 1994"
    output_range = (0.0, 1.0)

    def __init__(self, clipLimit: float = 2.0, tileGridSize: tuple[int, int] = (8, 8)) -> None:  # noqa: N803 -- OpenCV names
        self.clipLimit = check_positive("clipLimit", clipLimit)
        tiles = tuple(int(t) for t in tileGridSize)
        if len(tiles) != 2 or min(tiles) < 1:
            raise InputError(f"tileGridSize must be two positive integers, got {tileGridSize}")
        self.tileGridSize = tiles

    def _clahe(self) -> cv2.CLAHE:
        # one per call (cheap): a cv2.CLAHE keeps its buffers between calls, so that one shared by two threads
        # mixes their images, and it cannot be pickled
        return cv2.createCLAHE(clipLimit=self.clipLimit, tileGridSize=self.tileGridSize)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return to_unit_float(self._clahe().apply(_to_uint8(gray)))

    def _apply_gray_uint8(self, gray8: np.ndarray) -> np.ndarray:
        return self._clahe().apply(gray8)  # output_range (0, 1): the fixed map is the identity
