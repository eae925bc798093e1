r"""Joint training of the Normalizer with a detector (Rad, Roth & Lepetit, BMVC 2017, Eq. 2).

No one knows the right mixture weights for a window, so the Normalizer ``f`` is trained through
a detector ``g`` that classifies the normalized windows::

    min_{Theta, Phi}  sum_j  -log p( y_j | g_Phi( ALCN(I_j; f_Theta(I_j)) ) )         (Eq. 2)

where ``ALCN(I; w) = (sum_i w_i G_{sigma_i}) * I`` (Eq. 1) is differentiable in ``w``, so the
gradient reaches ``Theta``. Only the centre 32x32 of the mixture is needed and the image needs no
gradient, so :class:`CentreMixture` blurs just that centre with each kernel's own width (no
padding: the 64x64 window holds every tap) and weighs the blurs; it equals the centre of
:class:`~alcn_cv.filters.kornia_mixture.GaussianMixture2d` on the window (a test checks it to
1e-5) at a tenth of its cost, which matters on 2 CPU cores.
Each 64x64 training window (:mod:`alcn_cv.data.phos`) is used as in the paper: the Normalizer
sees its centre 48x48, the mixture filters the whole 64x64 and the detector gets the centre
32x32 (free of border effects for sigmas up to 5), after the detector input policy
(``model.detector_input``, per-window standardization by default).
With ``model.mixture = "dense"`` the window is filtered by Eq. 3 instead, as at inference: the
Normalizer runs fully-convolutionally over the 64x64 window (:meth:`Normalizer.dense`, windows
every :data:`DENSE_GRID_STRIDE` pixels, reflect-101 beyond the window) and its per-pixel weight
maps multiply the image before the blurs (:meth:`CentreMixture.dense`), so the weights can change
inside a window, across a shadow edge for example. Eq. 1 cannot learn that; a dense step costs ~6x a window step.

The default objective (``optim.objective = "meta"``) rehearses the paper's second stage inside
the first: the detector learns from windows under one *anchor* lighting only (as a new detector
later learns from a few images under one light), while the Normalizer minimises the loss on
*all* windows with the detector held fixed for the non-anchor ones (:meth:`JointModel.forward`
with an ``anchor`` mask). Its gradient therefore says "make this lighting look like the anchor
lighting to a detector", the invariance the second stage needs. With plain Eq. 2
(``"joint"``), the Normalizer beat a DoG on held-out lightings of the training objects but lost
to it on new objects learnt from one image; with ``"meta"`` it beat the DoG on both in our
measurements (``alcn_cv/weights/MODEL_CARD.md``).

The same command trains the same detector on a fixed DoG (``model.method = "dog"``) or on the
raw windows (``"none"``), so the benefit of the learned Normalizer is measured, not assumed.
Validation uses *held-out lighting families* (``data.val_lighting``), never the training light.

Outputs in the run folder: ``checkpoint.pt`` (atomic, every epoch and on Ctrl-C),
``train.log``, ``history.json``, ``curves.png`` and, for ``method = "alcn"``, the Normalizer
weight file ``alcn_normalizer.npz`` (:mod:`alcn_cv.weight_file`) with ``trained = True``.
``resume=True`` continues from the checkpoint with the same result as an uninterrupted run.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import logging
import math
import os
import platform
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from tqdm.auto import tqdm

from alcn_cv.data.phos import WINDOW, PhosBatch, load, render_windows
from alcn_cv.errors import InputError, WeightFileError
from alcn_cv.filters.gaussian_mixture import gaussian_kernel1d, gaussian_sigmas, kernel_radius
from alcn_cv.io import atomic_write
from alcn_cv.nets.detector import INPUT, Detector
from alcn_cv.nets.normalizer import Normalizer
from alcn_cv.train import distributed
from alcn_cv.train.config import TrainConfig, dump_toml, load_config
from alcn_cv.train.stage2 import NonFiniteLossError
from alcn_cv.weight_file import save_normalizer_file

__all__ = ["CHECKPOINT_FORMAT", "CHECKPOINT_VERSION", "JointModel", "TrainResult", "load_checkpoint", "train"]

logger = logging.getLogger(__name__)

CHECKPOINT_FORMAT = "alcn-cv/checkpoint"
CHECKPOINT_VERSION = 1
_NORMALIZER_CROP = (WINDOW - Normalizer.window) // 2  # 8: the Normalizer sees the centre 48x48
_DETECTOR_CROP = (WINDOW - INPUT) // 2  # 16: the detector sees the centre 32x32
_STD_EPS = 1e-4
#: Spacing of the windows whose weights the Normalizer predicts in ``model.mixture = "dense"``
#: training; the maps are interpolated in between, as the default runtime does at its stride 8.
DENSE_GRID_STRIDE = 8
_PART = 4096  # windows rendered per part (parts are independent of the worker count)
_ARRAYS = ("windows", "labels", "light_ids", "kinds", "offsets", "extents")


def dog_weights(num_kernels: int, step: float, sigmas: list[float]) -> list[float]:
    """Mixture weights of the DoG ``G_a - G_b`` in the basis ``sigma_i = i * step``."""
    w = [0.0] * num_kernels
    a, b = (int(round(s / step)) - 1 for s in sigmas)
    w[a] += 1.0
    w[b] -= 1.0
    return w


def standardize(x: torch.Tensor, eps: float = _STD_EPS) -> torch.Tensor:
    """Per-window standardization of ``(B, 1, H, W)``: zero mean and unit variance per window."""
    mean = x.mean(dim=(2, 3), keepdim=True)
    std = x.std(dim=(2, 3), keepdim=True, unbiased=False)
    return (x - mean) / (std + eps)


class CentreMixture(nn.Module):
    """Eq. 1 on the centre ``size x size`` of ``(B, 1, H, W)`` windows, one weight vector per window.

    The kernels are :func:`~alcn_cv.filters.gaussian_mixture.gaussian_kernel1d` (the library's
    definition), applied as banded matrices ``K_i`` (``size x H``): the centre of ``G_i * I`` is
    ``K_i I K_i^T``, two batched matrix products. Every tap must fall inside the window
    (``(H - size) / 2 >= radius``), so no border rule is involved.

    Shape:
        windows ``(B, 1, H, W)``, weights ``(B, N)`` -> ``(B, 1, size, size)``
    """

    def __init__(self, sigmas: tuple[float, ...], window: int = WINDOW, size: int = INPUT) -> None:
        super().__init__()
        self.sigmas, self.window, self.size = sigmas, window, size
        top = (window - size) // 2
        bands = np.zeros((len(sigmas), size, window), np.float32)
        for i, s in enumerate(sigmas):
            r = kernel_radius(s)
            if top < r:
                raise InputError(f"{window}x{window} windows are too small for sigma {s} around a {size}x{size} centre")
            k = gaussian_kernel1d(s)
            for y in range(size):
                bands[i, y, top + y - r : top + y + r + 1] = k
        self.register_buffer("bands", torch.from_numpy(bands), persistent=False)

    def blurs(self, windows: torch.Tensor) -> torch.Tensor:
        """``(B, N, size, size)``: the centre of the window blurred by each kernel."""
        if windows.shape[-2:] != (self.window, self.window):
            raise InputError(f"windows must be {self.window}x{self.window}, got {tuple(windows.shape[-2:])}")
        return self.bands @ windows @ self.bands.transpose(1, 2)

    def forward(self, windows: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            blurs = self.blurs(windows)
        return torch.einsum("bnhw,bn->bhw", blurs, weights).unsqueeze(1)

    def dense(self, windows: torch.Tensor, maps: torch.Tensor) -> torch.Tensor:
        """Eq. 3 on the centre: ``sum_i G_i * (F_i o I)`` with per-pixel weight maps.

        Shape:
            windows ``(B, 1, H, W)``, maps ``(B, N, H, W)`` -> ``(B, 1, size, size)``
        """
        if windows.shape[-2:] != (self.window, self.window) or maps.shape[-2:] != windows.shape[-2:]:
            raise InputError(f"windows and maps must be {self.window}x{self.window}, got "
                             f"{tuple(windows.shape[-2:])} and {tuple(maps.shape[-2:])}")
        return (self.bands @ (maps * windows) @ self.bands.transpose(1, 2)).sum(1, keepdim=True)


class JointModel(nn.Module):
    """Normalizer (or a fixed filter) + Gaussian mixture + detector input policy + detector.

    Args:
        cfg: the ``[model]`` section of a :class:`~alcn_cv.train.config.TrainConfig`.
        num_classes: background + objects.

    Shape:
        ``(B, 1, 64, 64)`` windows, float intensities in [0, 1] -> ``(B, num_classes)`` logits.
    """

    def __init__(self, cfg: Any, num_classes: int) -> None:
        super().__init__()
        self.method = cfg.method
        self.policy = cfg.detector_input
        self.dense_mixture = cfg.mixture == "dense"
        sigmas = gaussian_sigmas(cfg.num_kernels, cfg.sigma_step)
        dog = dog_weights(cfg.num_kernels, cfg.sigma_step, cfg.dog)
        self.mixture = CentreMixture(sigmas)
        self.normalizer: Normalizer | None = None
        if self.method == "alcn":
            self.normalizer = Normalizer(
                cfg.num_kernels, tuple(cfg.channels), cfg.hidden, cfg.output_scale,
                init_weights=dog if cfg.init == "dog" else None, activation=cfg.activation,
            )
        self.register_buffer("fixed_weights", torch.tensor(dog, dtype=torch.float32))
        self.detector = Detector(num_classes, tuple(cfg.detector_channels), cfg.detector_hidden, cfg.detector_dropout)

    def weights(self, windows: torch.Tensor) -> torch.Tensor:
        """Mixture weights ``(B, N)`` of each window: the Normalizer's, or the fixed DoG."""
        if self.normalizer is None:
            return self.fixed_weights.expand(len(windows), -1)
        c = _NORMALIZER_CROP
        return self.normalizer(windows[..., c : c + Normalizer.window, c : c + Normalizer.window])

    def normalized(self, windows: torch.Tensor) -> torch.Tensor:
        """The detector's input ``(B, 1, 32, 32)``: mixture output (or raw) centre, after the policy."""
        c = _DETECTOR_CROP
        out = windows[..., c : c + INPUT, c : c + INPUT] if self.method == "none" else self.response(windows)
        return standardize(out) if self.policy == "standardize" else out

    def response(self, windows: torch.Tensor) -> torch.Tensor:
        """The raw mixture output ``(B, 1, 32, 32)`` on the centre (before the input policy):
        Eq. 1 with one weight vector per window, or Eq. 3 with the Normalizer's per-pixel maps
        (``model.mixture = "dense"``)."""
        if self.dense_mixture and self.normalizer is not None:
            return self.mixture.dense(windows, self.normalizer.dense(windows, DENSE_GRID_STRIDE))
        return self.mixture(windows, self.weights(windows))

    def forward(self, windows: torch.Tensor, anchor: torch.Tensor | None = None) -> torch.Tensor:
        """Logits ``(B, num_classes)``. With a boolean ``anchor`` mask (the ``"meta"`` objective),
        the detector's parameters are seen as constants for the windows outside the mask: their
        loss trains the Normalizer only."""
        z = self.normalized(windows)
        if anchor is None:
            return self.detector(z)
        fixed = {k: v.detach() for k, v in self.detector.named_parameters()}
        logits = torch.empty(len(z), self.detector.num_classes, dtype=z.dtype, device=z.device)
        logits[anchor] = self.detector(z[anchor])
        logits[~anchor] = torch.func.functional_call(self.detector, fixed, (z[~anchor],))
        return logits


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
        model: the trained :class:`JointModel` (in eval mode).
        fewshot: results of the few-shot validation (:mod:`alcn_cv.train.fewshot`) per method.
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


