"""Training of ALCN (Rad, Roth & Lepetit, BMVC 2017): the joint training of the Normalizer with a
detector (Eq. 2, :mod:`~alcn_cv.train.trainer`), the second stage that trains a new detector on
a frozen Normalizer (:mod:`~alcn_cv.train.stage2`), ONNX export and the torch-free OpenCV runtime.

Importing this package does not import torch; the names below load their module on first use.
"""

from __future__ import annotations

import importlib

__all__ = ["train_detector"]

_LAZY = {
    "train_detector": "alcn_cv.train.stage2",
}


def __getattr__(name: str):
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
