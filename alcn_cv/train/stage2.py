"""The second stage of ALCN (Rad, Roth & Lepetit, BMVC 2017, Sec. 3.2 and 4.3).

Once the Normalizer has been trained jointly with a detector on many objects (the first stage,
:mod:`alcn_cv.train.trainer`), it is frozen; for *new* objects, seen in a few images under one
lighting, a *new* detector is trained on the Normalizer's outputs. :func:`train_detector` is
that training step, on windows already normalized by the caller (ALCN, a baseline, or none),
so every method of a benchmark trains the same detector in the same way.

:func:`main` is the user-facing second stage (``alcn train-detector``): from a few real images
of new objects it makes the paper's simple synthetic images (:mod:`alcn_cv.data.synthetic`),
normalizes them with the frozen Normalizer (or any registered normalization), applies the
per-window standardization the Normalizer was trained with, and trains a new detector.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from tqdm.auto import tqdm

from alcn_cv.enhance.alcn import ALCN, pin_default_model
from alcn_cv.enhance.registry import format_spec, from_spec, parse_spec
from alcn_cv.errors import InputError
from alcn_cv.filters.standardize import standardize_windows
from alcn_cv.io import atomic_write, check_no_earlier_output, holds_out_dir, write_json
from alcn_cv.nets.detector import INPUT, Detector

if TYPE_CHECKING:
    from alcn_cv.enhance.base import Normalization

__all__ = [
    "NonFiniteLossError",
    "evaluate_detector",
    "main",
    "normalize_windows",
    "object_windows",
    "train_detector",
]

logger = logging.getLogger(__name__)

_EVAL_BATCH = 1024


class NonFiniteLossError(RuntimeError):
    """The training loss became NaN or inf."""


def _check_windows(
    windows: object, labels: object, num_classes: int | None, what: str, size: int = INPUT
) -> tuple[torch.Tensor, torch.Tensor]:
    # num_classes None: every label is a class (only the lower bound is checked)
    if not isinstance(windows, np.ndarray) or windows.ndim != 3 or windows.shape[1:] != (size, size):
        shape = getattr(windows, "shape", None)
        raise InputError(f"{what} windows must be an (n, {size}, {size}) array, got {shape}")
    if windows.dtype != np.float32:
        raise InputError(f"{what} windows must be float32, got {windows.dtype}")
    if len(windows) == 0:
        raise InputError(f"{what} windows are empty")
    if not np.isfinite(windows).all():
        raise InputError(f"{what} windows contain NaN or inf")
    if (
        not isinstance(labels, np.ndarray)
        or labels.shape != (len(windows),)
        or not np.issubdtype(labels.dtype, np.integer)
    ):
        raise InputError(
            f"{what} labels must be an integer array of shape ({len(windows)},), got "
            f"{getattr(labels, 'dtype', None)} {getattr(labels, 'shape', None)}"
        )
    if labels.min() < 0 or (num_classes is not None and labels.max() >= num_classes):
        bound = "non-negative" if num_classes is None else f"in [0, {num_classes - 1}]"
        raise InputError(f"{what} labels must be {bound}, got [{labels.min()}, {labels.max()}]")
    return torch.from_numpy(windows).unsqueeze(1), torch.from_numpy(labels.astype(np.int64))


@torch.no_grad()
def evaluate_detector(net: nn.Module, windows: np.ndarray, labels: np.ndarray) -> tuple[float, float]:
    """Mean cross-entropy and accuracy of a detector on normalized windows.

    Args:
        net: the detector (its mode is restored afterwards).
        windows: ``(n, S, S)`` float32 normalized windows, ``S`` the network's ``input_size``.
        labels: ``(n,)`` int64, 0 = background, 1..K = objects.

    Returns:
        ``(loss, accuracy)``, accuracy in [0, 1].
    """
    x, y = _check_windows(
        windows, labels, getattr(net, "num_classes", None), "validation", getattr(net, "input_size", INPUT)
    )
    device = next(net.parameters()).device
    was_training = net.training
    net.eval()
    loss, correct = 0.0, 0
    for i in range(0, len(x), _EVAL_BATCH):
        xb, yb = x[i : i + _EVAL_BATCH].to(device), y[i : i + _EVAL_BATCH].to(device)
        logits = net(xb)
        loss += float(F.cross_entropy(logits, yb, reduction="sum"))
        correct += int((logits.argmax(1) == yb).sum())
    net.train(was_training)
    return loss / len(x), correct / len(x)


def train_detector(
    windows: np.ndarray,
    labels: np.ndarray,
    num_classes: int,
    *,
    epochs: int,
    batch_size: int,
    lr: float,
    seed: int,
    val: tuple[np.ndarray, np.ndarray] | None = None,
    progress: bool = True,
    net: nn.Module | None = None,
    device: str = "cpu",
) -> nn.Module:
    """Train a detector on normalized windows (the paper's second stage, Normalizer frozen).

    Minimises the cross-entropy (negative log-likelihood of the labels) with Adam over shuffled
    mini-batches. Deterministic for a ``seed`` on the CPU: the initial weights (when ``net`` is
    None), the shuffling and dropout all draw from generators seeded by it, and the global
    torch random state is left as it was.

    Args:
        windows: ``(n, S, S)`` float32, the ``S x S`` centres of the windows *after*
            normalization and whatever input policy the caller applies (for example per-window
            standardization); the same policy must be applied at test time. ``S`` is the
            network's ``input_size`` (32 for the Detector).
        labels: ``(n,)`` int64, 0 = background, 1..K = objects.
        num_classes: K + 1.
        epochs: passes over the data (>= 1).
        batch_size: windows per step (>= 1).
        lr: Adam learning rate (> 0).
        seed: random seed.
        val: optional ``(windows, labels)`` in the same format; loss and accuracy on it are
            logged after every epoch.
        progress: show a tqdm bar with the loss and accuracy.
        net: the network to train (modified in place); default ``Detector(num_classes)``
            initialised from ``seed``. It must map ``(B, 1, S, S)`` to ``(B, num_classes)``.
        device: torch device to train on.

    Returns:
        The trained network, in eval mode.

    Raises:
        InputError: malformed windows or labels, or a non-positive setting.
    """
    if epochs < 1 or batch_size < 1 or not lr > 0:
        raise InputError(f"need epochs >= 1, batch_size >= 1 and lr > 0, got {epochs}, {batch_size}, {lr}")
    size = getattr(net, "input_size", INPUT)
    x, y = _check_windows(windows, labels, num_classes, "training", size)
    if val is not None:
        _check_windows(val[0], val[1], num_classes, "validation", size)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        if net is None:
            net = Detector(num_classes)
        net.to(device).train()
        optimiser = torch.optim.Adam(net.parameters(), lr=lr)
        order = torch.Generator().manual_seed(seed)
        bar = tqdm(range(epochs), desc="detector", unit="epoch", disable=not progress, leave=False)
        for epoch in bar:
            perm = torch.randperm(len(x), generator=order)
            total, correct = 0.0, 0
            for i in range(0, len(x), batch_size):
                idx = perm[i : i + batch_size]
                xb, yb = x[idx].to(device), y[idx].to(device)
                logits = net(xb)
                loss = F.cross_entropy(logits, yb)
                if not torch.isfinite(loss):
                    raise NonFiniteLossError(f"detector loss is {float(loss)} at epoch {epoch + 1}; lower lr ({lr})")
                optimiser.zero_grad(set_to_none=True)
                loss.backward()
                optimiser.step()
                total += loss.item() * len(idx)
                correct += int((logits.argmax(1) == yb).sum())
            stats = {"loss": total / len(x), "acc": correct / len(x)}
            if val is not None:
                stats["val_loss"], stats["val_acc"] = evaluate_detector(net, *val)
                net.train()
            bar.set_postfix({k: f"{v:.3f}" for k, v in stats.items()})
            logger.debug("detector epoch %d/%d: %s", epoch + 1, epochs, stats)
    if val is not None:  # a benchmark trains many: its own lines say what each scored
        logger.debug("detector: val_loss %.4f, val_acc %.4f", stats["val_loss"], stats["val_acc"])
    return net.eval()


def normalize_windows(windows: np.ndarray, normalization: Normalization) -> np.ndarray:
    """Normalize 64x64 windows, keep the detector's centre 32x32 and standardize each (as the shipped Normalizer was
    trained).

    Args:
        windows: ``(n, 64, 64)`` uint8 windows (at the Normalizer's working resolution).
        normalization: an object with ``normalize(gray_float32) -> float32`` (any
            :func:`alcn_cv.create` result; for ALCN create it with ``scale=1`` since the
            windows are already at the working resolution).

    Returns:
        ``(n, 32, 32)`` float32 detector inputs.
    """
    if windows.ndim != 3 or windows.shape[1:] != (64, 64) or windows.dtype != np.uint8:
        raise InputError(f"windows must be uint8 (n, 64, 64), got {windows.dtype} {windows.shape}")
    c = (64 - INPUT) // 2
    out = (
        np.stack(
            [
                normalization.normalize(w.astype(np.float32) / np.float32(255))[c : c + INPUT, c : c + INPUT]
                for w in windows
            ]
        )
        if len(windows)
        else np.zeros((0, INPUT, INPUT), np.float32)
    )
    return standardize_windows(out)


def _read_objects(folder: Path) -> list[tuple[str, list[tuple[np.ndarray, object]]]]:
    """``[(object name, [(gray image, mask or box), ...]), ...]`` from one sub-folder per object: an image's mask is
    ``NAME.mask.png`` beside it, else the folder's ``OBJECT/OBJECT.mask.png`` (one view under several lights, as the
    photometric-stereo sets), else the whole image is the object; a mask is white on the object
    (:func:`~alcn_cv.io.read_mask`)."""
    from alcn_cv.io import list_images, read_image, read_mask

    if not folder.is_dir():
        raise InputError(f"not a folder: {folder}")
    objects = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()):
        items = []
        for path in list_images(sub):
            if path.name.endswith(".mask.png"):
                continue
            image = read_image(path)
            mask_path = path.with_name(path.stem + ".mask.png")
            if not mask_path.is_file():
                mask_path = sub / f"{sub.name}.mask.png"
            if mask_path.is_file():
                mask = read_mask(mask_path)
                if mask.shape != image.shape[:2]:
                    raise InputError(f"{mask_path}: mask {mask.shape} does not match the image {image.shape[:2]}")
                items.append((image, mask))
            else:
                items.append((image, [0, 0, image.shape[1], image.shape[0]]))
        if items:
            objects.append((sub.name, items))
    if not objects:
        raise InputError(f"{folder} holds no sub-folder with images (one sub-folder per object)")
    return objects


def object_windows(
    objects: list[tuple[str, list[tuple[np.ndarray, object]]]],
    per_image: int,
    negatives: int,
    extent: float,
    seed: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Synthetic training windows (paper Sec. 4.1) for objects given as ``(name, [(image, mask or box)])``.

    Returns:
        ``(windows (n, 64, 64) uint8, labels (n,) int64)``; label ``k`` is the k-th object (from
        1), 0 background; ``negatives`` (0: as many as the positives) background windows.
    """
    from alcn_cv.data.synthetic import augment, sample_negatives

    rng = np.random.default_rng(seed)
    parts, labels = [], []
    for k, (_, items) in enumerate(objects, start=1):
        for image, mask_or_box in items:
            parts.append(augment(image, mask_or_box, per_image, rng, extent=extent))
            labels.append(np.full(per_image, k, np.int64))
    n_neg = negatives or sum(len(p) for p in parts)
    images = [im for _, items in objects for im, _ in items]
    boxes = [mb for _, items in objects for _, mb in items]
    parts.append(sample_negatives(images, boxes, n_neg, rng, extent=extent))
    labels.append(np.zeros(n_neg, np.int64))
    return np.concatenate(parts), np.concatenate(labels)


