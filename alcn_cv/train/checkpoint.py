"""What a training run saves: its checkpoint, and the trained Normalizer's weight file.

The checkpoint (``checkpoint.pt``, written atomically after every epoch and on Ctrl-C) holds
the model, the optimizer, the torch random state and the :class:`TrainState`, so that a run
resumed from it ends with the same weights as an uninterrupted one. The weight file
(``alcn_normalizer.npz``, :mod:`alcn_cv.weight_file`) holds the Normalizer with ``trained = True``
and the record of its training.

Every checkpoint, ``alcn train-real-light``'s (:mod:`alcn_cv.train.real_light`) too, starts with
:func:`checkpoint_header` and is read back by :func:`load_checkpoint`.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch

from alcn_cv.data.phos import PhosBatch
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.gaussian_mixture import gaussian_sigmas
from alcn_cv.io import atomic_write, check_writable, make_folder
from alcn_cv.report import listed, provenance
from alcn_cv.train.config import RealLightConfig, TrainConfig
from alcn_cv.train.models import JointModel, measure_output_range
from alcn_cv.weight_file import save_normalizer_file

if TYPE_CHECKING:
    from alcn_cv.train.trainer import TrainResult

__all__ = [
    "CHECKPOINT_FORMAT",
    "CHECKPOINT_VERSION",
    "REAL_LIGHT_CHECKPOINT_FORMAT",
    "TrainState",
    "check_checkpoint",
    "check_run_folder",
    "checkpoint_header",
    "earlier_run",
    "load_checkpoint",
    "restore_checkpoint",
    "run_folder",
    "save_checkpoint",
    "versions",
    "write_normalizer_file",
]

CHECKPOINT_FORMAT = "alcn-cv/checkpoint"
#: The format of ``alcn train-real-light``'s checkpoints: another run state than ``alcn train``'s.
REAL_LIGHT_CHECKPOINT_FORMAT = "alcn-cv/real-light-checkpoint"
CHECKPOINT_VERSION = 1

#: The checkpoint format and the command of each kind of run configuration.
_KINDS: dict[type, tuple[str, str]] = {
    TrainConfig: (CHECKPOINT_FORMAT, "alcn train"),
    RealLightConfig: (REAL_LIGHT_CHECKPOINT_FORMAT, "alcn train-real-light"),
}


@dataclass
class TrainState:
    """Where a run is.

    Attributes:
        history: one dict per finished epoch.
        epoch: the current epoch (0-based; equals the number of finished epochs).
        step_in_epoch: optimisation steps done in the current epoch.
        sums: the current epoch's running ``[loss sum, correct windows, windows]``.
        start: the :func:`time.perf_counter` origin of the run's clock (moved back by the time
            already spent when resuming).
    """

    history: list[dict[str, Any]] = field(default_factory=list)
    epoch: int = 0
    step_in_epoch: int = 0
    sums: list[float] = field(default_factory=lambda: [0.0, 0, 0])
    start: float = field(default_factory=time.perf_counter)

    def elapsed(self) -> float:
        """Seconds of the run so far (across resumptions)."""
        return time.perf_counter() - self.start


def run_folder(out: str | Path) -> Path:
    """The run folder ``out`` of a training command, made when missing: a folder empty but for hidden files (a
    ``.gitkeep``) and configurations (``*.toml``), or an earlier run's (its ``train.log``); never a folder of other
    files, so that a run's files never mix with a data set's.

    Raises:
        InputError: ``out`` holds other files and no ``train.log``, or lies under a file.
    """
    out = Path(out)
    _check_not_foreign(out)
    return make_folder(out)


def _check_not_file(out: Path) -> None:
    """Refuse a run folder that is a file (a weight file's path given for the folder), or lies under one."""
    if out.exists() and not out.is_dir():
        raise InputError(
            f"{out} is a file, not a folder: --out names the run folder, into which the run writes its weight file "
            f"and checkpoints; give a folder{f' (e.g. {out.parent})' if out.suffix == '.npz' else ''}"
        )
    file = next((p for p in out.parents if p.exists() and not p.is_dir()), None)
    if file is not None:
        raise InputError(f"{out} lies under the file {file}: --out names the run folder; give a folder")


def _check_not_foreign(out: Path) -> None:
    others = out.is_dir() and any(not p.name.startswith(".") and p.suffix != ".toml" for p in out.iterdir())
    if others and not (out / "train.log").is_file():
        raise InputError(f"{out} holds other files than a training run's (no train.log); give another --out")


def earlier_run(out: str | Path) -> list[str]:
    """The results of an earlier run in the run folder ``out`` (its ``train.log`` beside them): its checkpoint,
    ``history.json`` and weight files (``*.npz``), by name; none for a run that failed before its first save."""
    out = Path(out)
    if not (out / "train.log").is_file():
        return []
    names = ("checkpoint.pt", "history.json")
    return sorted(p.name for p in out.iterdir() if p.is_file() and (p.name in names or p.suffix == ".npz"))


def check_run_folder(out: str | Path, *, resume: bool = False, overwrite: bool = False, resumable: bool = True) -> Path:
    """Check, before any work and writing nothing, that a run may go into the folder ``out``: not a folder of other
    files (:func:`run_folder`), nor, unless the run resumes it or ``overwrite``, a folder of an earlier run
    (:func:`earlier_run`); ``resume`` and ``overwrite`` are exclusive. ``resumable``: the command has ``--resume``.

    Raises:
        InputError: either, named with the way out (``--resume`` where ``resumable``, ``--overwrite``, another
            ``--out``); ``out`` is a file or lies under one, or cannot be written; both ``resume`` and ``overwrite``.
    """
    if resume and overwrite:
        raise InputError("give --resume (go on with the run in --out) or --overwrite (replace it), not both")
    out = Path(out)
    _check_not_file(out)
    _check_not_foreign(out)
    check_writable(out / "train.log")  # before the data are read: the first file a run writes
    results = [] if resume or overwrite else earlier_run(out)
    if results:
        shown = listed(results, 4)
        ways = "--resume continues it, --overwrite replaces it" if resumable else "--overwrite replaces it"
        raise InputError(f"{out} holds an earlier run ({shown}): {ways}, or give another --out")
    return out


def versions() -> dict[str, str]:
    """The versions that write a checkpoint or weight file."""
    import alcn_cv

    return {"alcn_cv": str(alcn_cv.__version__), "torch": str(torch.__version__)}


def save_checkpoint(
    path: Path, cfg: TrainConfig, model: JointModel, optimizer: torch.optim.Optimizer, state: TrainState, status: str
) -> None:
    """Write the checkpoint atomically (``status``: ``"epoch"`` or ``"interrupted"``), with the random state of torch
    on the CPU and, for a model on a CUDA device, of that device (its dropout draws there)."""
    device = next(model.parameters()).device
    ckpt = {
        **checkpoint_header(cfg),
        "status": status,
        "epoch": state.epoch,
        "step_in_epoch": state.step_in_epoch,
        "sums": state.sums,
        "history": state.history,
        "model": model.state_dict(),
        "optimizer": optimizer.state_dict(),
        "rng": torch.get_rng_state(),
        "cuda_rng": torch.cuda.get_rng_state(device) if device.type == "cuda" else None,
        "elapsed": state.elapsed(),
    }
    atomic_write(path, lambda f: torch.save(ckpt, f))


def _config_dict(cfg: TrainConfig | RealLightConfig) -> dict[str, Any]:
    return cfg.to_dict() if isinstance(cfg, TrainConfig) else asdict(cfg)


def checkpoint_header(cfg: TrainConfig | RealLightConfig) -> dict[str, Any]:
    """The entries of a checkpoint that :func:`load_checkpoint` checks: the format of the command ``cfg`` configures
    (``alcn train`` or ``alcn train-real-light``), its version, the versions that write it and ``cfg`` with its folders
    absolute (``cfg.resolved()``), so that a run resumed from another working folder is checked against, and reads,
    the same data."""
    return {
        "format": _KINDS[type(cfg)][0],
        "version": CHECKPOINT_VERSION,
        "versions": versions(),
        "config": _config_dict(cfg.resolved()),
    }


def _differences(saved: dict[str, Any], cfg: TrainConfig | RealLightConfig) -> list[str]:
    """The settings of ``cfg`` a run resumed from a checkpoint written with ``saved`` must keep and does not, each
    with both values: all of a :class:`RealLightConfig` but a larger ``steps`` (training longer; a setting the
    checkpoint predates compared as its default, which that run had); a :class:`TrainConfig`'s model, data, seed and
    optimisation (not its run options). Folders are compared absolute, as the checkpoint holds them
    (:func:`checkpoint_header`)."""
    now = _config_dict(cfg.resolved())
    if isinstance(cfg, RealLightConfig):
        saved = {**_config_dict(RealLightConfig()), **saved}  # a key added since it was written: its default
        pairs = [(k, saved.get(k), v) for k, v in now.items()]
        changed = [(k, a, b) for k, a, b in pairs if a != b and not (k == "steps" and _larger(b, a))]
    else:
        pairs = [(f"{t}.{k}", saved[t].get(k), now[t][k]) for t in ("model", "data", "optim") for k in now[t]]
        changed = [(k, a, b) for k, a, b in [*pairs, ("seed", saved.get("seed"), now["seed"])] if a != b]
    return [f"{key} ({before!r} in the checkpoint, {after!r} now)" for key, before, after in sorted(changed)]


def _larger(now: Any, saved: Any) -> bool:
    return isinstance(now, int) and isinstance(saved, int) and now > saved


def load_checkpoint(path: str | Path, cfg: TrainConfig | RealLightConfig | None = None) -> dict[str, Any]:
    """Read a checkpoint of ``alcn train`` or ``alcn train-real-light`` (:func:`checkpoint_header`) and check it
    (:func:`check_checkpoint`): given ``cfg``, that it is one of the command ``cfg`` configures, written with the
    settings a resumed run keeps.

    Raises:
        WeightFileError: missing, corrupt, or as :func:`check_checkpoint`.
    """
    path = Path(path)
    if not path.is_file():
        raise WeightFileError(f"checkpoint not found: {path} (a run writes it at its first save)")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)  # a run on a GPU resumes on a CPU too
    except Exception as exc:  # torch raises many kinds for a damaged zip or pickle
        raise WeightFileError(f"checkpoint {path} is corrupt or unreadable ({type(exc).__name__}: {exc})") from None
    check_checkpoint(ckpt, path, cfg)
    return ckpt