# ---------------------------------------------------------------------------------------- data


def _render_part(args: tuple) -> PhosBatch:
    n, seed, kwargs = args
    return render_windows(n, seed, **kwargs)


def _render(n: int, seed: int, lighting: list[str], cfg: TrainConfig, desc: str, progress: bool) -> PhosBatch:
    """Render ``n`` windows in parts of 4096 (part ``p`` seeded by ``[seed, p]``), on ``run.workers`` processes."""
    kwargs = {"n_objects": cfg.data.n_objects, "object_seed": cfg.data.object_seed, "lighting": lighting,
              "background_fraction": cfg.data.background_fraction}
    jobs = [(min(_PART, n - s), int(np.random.SeedSequence([seed, p]).generate_state(1)[0]), kwargs)
            for p, s in enumerate(range(0, n, _PART))]
    if cfg.run.workers > 0 and len(jobs) > 1:
        import multiprocessing

        with multiprocessing.get_context("spawn").Pool(cfg.run.workers) as pool:
            parts = list(tqdm(pool.imap(_render_part, jobs), total=len(jobs), desc=desc, disable=not progress))
    else:
        parts = [_render_part(j) for j in tqdm(jobs, desc=desc, disable=not progress)]
    first = parts[0]
    cat = {k: np.concatenate([getattr(p, k) for p in parts]) for k in _ARRAYS}
    return PhosBatch(**cat, n_objects=first.n_objects, object_seed=first.object_seed, seed=seed)