@holds_out_dir
def main(
    images: str | Path,
    out_dir: str | Path,
    *,
    method: str = "alcn",
    weights: str | Path | None = None,
    per_image: int = 300,
    negatives: int = 0,
    extent: float = 40.0,
    epochs: int = 15,
    batch_size: int = 64,
    lr: float = 1e-3,
    seed: int = 0,
    overwrite: bool = False,
    progress: bool = True,
) -> Path:
    """The second stage from image files (``alcn train-detector``).

    Args:
        images: a folder with one sub-folder per new object holding its real images (the whole
            image is the object unless a mask marks it: ``NAME.mask.png`` beside ``NAME.*``, or ``OBJECT.mask.png``
            in the object's folder for all its images).
        out_dir: output folder, held while the command runs (:func:`~alcn_cv.io.held_folder`); ``detector.pt`` holds
            ``{"state_dict", "config", "classes", "method", "policy"}``, ``classes.json`` the class names (0:
            background).
        method: the normalization, a spec ``NAME[:KEY=VALUE...]``; ALCN's windows are at its working scale
            (``scale=1`` unless the spec says otherwise).
        weights: the Normalizer of ``method`` ``"alcn"`` (default: the shipped default's), as ``alcn:weights=...``.
        per_image, negatives, extent: see :func:`object_windows`.
        epochs, batch_size, lr, seed: see :func:`train_detector`.
        overwrite: replace the detector an earlier run wrote into ``out_dir``.

    Returns:
        The path of ``detector.pt``; its ``"method"`` is the spec with the parameters set here and ALCN's model
        named (:func:`~alcn_cv.enhance.alcn.pin_default_model`).

    Raises:
        InputError: ``weights`` with another method than ALCN, or given twice; ``per_image`` below 1, ``negatives``
            below 0, ``extent`` outside (0, 64] (the window's side), ``epochs`` or ``batch_size`` below 1, ``lr`` not
            positive, ``seed`` negative (all before the windows are made); an earlier detector in ``out_dir`` without
            ``overwrite``; ``out_dir`` held by another run.
    """
    from alcn_cv.data.synthetic import WINDOW

    if per_image < 1 or negatives < 0:
        raise InputError(f"need --per-image >= 1 and --negatives >= 0, got {per_image} and {negatives}")
    # train_detector's own check, here before the windows are made
    if epochs < 1 or batch_size < 1 or not lr > 0 or seed < 0:
        raise InputError(
            f"need --epochs >= 1, --batch-size >= 1, --lr > 0 and --seed >= 0, got {epochs}, {batch_size}, {lr:g} "
            f"and {seed}"
        )
    if not 0 < extent <= WINDOW:
        raise InputError(f"--extent is the object's size in the {WINDOW}-px window: (0, {WINDOW}], got {extent:g}")
    out = Path(out_dir)
    check_no_earlier_output([out / "detector.pt", out / "classes.json"], overwrite)
    name, given = parse_spec(method)
    defaults: dict[str, object] = {}
    if name == ALCN.name:
        defaults["scale"] = 1.0  # the windows are cut at the detector's scale already
        if weights is not None:
            if "weights" in given:
                raise InputError(f"the Normalizer's weights are given twice: --weights and in {method!r}")
            defaults["weights"] = str(weights)
    elif weights is not None:
        raise InputError(f"--weights is the Normalizer of --method alcn, not of {name!r}")
    normalization = from_spec(method, **defaults)  # a path's own ":" stays out of the spec's parsing
    method = format_spec(name, {**defaults, **given})
    if "weights" not in defaults:  # a --weights path may hold a ":", which parsing the spec again would split on
        method = pin_default_model(method)
    objects = _read_objects(Path(images))
    windows, labels = object_windows(objects, per_image, negatives, extent, seed)
    x = normalize_windows(windows, normalization)
    logger.info(
        "%d objects, %d windows (%d background), method %s", len(objects), len(x), int((labels == 0).sum()), method
    )
    net = train_detector(
        x, labels, len(objects) + 1, epochs=epochs, batch_size=batch_size, lr=lr, seed=seed, progress=progress
    )
    path = out / "detector.pt"
    state = {
        "state_dict": net.state_dict(),
        "config": net.config,
        "classes": ["background"] + [n for n, _ in objects],
        "method": method,
        "policy": "standardize",
    }
    atomic_write(path, lambda f: torch.save(state, f))
    write_json(out / "classes.json", state["classes"])
    logger.info("detector written to %s", path)
    return path
