"""Image normalizations with an OpenCV-style ``apply``: ALCN and the classical baselines."""

from alcn_cv.enhance import histogram, lcn, retinex, tantriggs  # noqa: F401, I001 -- registers the classical baselines
from alcn_cv.enhance.alcn import ALCN, createALCN
from alcn_cv.enhance.base import NoNormalization, Normalization
from alcn_cv.enhance.registry import available, create, register

__all__ = ["ALCN", "NoNormalization", "Normalization", "available", "create", "createALCN", "register"]
