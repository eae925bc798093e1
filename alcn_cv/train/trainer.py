r"""Joint training of the Normalizer with a detector (Rad, Roth & Lepetit, BMVC 2017, Eq. 2).

No one knows the right mixture weights for a window, so the Normalizer ``f`` is trained through
a detector ``g`` that classifies the normalized windows (:class:`~alcn_cv.train.models.JointModel`,
Eq. 2). :func:`train` runs the stages of a run, one function each: read or render the windows
(:mod:`alcn_cv.train.windows`), build the models, the epoch loop (training steps, then the
held-out validation and a checkpoint after every epoch, :mod:`alcn_cv.train.checkpoint`), the
few-shot validation (:mod:`alcn_cv.train.fewshot`), the Normalizer weight file, and the summary
(:mod:`alcn_cv.train.summary`); the :class:`~alcn_cv.train.config.TrainConfig` holds every setting.

The default objective (``optim.objective = "meta"``) rehearses the paper's second stage inside
the first: the detector learns from windows under one *anchor* lighting only (as a new detector
later learns from a few images under one light), while the Normalizer minimises the loss on
*all* windows with the detector held fixed for the non-anchor ones (:meth:`JointModel.forward`
with an ``anchor`` mask). Its gradient therefore says "make this lighting look like the anchor
lighting to a detector", the invariance the second stage needs (plain Eq. 2 is ``"joint"``).

The same command trains the same detector on a fixed DoG (``model.method = "dog"``) or on the
raw windows (``"none"``), so the benefit of the learned Normalizer is measured, not assumed.
Validation uses *held-out lighting families* (``data.val_lighting``), never the training light.

Outputs in the run folder: ``checkpoint.pt`` (atomic, every epoch and on Ctrl-C),
``train.log``, ``config.toml``, ``history.json``, ``curves.png``, ``summary.md`` and, for
``method = "alcn"``, ``fewshot.json`` and the Normalizer weight file ``alcn_normalizer.npz``
(:mod:`alcn_cv.weight_file`) with ``trained = True``.
``resume=True`` continues from the checkpoint with the same result as an uninterrupted run.
"""

from __future__ import annotations

import contextlib
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from alcn_cv.data.phos import PhosBatch
from alcn_cv.errors import InputError
from alcn_cv.io import atomic_write, held_folder, interrupts_deferred, sigint_as_keyboard_interrupt, write_json
from alcn_cv.nets.device import torch_device
from alcn_cv.nn import torch_threads
from alcn_cv.presets import dump_toml
from alcn_cv.report import log_to, machine, nan_to_none
from alcn_cv.train import distributed
from alcn_cv.train.checkpoint import (
    TrainState,
    check_run_folder,
    load_checkpoint,
    restore_checkpoint,
    run_folder,
    save_checkpoint,
    write_normalizer_file,
)
from alcn_cv.train.config import TrainConfig, load_config
from alcn_cv.train.fewshot import FewShotSetup, fewshot_validation, standard_methods
from alcn_cv.train.models import JointModel
from alcn_cv.train.stage2 import NonFiniteLossError
from alcn_cv.train.summary import plot_curves, summary_markdown
from alcn_cv.train.windows import check_windows, load_windows

__all__ = ["JointModel", "TrainResult", "load_checkpoint", "train"]

logger = logging.getLogger(__name__)

_CHECKPOINT = "checkpoint.pt"


@dataclass
class TrainResult:
    """What :func:`train` returns.

    Attributes:
        out_dir: the run folder.
        status: ``"done"``, ``"interrupted"`` (Ctrl-C; a checkpoint was saved) or ``"nan"``.
        history: one dict per finished epoch (losses, accuracies, per-family validation accuracy).
        val_accuracy: validation accuracy after the last finished epoch (held-out lightings).
        val_by_family: the same per held-out lighting family.
        weights: the exported Normalizer weight file (``method = "alcn"`` and status ``"done"``).
        seconds: wall-clock time of this call.
        model: the trained :class:`JointModel` (in eval mode, on the CPU).
        fewshot: results of the few-shot validation (:mod:`alcn_cv.train.fewshot`) per method.
        stopped_at: an interrupted run's place, that of its checkpoint: the epoch under way (from 1) and the steps
            done in it.
        interruption: what interrupted the run: Ctrl-C's ``KeyboardInterrupt``, or the command line's
            :class:`~alcn_cv.cli.Terminated` (SIGTERM).
    """

    out_dir: Path
    status: str
    history: list[dict[str, Any]] = field(default_factory=list)
    val_accuracy: float = float("nan")
    val_by_family: dict[str, float] = field(default_factory=dict)
    weights: Path | None = None
    seconds: float = 0.0
    model: JointModel | None = None
    fewshot: dict[str, Any] = field(default_factory=dict)
    stopped_at: tuple[int, int] | None = None
    interruption: KeyboardInterrupt | None = None


