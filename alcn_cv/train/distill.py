"""Distil a light Normalizer from a trained one (``alcn distill``).

From the paper's Normalizer (or any but the gain one), the student is a
:class:`~alcn_cv.nets.lite.LiteNormalizer` (below); from a gain Normalizer
(:mod:`alcn_cv.nets.gain`) it is a smaller gain Normalizer (:func:`distill_gain`, at the end).

The student learns to predict the teacher's mixture weights on the data engine's windows
(:func:`alcn_cv.data.phos.render_windows`, the Normalizer's own training distribution). Both
networks run on each 64x64 window without padding: the teacher's output at offsets 0, 8, 16
(its fully connected layer with stride 2), the student's on its stride-8 grid -- 9 targets
per window, each the weights of the 48x48 window at that offset.

The loss is the error the weights make in ALCN's output, not in the weights themselves: for a
window with blurred images ``B_k = G_{sigma_k} * I`` (its centre 32x32 pixels), the squared
output error of weights off by ``d`` is ``d^T M d`` with ``M_ij = mean(B_i B_j)``; the blurs
are strongly correlated, so most weight errors cost little in the output and the loss says
which. A small plain squared error on the weights (``weight_decay_w``) keeps the directions the
windows do not see from drifting.

The written weight file holds the teacher's header (sigmas, working scale, output range,
whether it is trained), ``architecture: "lite"``, the teacher's file name and SHA-256 (ALCN
warns when the installed teacher differs), and the validation fidelity; a model card
(``<name>.md``) beside it gives the command, data, seed, time and the fidelity.
"""

from __future__ import annotations

import hashlib
import logging
import os
import shlex
import sys
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from alcn_cv.data.phos import render_windows
from alcn_cv.data.scenes import WEBCAM_SCENES, Scene
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.filters.gaussian_mixture import gaussian_blur_stack
from alcn_cv.io import atomic_write, output_path
from alcn_cv.nets.gain import GainNormalizer
from alcn_cv.nets.lite import ARCHITECTURES, LiteNormalizer, normalizer_from_file
from alcn_cv.report import describe_machine, provenance
from alcn_cv.runtime import MODELS
from alcn_cv.train.config import GainDistillConfig, LiteDistillConfig
from alcn_cv.train.export import export_onnx
from alcn_cv.train.real_light import source_scenes
from alcn_cv.weight_file import load_normalizer_file, save_normalizer_file

__all__ = ["distill", "distill_gain", "main", "output_gram", "teacher_file"]

logger = logging.getLogger(__name__)

CENTRE = 32  # the detector's window, where the output matters (Sec. 4.2)


def output_gram(windows: np.ndarray, sigmas: list[float]) -> np.ndarray:
    """``(n, N, N)`` float32: ``M_ij = mean(B_i B_j)`` over each window's centre 32x32, with
    ``B_k = G_{sigma_k} * window`` (reflect-101). ``windows``: ``(n, S, S)`` float32."""
    n, size, _ = windows.shape
    lo = (size - CENTRE) // 2
    out = np.empty((n, len(sigmas), len(sigmas)), np.float32)
    for i, w in enumerate(windows):
        b = gaussian_blur_stack(w, sigmas)[:, lo : lo + CENTRE, lo : lo + CENTRE].reshape(len(sigmas), -1)
        out[i] = b @ b.T / b.shape[1]
    return out


def _teacher_targets(teacher: torch.nn.Module, x: torch.Tensor, batch: int) -> torch.Tensor:
    """The teacher's weights at offsets 0, 8, 16 of each 64x64 window: ``(n, N, 3, 3)``."""
    step = LiteNormalizer.stride // teacher.stride
    with torch.inference_mode():
        return torch.cat([teacher._weights(x[i : i + batch], step) for i in range(0, len(x), batch)])


def _fidelity(student: LiteNormalizer, x: torch.Tensor, target: torch.Tensor, gram: torch.Tensor) -> dict[str, float]:
    with torch.inference_mode():
        d = student._weights(x) - target
        out_err = torch.einsum("bkyx,bkl,blyx->b", d, gram, d) / 9
        out_var = torch.einsum("bkyx,bkl,blyx->b", target, gram, target) / 9
    return {
        "output_rmse": float(out_err.mean().sqrt()),
        "output_rms_teacher": float(out_var.mean().sqrt()),
        "weights_rmse": float(d.pow(2).mean().sqrt()),
        "weights_max_abs_error": float(d.abs().max()),
        "weights_spread_teacher": float(target.std(dim=(0, 2, 3)).mean()),
    }


