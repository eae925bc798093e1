"""The real-light training objective of trained weight files on the bench's training and test scenes: how well
each file fits the scenes it was tuned on and how much of that holds on new ones.

The objective is :func:`~alcn_cv.train.real_light.pair_loss` (identification, consistency and repeatability), the
U-Net's on the centres of its crops (:data:`~alcn_cv.train.unet.unet_pair_loss`), with the crops, locations and
loss weights of an ``alcn train-real-light`` preset, on ``draws`` draws (frames and locations, as training draws
them, from seed 0 in each scene) of each scene of :data:`~alcn_cv.data.scenes.TRAIN_SCENES` and
:data:`~alcn_cv.data.scenes.TEST_SCENES`. Output: ``objective.json``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch

from alcn_cv.data.scenes import TEST_SCENES, TRAIN_SCENES, load_scenes, select_scenes, shared_root
from alcn_cv.errors import InputError
from alcn_cv.io import make_folder, write_json
from alcn_cv.nets.gain import ARCHITECTURE as GAIN
from alcn_cv.nets.gain import GainNormalizer
from alcn_cv.presets import preset
from alcn_cv.train.config import REAL_LIGHT_CONFS
from alcn_cv.train.real_light import draw_step, pair_loss, training_scene
from alcn_cv.train.unet import unet_pair_loss
from alcn_cv.train.unet_normalizer import ARCHITECTURE as UNET
from alcn_cv.train.unet_normalizer import UNetNormalizer
from alcn_cv.weight_file import load_normalizer_file

__all__ = ["main"]

logger = logging.getLogger(__name__)


def _network(path: str | os.PathLike) -> tuple[torch.nn.Module, Callable[..., torch.Tensor]]:
    """The network of a weight file with its loss."""
    weight_file = load_normalizer_file(Path(path))
    architecture = weight_file.meta.get("architecture")
    if architecture == UNET:
        return UNetNormalizer.from_file(weight_file), unet_pair_loss
    if architecture == GAIN:
        return GainNormalizer.from_file(weight_file), pair_loss
    raise InputError(
        f"{path}: a weight file of architecture {architecture!r}; the objective takes {GAIN!r} or {UNET!r}"
    )


def main(
    out_dir: str | os.PathLike, weights: Mapping[str, str | os.PathLike], conf: str = "gain", draws: int = 8
) -> dict[str, Any]:
    """The mean objective of each weight file per scene and over the training and the test scenes.

    Args:
        out_dir: output folder (created); ``objective.json`` is written in it.
        weights: label -> weight file of a gain Normalizer or a U-Net.
        conf: the ``alcn train-real-light`` preset (:data:`~alcn_cv.train.config.REAL_LIGHT_CONFS`).
        draws: draws per scene.

    Returns:
        The dictionary written to ``objective.json``: ``conf``, ``draws``, ``scenes`` (name -> ``group``, ``"train"``
        or ``"test"``, and the mean loss of each label), ``mean_train`` and ``mean_test`` (label -> the mean of the
        group's scenes).

    Raises:
        InputError: an unknown preset, ``draws`` below 1 or a weight file of another architecture.
        WeightFileError: a missing or unreadable weight file.
    """
    cfg = preset(REAL_LIGHT_CONFS, conf)
    if draws < 1:
        raise InputError(f"need draws >= 1, got {draws}")
    nets = {label: _network(path) for label, path in weights.items()}
    scenes = load_scenes([shared_root("webcam"), shared_root("psm")])
    groups = {"train": select_scenes(scenes, TRAIN_SCENES), "test": select_scenes(scenes, TEST_SCENES)}
    result: dict[str, Any] = {"conf": conf, "draws": draws, "scenes": {}}
    for group, members in groups.items():
        for scene in members:
            ready = training_scene(scene, cfg.crop // 2, cfg.patch)
            rng = np.random.default_rng(0)
            losses: dict[str, list[float]] = {label: [] for label in nets}
            for _ in range(draws):
                _, pair, centres, anywhere = draw_step([ready], [], cfg, rng)
                with torch.no_grad():
                    for label, (net, loss) in nets.items():
                        losses[label].append(float(loss(net, ready, pair, centres, cfg, anywhere)))
            means = {label: float(np.mean(v)) for label, v in losses.items()}
            result["scenes"][scene.name] = {"group": group, **means}
            logger.info("objective, %s (%s): %s", scene.name, group, {k: round(v, 3) for k, v in means.items()})
    for group in groups:
        rows = [r for r in result["scenes"].values() if r["group"] == group]
        result[f"mean_{group}"] = {label: float(np.mean([r[label] for r in rows])) for label in nets}
        logger.info("objective, %s scenes: %s", group, {k: round(v, 3) for k, v in result[f"mean_{group}"].items()})
    write_json(make_folder(out_dir) / "objective.json", result)
    return result