@dataclass
class _Shards:
    """The training windows as tensors, and how each process walks them in an epoch."""

    windows: torch.Tensor
    labels: torch.Tensor
    anchors: torch.Tensor | None  # the "meta" objective's anchor-lighting mask
    used: int  # windows used per epoch: a multiple of the number of processes
    steps_per_epoch: int


def train(
    config: str | Path | dict[str, Any] | TrainConfig | None = None,
    out_dir: str | Path = "out/alcn",
    *,
    resume: bool = False,
    overwrite: bool = False,
    progress: bool = True,
    command: str = "",
    conf: str | None = None,
) -> TrainResult:
    """Train ALCN's Normalizer jointly with a detector (Eq. 2), or a baseline detector, on ``run.threads`` torch
    threads (:func:`alcn_cv.nn.torch_threads`: the caller's count is restored after the run).

    Args:
        config: a :class:`~alcn_cv.train.config.TrainConfig`, a preset name, a TOML path or a dict
            (see :mod:`alcn_cv.train.config`).
        out_dir: the run folder (checkpoint, log, curves, history, exported weights).
        resume: continue from ``out_dir/checkpoint.pt``; the result equals an uninterrupted run.
        overwrite: replace the earlier run that ``out_dir`` holds (checked before any work,
            :func:`~alcn_cv.train.checkpoint.check_run_folder`).
        progress: show progress bars.
        command, conf: the command line that makes the run again and the preset's name, recorded in the weight file.

    Returns:
        A :class:`TrainResult`. Ctrl-C (and SIGTERM under the command line) saves a checkpoint and returns status
        ``"interrupted"``.

    Raises:
        InputError: bad configuration or data; ``out_dir`` holds an earlier run (without ``resume`` or
            ``overwrite``) or other files, or another run is writing into it (:func:`alcn_cv.io.held_folder`).
        WeightFileError: ``resume`` with a missing, corrupt or incompatible checkpoint.
        NonFiniteLossError: the loss became NaN or inf; the last good checkpoint is kept.
    """
    cfg = load_config(config)
    check_run_folder(out_dir, resume=resume, overwrite=overwrite)
    distributed.init(cfg.run.device)
    out = run_folder(out_dir)
    start = time.perf_counter()
    machine_start = machine()
    with (
        # the main process holds the folder (a second run into it is refused); the others write where it does
        held_folder(out) if distributed.is_main() else contextlib.nullcontext(),
        log_to(out / "train.log", append=resume) if distributed.is_main() else contextlib.nullcontext(),
        torch_threads(cfg.run.threads or None),
    ):
        ckpt, device = _prepare_run(cfg, out, resume)
        train_set, val_set, num_classes = _prepare_data(cfg, out, device, progress and distributed.is_main())
        model, optimizer, state = _build_models(cfg, num_classes, device, ckpt, start, out)
        result = TrainResult(out, "done", state.history, model=model)
        result.interruption = _fit(cfg, model, optimizer, state, train_set, val_set, device, out, progress)
        if result.interruption is not None:
            result.status, result.stopped_at = "interrupted", (state.epoch + 1, state.step_in_epoch)
        _finish(cfg, result, train_set, state, progress, command, conf)
        result.seconds = time.perf_counter() - start
        if distributed.is_main():
            atomic_write(out / "summary.md", summary_markdown(cfg, result, machine_start))
        logger.info(
            "%s run %s in %.1f min: held-out validation accuracy %.4f",
            cfg.model.method,
            result.status,
            result.seconds / 60,
            result.val_accuracy,
        )
    return result


# ------------------------------------------------------------------------------ preparation


def _prepare_run(cfg: TrainConfig, out: Path, resume: bool) -> tuple[dict[str, Any] | None, torch.device]:
    """Read the checkpoint to resume (or record the configuration), choose the device."""
    ckpt = load_checkpoint(out / _CHECKPOINT, cfg) if resume else None
    if not resume and distributed.is_main():
        # its folders absolute, as the checkpoint's: `--conf OUT/config.toml` reads the same data from any folder
        (out / "config.toml").write_text(dump_toml(cfg.resolved()), encoding="utf-8")
    device = torch_device(cfg.run.device, "config key 'run.device'")
    if distributed.world_size() > 1 and device.type == "cuda":
        device = torch.device("cuda", distributed.local_rank())
    return ckpt, device


