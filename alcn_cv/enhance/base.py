"""The contract every normalization follows, in the style of ``cv2.createCLAHE(...).apply``.

A normalization object has two entry points:

* :meth:`Normalization.apply` -- the image API an OpenCV app calls: grayscale ``HxW`` (or
  ``HxWx1``) or BGR ``HxWx3``; ``uint8``, ``uint16`` or ``float32`` (float intensities in
  [0, 1]). The output has the input's shape and, unless ``out_dtype`` says otherwise, its
  dtype. Colour images are normalized on the L channel of CIE Lab, keeping a and b (Rad et al.
  2017, Sec. 4.4). The raw response is mapped to the output range through a *fixed* linear map
  (:attr:`Normalization.output_range` -> [0, 1], clipped), never a per-frame min/max, so the
  frames of a video stay consistent.
* :meth:`Normalization.normalize` -- the raw response on a float32 ``HxW`` intensity image in
  [0, 1], for detectors and benchmarks that want unclipped values.

The caller's array is never modified.
"""

from __future__ import annotations

from typing import ClassVar

import cv2
import numpy as np

from alcn_cv.checks import FULL_SCALE, SUPPORTED_DTYPES, unit_windows, check_gray, check_image
from alcn_cv.errors import InputError

__all__ = ["Normalization", "NoNormalization", "check_image", "check_gray"]

def _to_unit_float(img: np.ndarray) -> np.ndarray:
    if img.dtype == np.float32:
        return np.clip(img, 0.0, 1.0)  # a copy: the caller's array stays untouched
    return img.astype(np.float32) * np.float32(1.0 / FULL_SCALE[img.dtype])


class Normalization:
    """Base class of every normalization (ALCN and the classical baselines).

    Subclasses set :attr:`name` (the registry key), implement :meth:`_normalize` and set
    :attr:`output_range`, the range of raw responses that :meth:`apply` maps linearly onto the
    full output range (values outside are clipped).
    """

    name: ClassVar[str] = ""
    output_range: tuple[float, float] = (0.0, 1.0)

    def normalize(self, gray: np.ndarray) -> np.ndarray:
        """Raw normalized response.

        Args:
            gray: ``(H, W)`` float32 intensities in [0, 1].

        Returns:
            ``(H, W)`` float32, unbounded (see :attr:`output_range` for the typical range).
        """
        out = self._normalize(check_gray(gray))
        return np.asarray(out, dtype=np.float32)

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def normalize_windows(self, windows: np.ndarray) -> np.ndarray:
        """The raw response of every window of a batch, each normalized on its own.

        What a detector trained on windows sees (the paper's second stage); a method whose
        response depends on the window as a whole overrides it (ALCN: Eq. 1, one weight vector
        per window).

        Args:
            windows: ``(n, S, S)`` uint8, or float32 intensities in [0, 1].

        Returns:
            ``(n, S, S)`` float32, unbounded.
        """
        return np.stack([self.normalize(w) for w in unit_windows(windows)])

    def to_unit(self, response: np.ndarray) -> np.ndarray:
        """The fixed map of raw responses to [0, 1]: ``output_range`` -> [0, 1], clipped."""
        lo, hi = self.output_range
        return np.clip((response - lo) * np.float32(1.0 / (hi - lo)), 0.0, 1.0).astype(np.float32, copy=False)

    def apply(self, img: np.ndarray, out_dtype: type | np.dtype | str | None = None) -> np.ndarray:
        """Normalize an image, OpenCV style.

        Args:
            img: ``HxW``, ``HxWx1`` or BGR ``HxWx3``; uint8, uint16 or float32 in [0, 1].
            out_dtype: ``None`` (the input's dtype), ``np.uint8``, ``np.uint16`` or ``np.float32``
                (values in [0, 1]).

        Returns:
            An array of the input's shape and the requested dtype.
        """
        img = check_image(img)
        out_dtype = np.dtype(img.dtype if out_dtype is None else out_dtype)
        if out_dtype not in SUPPORTED_DTYPES:
            raise InputError(f"unsupported out_dtype {out_dtype}; use uint8, uint16 or float32")
        unit = _to_unit_float(img)
        if img.ndim == 3 and img.shape[2] == 3:
            lab = cv2.cvtColor(unit, cv2.COLOR_BGR2Lab)  # float input: L in [0, 100]
            lab[..., 0] = 100.0 * self.to_unit(self.normalize(np.ascontiguousarray(lab[..., 0]) / np.float32(100)))
            result = np.clip(cv2.cvtColor(lab, cv2.COLOR_Lab2BGR), 0.0, 1.0)
        else:
            result = self.to_unit(self.normalize(np.ascontiguousarray(unit.reshape(img.shape[:2]))))
            result = result.reshape(img.shape)
        if out_dtype == np.float32:
            return result.astype(np.float32, copy=False)
        return np.rint(result * FULL_SCALE[out_dtype]).astype(out_dtype)

    def __repr__(self) -> str:
        return f"{type(self).__name__}(name={self.name!r})"


class NoNormalization(Normalization):
    """The identity: the input intensities unchanged (the ``"none"`` baseline)."""

    name = "none"

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return gray.copy()
