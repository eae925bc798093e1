"""alcn-cv: Adaptive Local Contrast Normalization (Rad, Roth & Lepetit, BMVC 2017).

The OpenCV-style API::

    import alcn_cv
    out = alcn_cv.createALCN().apply(frame)          # like cv2.createCLAHE().apply
    out = alcn_cv.create("dog").apply(frame)          # any registered normalization
    alcn_cv.available()                               # their names

Importing this package does not import torch; the networks (:mod:`alcn_cv.nets`) and the
differentiable mixture (:mod:`alcn_cv.filters.kornia_mixture`) load it when used.
"""

from alcn_cv.enhance import ALCN, Normalization, available, create, createALCN, register
from alcn_cv.errors import ALCNError, DatasetError, InputError, WeightFileError
from alcn_cv.filters.gaussian_mixture import alcn_filter, gaussian_sigmas

__version__ = "0.1.0"

__all__ = [
    "ALCN",
    "ALCNError",
    "DatasetError",
    "InputError",
    "Normalization",
    "WeightFileError",
    "alcn_filter",
    "available",
    "create",
    "createALCN",
    "gaussian_sigmas",
    "register",
]
