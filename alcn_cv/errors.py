"""Exceptions raised for bad input. All derive from ``ValueError`` so callers that
already guard OpenCV-style calls with ``except ValueError`` keep working."""


class ALCNError(ValueError):
    """Base class of the errors raised by alcn-cv for bad input or bad files."""


class InputError(ALCNError):
    """An array or file given by the caller cannot be processed (shape, dtype, values)."""


class WeightFileError(ALCNError):
    """A weight, checkpoint or model file is missing, corrupt or incompatible."""


class DatasetError(ALCNError):
    """A dataset file is missing, truncated or malformed; the message names file and field."""
