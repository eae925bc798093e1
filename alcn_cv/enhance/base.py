"""The contract every normalization follows, in the style of ``cv2.createCLAHE(...).apply``.

A normalization object has two entry points:

* :meth:`Normalization.apply` -- the image API an OpenCV app calls: grayscale ``HxW`` (or
  ``HxWx1``), BGR ``HxWx3``, or either with an alpha channel (``HxWx2``, BGRA ``HxWx4``);
  ``uint8``, ``uint16`` or ``float32`` (float intensities in [0, 1]). The output has the
  input's shape and, unless ``out_dtype`` says otherwise, its dtype. Colour images are
  normalized on the L channel of CIE Lab, keeping a and b (Rad et al. 2017, Sec. 4.4); an
  alpha channel is passed through unchanged. The raw response is mapped to the output range
  through a *fixed* linear map (:attr:`Normalization.output_range` -> [0, 1], clipped), never
  a per-frame min/max, so the frames of a video stay consistent.
* :meth:`Normalization.normalize` -- the raw response on a float32 ``HxW`` intensity image in
  [0, 1], for detectors and benchmarks that want unclipped values.

The caller's array is never modified. An image of more than :data:`TILE_PIXELS` pixels is
normalized in horizontal strips, each with the rows around it that its output depends on, by
the methods whose output is local (:meth:`Normalization._tiling`; ALCN, ``dog``, ``slcn``): the
result is the whole image's and the memory a strip's.
"""

from __future__ import annotations

import inspect
import logging
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from typing import ClassVar

import cv2
import numpy as np

from alcn_cv.checks import (
    UINT8_LEVELS,
    check_gray,
    check_image,
    check_out_dtype,
    from_unit_float,
    to_unit_float,
    unit_windows,
)
from alcn_cv.errors import InputError
from alcn_cv.filters.lab import lab_and_lightness, normalized_bgr

__all__ = ["NoNormalization", "Normalization"]

logger = logging.getLogger(__name__)
#: Images of more pixels are normalized in horizontal strips by the methods that allow it
#: (:meth:`Normalization._tiling`): the peak memory stays a small multiple of a strip's.
TILE_PIXELS = 2**24
#: The classes that already warned about an image smaller than their window (once per process).
_WARNED_SMALL: set[type] = set()
#: The classes of methods of one's own that already warned about a non-finite response (once per process).
_WARNED_NON_FINITE: set[type] = set()


def with_alpha(result: np.ndarray, alpha: np.ndarray, out_dtype: np.dtype) -> np.ndarray:
    """``result`` (``HxWxC`` of ``out_dtype``) with the ``HxW`` ``alpha`` as its last channel, converted to
    ``out_dtype`` when that differs: a new array, so that the input's alpha is not shared."""
    if alpha.dtype != out_dtype:
        alpha = from_unit_float(to_unit_float(alpha), out_dtype)
    return np.concatenate([result, alpha[..., None]], axis=2)


