"""Few-shot validation: the paper's second stage on new objects, at the window level (Sec. 4.3).

The question ALCN answers is not "can a detector learn these objects under many lights" (every
method can, given the lights) but "does a detector trained from *one image under one light* of a
new object still work under other lights once the images are normalized". This validation asks
exactly that, for every method with the same detector and the same input policy:

1. ``n_objects`` new objects (a catalogue seed the Normalizer never saw), ``real_images`` images
   each, rendered under the ``ambient`` (training-like) lighting;
2. the paper's simple synthetic images of them (:func:`alcn_cv.data.synthetic.augment`) and
   matching negatives (:func:`~alcn_cv.data.synthetic.sample_negatives`);
3. per method: normalize, train a fresh detector (:func:`~alcn_cv.train.stage2.train_detector`);
4. test on rendered windows of the same objects and of background under held-out lighting
   families: accuracy (background + objects) and the ROC AUC of object vs. background
   (score ``1 - p(background)``), overall and per family.

Steps 3 and 4 are :func:`score_inputs`, the same for every method. :func:`fewshot_validation`
runs them on the methods built inside the trainer (:func:`standard_methods`); ``alcn bench
fewshot`` (:mod:`alcn_cv.bench.fewshot`) on any registered normalization spec, through
:meth:`~alcn_cv.enhance.base.Normalization.normalize_windows` and the detection benchmark's
input policies.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence

import numpy as np
import torch

from alcn_cv.data.phos import PhosBatch, render_windows
from alcn_cv.data.synthetic import augment, sample_negatives
from alcn_cv.filters.gaussian_mixture import gaussian_sigmas
from alcn_cv.filters.standardize import standardize_windows
from alcn_cv.nets.gain import dog_weights
from alcn_cv.train.config import FewShotSetup
from alcn_cv.train.models import CentreMixture, JointModel
from alcn_cv.train.stage2 import train_detector

__all__ = ["FewShotSetup", "auc", "fewshot_validation", "make_fewshot_data", "score_inputs", "standard_methods"]

logger = logging.getLogger(__name__)

#: A method: ``(B, 1, 64, 64)`` float windows in [0, 1] -> ``(B, 1, 32, 32)`` detector inputs.
Method = Callable[[torch.Tensor], torch.Tensor]


def auc(scores: np.ndarray, positive: np.ndarray) -> float:
    """ROC AUC (Mann-Whitney U, ties counted half) of ``scores`` for the ``positive`` mask."""
    pos, neg = scores[positive], scores[~positive]
    if len(pos) == 0 or len(neg) == 0:
        return float("nan")
    order = np.argsort(np.concatenate([pos, neg]), kind="mergesort")
    ranks = np.empty(len(order), np.float64)
    ranks[order] = np.arange(1, len(order) + 1)
    values = np.concatenate([pos, neg])
    for v in np.unique(values):  # average ranks of ties
        tie = values == v
        if tie.sum() > 1:
            ranks[tie] = ranks[tie].mean()
    return float((ranks[: len(pos)].sum() - len(pos) * (len(pos) + 1) / 2) / (len(pos) * len(neg)))


def make_fewshot_data(setup: FewShotSetup) -> tuple[np.ndarray, np.ndarray, PhosBatch]:
    """Synthetic training windows from the reference images, and the test windows.

    Returns:
        ``(train windows (n, 64, 64) uint8, train labels (n,), test PhosBatch)``.
    """
    rng = np.random.default_rng(setup.seed)
    refs = render_windows(
        setup.n_objects * setup.real_images * 8 + 64,
        setup.seed + 17,
        n_objects=setup.n_objects,
        object_seed=setup.object_seed,
        lighting="ambient",
        background_fraction=0.0,
    )
    images, boxes, windows, labels = [], [], [], []
    for k in range(1, setup.n_objects + 1):
        idx = np.flatnonzero(refs.labels == k)[: setup.real_images]
        for i in idx:
            (dx, dy), e = refs.offsets[i], float(refs.extents[i])
            c = (refs.windows.shape[1] - 1) / 2
            box = [c + dx - e / 2, c + dy - e / 2, e, e]
            images.append(refs.windows[i])
            boxes.append(box)
            windows.append(augment(refs.windows[i], box, setup.per_image, rng, extent=None))
            labels.append(np.full(setup.per_image, k, np.int64))
    n_pos = sum(len(w) for w in windows)
    windows.append(sample_negatives(images, boxes, n_pos, rng, extent=None))
    labels.append(np.zeros(n_pos, np.int64))
    test = render_windows(
        setup.n_test,
        setup.seed + 29,
        n_objects=setup.n_objects,
        object_seed=setup.object_seed,
        lighting=list(setup.test_lighting),
        background_fraction=0.5,
    )
    return np.concatenate(windows), np.concatenate(labels), test


@torch.no_grad()
def _apply(method: Method, windows: np.ndarray) -> np.ndarray:
    out = [
        method(torch.from_numpy(windows[i : i + 512]).unsqueeze(1).float() / 255.0) for i in range(0, len(windows), 512)
    ]
    return torch.cat(out)[:, 0].numpy().astype(np.float32)


def score_inputs(
    name: str,
    train_inputs: np.ndarray,
    train_labels: np.ndarray,
    test_inputs: np.ndarray,
    test: PhosBatch,
    setup: FewShotSetup,
    progress: bool = False,
) -> dict:
    """Train a fresh detector on one method's detector inputs and test it (steps 3 and 4 above).

    Every method goes through this one function: same detector, training and scores.

    Args:
        name: the method's name (for the log).
        train_inputs: ``(n, 32, 32)`` float32 detector inputs of the training windows (normalized
            and under the input policy).
        train_labels: ``(n,)`` int64, 0 = background, 1..K = objects.
        test_inputs: ``(m, 32, 32)`` float32 detector inputs of ``test.windows``, made the same way.
        test: the test windows' labels and lighting families.
        setup: the settings.
        progress: progress bar of the detector training.

    Returns:
        ``{"accuracy", "auc", "by_family": {family: {"accuracy", "auc"}}}``.
    """
    net = train_detector(
        train_inputs,
        train_labels,
        setup.n_objects + 1,
        epochs=setup.epochs,
        batch_size=setup.batch_size,
        lr=setup.lr,
        seed=setup.seed,
        progress=progress,
    )
    x = torch.from_numpy(np.ascontiguousarray(test_inputs, dtype=np.float32)).unsqueeze(1)
    with torch.no_grad():
        prob = torch.cat([torch.softmax(net(x[i : i + 512]), 1) for i in range(0, len(x), 512)]).numpy()
    correct = prob.argmax(1) == test.labels
    score = 1.0 - prob[:, 0]
    entry = {"accuracy": float(correct.mean()), "auc": auc(score, test.labels > 0), "by_family": {}}
    for f in np.unique(test.light_ids):
        m = test.light_ids == f
        entry["by_family"][test.light_families[f]] = {
            "accuracy": float(correct[m].mean()),
            "auc": auc(score[m], test.labels[m] > 0),
        }
    logger.info(
        "few-shot %s: accuracy %.4f, AUC %.4f (%s)",
        name,
        entry["accuracy"],
        entry["auc"],
        ", ".join(f"{k} {v['auc']:.3f}" for k, v in entry["by_family"].items()),
    )
    return entry


def fewshot_validation(
    methods: dict[str, Method],
    setup: FewShotSetup | None = None,
    data: tuple[np.ndarray, np.ndarray, PhosBatch] | None = None,
    progress: bool = False,
) -> dict[str, dict]:
    """Train one detector per method on the few-shot windows and test it under held-out lightings.

    The methods built inside the trainer (its Normalizer, DoGs of its mixture, none);
    ``alcn bench fewshot`` (:mod:`alcn_cv.bench.fewshot`) runs the same validation on any
    registered normalization through :meth:`~alcn_cv.enhance.base.Normalization.normalize_windows`.

    Args:
        methods: name -> function mapping ``(B, 1, 64, 64)`` windows in [0, 1] to the detector's
            ``(B, 1, 32, 32)`` input (normalization *and* input policy).
        setup: the settings; default :class:`FewShotSetup`.
        data: precomputed :func:`make_fewshot_data` output (to share it between calls).
        progress: progress bars of the detector training.

    Returns:
        name -> :func:`score_inputs`'s result.
    """
    setup = setup or FewShotSetup()
    train_x, train_y, test = data if data is not None else make_fewshot_data(setup)
    return {
        name: score_inputs(name, _apply(method, train_x), train_y, _apply(method, test.windows), test, setup, progress)
        for name, method in methods.items()
    }


def standard_methods(
    model: JointModel | None, dog_pairs: Sequence[Sequence[float]], num_kernels: int, step: float, policy: str
) -> dict[str, Method]:
    """The trained model's normalization (``"alcn"``), DoGs ``"dog a/b"`` and ``"none"``, all under ``policy``."""
    finish = standardize_windows if policy == "standardize" else (lambda z: z)
    sigmas = gaussian_sigmas(num_kernels, step)
    mixture = model.mixture if model is not None else CentreMixture(sigmas)
    methods: dict[str, Method] = {}
    if model is not None and model.normalizer is not None:
        methods["alcn"] = model.normalized
    for a, b in dog_pairs:
        w = torch.tensor(dog_weights(sigmas, a, b))
        methods[f"dog {a:g}/{b:g}"] = lambda x, w=w: finish(mixture(x, w.expand(len(x), -1)))
    methods["none"] = lambda x: finish(x[..., 16:48, 16:48])
    return methods
