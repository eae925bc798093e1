"""Distil a :class:`~alcn_cv.nets.lite.LiteNormalizer` from a Normalizer (``alcn distill``).

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
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm.auto import tqdm

from alcn_cv.data.phos import render_windows
from alcn_cv.errors import InputError
from alcn_cv.filters.gaussian_mixture import gaussian_blur_stack
from alcn_cv.io import atomic_write
from alcn_cv.nets.lite import LiteNormalizer, normalizer_from_file
from alcn_cv.report import describe_machine
from alcn_cv.weight_file import DEFAULT_WEIGHTS, load_normalizer_file, save_normalizer_file

__all__ = ["distill", "main", "output_gram"]

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


def distill(
    teacher: str | os.PathLike | None = None,
    n_windows: int = 20000,
    n_val: int = 2000,
    seed: int = 0,
    epochs: int = 30,
    batch_size: int = 256,
    lr: float = 3e-3,
    channels: tuple[int, int] = (8, 16),
    weight_decay_w: float = 0.01,
    n_objects: int = 100,
    progress: bool = True,
) -> tuple[LiteNormalizer, dict[str, Any]]:
    """Train a :class:`LiteNormalizer` to reproduce ``teacher``'s weights.

    Args:
        teacher: the teacher's weight file (default: the paper-model file shipped).
        n_windows, n_val: training and validation windows rendered by
            :func:`alcn_cv.data.phos.render_windows` (seeds ``seed`` and ``seed + 1``).
        epochs, batch_size, lr: Adam with a cosine learning-rate schedule.
        channels: the student's widths.
        weight_decay_w: weight of the plain squared weight error, relative to the output error.
        n_objects: catalogue size of the rendered windows.

    Returns:
        The student (eval mode) and a record of the run (settings, time, validation fidelity).
    """
    if n_windows < 1 or n_val < 1 or epochs < 1 or batch_size < 1:
        raise InputError("n_windows, n_val, epochs and batch_size must be >= 1")
    torch.manual_seed(seed)
    teacher_path = Path(teacher) if teacher is not None else DEFAULT_WEIGHTS
    teacher_file = load_normalizer_file(teacher_path)
    teacher_net = normalizer_from_file(teacher_file)
    sigmas = [float(s) for s in teacher_file.meta["sigmas"]]
    start = time.perf_counter()

    def data(n: int, data_seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        windows = render_windows(n, data_seed, n_objects=n_objects, progress=progress).windows.astype(np.float32) / 255
        x = torch.from_numpy(windows)[:, None]
        return x, _teacher_targets(teacher_net, x, batch_size), torch.from_numpy(output_gram(windows, sigmas))

    x, target, gram = data(n_windows, seed)
    x_val, target_val, gram_val = data(n_val, seed + 1)
    prepared = time.perf_counter() - start

    student = LiteNormalizer(num_kernels=teacher_net.num_kernels, channels=channels)
    with torch.no_grad():  # start predicting the teacher's mean weights everywhere
        student.head.weight.zero_()
        student.head.bias.copy_(target.mean(dim=(0, 2, 3)) / student.output_scale)
    initial = _fidelity(student, x_val, target_val, gram_val)
    # A teacher that predicts the same weights everywhere (an untrained, DoG-initialised one) is
    # reproduced exactly by those weights as the student's bias; training would only add noise
    # (Adam scales the rounding-level gradients up to full steps).
    constant = bool(float((target - target.mean(dim=(0, 2, 3), keepdim=True)).abs().max()) <= 1e-6 * (1 + float(target.abs().max())))
    if constant:
        logger.info("the teacher predicts the same weights for every window: the student is that constant")
        epochs = 0
    optimiser = torch.optim.Adam(student.parameters(), lr=lr)
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
            loss = torch.einsum("bkyx,bkl,blyx->b", d, gb, d).mean() / 9 + weight_decay_w * scale * d.pow(2).mean()
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            schedule.step()
        student.eval()
        bar.set_postfix(val_output_rmse=f"{_fidelity(student, x_val, target_val, gram_val)['output_rmse']:.2e}")
    record = {
        "teacher": {"file": teacher_path.name, "sha256": hashlib.sha256(teacher_path.read_bytes()).hexdigest(),
                    "description": teacher_file.meta.get("description", "")},
        "constant_teacher": constant,
        "settings": {"n_windows": n_windows, "n_val": n_val, "seed": seed, "epochs": epochs, "batch_size": batch_size,
                     "lr": lr, "channels": list(channels), "weight_decay_w": weight_decay_w, "n_objects": n_objects},
        "seconds": {"data_and_targets": round(prepared, 1), "total": round(time.perf_counter() - start, 1)},
        "validation": _fidelity(student, x_val, target_val, gram_val),
        "validation_initial": initial,
    }
    return student, record


def main(
    out_path: str | os.PathLike,
    teacher: str | os.PathLike | None = None,
    command: str | None = None,
    **params: Any,
) -> Path:
    """Distil a student (:func:`distill`) and write its weight file and model card.

    Args:
        out_path: the ``.npz`` to write (the card is the same name with ``.md``).
        teacher: the teacher's weight file (default: the shipped paper-model file).
        command: the command line recorded in the card (default: this process').
        params: passed to :func:`distill`.

    Returns:
        The weight file's path.
    """
    out_path = Path(out_path)
    student, record = distill(teacher, **params)
    teacher_meta = load_normalizer_file(teacher).meta
    meta = {k: v for k, v in teacher_meta.items() if k not in ("format", "version", "config", "description", "training")}
    meta.update(
        config=student.config,
        architecture="lite",
        teacher=record["teacher"],
        distillation={k: record[k] for k in ("constant_teacher", "settings", "seconds", "validation", "validation_initial")},
        description=f"LiteNormalizer distilled from {record['teacher']['file']} ({record['teacher']['description']})",
    )
    save_normalizer_file(out_path, student.state_arrays(), meta)
    command = command or " ".join(shlex.quote(a) for a in sys.argv)
    _write_card(out_path.with_suffix(".md"), out_path.name, record, bool(meta["trained"]), command)
    return out_path


def _write_card(path: Path, name: str, record: dict[str, Any], trained: bool, command: str) -> None:
    v, s = record["validation"], record["settings"]
    constant_note = (
        "\n- The teacher predicts the same weights for every window, so the student is those weights (its bias) "
        "and was not trained (0 epochs)." if record["constant_teacher"] else ""
    )
    text = f"""# Model card: `{name}`

A light Normalizer (`alcn_cv.nets.lite.LiteNormalizer`, channels {s['channels']}, grid stride 8) distilled
from the paper-architecture Normalizer `{record['teacher']['file']}` (SHA-256 `{record['teacher']['sha256'][:16]}...`:
{record['teacher']['description']}). It predicts that teacher's ALCN mixture weights; it is only as good as the
teacher. {"The teacher is trained." if trained else "**The teacher is an UNTRAINED placeholder**, so this student is one too."}

Use: `alcn_cv.createALCN(model="lite")`, real time: `alcn_cv.createALCN(model="lite", mixture="pyramid")`.
ALCN warns when the installed teacher differs from this one: then re-run the command below.

## How it was made

- Command: `{command}`
- Data: {s['n_windows']} training and {s['n_val']} validation 64x64 windows of the data engine
  (`alcn_cv.data.phos.render_windows`, {s['n_objects']} objects, seeds {s['seed']} and {s['seed'] + 1});
  targets: the teacher's weights at offsets 0, 8, 16 of each window (9 per window).
- Loss: ALCN output error of the weights on the window's centre 32x32 (`d^T M d`, `M` the Gram matrix of the
  window's blurs) plus {s['weight_decay_w']} x the plain weight error. Adam, lr {s['lr']}, cosine schedule,
  {s['epochs']} epochs, batch {s['batch_size']}, seed {s['seed']}.{constant_note}
- Time: {record['seconds']['total']} s ({record['seconds']['data_and_targets']} s rendering and teacher targets) on
  {describe_machine()}.

## Fidelity to the teacher (validation windows)

| measure | value |
|---|---|
| RMS error of the ALCN output (centre 32x32) | {v['output_rmse']:.3g} |
| the same, predicting the teacher's mean weights everywhere (the student before training) | {record['validation_initial']['output_rmse']:.3g} |
| RMS of the teacher's ALCN output | {v['output_rms_teacher']:.3g} |
| RMS error of the weights | {v['weights_rmse']:.3g} |
| largest weight error | {v['weights_max_abs_error']:.3g} |
| the teacher's weights: standard deviation over windows (mean over kernels) | {v['weights_spread_teacher']:.3g} |

Speed and the difference from the exact ALCN output on whole frames: `alcn bench speed` (rows `alcn lite ...`).
"""
    atomic_write(path, text)

