"""The networks of ALCN: the Normalizer (predicts mixture weights) and its runtimes, the Detector.

* :mod:`~alcn_cv.nets.gain` -- the gain Normalizer (the default model); :mod:`~alcn_cv.nets.normalizer` -- the
  paper's Normalizer; :mod:`~alcn_cv.nets.lite` -- the real-time Normalizer and the loader of weight files;
  :mod:`~alcn_cv.nets.opencv_runtime` -- each of them run by ``cv2.dnn`` from its ONNX export, without torch;
  :mod:`~alcn_cv.nets.cpu_inference` -- when a Normalizer may take faster CPU kernels.
* :mod:`~alcn_cv.nets.detector` -- the Detector trained jointly with the Normalizer (Eq. 2).
* :mod:`~alcn_cv.nets.device` -- the torch device a network runs or trains on.

Importing this package does not import torch; the names below load their module on first use
(without torch, those that need it raise :class:`~alcn_cv.errors.MissingDependencyError`).
"""

from __future__ import annotations

import importlib

from alcn_cv.extras import missing_extra

__all__ = ["Detector", "Normalizer", "OpenCVNormalizer"]

_LAZY = {
    "Detector": "alcn_cv.nets.detector",
    "Normalizer": "alcn_cv.nets.normalizer",
    "OpenCVNormalizer": "alcn_cv.nets.opencv_runtime",
}


def __getattr__(name: str) -> object:
    if name in _LAZY:
        try:
            module = importlib.import_module(_LAZY[name])
        except ModuleNotFoundError as exc:
            error = missing_extra(exc, f"alcn_cv.nets.{name}")
            if error is None:
                raise
            raise error from exc
        return getattr(module, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
