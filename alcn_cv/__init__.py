"""alcn-cv: Adaptive Local Contrast Normalization (Rad, Roth & Lepetit, BMVC 2017).

The OpenCV-style API::

    import alcn_cv
    out = alcn_cv.createALCN().apply(frame)          # like cv2.createCLAHE().apply
    out = alcn_cv.create("dog").apply(frame)          # any registered normalization
    alcn_cv.available()                               # their names
    alcn_cv.keep_freed_memory()                       # once, on glibc: no page faults from frame to frame

The base install (NumPy, SciPy and the app's own OpenCV, any of its four wheels) runs all of this: without
torch, ``createALCN()`` runs the shipped Normalizer by ``cv2.dnn`` (before OpenCV 4.8, whose ``cv2.dnn`` cannot run
the default ``gain`` model, with ``model="lite"``). Importing this package does
not import torch; the networks (:mod:`alcn_cv.nets`) and the differentiable mixture
(:mod:`alcn_cv.filters.kornia_mixture`) load it when used. Where a package of an extra is
missing, ``ALCN``, :mod:`alcn_cv.nets` and the ``alcn`` command raise or print one line naming
the extra to install (:class:`MissingDependencyError`); without OpenCV, importing this package raises it (and
the ``alcn`` command prints its line and exits with code 2).
"""

from alcn_cv.errors import MissingDependencyError
from alcn_cv.extras import require_opencv

try:
    require_opencv()  # one line saying how to install OpenCV, before the first import of cv2
except MissingDependencyError as error:
    from alcn_cv.cli import exit_in_the_command

    exit_in_the_command(error)  # the `alcn` command, whose script imports this package before its main: exit 2
    raise

from alcn_cv.enhance import ALCN, Normalization, available, create, createALCN, register  # noqa: E402
from alcn_cv.errors import ALCNError, DatasetError, InputError, WeightFileError  # noqa: E402
from alcn_cv.filters.gaussian_mixture import alcn_filter, gaussian_sigmas  # noqa: E402
from alcn_cv.malloc import keep_freed_memory  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "ALCN",
    "ALCNError",
    "DatasetError",
    "InputError",
    "MissingDependencyError",
    "Normalization",
    "WeightFileError",
    "alcn_filter",
    "available",
    "create",
    "createALCN",
    "gaussian_sigmas",
    "keep_freed_memory",
    "register",
]
