"""Training of ALCN (Rad, Roth & Lepetit, BMVC 2017): the joint training of the Normalizer with a
detector (Eq. 2, :mod:`~alcn_cv.train.trainer`, its stages in :mod:`~alcn_cv.train.windows`,
:mod:`~alcn_cv.train.models`, :mod:`~alcn_cv.train.checkpoint`, :mod:`~alcn_cv.train.fewshot` and
:mod:`~alcn_cv.train.summary`), the second stage that trains a new detector on a frozen Normalizer
(:mod:`~alcn_cv.train.stage2`), the distillation of the light Normalizer
(:mod:`~alcn_cv.train.distill`) and the ONNX export read by the torch-free OpenCV runtime
(:mod:`alcn_cv.nets.opencv_runtime`).

Example::

    import alcn_cv.train
    result = alcn_cv.train.train("paper", "out/alcn")  # a preset of TRAIN_CONFS, a TOML file, a dict, a TrainConfig
    result.val_by_family, result.fewshot, result.weights

Importing this package does not import torch; the names below load their module on first use.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "JointModel",
    "TrainConfig",
    "TrainResult",
    "export_onnx",
    "load_checkpoint",
    "load_config",
    "train",
    "train_detector",
]

_LAZY = {
    "train": "alcn_cv.train.trainer",
    "TrainResult": "alcn_cv.train.trainer",
    "JointModel": "alcn_cv.train.models",
    "load_checkpoint": "alcn_cv.train.checkpoint",
    "TrainConfig": "alcn_cv.train.config",
    "load_config": "alcn_cv.train.config",
    "train_detector": "alcn_cv.train.stage2",
    "export_onnx": "alcn_cv.train.export",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
