"""Exceptions of alcn-cv.

The errors for bad input derive from ``ValueError`` so callers that already guard
OpenCV-style calls with ``except ValueError`` keep working; :class:`MissingDependencyError`
also derives from ``ImportError`` (a package of an optional extra is not installed).
"""

from __future__ import annotations

__all__ = [
    "ALCNError",
    "DatasetError",
    "InputError",
    "MissingDependencyError",
    "WeightFileError",
]


class ALCNError(ValueError):
    """Base class of the errors raised by alcn-cv for bad input or bad files."""


class InputError(ALCNError):
    """An array or file given by the caller cannot be processed (shape, dtype, values)."""


class WeightFileError(ALCNError):
    """A weight, checkpoint or model file is missing, corrupt or incompatible."""


class DatasetError(ALCNError):
    """A dataset file is missing, truncated or malformed; the message names file and field."""


class MissingDependencyError(ALCNError, ImportError):
    """A package of an optional extra is not installed; the message names the extra to install."""

    #: The extra of alcn-cv that installs the package (None when none does).
    extra: str | None = None