def check_checkpoint(ckpt: Any, path: str | Path, cfg: TrainConfig | RealLightConfig | None = None) -> None:
    """Check a checkpoint read from ``path`` (:func:`load_checkpoint`, which checks it without ``cfg``): one of
    ``alcn train`` or ``alcn train-real-light`` of this version and, given ``cfg``, of the command ``cfg`` configures,
    written with the settings a resumed run keeps.

    Raises:
        WeightFileError: of another format (another command's) or version (the message gives the versions that wrote
            it and this one), or written with other settings (each named with both values).
    """
    kinds = [_KINDS[type(cfg)]] if cfg is not None else list(_KINDS.values())
    if not isinstance(ckpt, dict) or ckpt.get("format") not in [fmt for fmt, _ in kinds]:
        raise WeightFileError(f"{path} is not a checkpoint of {' or '.join(command for _, command in kinds)}")
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise WeightFileError(
            f"{path}: checkpoint version {ckpt.get('version')} written by {ckpt.get('versions')}; this alcn-cv "
            f"({versions()}) reads version {CHECKPOINT_VERSION}"
        )
    if cfg is not None:
        diff = _differences(ckpt["config"], cfg)
        if diff:
            raise WeightFileError(
                f"checkpoint {path} was written with another configuration: differs in {'; '.join(diff)}; start a "
                "new run folder or use its configuration"
            )


