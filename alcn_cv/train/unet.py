r"""Training the free-form baseline, :class:`~alcn_cv.train.unet_normalizer.UNetNormalizer`, exactly as the gain
Normalizer.

The same data, objective and budget as :func:`alcn_cv.train.real_light.train_real_light` under a
:class:`~alcn_cv.train.config.UNetConfig` (a :class:`~alcn_cv.train.config.RealLightConfig` whose ``net`` holds the
U-Net's arguments; presets :data:`~alcn_cv.train.config.UNET_CONFS`): the scenes of
:func:`~alcn_cv.train.real_light.training_scenes`,
each step's scene, frames and locations drawn in the same order from the same generator, the crops of
:func:`~alcn_cv.train.real_light.crop_windows`, :func:`~alcn_cv.train.real_light.identification_loss` on the
textured locations plus the consistency and repeatability terms on those and the ``anywhere`` ones
(:func:`~alcn_cv.train.real_light.objective`), ``steps`` steps of Adam at ``lr``, gradients clipped to norm 5.

The U-Net runs only on the part of each crop that its output on the central ``patch`` depends on
(:func:`centre_outputs`), with the same result as on the whole crop.

Outputs in the run folder: ``train.log``, ``history.json`` (every ``save_every`` steps) and
``unet_normalizer.npz`` (:mod:`alcn_cv.weight_file`, ``architecture: "unet"``) at the end, its ``output_range``
measured on the training scenes (:func:`output_range`).

Command::

    alcn train-unet --conf gain --out out/unet   # the default's data: relit permissive photographs
"""

from __future__ import annotations

import copy
import functools
import logging
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from alcn_cv.errors import InputError
from alcn_cv.report import provenance
from alcn_cv.train.checkpoint import check_run_folder
from alcn_cv.train.config import UNetConfig
from alcn_cv.train.real_light import TrainingScene, fit, pair_loss, training_run, training_scenes
from alcn_cv.train.unet_normalizer import UNetNormalizer
from alcn_cv.weight_file import save_normalizer_file

__all__ = ["centre_outputs", "output_range", "train_unet", "unet_pair_loss"]

logger = logging.getLogger(__name__)


def centre_outputs(
    net: UNetNormalizer, crops: torch.Tensor, patch: int, frames: Sequence[tuple[slice, slice]] = ()
) -> torch.Tensor:
    """The U-Net's output on the central ``patch x patch`` of each crop ``(B, 1, crop, crop)``: ``(B, 1, patch,
    patch)``, equal to the centre of ``net(crops)`` (``frames``, which crops belong to which frame, does not
    matter to it: it has no frame-wide floor).

    The network runs on the centre and :attr:`~UNetNormalizer.reach` pixels around it, the region starting on
    a multiple of :attr:`~UNetNormalizer.multiple` so that its pooling grid is the whole crop's.
    """
    crop = crops.shape[-1]
    if crops.shape[-2] != crop or patch > crop:
        raise InputError(f"crops must be square and at least {patch} pixels, got {tuple(crops.shape[-2:])}")
    first = (crop - patch) // 2
    lo = max(0, first - net.reach) // net.multiple * net.multiple
    hi = min(crop, first + patch + net.reach)
    start = first - lo
    return net(crops[..., lo:hi, lo:hi])[..., start : start + patch, start : start + patch]


#: :func:`~alcn_cv.train.real_light.pair_loss` on the U-Net's :func:`centre_outputs`: the gain Normalizer's
#: objective (identification, consistency, repeatability) on the U-Net's output.
unet_pair_loss = functools.partial(pair_loss, normalize=centre_outputs)


def output_range(
    net: UNetNormalizer, scenes: Sequence[TrainingScene], frames: int = 4, progress: bool = False
) -> tuple[float, float]:
    """The 0.1 and 99.9 percentiles of the U-Net's output on ``frames`` evenly spaced frames of each scene (their
    padding left out): the fixed map of its responses to an image's range (the weight file's ``output_range``);
    ``progress``: a bar over the scenes.

    The objective is blind to the output's offset and scale (normalized cross-correlation, and a consistency
    relative to the outputs' energy), so nothing fixes them: a fixed map of (-1, 1) may leave the image flat."""
    values = []
    with torch.no_grad():
        for scene in tqdm(scenes, desc="output range", unit="scene", leave=False, disable=not progress):
            p = scene.pad
            for index in np.linspace(0, len(scene.frames) - 1, min(frames, len(scene.frames))).round().astype(int):
                values.append(net(torch.from_numpy(scene.frames[index, p:-p, p:-p])[None, None]).flatten())
    lo, hi = np.percentile(torch.cat(values).numpy(), [0.1, 99.9])
    return float(lo), float(max(hi, lo + 1e-6))


def train_unet(
    cfg: UNetConfig,
    out: str | Path,
    *,
    command: str = "",
    conf: str | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> Path:
    """Train a :class:`~alcn_cv.train.unet_normalizer.UNetNormalizer` as the gain Normalizer is trained (see the
    module).

    Args:
        cfg: the settings (a preset of :data:`~alcn_cv.train.config.UNET_CONFS`); ``cfg.net`` holds the
            :class:`~alcn_cv.train.unet_normalizer.UNetNormalizer` arguments, recorded in the weight file, which users
            share, as given, the home folder written ``~`` (:meth:`~alcn_cv.train.config.RealLightConfig.shareable`).
        out: the run folder.
        command, conf: the command line and the preset's name, recorded in the weight file with ``cfg``.
        progress: show a progress bar.
        overwrite: replace the earlier run that ``out`` holds (checked before any work,
            :func:`~alcn_cv.train.checkpoint.check_run_folder`).

    Returns:
        The weight file ``out/unet_normalizer.npz``.

    Raises:
        InputError: settings out of range (:meth:`~alcn_cv.train.config.UNetConfig.check`); ``out`` holds an
            earlier run (without ``overwrite``) or other files, or is a file.
        TrainingInterrupted: Ctrl-C or SIGTERM (:func:`~alcn_cv.train.real_light.fit`); no checkpoint is written
            (its ``checkpoint`` is False): ``history.json`` holds the steps done.
    """
    cfg.check()
    check_run_folder(out, overwrite=overwrite, resumable=False)
    with training_run(cfg, out, check=False) as folder:
        return _train(cfg, folder, {"command": command, "conf": conf}, progress)


def _train(cfg: UNetConfig, out: Path, record: dict[str, Any], progress: bool) -> Path:
    # The generators as in real_light._train: the same seeds, the network built first, the same draws per step.
    rng = np.random.default_rng(cfg.seed)
    torch.manual_seed(cfg.seed)
    net = UNetNormalizer(**cfg.net)
    initial = copy.deepcopy(net)  # the untrained start, the log's reference (fit)
    scenes, rendered = training_scenes(cfg)
    logger.info("U-Net %s: %d parameters", net.config, sum(p.numel() for p in net.parameters()))
    seconds = fit(net, unet_pair_loss, scenes, rendered, cfg, rng, out, None, "unet", progress, initial=initial)
    meta = net.file_meta(
        trained=True,
        output_range=output_range(net, scenes + rendered, progress=progress),
        description="free-form U-Net normalizer trained as the gain Normalizer (identification objective)",
        training={
            **provenance(record.get("command", ""), record.get("conf")),
            "config": asdict(cfg.shareable()),
            "seconds": round(seconds, 1),
        },
    )
    return save_normalizer_file(out / "unet_normalizer.npz", net.state_arrays(), meta)
