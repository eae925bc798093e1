"""Histogram equalizations (OpenCV): ``he`` and ``clahe``.

Both run OpenCV's uint8 implementations: the float32 image in [0, 1] is quantized to 8 bits
(``round(255 I)``), equalized, and returned as float32 in [0, 1].
"""

from __future__ import annotations

import cv2
import numpy as np

from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import register
from alcn_cv.errors import InputError

__all__ = ["CLAHE", "HistogramEqualization"]


def _to_uint8(gray: np.ndarray) -> np.ndarray:
    # rint(clip(gray, 0, 1) * 255) in two OpenCV passes: convertScaleAbs rounds half to even
    # and saturates, bit for bit the same once the negatives are gone
    return cv2.convertScaleAbs(cv2.threshold(gray, 0.0, 0.0, cv2.THRESH_TOZERO)[1], alpha=255.0)


def _to_unit(gray8: np.ndarray) -> np.ndarray:
    # gray8 * float32(1 / 255) in one pass (addWeighted multiplies in float32, adds exact zeros)
    return cv2.addWeighted(gray8, float(np.float32(1.0 / 255.0)), gray8, 0.0, 0.0, dtype=cv2.CV_32F)


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
        return _to_unit(cv2.equalizeHist(_to_uint8(gray)))

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
        if not np.isfinite(clipLimit) or clipLimit <= 0:
            raise InputError(f"clipLimit must be positive, got {clipLimit}")
        tiles = tuple(int(t) for t in tileGridSize)
        if len(tiles) != 2 or min(tiles) < 1:
            raise InputError(f"tileGridSize must be two positive integers, got {tileGridSize}")
        self.clipLimit = float(clipLimit)
        self.tileGridSize = tiles

    def _clahe(self) -> cv2.CLAHE:
        # one per call (0.2 us): a cv2.CLAHE keeps its buffers between calls, so that one shared by two threads
        # mixes their images, and it cannot be pickled
        return cv2.createCLAHE(clipLimit=self.clipLimit, tileGridSize=self.tileGridSize)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return _to_unit(self._clahe().apply(_to_uint8(gray)))

    def _apply_gray_uint8(self, gray8: np.ndarray) -> np.ndarray:
        return self._clahe().apply(gray8)  # output_range (0, 1): the fixed map is the identity