def restore_checkpoint(
    ckpt: dict[str, Any], model: JointModel, optimizer: torch.optim.Optimizer, start: float
) -> TrainState:
    """Load a checkpoint read by :func:`load_checkpoint` into the model, the optimizer and torch's
    random state (the CPU's, and the model's CUDA device's where the checkpoint holds one); return the run's state,
    its clock (started at ``start``) moved back by the time the checkpoint records."""
    model.load_state_dict(ckpt["model"])
    optimizer.load_state_dict(ckpt["optimizer"])
    torch.set_rng_state(ckpt["rng"])
    device = next(model.parameters()).device
    if device.type == "cuda" and ckpt.get("cuda_rng") is not None:
        torch.cuda.set_rng_state(ckpt["cuda_rng"], device)
    return TrainState(ckpt["history"], ckpt["epoch"], ckpt["step_in_epoch"], ckpt["sums"], start - ckpt["elapsed"])


def write_normalizer_file(
    model: JointModel,
    cfg: TrainConfig,
    train_set: PhosBatch,
    result: TrainResult,
    seconds: float,
    command: str = "",
    conf: str | None = None,
) -> Path:
    """Write the trained Normalizer as ``alcn_normalizer.npz`` in the run folder.

    The header gets the output range measured on up to 4000 training windows (drawn with
    ``cfg.seed``), the detector input policy and the record of the training (configuration,
    versions, validation, few-shot validation, time; the command line, the preset's name, the machine and the date,
    :func:`~alcn_cv.report.provenance`). The configuration is ``cfg`` as a file users share
    records it (:meth:`TrainConfig.shareable <alcn_cv.train.config.TrainConfig.shareable>`: its folders as given, the
    home folder written ``~``), where the checkpoint holds them absolute.
    """
    if model.normalizer is None:
        raise ValueError(f"model.method {cfg.model.method!r} has no Normalizer to write")
    rng = np.random.default_rng(cfg.seed)
    sample = train_set.windows[rng.choice(len(train_set), min(len(train_set), 4000), replace=False)]
    model.eval()
    net = model.normalizer
    config = dict(net.config)
    config["init_weights"] = None  # the arrays hold the trained weights
    meta = {
        "config": config,
        "sigmas": list(gaussian_sigmas(cfg.model.num_kernels, cfg.model.sigma_step)),
        "working_scale": cfg.model.working_scale,
        "output_range": measure_output_range(model, sample),
        "trained": True,
        "detector_input": cfg.model.detector_input,
        "description": f"trained with a detector by `alcn train` (objective {cfg.optim.objective!r}), seed {cfg.seed}, "
        f"{len(train_set)} windows of {train_set.n_objects} objects, {seconds / 60:.1f} min",
        "training": {
            "config": cfg.shareable().to_dict(),
            "versions": versions(),
            "val_accuracy": result.val_accuracy,
            "val_by_family": result.val_by_family,
            "fewshot": result.fewshot,
            "seconds": round(seconds, 1),
            **provenance(command, conf),
        },
    }
    return save_normalizer_file(result.out_dir / "alcn_normalizer.npz", net.state_arrays(), meta)