def _data_key(cfg: TrainConfig) -> str:
    d = cfg.data
    anchor = [d.anchor_lighting, d.anchor_fraction] if cfg.optim.objective == "meta" else None
    text = json.dumps([d.n_train, d.n_val, cfg.data_seed, d.n_objects, d.object_seed, d.train_lighting,
                       d.val_lighting, d.background_fraction, _PART, anchor], sort_keys=True)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def _load_data(cfg: TrainConfig, out_dir: Path, progress: bool) -> tuple[PhosBatch, PhosBatch]:
    """Training and held-out-lighting validation windows, from folders or rendered (cached in the run folder)."""
    train_set = load(cfg.data.path) if cfg.data.path else None
    val_set = load(cfg.data.val_path) if cfg.data.val_path else None
    cache = out_dir / f"windows-{_data_key(cfg)}.npz"
    if (train_set is None or val_set is None) and cache.is_file():
        with np.load(cache) as z:
            cached = {k: z[k] for k in z.files}
        meta = json.loads(str(cached.pop("meta")))
        sets = [PhosBatch(*[cached[f"{name}_{k}"] for k in _ARRAYS], n_objects=meta["n_objects"],
                          object_seed=meta["object_seed"], seed=meta[f"{name}_seed"]) for name in ("train", "val")]
        logger.info("windows read from the cache %s", cache.name)
        return train_set or sets[0], val_set or sets[1]
    if train_set is None and cfg.optim.objective == "meta":
        n_anchor = round(cfg.data.n_train * cfg.data.anchor_fraction)
        others = [f for f in cfg.data.train_lighting if f != cfg.data.anchor_lighting]
        parts = [_render(n_anchor, cfg.data_seed, [cfg.data.anchor_lighting], cfg, "anchor windows", progress),
                 _render(cfg.data.n_train - n_anchor, cfg.data_seed + 7, others, cfg, "training windows", progress)]
        train_set = PhosBatch(*[np.concatenate([getattr(p, k) for p in parts]) for k in _ARRAYS],
                              n_objects=parts[0].n_objects, object_seed=parts[0].object_seed, seed=cfg.data_seed)
    if train_set is None:
        train_set = _render(cfg.data.n_train, cfg.data_seed, cfg.data.train_lighting, cfg, "training windows", progress)
    if val_set is None:
        val_set = _render(cfg.data.n_val, cfg.data_seed + 1_000_003, cfg.data.val_lighting, cfg,
                          "validation windows", progress)
    if not (cfg.data.path and cfg.data.val_path) and distributed.is_main():
        arrays = {f"{name}_{k}": getattr(s, k) for name, s in (("train", train_set), ("val", val_set))
                  for k in _ARRAYS}
        meta = {"n_objects": train_set.n_objects, "object_seed": train_set.object_seed,
                "train_seed": train_set.seed, "val_seed": val_set.seed}
        atomic_write(cache, lambda f: np.savez(f, meta=np.array(json.dumps(meta)), **arrays))
    return train_set, val_set