def _prepare_data(
    cfg: TrainConfig, out: Path, device: torch.device, progress: bool
) -> tuple[PhosBatch, PhosBatch, int]:
    """The training and validation windows and the number of classes."""
    train_set, val_set = load_windows(cfg, out, progress)
    num_classes = check_windows(train_set, val_set)
    logger.info(
        "%s: %d training windows (%s), %d validation windows (held out: %s), %d classes, device %s, %d process(es)",
        cfg.model.method,
        len(train_set),
        ", ".join(cfg.data.train_lighting),
        len(val_set),
        ", ".join(cfg.data.val_lighting),
        num_classes,
        device,
        distributed.world_size(),
    )
    return train_set, val_set, num_classes


def _build_models(
    cfg: TrainConfig, num_classes: int, device: torch.device, ckpt: dict[str, Any] | None, start: float, out: Path
) -> tuple[JointModel, torch.optim.Optimizer, TrainState]:
    """The model (initialised from ``cfg.seed``), its optimizer and the run's state, restored from ``ckpt``."""
    torch.manual_seed(cfg.seed)
    model = JointModel(cfg.model, num_classes).to(device)
    optimizer = _make_optimizer(model, cfg)
    if ckpt is None:
        return model, optimizer, TrainState(start=start)
    state = restore_checkpoint(ckpt, model, optimizer, start)
    logger.info("resumed from %s at epoch %d, step %d", out / _CHECKPOINT, state.epoch + 1, state.step_in_epoch)
    return model, optimizer, state


def _make_optimizer(model: JointModel, cfg: TrainConfig) -> torch.optim.Optimizer:
    groups = [{"params": model.detector.parameters(), "lr": cfg.optim.lr, "base_lr": cfg.optim.lr}]
    if model.normalizer is not None:
        lr = cfg.optim.normalizer_lr
        groups.append({"params": model.normalizer.parameters(), "lr": lr, "base_lr": lr})
    return torch.optim.Adam(groups)