class Normalization:
    """Base class of every normalization (ALCN and the classical baselines).

    Subclasses set :attr:`name` (the registry key), implement :meth:`_normalize` and set
    :attr:`output_range`, the range of raw responses that :meth:`apply` maps linearly onto the
    full output range (values outside are clipped). :attr:`summary` and :attr:`reference`
    describe the method in ``alcn normalize --list`` (default: the first line of the class
    docstring, and no reference); a method whose window cannot be completed by mirroring without changing what it
    computes (ALCN's CNN window) sets :attr:`min_size`, its side in input pixels (the filters leave it 0). Its
    parameters are its constructor's keywords, with defaults and type hints, kept as attributes of the same names
    (its ``repr`` and spec show them).

    Example, a method of one's own (:func:`~alcn_cv.enhance.registry.register` makes it ``create("gamma")`` and a
    method of every command, given ``alcn --import MODULE``):

        >>> class Gamma(Normalization):
        ...     \"\"\"A gamma curve.\"\"\"
        ...     name = "gamma"
        ...     def __init__(self, gamma: float = 0.5) -> None:
        ...         self.gamma = gamma
        ...     def _normalize(self, gray: np.ndarray) -> np.ndarray:
        ...         return gray**self.gamma
        >>> Gamma().apply(np.full((2, 3), 64, np.uint8))
        array([[128, 128, 128],
               [128, 128, 128]], dtype=uint8)
    """

    name: ClassVar[str] = ""
    #: One line saying what the method does (default: the class docstring's first line).
    summary: ClassVar[str] = ""
    #: The publication the method follows.
    reference: ClassVar[str] = ""
    #: The side, in input pixels, of the window the method looks at (0: none).
    min_size: ClassVar[int] = 0
    output_range: tuple[float, float] = (0.0, 1.0)

    @classmethod
    def describe(cls) -> tuple[str, str]:
        """``(summary, reference)``: :attr:`summary` or the docstring's first line, and :attr:`reference`."""
        summary = cls.summary or (cls.__doc__ or "").strip().split("\n\n")[0].replace("\n", " ")
        return " ".join(summary.split()), cls.reference

    @classmethod
    def resolved(cls, params: dict[str, object]) -> dict[str, object]:
        """``params``, every constructor parameter given (defaults included), with the defaults that the others
        decide resolved: what :func:`~alcn_cv.enhance.registry.same_method` compares. The parameters themselves, by
        default."""
        return params

    def normalize(self, gray: np.ndarray) -> np.ndarray:
        """Raw normalized response.

        Args:
            gray: ``(H, W)`` float32 intensities in [0, 1].

        Returns:
            ``(H, W)`` float32, unbounded (see :attr:`output_range` for the typical range).
        """
        return self._normalize_checked(check_gray(gray))

    def _normalize_checked(self, gray: np.ndarray) -> np.ndarray:
        """:meth:`normalize` on an image already known to be a finite float32 ``HxW`` one: :meth:`_normalize` sees it
        read-only (the caller's array, which a method must not change), and must return an ``HxW`` response."""
        self._warn_if_small(gray.shape)
        seen = gray.view()
        seen.flags.writeable = False
        out = np.asarray(self._normalize(seen), dtype=np.float32)
        if out.shape != gray.shape:
            raise InputError(
                f"{self.name or type(self).__name__} returned a response of shape {out.shape} for an image of "
                f"{gray.shape}: its _normalize must return one value per pixel, (H, W)"
            )
        if type(self) not in _WARNED_NON_FINITE and not type(self).__module__.startswith("alcn_cv."):
            self._warn_if_non_finite(out)  # a method of one's own: the shipped ones are tested instead (a frame's cost)
        # a response that is the image itself (none's) is the caller's array: a copy, writable as any response
        return out.copy() if np.may_share_memory(out, gray) else out

    def _warn_if_non_finite(self, out: np.ndarray) -> None:
        """Log, once per class, that a response holds NaN or infinities, which :meth:`apply` writes as 0."""
        bad = out.size - int(np.count_nonzero(np.isfinite(out)))
        if bad:
            _WARNED_NON_FINITE.add(type(self))
            logger.warning(
                "%s returned %d non-finite values (NaN or infinity) of %d: apply() writes them as 0 (warned once)",
                self.name or type(self).__name__,
                bad,
                out.size,
            )

    def _warn_if_small(self, shape: tuple[int, ...]) -> None:
        """Log, once per class, that an image is smaller than the method's window."""
        if min(shape[:2]) < self.min_size and type(self) not in _WARNED_SMALL:
            _WARNED_SMALL.add(type(self))
            logger.warning(
                "%s: image of %dx%d px is smaller than the method's %d px window; the window is "
                "completed by mirroring the image at its borders (warned once)",
                self.name,
                shape[1],
                shape[0],
                self.min_size,
            )

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        """The method itself: the raw response of a ``(H, W)`` float32 image of intensities in [0, 1] (a colour
        image's CIE L / 100), read-only, as a ``(H, W)`` float array, typically within :attr:`output_range`.

        A subclass implements it; :meth:`apply` and :meth:`normalize` do the rest (dtypes, colour, alpha, strips,
        the output map). It keeps nothing from one image to the next (a benchmark normalizes every image of a run
        with one instance)."""
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
        return np.stack([self._normalize_checked(w) for w in unit_windows(windows)])  # checked as a stack

    def to_unit(self, response: np.ndarray) -> np.ndarray:
        """The fixed map of raw responses to [0, 1]: ``output_range`` -> [0, 1], clipped."""
        return self._response_to(response, np.dtype(np.float32))

    def _unclipped_unit(self, response: np.ndarray) -> np.ndarray:
        """``(response - lo) / (hi - lo)`` as a new float32 array: one ``cv2.addWeighted`` pass
        for a float32 plane (its single rounding of ``response * a + b``)."""
        lo, hi = self.output_range
        scale = 1.0 / (hi - lo)
        if isinstance(response, np.ndarray) and response.dtype == np.float32 and response.ndim == 2:
            return cv2.addWeighted(response, scale, response, 0.0, -lo * scale)
        return ((np.asarray(response) - lo) * np.float32(scale)).astype(np.float32)

    def _response_to(self, response: np.ndarray, dtype: np.dtype) -> np.ndarray:
        """:meth:`to_unit` then the conversion to ``dtype`` (the same values, fewer passes)."""
        return from_unit_float(self._unclipped_unit(response), dtype)

    def apply(
        self, src: np.ndarray, dst: np.ndarray | None = None, out_dtype: type | np.dtype | str | None = None
    ) -> np.ndarray:
        """Normalize an image, OpenCV style: ``apply(src)``, ``apply(src, dst)`` or ``apply(src, dst=out)``.

        Args:
            src: ``HxW``, ``HxWx1``, ``HxWx2`` (gray and alpha), BGR ``HxWx3`` or BGRA ``HxWx4``;
                uint8, uint16 or float32 in [0, 1], in any byte order.
            dst: as in OpenCV, an array the result is written into when it has the result's
                shape and dtype and is writable (it may be ``src`` itself); otherwise a new
                array is returned and ``dst`` is left as it was.
            out_dtype: ``None`` (the input's dtype), ``np.uint8``, ``np.uint16`` or ``np.float32``
                (values in [0, 1]).

        Returns:
            An array of the input's shape and the requested dtype (native byte order): ``dst``
            when the result was written into it. The colour (or gray) channels are normalized;
            an alpha channel is passed through unchanged (converted to ``out_dtype`` when that
            differs).

        Images smaller than :attr:`min_size` (the method's window; 0 for the pixel-wise and
        whole-image methods) are normalized all the same: the window is completed by
        mirroring the image at its borders (reflect-101), so the result is valid but reflects
        less of the scene; a warning is logged once per method.

        Raises:
            InputError: the image breaks this contract (:func:`alcn_cv.checks.check_image`).
        """
        if dst is not None and not isinstance(dst, np.ndarray):
            raise InputError(f"dst must be a numpy array or None, got {type(dst).__name__}")
        result = self._apply(check_image(src), out_dtype)
        if dst is not None and dst.shape == result.shape and dst.dtype == result.dtype and dst.flags.writeable:
            np.copyto(dst, result)
            return dst
        return result

    def _apply(self, img: np.ndarray, out_dtype: type | np.dtype | str | None) -> np.ndarray:
        """:meth:`apply` on a valid image, into a new array."""
        out_dtype = check_out_dtype(out_dtype, img.dtype)
        alpha = None
        if img.ndim == 3 and img.shape[2] in (2, 4):
            img, alpha = img[..., :-1], img[..., -1]
        strips = self._strips(img.shape[:2])
        if strips is None:
            result = self._apply_colour(img, out_dtype)
        else:  # a large image: strip by strip, each with the rows around it that its output sees
            result = np.empty(img.shape, out_dtype)
            with self._strip_context(img, strips):
                for start, stop, lo, hi in strips:
                    result[start:stop] = self._apply_colour(img[lo:hi], out_dtype)[start - lo : stop - lo]
        return result if alpha is None else with_alpha(result, alpha, out_dtype)

    def _apply_colour(self, img: np.ndarray, out_dtype: np.dtype) -> np.ndarray:
        """:meth:`apply` on a valid gray or BGR image without alpha."""
        if img.dtype == np.uint8 and out_dtype == np.uint8 and (img.ndim == 2 or img.shape[2] == 1):
            direct = self._apply_gray_uint8(img.reshape(img.shape[:2]))
            if direct is not None:
                self._warn_if_small(img.shape)
                return direct.reshape(img.shape)
        if img.ndim == 3 and img.shape[2] == 3:
            return self._apply_bgr(img, out_dtype)
        unit = to_unit_float(img)
        return self._response_to(self._normalize_checked(unit.reshape(img.shape[:2])), out_dtype).reshape(img.shape)

    def _apply_bgr(self, img: np.ndarray, out_dtype: np.dtype) -> np.ndarray:
        """:meth:`apply` on a valid BGR image (:func:`normalized_bgr`)."""
        return normalized_bgr(img, self._normalize_checked, self.output_range, out_dtype)

    def _apply_gray_uint8(self, gray8: np.ndarray) -> np.ndarray | None:
        """:meth:`apply`'s result for a uint8 ``HxW`` image and uint8 output, computed without the
        float round trip by a method that works on 8-bit images (the same values); None (the
        default): take the float path."""
        return None

    def _lookup_uint8(self, gray8: np.ndarray, response_of: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """:meth:`_apply_gray_uint8` for a method whose response is a function of each pixel's
        intensity alone (given statistics of the image): ``response_of`` on the 256 intensities
        as the float path sees them, mapped to uint8 as it maps them (the same float operations
        on the same values), then one ``cv2.LUT`` pass over the image."""
        return cv2.LUT(gray8, self._response_to(response_of(UINT8_LEVELS), np.dtype(np.uint8)))

    def _intensity(self, img: np.ndarray) -> np.ndarray:
        """The float32 ``HxW`` plane :meth:`apply` normalizes for a valid gray or BGR image
        without alpha: its intensities in [0, 1], or a BGR image's CIE L / 100 (as :meth:`_apply_bgr`)."""
        if img.ndim == 3 and img.shape[2] == 3:
            return lab_and_lightness(img)[1]
        return to_unit_float(img).reshape(img.shape[:2])

    def _strip_context(self, img: np.ndarray, strips: list[tuple[int, int, int, int]]) -> AbstractContextManager:
        """The context :meth:`apply` normalizes the strips of a large image in (:meth:`_strips`):
        a method whose output depends on a statistic of the whole image (ALCN's divisive floor)
        computes it here from the strips first; by default none is needed."""
        return nullcontext()

    def _tiling(self, shape: tuple[int, int]) -> tuple[int, int] | None:
        """How :meth:`apply` may cut an image of ``shape`` into horizontal strips: ``(halo,
        step)``, the rows a strip's output depends on above and below it, and the multiple of
        rows at which strips may start (so that the result equals the whole image's); None
        (the default) for a method that needs the whole image at once."""
        return None

    def _strips(self, shape: tuple[int, int]) -> list[tuple[int, int, int, int]] | None:
        """``(start, stop, lo, hi)`` for each strip of a large image: output rows
        ``start:stop`` computed from input rows ``lo:hi``; None to process it whole."""
        height, width = shape
        layout = self._tiling(shape) if height * width > TILE_PIXELS else None
        if layout is None:
            return None
        halo, step = layout
        rows = max(step, TILE_PIXELS // 2 // width // step * step)
        if rows >= height:
            return None
        return [
            (start, min(start + rows, height), max(0, start - halo), min(height, start + rows + halo))
            for start in range(0, height, rows)
        ]

    def __repr__(self) -> str:
        # the constructor's parameters that the instance keeps under their own names (scikit-learn's convention)
        names = [name for name in inspect.signature(type(self).__init__).parameters if hasattr(self, name)]
        shown = ", ".join(f"{name}={getattr(self, name)!r}" for name in names)
        return f"{type(self).__name__}({shown or f'name={self.name!r}'})"


class NoNormalization(Normalization):
    """The identity: the input intensities unchanged (the ``"none"`` baseline)."""

    name = "none"
    summary = "no normalization: the input intensities unchanged (the baseline)"

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return gray.copy()

    def _apply_gray_uint8(self, gray8: np.ndarray) -> np.ndarray:
        return gray8.copy()  # rint(255 * (v / 255)) is v for every uint8 v: the float path's result