def _check_sets(train_set: PhosBatch, val_set: PhosBatch, cfg: TrainConfig) -> int:
    if len(train_set) == 0 or len(val_set) == 0:
        raise InputError("training and validation windows must not be empty")
    if train_set.n_objects != val_set.n_objects:
        raise InputError(f"training windows have {train_set.n_objects} objects, validation {val_set.n_objects}")
    shared = set(np.unique(train_set.light_ids)) & set(np.unique(val_set.light_ids))
    if shared:
        names = sorted(train_set.light_families[i] for i in shared)
        raise InputError(f"validation windows share the training lightings {names}; hold some lightings out")
    return train_set.n_objects + 1


# ---------------------------------------------------------------------------------- checkpoint


def _versions() -> dict[str, str]:
    import alcn_cv

    return {"alcn_cv": str(alcn_cv.__version__), "torch": str(torch.__version__)}


def load_checkpoint(path: str | Path, cfg: TrainConfig | None = None) -> dict[str, Any]:
    """Read a training checkpoint and check that it fits ``cfg``.

    Raises:
        WeightFileError: missing, corrupt, of another format or version (the message gives the
            versions that wrote it and this one), or written for another model configuration.
    """
    path = Path(path)
    if not path.is_file():
        raise WeightFileError(f"checkpoint not found: {path}")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch raises many kinds for a damaged zip or pickle
        raise WeightFileError(f"checkpoint {path} is corrupt or unreadable ({type(exc).__name__}: {exc})") from None
    if not isinstance(ckpt, dict) or ckpt.get("format") != CHECKPOINT_FORMAT:
        raise WeightFileError(f"{path} is not an alcn-cv training checkpoint")
    if ckpt.get("version") != CHECKPOINT_VERSION:
        raise WeightFileError(
            f"{path}: checkpoint version {ckpt.get('version')} written by {ckpt.get('versions')}; this alcn-cv "
            f"({_versions()}) reads version {CHECKPOINT_VERSION}"
        )
    if cfg is not None:
        saved = ckpt["config"]
        now = cfg.to_dict()
        diff = [f"{t}.{k}" for t in ("model", "data") for k in now[t] if saved[t].get(k) != now[t][k]]
        diff += [k for k in ("seed",) if saved[k] != now[k]]
        diff += [f"optim.{k}" for k in now["optim"] if saved["optim"].get(k) != now["optim"][k]]
        if diff:
            raise WeightFileError(
                f"checkpoint {path} was written with another configuration (differs in {', '.join(diff)}; "
                f"written by {ckpt.get('versions')}); start a new run folder or use its configuration"
            )
    return ckpt