def _shards(cfg: TrainConfig, train_set: PhosBatch) -> _Shards:
    world = distributed.world_size()
    used = len(train_set) // world * world
    anchors = None
    if cfg.optim.objective == "meta":
        families = train_set.light_families  # windows read from data.path: the anchor is not checked against them yet
        anchor_id = families.index(cfg.data.anchor_lighting) if cfg.data.anchor_lighting in families else -1
        anchors = torch.from_numpy(train_set.light_ids == anchor_id)
        if not anchors.any() or anchors.all():
            raise InputError(
                f"optim.objective 'meta' needs training windows under the anchor lighting "
                f"{cfg.data.anchor_lighting!r} and under others"
            )
    return _Shards(
        torch.from_numpy(train_set.windows),
        torch.from_numpy(train_set.labels),
        anchors,
        used,
        math.ceil(used // world / cfg.optim.batch_size),
    )


# ------------------------------------------------------------------------------- epoch loop


def _fit(
    cfg: TrainConfig,
    model: JointModel,
    optimizer: torch.optim.Optimizer,
    state: TrainState,
    train_set: PhosBatch,
    val_set: PhosBatch,
    device: torch.device,
    out: Path,
    progress: bool,
) -> KeyboardInterrupt | None:
    """Train until ``optim.epochs``, validating and saving a checkpoint after every epoch.

    Returns:
        None, or the interrupt (Ctrl-C or SIGTERM) that stopped it, after a checkpoint was saved.
    """
    ddp = distributed.wrap(model, device)
    shards = _shards(cfg, train_set)
    model.train()
    try:
        with sigint_as_keyboard_interrupt():
            while state.epoch < cfg.optim.epochs:
                _train_epoch(cfg, ddp, optimizer, state, shards, device, out, progress)
                _end_epoch(cfg, model, optimizer, state, val_set, device, out)
    except KeyboardInterrupt as exc:
        _save(out, cfg, model, optimizer, state, "interrupted")
        logger.warning(
            "interrupted at epoch %d, step %d: checkpoint saved to %s (continue with --resume)",
            state.epoch + 1,
            state.step_in_epoch,
            out / _CHECKPOINT,
        )
        return exc
    except NonFiniteLossError as exc:
        logger.error("%s", exc)
        raise
    return None


def _train_epoch(
    cfg: TrainConfig,
    ddp: torch.nn.Module,
    optimizer: torch.optim.Optimizer,
    state: TrainState,
    shards: _Shards,
    device: torch.device,
    out: Path,
    progress: bool,
) -> None:
    """The remaining optimisation steps of the current epoch, on this process's share of its order."""
    rank, world, batch = distributed.rank(), distributed.world_size(), cfg.optim.batch_size
    steps, epoch, sums = shards.steps_per_epoch, state.epoch, state.sums
    perm, gains = _epoch_plan(cfg, epoch, len(shards.windows))
    mine = perm[: shards.used][rank::world]
    params = [p for p in ddp.parameters() if p.requires_grad]
    bar = tqdm(
        total=steps,
        initial=state.step_in_epoch,
        desc=f"epoch {epoch + 1}/{cfg.optim.epochs}",
        disable=not (progress and distributed.is_main()),
        leave=False,
    )
    while state.step_in_epoch < steps:
        idx = mine[state.step_in_epoch * batch : (state.step_in_epoch + 1) * batch]
        x = shards.windows[idx].unsqueeze(1).float().div_(255.0).mul_(gains[idx].view(-1, 1, 1, 1))
        x = x.clamp_(0.0, 1.0).to(device)
        y = shards.labels[idx].to(device)
        factor = _lr_factor(cfg, epoch * steps + state.step_in_epoch, steps)
        for group in optimizer.param_groups:
            group["lr"] = group["base_lr"] * factor
        logits = ddp(x) if shards.anchors is None else ddp(x, shards.anchors[idx].to(device))
        loss = F.cross_entropy(logits, y)
        if not torch.isfinite(loss):
            ckpt_path = out / _CHECKPOINT
            kept = (
                f"the last good checkpoint is {ckpt_path}" if ckpt_path.is_file() else "no checkpoint was written yet"
            )
            raise NonFiniteLossError(
                f"loss is {loss.item()} at epoch {epoch + 1}, step {state.step_in_epoch + 1}; "
                f"training stopped, {kept} (try a lower optim.lr)"
            )
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if cfg.optim.grad_clip:
            torch.nn.utils.clip_grad_norm_(params, cfg.optim.grad_clip)
        # a Ctrl-C between the step and its counter would checkpoint the step's weights with the counter of before
        # (a resumed run takes that step twice)
        with interrupts_deferred():
            optimizer.step()
            sums[0] += loss.item() * len(idx)
            sums[1] += int((logits.argmax(1) == y).sum())
            sums[2] += len(idx)
            state.step_in_epoch += 1
        bar.update()
        bar.set_postfix(loss=f"{sums[0] / sums[2]:.3f}", acc=f"{sums[1] / sums[2]:.3f}")
        if state.step_in_epoch % cfg.run.log_every == 0:
            logger.info(
                "epoch %d step %d/%d: loss %.4f acc %.4f lr %.2e",
                epoch + 1,
                state.step_in_epoch,
                steps,
                sums[0] / sums[2],
                sums[1] / sums[2],
                cfg.optim.lr * factor,
            )
        _on_step(epoch * steps + state.step_in_epoch)
    bar.close()


def _end_epoch(
    cfg: TrainConfig,
    model: JointModel,
    optimizer: torch.optim.Optimizer,
    state: TrainState,
    val_set: PhosBatch,
    device: torch.device,
    out: Path,
) -> None:
    """Validate on the held-out lightings, record the epoch, save the checkpoint, history and curves."""
    sums = state.sums
    val_loss, val_acc, by_family = _validate(model, val_set, device)
    logger.info(
        "epoch %d/%d: train loss %.4f acc %.4f | held-out val loss %.4f acc %.4f (%s)",
        state.epoch + 1,
        cfg.optim.epochs,
        sums[0] / sums[2],
        sums[1] / sums[2],
        val_loss,
        val_acc,
        ", ".join(f"{k} {v:.3f}" for k, v in by_family.items()),
    )
    # a Ctrl-C between the entry and the counter would checkpoint the epoch's entry with the epoch unfinished (a
    # resumed run records it twice)
    with interrupts_deferred():
        state.history.append(
            {
                "epoch": state.epoch + 1,
                "train_loss": sums[0] / sums[2],
                "train_acc": sums[1] / sums[2],
                "val_loss": val_loss,
                "val_acc": val_acc,
                "val_by_family": by_family,
                "seconds": round(state.elapsed(), 1),
            }
        )
        state.epoch, state.step_in_epoch, state.sums = state.epoch + 1, 0, [0.0, 0, 0]
    _save(out, cfg, model, optimizer, state, "epoch")
    if distributed.is_main():
        write_json(out / "history.json", nan_to_none(state.history))
        plot_curves(state.history, out / "curves.png")


def _save(
    out: Path, cfg: TrainConfig, model: JointModel, optimizer: torch.optim.Optimizer, state: TrainState, status: str
) -> None:
    if distributed.is_main():
        save_checkpoint(out / _CHECKPOINT, cfg, model, optimizer, state, status)


def _lr_factor(cfg: TrainConfig, step: int, steps_per_epoch: int) -> float:
    o = cfg.optim
    warm = min(1.0, (step + 1) / o.warmup_steps) if o.warmup_steps else 1.0
    total = steps_per_epoch * o.epochs
    return warm * 0.5 * (1.0 + math.cos(math.pi * min(step, total) / total))


def _epoch_plan(cfg: TrainConfig, epoch: int, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Order and intensity gains of an epoch; a function of (seed, epoch) only, so resuming is exact."""
    g = torch.Generator().manual_seed(int(np.random.SeedSequence([cfg.seed, epoch]).generate_state(1)[0]))
    perm = torch.randperm(n, generator=g)
    lo, hi = (math.log(v) for v in cfg.data.gain_jitter)
    gains = torch.exp(lo + (hi - lo) * torch.rand(n, generator=g))
    return perm, gains


def _on_step(global_step: int) -> None:
    """Called after every optimisation step (a hook for tests that simulate Ctrl-C)."""


# ------------------------------------------------------------------------------- validation


@torch.no_grad()
def _validate(model: JointModel, val_set: PhosBatch, device: torch.device) -> tuple[float, float, dict[str, float]]:
    model.eval()
    x = torch.from_numpy(val_set.windows)
    y = torch.from_numpy(val_set.labels)
    loss, preds = 0.0, []
    for i in range(0, len(x), 512):
        xb = x[i : i + 512].to(device).unsqueeze(1).float() / 255.0
        logits = model(xb)
        loss += float(F.cross_entropy(logits, y[i : i + 512].to(device), reduction="sum"))
        preds.append(logits.argmax(1).cpu())
    correct = (torch.cat(preds) == y).numpy()
    by_family = {
        val_set.light_families[f]: float(correct[val_set.light_ids == f].mean()) for f in np.unique(val_set.light_ids)
    }
    model.train()
    return loss / len(x), float(correct.mean()), by_family


def _fewshot(model: JointModel, cfg: TrainConfig, progress: bool) -> dict[str, Any]:
    f = cfg.fewshot
    setup = FewShotSetup.of(f, seed=cfg.seed)
    methods = standard_methods(model, f.dog, cfg.model.num_kernels, cfg.model.sigma_step, cfg.model.detector_input)
    logger.info(
        "few-shot validation: %d new objects, %d image(s) each, tested under %s",
        f.n_objects,
        f.real_images,
        ", ".join(f.test_lighting),
    )
    return fewshot_validation(methods, setup, progress=progress)


# ---------------------------------------------------------------------------------- export


def _finish(
    cfg: TrainConfig,
    result: TrainResult,
    train_set: PhosBatch,
    state: TrainState,
    progress: bool,
    command: str,
    conf: str | None,
) -> None:
    """After the loop: the last validation in ``result``, then, for a finished Normalizer run, the
    few-shot validation (``fewshot.json``) and the weight file. ``result.model`` ends on the CPU, where the few-shot
    validation runs its methods (a ``run.device = "cuda"`` run's too)."""
    model = result.model
    model.eval()
    if distributed.world_size() > 1 and not distributed.replicas_equal(model):
        logger.error("the replicas of the %d processes hold different weights", distributed.world_size())
    model.cpu()
    if state.history:
        result.val_accuracy = state.history[-1]["val_acc"]
        result.val_by_family = state.history[-1]["val_by_family"]
    if result.status != "done" or model.normalizer is None or not distributed.is_main():
        return
    total = state.history[-1]["seconds"] if state.history else state.elapsed()
    if cfg.fewshot.enabled:
        result.fewshot = _fewshot(model, cfg, progress)
        write_json(result.out_dir / "fewshot.json", nan_to_none(result.fewshot))
    result.weights = write_normalizer_file(model, cfg, train_set, result, total, command, conf)
    logger.info("Normalizer weights written to %s", result.weights)