def teacher_file(teacher: str) -> Path:
    """The weight file of ``teacher``: a shipped model's name (``paper``, ``gain``) or a path."""
    return MODELS[teacher] if teacher in MODELS else Path(teacher)


def distill(cfg: LiteDistillConfig | None = None, progress: bool = True) -> tuple[LiteNormalizer, dict[str, Any]]:
    """Train a :class:`LiteNormalizer` to reproduce a teacher's weights.

    Args:
        cfg: the settings (default: the ``lite`` preset, :class:`~alcn_cv.train.config.LiteDistillConfig`).
        progress: show progress bars.

    Returns:
        The student (eval mode) and a record of the run (settings, time, validation fidelity).

    Raises:
        InputError: a setting out of range (:meth:`~alcn_cv.train.config.LiteDistillConfig.check`), before any work;
            a teacher not of the paper's family.
    """
    cfg = cfg or LiteDistillConfig()
    cfg.check()
    n_windows, n_val, seed, epochs, batch_size = cfg.n_windows, cfg.n_val, cfg.seed, cfg.epochs, cfg.batch_size
    n_objects = cfg.n_objects
    torch.manual_seed(seed)
    teacher_path = teacher_file(cfg.teacher)
    teacher_weights = load_normalizer_file(teacher_path)
    architecture = teacher_weights.meta.get("architecture", "paper")  # the paper's files predate the key
    if architecture not in ARCHITECTURES:  # the student learns a paper-family teacher's mixture weights
        hint = "; distil a gain Normalizer with --conf gain-lite" if architecture == "gain" else ""
        raise InputError(
            f"{teacher_path} is a {architecture} Normalizer, not of the paper's family (paper, lite){hint}"
        )
    teacher_net = normalizer_from_file(teacher_weights)
    sigmas = [float(s) for s in teacher_weights.meta["sigmas"]]
    start = time.perf_counter()

    def data(n: int, data_seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        windows = render_windows(n, data_seed, n_objects=n_objects, progress=progress).windows.astype(np.float32) / 255
        x = torch.from_numpy(windows)[:, None]
        return x, _teacher_targets(teacher_net, x, batch_size), torch.from_numpy(output_gram(windows, sigmas))

    x, target, gram = data(n_windows, seed)
    x_val, target_val, gram_val = data(n_val, seed + 1)
    prepared = time.perf_counter() - start

    student = LiteNormalizer(num_kernels=teacher_net.num_kernels, channels=tuple(cfg.channels))
    with torch.no_grad():  # start predicting the teacher's mean weights everywhere
        student.head.weight.zero_()
        student.head.bias.copy_(target.mean(dim=(0, 2, 3)) / student.output_scale)
    initial = _fidelity(student, x_val, target_val, gram_val)
    # A teacher that predicts the same weights everywhere (an untrained, DoG-initialised one) is
    # reproduced exactly by those weights as the student's bias; training would only add noise
    # (Adam scales the rounding-level gradients up to full steps).
    constant = bool(
        float((target - target.mean(dim=(0, 2, 3), keepdim=True)).abs().max()) <= 1e-6 * (1 + float(target.abs().max()))
    )
    if constant:
        logger.info("the teacher predicts the same weights for every window: the student is that constant")
        epochs = 0
    optimiser = torch.optim.Adam(student.parameters(), lr=cfg.lr)
    steps = epochs * ((n_windows + batch_size - 1) // batch_size)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, steps)
    scale = float(torch.diagonal(gram, dim1=1, dim2=2).mean())
    generator = torch.Generator().manual_seed(seed)
    bar = tqdm(range(epochs), desc="distil", unit="epoch", disable=not progress or constant)
    for _ in bar:
        student.train()
        order = torch.randperm(n_windows, generator=generator)
        for i in range(0, n_windows, batch_size):
            idx = order[i : i + batch_size]
            d = student._weights(x[idx]) - target[idx]
            gb = gram[idx]
            loss = torch.einsum("bkyx,bkl,blyx->b", d, gb, d).mean() / 9 + cfg.weight_decay_w * scale * d.pow(2).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
        student.eval()
        bar.set_postfix(val_output_rmse=f"{_fidelity(student, x_val, target_val, gram_val)['output_rmse']:.2e}")
    record = {
        "teacher": {
            "file": teacher_path.name,
            "sha256": hashlib.sha256(teacher_path.read_bytes()).hexdigest(),
            "description": teacher_weights.meta.get("description", ""),
        },
        "constant_teacher": constant,
        "settings": {**asdict(cfg), "epochs": epochs},
        "seconds": {"data_and_targets": round(prepared, 1), "total": round(time.perf_counter() - start, 1)},
        "validation": _fidelity(student, x_val, target_val, gram_val),
        "validation_initial": initial,
    }
    return student, record


def main(
    out_path: str | os.PathLike,
    cfg: LiteDistillConfig | GainDistillConfig,
    command: str | None = None,
    *,
    conf: str | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> Path:
    """Distil a student (:func:`distill`, or :func:`distill_gain` for a :class:`GainDistillConfig`)
    and write its weight file, with the whole configuration, the command line, the preset's name, the machine and the
    date in its header (:func:`~alcn_cv.report.provenance`), its ONNX export (``.onnx`` beside it) and its model card.

    Args:
        out_path: the ``.npz`` to write (the card is the same name with ``.md``).
        cfg: the settings (a preset of :data:`~alcn_cv.train.config.DISTILL_CONFS`, overridden or not).
        command: the command line recorded in the header and the card (default: this process').
        conf: the preset's name, recorded in the header.
        progress: show progress bars.
        overwrite: replace an existing weight file (a shipped one, say, which its card's command rebuilds).

    Returns:
        The weight file's path.

    Raises:
        InputError: a setting out of range (the configuration's ``check``), ``out_path`` exists and ``overwrite``
            is false, or cannot be written: before any work.
    """
    cfg.check()
    out_path = output_path(out_path, ".npz", "a weight file")  # before the distillation, not after it
    if out_path.exists() and not overwrite:
        raise InputError(f"{out_path} exists (--overwrite replaces it, its card and ONNX export with it)")
    command = command or " ".join(shlex.quote(a) for a in sys.argv)
    if isinstance(cfg, GainDistillConfig):
        return _main_gain(out_path, cfg, command, conf, progress)
    student, record = distill(cfg, progress)
    teacher_meta = load_normalizer_file(teacher_file(cfg.teacher)).meta
    meta = {
        k: v for k, v in teacher_meta.items() if k not in ("format", "version", "config", "description", "training")
    }
    meta.update(
        config=student.config,
        architecture="lite",
        teacher=record["teacher"],
        distillation={
            **provenance(command, conf),
            **{k: record[k] for k in ("constant_teacher", "settings", "seconds", "validation", "validation_initial")},
        },
        description=f"LiteNormalizer distilled from {record['teacher']['file']} ({record['teacher']['description']})",
    )
    save_normalizer_file(out_path, student.state_arrays(), meta)
    export_onnx(out_path.with_suffix(".onnx"), out_path)
    _write_card(out_path.with_suffix(".md"), out_path.name, record, bool(meta["trained"]), command)
    return out_path


def _created(path: Path, model: str, **params: str) -> str:
    """How to create ALCN from the weight file ``path``: by the shipped ``model``'s name where it is that file."""
    shipped = MODELS[model].resolve() == Path(path).resolve()
    args = [
        f'model="{model}"' if shipped else f'weights="{Path(path).name}"',
        *(f'{k}="{v}"' for k, v in params.items()),
    ]
    return f"`alcn_cv.createALCN({', '.join(args)})`"


def _onnx_twin(name: str) -> str:
    """The card's sentence on the weight file ``name``'s ONNX export, which :func:`main` writes beside it."""
    return (
        f'`{Path(name).with_suffix(".onnx").name}` is the same network for the torch-free `backend="opencv"` '
        "(written by the same command through `alcn export`)."
    )


def _write_card(path: Path, name: str, record: dict[str, Any], trained: bool, command: str) -> None:
    v, s, weights = record["validation"], record["settings"], path.with_suffix(".npz")
    constant_note = (
        "\n- The teacher predicts the same weights for every window, so the student is those weights (its bias) "
        "and was not trained (0 epochs)."
        if record["constant_teacher"]
        else ""
    )
    text = f"""# Model card: `{name}`

A light Normalizer (`alcn_cv.nets.lite.LiteNormalizer`, channels {s["channels"]}, grid stride 8) distilled
from the paper-architecture Normalizer `{record["teacher"]["file"]}` (SHA-256 `{record["teacher"]["sha256"][:16]}...`:
{record["teacher"]["description"]}). It predicts that teacher's ALCN mixture weights; it is only as good as the
teacher.
{"The teacher is trained." if trained else "**The teacher is an UNTRAINED placeholder**, so this student is one too."}

Use: {_created(weights, "lite")}, real time (Eq. 3 by its `pyramid` approximation, the default);
{_created(weights, "lite", mixture="exact")} for Eq. 3 exactly. {_onnx_twin(name)}
For the shipped models, ALCN warns when the installed teacher differs from this one: then re-run the command
below (for another teacher, compare its SHA-256 with the one above).

## How it was made

- Command: `{command}`
- Data: {s["n_windows"]} training and {s["n_val"]} validation 64x64 windows of the data engine
  (`alcn_cv.data.phos.render_windows`, {s["n_objects"]} objects, seeds {s["seed"]} and {s["seed"] + 1});
  targets: the teacher's weights at offsets 0, 8, 16 of each window (9 per window).
- Loss: ALCN output error of the weights on the window's centre 32x32 (`d^T M d`, `M` the Gram matrix of the
  window's blurs) plus {s["weight_decay_w"]} x the plain weight error. Adam, lr {s["lr"]}, cosine schedule,
  {s["epochs"]} epochs, batch {s["batch_size"]}, seed {s["seed"]}.{constant_note}
- Time: {record["seconds"]["total"]} s ({record["seconds"]["data_and_targets"]} s rendering and teacher targets) on
  {describe_machine()}.

## Fidelity to the teacher (validation windows)

| measure | value |
|---|---|
| RMS error of the ALCN output (centre 32x32) | {v["output_rmse"]:.3g} |
| the same, untrained (the teacher's mean weights) | {record["validation_initial"]["output_rmse"]:.3g} |
| RMS of the teacher's ALCN output | {v["output_rms_teacher"]:.3g} |
| RMS error of the weights | {v["weights_rmse"]:.3g} |
| largest weight error | {v["weights_max_abs_error"]:.3g} |
| the teacher's weights: standard deviation over windows (mean over kernels) | {v["weights_spread_teacher"]:.3g} |

Speed and the difference from the exact ALCN output on whole frames: `alcn bench speed` (rows `alcn lite ...`).
"""
    atomic_write(path, text)


# --- The gain Normalizer's lite variant ----------------------------------------------------------

#: Every ``_GAIN_VAL_EVERY``-th frame of each real scene is held out for validation.
_GAIN_VAL_EVERY = 5
#: Side and frames of the rendered registered scenes (:func:`alcn_cv.data.relief_scenes.render_scene`).
_RENDERED_SIZE, _RENDERED_FRAMES = 256, 4


@dataclass
class _GridSample:
    """One frame's network input on the gain Normalizer's grid and the teacher's output there."""

    features: torch.Tensor  # (1, 4, gh, gw)
    maps: torch.Tensor  # (1, N, gh, gw), the teacher's F_k = exp(g) w_k
    energy: float  # mean of sum_k F_k^2 over the grid: the scale of the relative error


def _gain_frames(
    scenes: Sequence[Scene], n_rendered: int, seed: int, progress: bool
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Training and validation frames, ``(H, W)`` float32 in [0, 1]: the frames of the real
    scenes (every :data:`_GAIN_VAL_EVERY`-th held out) and of ``n_rendered`` rendered scenes
    (the last one held out when there are two or more)."""
    from alcn_cv.data.relief_scenes import render_scene

    train: list[np.ndarray] = []
    val: list[np.ndarray] = []
    for scene in scenes:
        for i, frame in enumerate(scene.unit_frames()):
            (val if i % _GAIN_VAL_EVERY == _GAIN_VAL_EVERY - 1 else train).append(frame)
    for i in tqdm(range(n_rendered), desc="render scenes", unit="scene", disable=not progress):
        stack, _ = render_scene(np.random.default_rng([seed, i]), _RENDERED_SIZE, _RENDERED_FRAMES)
        held_out = i == n_rendered - 1 and n_rendered > 1
        (val if held_out else train).extend(stack.astype(np.float32) * np.float32(1 / 255))
    return train, val


def _relit(frame: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The frame under another light's strength (a gain of 0.3 to 1.5, clipped as a camera
    would) and mirrored half of the time: the changes the teacher's log features must follow."""
    out = np.clip(frame * np.float32(np.exp(rng.uniform(np.log(0.3), np.log(1.5)))), 0, 1)
    return np.ascontiguousarray(out[:, ::-1]) if rng.random() < 0.5 else out


def _grid_sample(teacher: GainNormalizer, frame: np.ndarray) -> _GridSample:
    with torch.no_grad():  # not inference tensors: the loss saves the targets for its backward pass
        features = teacher.features(torch.from_numpy(frame)[None, None])
        maps = teacher.maps_from_features(features)
    return _GridSample(features, maps, float(maps.pow(2).sum(1).mean()) + 1e-12)


def _maps_error(student: GainNormalizer, sample: _GridSample) -> torch.Tensor:
    """The squared error of the student's maps F_k on the grid, relative to the teacher's mean
    squared map, after the common scale that fits them best: the divisive step that follows the
    maps cancels a scale of the whole frame's maps (its floor is relative to the frame's mean
    energy), so only their shape over the frame is the teacher's to copy."""
    maps = student.maps_from_features(sample.features)
    scale = (maps * sample.maps).sum() / maps.pow(2).sum().clamp_min(1e-30)
    return (scale * maps - sample.maps).pow(2).sum(1).mean() / sample.energy


def _output_fidelity(teacher: GainNormalizer, student: GainNormalizer, frames: list[np.ndarray]) -> dict[str, float]:
    """The whole normalization (:meth:`GainNormalizer.forward`, in (-1, 1) plus the wide band) of the student
    against the teacher's on validation frames: the RMS and the largest absolute difference over every pixel, the
    mean over frames of each frame's 99th percentile of the absolute difference (on at most about 100000 of its
    pixels, evenly strided), and the RMS of the teacher's output."""
    squared, total, count, worst, p99 = 0.0, 0.0, 0, 0.0, []
    with torch.inference_mode():
        for frame in frames:
            x = torch.from_numpy(frame)[None, None]
            expected, got = teacher(x), student(x)
            d = (got - expected).abs()
            squared += float(d.pow(2).sum())
            total += float(expected.pow(2).sum())
            count += d.numel()
            worst = max(worst, float(d.max()))
            p99.append(float(torch.quantile(d.flatten()[:: max(1, d.numel() // 100000)], 0.99)))
    return {
        "output_rmse": (squared / count) ** 0.5,
        "output_rms_teacher": (total / count) ** 0.5,
        "output_max_abs_error": worst,
        "output_p99_abs_error": float(np.mean(p99)),
    }


def distill_gain(cfg: GainDistillConfig | None = None, progress: bool = True) -> tuple[GainNormalizer, dict[str, Any]]:
    """Train a smaller :class:`~alcn_cv.nets.gain.GainNormalizer` to reproduce a gain teacher's maps.

    The student has the teacher's features, kernels, divisive step and ``tau`` (copied, fixed)
    and fewer or narrower convolutions; it learns the teacher's maps F_k on its grid
    (:func:`_maps_error`) on the frames of the real training scenes, each also under another
    light's strength (:func:`_relit`, drawn anew every epoch), and of rendered registered scenes.

    Args:
        cfg: the settings (default: the ``gain-lite`` preset, :class:`~alcn_cv.train.config.GainDistillConfig`).
        progress: show progress bars.

    Returns:
        The student (eval mode) and a record of the run (settings, time, fidelity).

    Raises:
        InputError: a setting out of range (:meth:`~alcn_cv.train.config.GainDistillConfig.check`), before any work;
            a teacher that is no gain Normalizer.
        DatasetError: no validation frames.
    """
    cfg = cfg or GainDistillConfig()
    cfg.check()
    seed, epochs, n_rendered, channels, dilations = cfg.seed, cfg.epochs, cfg.n_rendered, cfg.channels, cfg.dilations
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    teacher_path = teacher_file(cfg.teacher)
    teacher_weights = load_normalizer_file(teacher_path)
    if teacher_weights.meta.get("architecture") != "gain":
        raise InputError(f"{teacher_path} is not a gain Normalizer")
    teacher_net = normalizer_from_file(teacher_weights).eval()
    start = time.perf_counter()
    scenes = source_scenes(cfg.scenes, cfg.relit, seed, cfg.light)
    train_frames, val_frames = _gain_frames(scenes, n_rendered, seed, progress)
    if not val_frames:
        raise DatasetError(
            f"no validation frames: every {_GAIN_VAL_EVERY}th frame of a scene is held out, so a scene needs "
            f"{_GAIN_VAL_EVERY} frames or more (relit >= {_GAIN_VAL_EVERY}, or a folder of scenes= with as many), or "
            "give 2 rendered scenes or more (n_rendered >= 2)"
        )
    base = [_grid_sample(teacher_net, f) for f in train_frames]
    val_samples = [_grid_sample(teacher_net, f) for f in val_frames]
    prepared = time.perf_counter() - start

    config = {
        **teacher_net.config,
        "channels": int(channels),
        "dilations": [int(d) for d in dilations],
        "learn_scales": False,
    }
    student = GainNormalizer(**config)
    with torch.no_grad():  # the teacher's fixed steps: tau and the divisive floor's scale
        student.log_tau.copy_(teacher_net.log_tau)
        student.log_floor_scale.copy_(teacher_net.log_floor_scale)

    def val_error() -> float:
        with torch.inference_mode():
            return float(np.mean([float(_maps_error(student, s)) for s in val_samples]))

    initial = {"maps_relative_error": val_error(), **_output_fidelity(teacher_net, student, val_frames)}
    optimiser = torch.optim.Adam(student.parameters(), lr=cfg.lr)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, epochs * 2 * len(base))
    bar = tqdm(range(epochs), desc="distil gain", unit="epoch", disable=not progress)
    for _ in bar:
        # every frame as it is and under a light drawn for this epoch, in a seeded order
        samples = base + [_grid_sample(teacher_net, _relit(f, rng)) for f in train_frames]
        student.train()
        for i in rng.permutation(len(samples)):
            loss = _maps_error(student, samples[i])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
        student.eval()
        bar.set_postfix(val_maps_error=f"{val_error():.2e}")
    validation = {"maps_relative_error": val_error(), **_output_fidelity(teacher_net, student, val_frames)}
    record = {
        "teacher": {
            "file": teacher_path.name,
            "sha256": hashlib.sha256(teacher_path.read_bytes()).hexdigest(),
            "description": teacher_weights.meta.get("description", ""),
        },
        "settings": {
            **asdict(cfg),
            "scenes": [s.name for s in scenes if s.group != "relit"],
            "frames": {"train": len(train_frames), "validation": len(val_frames)},
        },
        "seconds": {"data_and_targets": round(prepared, 1), "total": round(time.perf_counter() - start, 1)},
        "validation": validation,
        "validation_initial": initial,
        "parameters": {  # the values each weight file stores (tau and the floor scale, fixed in training, included)
            name: sum(a.size for a in net.state_arrays().values())
            for name, net in (("student", student), ("teacher", teacher_net))
        },
    }
    return student, record


def _main_gain(out_path: Path, cfg: GainDistillConfig, command: str, conf: str | None, progress: bool) -> Path:
    """:func:`main` for a gain teacher: the weight file, its ONNX export and its card."""
    student, record = distill_gain(cfg, progress)
    trained = bool(load_normalizer_file(teacher_file(cfg.teacher)).meta["trained"])
    meta = student.file_meta(
        trained,
        teacher=record["teacher"],
        distillation={
            **provenance(command, conf),
            **{k: record[k] for k in ("settings", "seconds", "validation", "validation_initial", "parameters")},
        },
        description=f"gain Normalizer distilled from {record['teacher']['file']} "
        f"({record['settings']['channels']} channels, dilations {record['settings']['dilations']})",
    )
    save_normalizer_file(out_path, student.state_arrays(), meta)
    export_onnx(out_path.with_suffix(".onnx"), out_path)
    _write_gain_card(out_path.with_suffix(".md"), out_path.name, record, trained, command)
    return out_path


def _gain_sources(s: dict[str, Any]) -> str:
    """The distillation data, in words, from the run's settings."""
    parts = []
    if s["scenes"]:
        parts.append(f"the registered scenes {', '.join(s['scenes'])}")
    if s["relit"]:
        parts.append(
            f"the permissive photographs relit {s['relit']} times each (`alcn_cv.data.permissive_images`, "
            f"light `{s['light']}`)"
        )
    if s["n_rendered"]:
        parts.append(
            f"{s['n_rendered']} rendered registered scenes ({_RENDERED_SIZE}x{_RENDERED_SIZE}, {_RENDERED_FRAMES} "
            "lights each, `alcn_cv.data.relief_scenes.render_scene`, the last held out)"
        )
    return "; ".join(parts)


def _gain_terms(s: dict[str, Any]) -> str:
    """What the student's data allow: the webcam frames are for academic research only, other scenes carry
    their own terms, the relit permissive photographs (and the rendered scenes) permit any use."""
    if any(scene in WEBCAM_SCENES for scene in s["scenes"]):
        return (
            '**Distilled on frames of the "Webcam" data set (Verdie, Yi, Fua & Lepetit, TILDE, CVPR 2015; AMOS, '
            "Jacobs, Roman & Pless, CVPR 2007): these weights are for academic research only, as those "
            "photographs are.**"
        )
    if s["scenes"]:
        return "**Distilled on the registered scenes named below: these weights carry those photographs' terms.**"
    return "Distilled on photographs that permit any use: so may these weights be used (mind the teacher's terms)."


def _write_gain_card(path: Path, name: str, record: dict[str, Any], trained: bool, command: str) -> None:
    v, start, s = record["validation"], record["validation_initial"], record["settings"]
    teacher, weights = record["teacher"], path.with_suffix(".npz")
    text = f"""# Model card: `{name}` (the gain Normalizer's lite variant)

{_created(weights, "gain-lite")}. A smaller gain-adaptive Normalizer (`alcn_cv.nets.gain.GainNormalizer`,
{s["channels"]} channels, dilations {s["dilations"]}; {record["parameters"]["student"]} stored values, `tau` and `c`
among them, against the teacher's {record["parameters"]["teacher"]}) distilled from `{teacher["file"]}` (SHA-256 \
`{teacher["sha256"][:16]}...`:
{teacher["description"] or "the gain Normalizer"}). Same features, kernels, divisive step and `tau` as the teacher
(copied, fixed); only the network on the grid is smaller. It is only as good as the teacher.
{"The teacher is trained." if trained else "**The teacher is an UNTRAINED placeholder**, so this student is one too."}
{_onnx_twin(name)} For the shipped models, ALCN warns when the installed teacher
differs from this one; for another teacher, compare its SHA-256 with the one above.
{_gain_terms(s)}

## How it was made

- Command: `{command}`
- Data: the frames of {_gain_sources(s)} (every {_GAIN_VAL_EVERY}th frame of a scene held out for validation;
  the test scenes `mexico` and the psm objects never read): {s["frames"]["train"]} training and
  {s["frames"]["validation"]} validation frames, grayscale; each training frame also under another light's
  strength every epoch (a gain of 0.3 to 1.5, clipped, mirrored half of the time).
- Targets: the teacher's maps `F_k = exp(g) w_k` on its stride-8 grid (the features are the same, computed
  once). Loss: their squared error relative to the teacher's mean squared map on the frame, after the common
  scale that fits them best (the divisive step that follows cancels a scale of the whole frame's maps).
  Adam, lr {s["lr"]}, cosine schedule, {s["epochs"]} epochs of one frame per step, seed {s["seed"]}.
- Time: {record["seconds"]["total"]} s ({record["seconds"]["data_and_targets"]} s reading, rendering and teacher
  targets) on {describe_machine()}.

## Fidelity to the teacher (validation frames, the whole normalization: its output in (-1, 1) plus the wide band)

| measure | this student | its start (DoG + divisive, untrained) |
|---|---|---|
| maps on the grid, relative squared error (best common scale) | {v["maps_relative_error"]:.3g} |\
 {start["maps_relative_error"]:.3g} |
| RMS difference from the teacher's output | {v["output_rmse"]:.3g} | {start["output_rmse"]:.3g} |
| 99th percentile of the absolute difference | {v["output_p99_abs_error"]:.3g} | {start["output_p99_abs_error"]:.3g} |
| largest absolute difference | {v["output_max_abs_error"]:.3g} | {start["output_max_abs_error"]:.3g} |
| RMS of the teacher's output | {v["output_rms_teacher"]:.3g} | |
"""
    atomic_write(path, text)