# ------------------------------------------------------------------------------------ training


def _lr_factor(cfg: TrainConfig, step: int, steps_per_epoch: int) -> float:
    o = cfg.optim
    warm = min(1.0, (step + 1) / o.warmup_steps) if o.warmup_steps else 1.0
    if o.schedule == "constant":
        return warm
    if o.schedule == "step":
        return warm * o.step_gamma ** (step // (steps_per_epoch * o.step_epochs))
    total = steps_per_epoch * o.epochs
    return warm * 0.5 * (1.0 + math.cos(math.pi * min(step, total) / total))


def _make_optimizer(model: JointModel, cfg: TrainConfig) -> torch.optim.Optimizer:
    groups = [{"params": model.detector.parameters(), "lr": cfg.optim.lr, "base_lr": cfg.optim.lr}]
    if model.normalizer is not None:
        lr = cfg.optim.normalizer_lr
        groups.append({"params": model.normalizer.parameters(), "lr": lr, "base_lr": lr})
    if cfg.optim.optimizer == "sgd":
        return torch.optim.SGD(groups, momentum=cfg.optim.momentum, weight_decay=cfg.optim.weight_decay)
    return torch.optim.Adam(groups, weight_decay=cfg.optim.weight_decay)


def _epoch_plan(cfg: TrainConfig, epoch: int, n: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Order and intensity gains of an epoch; a function of (seed, epoch) only, so resuming is exact."""
    g = torch.Generator().manual_seed(int(np.random.SeedSequence([cfg.seed, epoch]).generate_state(1)[0]))
    perm = torch.randperm(n, generator=g)
    lo, hi = (math.log(v) for v in cfg.data.gain_jitter)
    gains = torch.exp(lo + (hi - lo) * torch.rand(n, generator=g))
    return perm, gains


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
    by_family = {val_set.light_families[f]: float(correct[val_set.light_ids == f].mean())
                 for f in np.unique(val_set.light_ids)}
    model.train()
    return loss / len(x), float(correct.mean()), by_family


@contextlib.contextmanager
def _log_to(path: Path) -> Iterator[None]:
    handler = logging.FileHandler(path)
    handler.setFormatter(logging.Formatter("[%(asctime)s %(name)s %(levelname)s] %(message)s", "%Y/%m/%d %H:%M:%S"))
    root = logging.getLogger("alcn_cv")
    previous = root.level
    root.addHandler(handler)
    if root.getEffectiveLevel() > logging.INFO:
        root.setLevel(logging.INFO)
    try:
        yield
    finally:
        root.removeHandler(handler)
        root.setLevel(previous)
        handler.close()


@contextlib.contextmanager
def _sigint_as_keyboard_interrupt() -> Iterator[None]:
    """Make sure Ctrl-C raises KeyboardInterrupt (a parent may have set SIGINT to be ignored)."""
    try:
        previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _on_step(global_step: int) -> None:
    """Called after every optimisation step (a hook for tests that simulate Ctrl-C)."""


def _plot(history: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] for h in history]
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4))
    ax1.plot(epochs, [h["train_loss"] for h in history], "o-", label="training")
    ax1.plot(epochs, [h["val_loss"] for h in history], "o-", label="validation (held-out lightings)")
    ax1.set(xlabel="epoch", ylabel="cross-entropy", title="loss")
    ax2.plot(epochs, [h["train_acc"] for h in history], "o-", label="training")
    ax2.plot(epochs, [h["val_acc"] for h in history], "o-", lw=2, label="validation, all held-out")
    for fam in history[-1]["val_by_family"]:
        ax2.plot(epochs, [h["val_by_family"][fam] for h in history], "--", label=f"validation, {fam}")
    ax2.set(xlabel="epoch", ylabel="accuracy", title="accuracy", ylim=(0, 1))
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    atomic_write(path, lambda f: fig.savefig(f, format="png", dpi=100))
    plt.close(fig)


@torch.no_grad()
def measure_output_range(
    model: JointModel, windows: np.ndarray, percentiles: tuple[float, float] = (0.5, 99.5)
) -> list[float]:
    """Range of raw mixture responses (before the detector input policy) on training windows."""
    values = []
    for i in range(0, len(windows), 512):
        x = torch.from_numpy(windows[i : i + 512]).unsqueeze(1).float() / 255.0
        values.append(model.response(x).flatten().numpy())
    lo, hi = np.percentile(np.concatenate(values), percentiles)
    return [float(lo), float(hi)]


def _export(model: JointModel, cfg: TrainConfig, train_set: PhosBatch, result: TrainResult, seconds: float) -> Path:
    assert model.normalizer is not None
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
        "training": {"config": cfg.to_dict(), "versions": _versions(), "val_accuracy": result.val_accuracy,
                     "val_by_family": result.val_by_family, "fewshot": result.fewshot, "seconds": round(seconds, 1),
                     "machine": _machine()},
    }
    return save_normalizer_file(result.out_dir / "alcn_normalizer.npz", net.state_arrays(), meta)


def _machine() -> str:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return (f"{platform.machine()} {platform.system()}, {os.cpu_count()} cores, "
            f"torch threads {torch.get_num_threads()}, "
            f"load average {load[0]:.1f}/{load[1]:.1f}/{load[2]:.1f} (1/5/15 min)")


def _summary(cfg: TrainConfig, result: TrainResult, machine_start: str) -> str:
    """A Markdown summary of a run: settings, time, machine, held-out and few-shot validation."""
    lines = [f"# `alcn train` run: {cfg.model.method}", "",
             f"- status: {result.status}; {len(result.history)} epoch(s); training "
             f"{result.history[-1]['seconds'] / 60 if result.history else 0:.1f} min, whole run (data, training, "
             f"few-shot validation, export) {result.seconds / 60:.1f} min",
             f"- machine at start: {machine_start}", f"- machine at end: {_machine()}",
             f"- versions: {_versions()}", f"- seed {cfg.seed}; configuration: `config.toml` in this folder", "",
             "## Held-out lightings (stage 1: the training objects, lighting families never trained on)", "",
             "| epoch | train acc | held-out acc | " + " | ".join(result.val_by_family) + " |",
             "|---|---|---|" + "---|" * len(result.val_by_family)]
    for h in result.history:
        lines.append(f"| {h['epoch']} | {h['train_acc']:.4f} | {h['val_acc']:.4f} | "
                     + " | ".join(f"{h['val_by_family'].get(f, float('nan')):.4f}" for f in result.val_by_family)
                     + " |")
    if result.fewshot:
        families = list(next(iter(result.fewshot.values()))["by_family"])
        lines += ["", "## Few-shot validation (stage 2: new objects, 1 image under one light; same detector and "
                  f"input policy `{cfg.model.detector_input}` for every method)", "",
                  "AUC object vs. background (accuracy over background + objects in brackets)", "",
                  "| method | all | " + " | ".join(families) + " |", "|---|---|" + "---|" * len(families)]
        for name, r in result.fewshot.items():
            lines.append(f"| {name} | {r['auc']:.4f} ({r['accuracy']:.3f}) | "
                         + " | ".join(f"{r['by_family'][f]['auc']:.4f}" for f in families) + " |")
    return "\n".join(lines) + "\n"


def _fewshot(model: JointModel, cfg: TrainConfig, progress: bool) -> dict[str, Any]:
    from alcn_cv.train.fewshot import FewShotSetup, fewshot_validation, standard_methods

    f = cfg.fewshot
    setup = FewShotSetup(n_objects=f.n_objects, real_images=f.real_images, per_image=f.per_image, n_test=f.n_test,
                         test_lighting=tuple(f.test_lighting), epochs=f.epochs, seed=cfg.seed)
    methods = standard_methods(model, f.dog, cfg.model.num_kernels, cfg.model.sigma_step, cfg.model.detector_input)
    logger.info("few-shot validation: %d new objects, %d image(s) each, tested under %s", f.n_objects,
                f.real_images, ", ".join(f.test_lighting))
    return fewshot_validation(methods, setup, progress=progress)


def train(
    config: str | Path | dict[str, Any] | TrainConfig | None = None,
    out_dir: str | Path = "runs/alcn",
    *,
    resume: bool = False,
    progress: bool = True,
) -> TrainResult:
    """Train ALCN's Normalizer jointly with a detector (Eq. 2), or a baseline detector.

    Args:
        config: a :class:`~alcn_cv.train.config.TrainConfig`, a preset name, a TOML path or a dict
            (see :mod:`alcn_cv.train.config`).
        out_dir: the run folder (checkpoint, log, curves, history, exported weights).
        resume: continue from ``out_dir/checkpoint.pt``; the result equals an uninterrupted run.
        progress: show progress bars.

    Returns:
        A :class:`TrainResult`. Ctrl-C saves a checkpoint and returns status ``"interrupted"``.

    Raises:
        InputError: bad configuration or data.
        WeightFileError: ``resume`` with a missing, corrupt or incompatible checkpoint.
        NonFiniteLossError: the loss became NaN or inf; the last good checkpoint is kept.
    """
    cfg = load_config(config)
    distributed.init(cfg.run.device)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ckpt_path = out / "checkpoint.pt"
    start = time.perf_counter()
    machine_start = _machine()
    with _log_to(out / "train.log") if distributed.is_main() else contextlib.nullcontext():
        ckpt = load_checkpoint(ckpt_path, cfg) if resume else None
        if not resume and distributed.is_main():
            (out / "config.toml").write_text(dump_toml(cfg))
        if cfg.run.threads:
            torch.set_num_threads(cfg.run.threads)
        device = torch.device(cfg.run.device)
        if device.type == "cuda" and not torch.cuda.is_available():
            raise InputError("config key 'run.device' is 'cuda' but torch sees no CUDA device")
        if distributed.world_size() > 1 and device.type == "cuda":
            device = torch.device("cuda", distributed.local_rank())
        train_set, val_set = _load_data(cfg, out, progress and distributed.is_main())
        num_classes = _check_sets(train_set, val_set, cfg)
        logger.info("%s: %d training windows (%s), %d validation windows (held out: %s), %d classes, device %s, "
                    "%d process(es)", cfg.model.method, len(train_set), ", ".join(cfg.data.train_lighting),
                    len(val_set), ", ".join(cfg.data.val_lighting), num_classes, device, distributed.world_size())
        torch.manual_seed(cfg.seed)
        model = JointModel(cfg.model, num_classes).to(device)
        optimizer = _make_optimizer(model, cfg)
        history: list[dict[str, Any]] = []
        epoch, step_in_epoch, sums = 0, 0, [0.0, 0, 0]
        if ckpt is not None:
            model.load_state_dict(ckpt["model"])
            optimizer.load_state_dict(ckpt["optimizer"])
            torch.set_rng_state(ckpt["rng"])
            history, epoch, step_in_epoch, sums = ckpt["history"], ckpt["epoch"], ckpt["step_in_epoch"], ckpt["sums"]
            start -= ckpt["elapsed"]
            logger.info("resumed from %s at epoch %d, step %d", ckpt_path, epoch + 1, step_in_epoch)
        ddp = distributed.wrap(model, device)
        rank, world = distributed.rank(), distributed.world_size()
        batch = cfg.optim.batch_size
        n = len(train_set) // world * world
        steps_per_epoch = math.ceil(n // world / batch)
        windows = torch.from_numpy(train_set.windows)
        labels = torch.from_numpy(train_set.labels)
        anchors = None
        if cfg.optim.objective == "meta":
            anchor_id = train_set.light_families.index(cfg.data.anchor_lighting)
            anchors = torch.from_numpy(train_set.light_ids == anchor_id)
            if not anchors.any() or anchors.all():
                raise InputError(f"optim.objective 'meta' needs training windows under the anchor lighting "
                                 f"{cfg.data.anchor_lighting!r} and under others")
        params = [p for p in model.parameters() if p.requires_grad]

        def save(status: str) -> None:
            if not distributed.is_main():
                return
            state = {"format": CHECKPOINT_FORMAT, "version": CHECKPOINT_VERSION, "versions": _versions(),
                     "config": cfg.to_dict(), "status": status, "epoch": epoch, "step_in_epoch": step_in_epoch,
                     "sums": sums, "history": history, "model": model.state_dict(),
                     "optimizer": optimizer.state_dict(), "rng": torch.get_rng_state(),
                     "elapsed": time.perf_counter() - start}
            atomic_write(ckpt_path, lambda f: torch.save(state, f))

        result = TrainResult(out, "done", history, model=model)
        model.train()
        try:
            with _sigint_as_keyboard_interrupt():
                while epoch < cfg.optim.epochs:
                    perm, gains = _epoch_plan(cfg, epoch, len(train_set))
                    mine = perm[:n][rank::world]
                    bar = tqdm(total=steps_per_epoch, initial=step_in_epoch,
                               desc=f"epoch {epoch + 1}/{cfg.optim.epochs}",
                               disable=not (progress and distributed.is_main()), leave=False)
                    while step_in_epoch < steps_per_epoch:
                        idx = mine[step_in_epoch * batch : (step_in_epoch + 1) * batch]
                        x = windows[idx].unsqueeze(1).float().div_(255.0).mul_(gains[idx].view(-1, 1, 1, 1))
                        x = x.clamp_(0.0, 1.0).to(device)
                        y = labels[idx].to(device)
                        factor = _lr_factor(cfg, epoch * steps_per_epoch + step_in_epoch, steps_per_epoch)
                        for group in optimizer.param_groups:
                            group["lr"] = group["base_lr"] * factor
                        logits = ddp(x) if anchors is None else ddp(x, anchors[idx].to(device))
                        loss = F.cross_entropy(logits, y)
                        if not torch.isfinite(loss):
                            kept = (f"the last good checkpoint is {ckpt_path}" if ckpt_path.is_file()
                                    else "no checkpoint was written yet")
                            raise NonFiniteLossError(
                                f"loss is {loss.item()} at epoch {epoch + 1}, step {step_in_epoch + 1}; "
                                f"training stopped, {kept} (try a lower optim.lr)")
                        optimizer.zero_grad(set_to_none=True)
                        loss.backward()
                        if cfg.optim.grad_clip:
                            torch.nn.utils.clip_grad_norm_(params, cfg.optim.grad_clip)
                        optimizer.step()
                        sums[0] += loss.item() * len(idx)
                        sums[1] += int((logits.argmax(1) == y).sum())
                        sums[2] += len(idx)
                        step_in_epoch += 1
                        bar.update()
                        bar.set_postfix(loss=f"{sums[0] / sums[2]:.3f}", acc=f"{sums[1] / sums[2]:.3f}")
                        if step_in_epoch % cfg.run.log_every == 0:
                            logger.info("epoch %d step %d/%d: loss %.4f acc %.4f lr %.2e", epoch + 1, step_in_epoch,
                                        steps_per_epoch, sums[0] / sums[2], sums[1] / sums[2], cfg.optim.lr * factor)
                        _on_step(epoch * steps_per_epoch + step_in_epoch)
                    bar.close()
                    val_loss, val_acc, by_family = _validate(model, val_set, device)
                    history.append({"epoch": epoch + 1, "train_loss": sums[0] / sums[2], "train_acc": sums[1] / sums[2],
                                    "val_loss": val_loss, "val_acc": val_acc, "val_by_family": by_family,
                                    "seconds": round(time.perf_counter() - start, 1)})
                    logger.info("epoch %d/%d: train loss %.4f acc %.4f | held-out val loss %.4f acc %.4f (%s)",
                                epoch + 1, cfg.optim.epochs, sums[0] / sums[2], sums[1] / sums[2], val_loss, val_acc,
                                ", ".join(f"{k} {v:.3f}" for k, v in by_family.items()))
                    epoch, step_in_epoch, sums = epoch + 1, 0, [0.0, 0, 0]
                    save("epoch")
                    if distributed.is_main():
                        atomic_write(out / "history.json", lambda f: f.write(json.dumps(history, indent=1).encode()))
                        _plot(history, out / "curves.png")
        except KeyboardInterrupt:
            save("interrupted")
            logger.warning("interrupted at epoch %d, step %d: checkpoint saved to %s (continue with --resume)",
                           epoch + 1, step_in_epoch, ckpt_path)
            result.status = "interrupted"
        except NonFiniteLossError as exc:
            logger.error("%s", exc)
            raise
        model.eval()
        if distributed.world_size() > 1 and not distributed.replicas_equal(model):
            logger.error("the replicas of the %d processes hold different weights", distributed.world_size())
        if history:
            result.val_accuracy = history[-1]["val_acc"]
            result.val_by_family = history[-1]["val_by_family"]
        if result.status == "done" and model.normalizer is not None and distributed.is_main():
            total = history[-1]["seconds"] if history else time.perf_counter() - start
            if cfg.fewshot.enabled:
                result.fewshot = _fewshot(model, cfg, progress)
                atomic_write(out / "fewshot.json", lambda f: f.write(json.dumps(result.fewshot, indent=1).encode()))
            result.weights = _export(model, cfg, train_set, result, total)
            logger.info("Normalizer weights written to %s", result.weights)
        result.seconds = time.perf_counter() - start
        if distributed.is_main():
            atomic_write(out / "summary.md", lambda f: f.write(_summary(cfg, result, machine_start).encode()))
        logger.info("%s run %s in %.1f min: held-out validation accuracy %.4f", cfg.model.method, result.status,
                    result.seconds / 60, result.val_accuracy)
    return result

