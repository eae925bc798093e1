"""The few-shot detection benchmark of ALCN (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3, Fig. 5).

For every method and for 1 and 10 real training images per object:

1. **Training windows** (:mod:`alcn_cv.bench.detect_data`): the paper's simple synthetic images
   from the first ``n`` training images of each object, and background windows, 64x64 each,
   drawn once per ``n`` and seed, so every method trains on the same windows.
2. **Normalization.** Each window is normalized with the method
   (:meth:`~alcn_cv.enhance.base.Normalization.normalize_windows`: ALCN with ``scale=1``, the
   window being already at the working scale, and Eq. 1 as in the paper's second stage; every
   other method normalizes the 64x64 window) and its 32x32 centre kept. Global methods (``ns``,
   ``he``, ``whitening``, ...) therefore see the window at training time and the whole image at
   test time, as a user would apply them.
3. **Input policy** (:mod:`alcn_cv.bench.policies`), the same for every method: ``raw``,
   ``standardize`` or ``local`` (:data:`~alcn_cv.bench.detect_settings.POLICY_DESCRIPTIONS`).
4. **Detector.** The same network (:class:`alcn_cv.nets.Detector`, Sec. 4.2) trained in the
   same way (:func:`alcn_cv.train.stage2.train_detector`: Adam, same epochs, batch, rate and
   seed). The deep baselines of Sec. 4.3.1 train their own networks on the same windows
   without normalization: ``cnn`` (the plain CNN of :mod:`alcn_cv.bench.deep_baselines` whose depth and
   width, from a small sweep, scores best on relit held-out training windows), ``resnet20``
   and ``resnet56`` (:mod:`alcn_cv.bench.deep_baselines`). The Detector and the plain CNN have valid
   convolutions: their dense scores equal scoring every window alone. The ResNets' padded
   convolutions see the image around a window in a dense run, so with the dense input
   policies they are trained on the 32x32 windows with
   :data:`~alcn_cv.bench.detect_settings.RESNET_CONTEXT` pixels of their surroundings and
   classify from the central 32x32's feature cells, which is what their dense run pools (see
   :mod:`alcn_cv.bench.deep_baselines`).
5. **Test.** Every test image is resized to the working scale, normalized whole, and every
   32x32 window at stride 4 is scored (``dense``; with ``standardize`` each window is
   standardized and scored alone). Per object: a fixed-size square box (``box_size`` at the
   working scale) centred on each window, greedy non-maximum suppression, and the PASCAL
   criterion (IoU >= 0.8) against fixed-size boxes of the same size centred on the ground
   truth. Precision-recall over all test images, and its area (AUC, PASCAL VOC average
   precision).

Training windows are normalized alone, test images whole: a method that looks further than the
64x64 window (a wide context, a global statistic) gives the detector another response at test
than at training, whatever the input policy. ``detect.json``'s ``window_agreement`` measures it
per method (:func:`window_agreement`: 1 for DoG, lower for methods with a wide context), and the
report shows it beside the AUCs.

A method may carry parameters, ``NAME:KEY=VALUE[:KEY=VALUE...]`` (``alcn:model=lite:mixture=pyramid``
is the paper family's real-time ALCN, ``dog:sigma2=2``), and every run may be repeated
over several seeds (``--seeds 0 1 2``): a single seed's AUC moves by several hundredths with the
training windows and the detector's initialisation, so differences between methods are only
read against the spread over seeds.

With ``--tune`` (``settings.tune``), DoG, SLCN and DLCN are first tuned (the paper tunes them, Sec. 4.3) by the
benchmark itself on the validation images (``val.json``: test-like images that ``alcn data detect`` draws apart from
the test images, which take no part): for every number of real images, each setting of a method
(:data:`TUNING_GRIDS`: the same number per method, the default first) normalizes the first seed's training windows,
the detector is trained on them as in that seed's runs under each of the run's input policies, and the setting scores
the mean AUC over objects on the validation images, averaged over the policies. The first best setting serves the
method's runs for every seed. Without ``--tune`` every method keeps its defaults.

Outputs: ``detect.json`` (every number, PR curves, settings, tuned parameters and every setting's validation AUC,
timings, machine, command), ``detect.md`` (:mod:`alcn_cv.bench.detect_report`) and
``pr_<object>_<n>real.png`` (precision-recall, all methods, :mod:`alcn_cv.bench.plots`), all replaced together;
while it runs, ``detect.partial.json`` holds the runs done so far (left by an interrupted run, for a look at them;
removed by a run that finishes).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm.auto import tqdm

from alcn_cv.bench.detect_data import DetectData, ScaledImage, TrainingSet, load_data, read_images, training_set
from alcn_cv.bench.detect_report import detect_command, detect_markdown
from alcn_cv.bench.detect_settings import (
    CROP,
    DEEP_BASELINES,
    RESNET_CONTEXT,
    RESNETS,
    STRIDE,
    WINDOW,
    DetectSettings,
    run_key,
)
from alcn_cv.bench.methods import build_methods
from alcn_cv.bench.metrics import match_detections, nms, pr_auc, precision_recall
from alcn_cv.bench.plots import plot_pr_curves, pr_figure_names
from alcn_cv.bench.policies import BENCH_STANDARDIZE_EPS, InputPolicy
from alcn_cv.enhance.alcn import ALCN
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import format_spec, from_spec, parse_spec
from alcn_cv.errors import InputError
from alcn_cv.filters.standardize import standardize_windows
from alcn_cv.io import atomic_paths, atomic_write, check_no_earlier_output, holds_out_dir, make_folder, write_json
from alcn_cv.report import machine, spread

if TYPE_CHECKING:
    from torch import nn

    from alcn_cv.formats.coco import CocoDataset

__all__ = [
    "TUNING_GRIDS",
    "best_trial",
    "create_normalization",
    "detect_in_image",
    "fixed_boxes",
    "main",
    "score_maps",
    "summarize",
    "window_agreement",
]

logger = logging.getLogger(__name__)

_BATCH = 1024
#: Windows drawn from the test images for :func:`window_agreement`.
AGREEMENT_WINDOWS = 200

_DOG_GRID = [(0.5, 1.5), (0.5, 3.0), (1.0, 2.0), (1.0, 3.0), (1.5, 4.5), (2.0, 5.0)]
_LCN_GRID = [2.0, 1.0, 1.5, 3.0, 4.0, 5.0]
#: The settings ``--tune`` searches per method, the same number for each, the default first (a tie keeps it).
#: Kernels stay within the context that the 64x64 training windows give around the detector's 32x32 input (16 pixels;
#: a Gaussian reaches 3 sigma): a larger kernel sees reflected window borders at training time and the real
#: surroundings at test time.
TUNING_GRIDS: dict[str, list[dict[str, float]]] = {
    "dog": [{"sigma1": a, "sigma2": b} for a, b in _DOG_GRID],
    "slcn": [{"sigma": s} for s in _LCN_GRID],
    "dlcn": [{"sigma": s} for s in _LCN_GRID],
}


def best_trial(trials: list[dict[str, Any]]) -> dict[str, Any]:
    """The first of a tuning grid's ``trials`` (``{"params", "val_auc", ...}``, in :data:`TUNING_GRIDS`' order) with the
    highest ``val_auc``: a tie keeps the earlier setting (the default first); an AUC that could not be computed (None
    or NaN) never wins."""
    return max(trials, key=lambda t: -np.inf if t["val_auc"] is None or np.isnan(t["val_auc"]) else t["val_auc"])


def score_maps(net: nn.Module, image: np.ndarray, policy: InputPolicy, device: str = "cpu") -> np.ndarray:
    """Class probabilities of every 32x32 window at stride 4 of a normalized image.

    Args:
        net: a window classifier with ``forward`` on ``(B, 1, 32, 32)`` and ``dense``.
        image: ``(H, W)`` float32 normalized image at the working scale (``H, W >= 32``).
        policy: the input policy the network was trained with.

    Returns:
        ``(C, (H-32)//4+1, (W-32)//4+1)`` float32 softmax probabilities; entry ``(c, i, j)``
        is class ``c`` for the window with top-left corner ``(4j, 4i)`` (x, y).
    """
    import torch
    import torch.nn.functional as F

    hd, wd = (image.shape[0] - CROP) // STRIDE + 1, (image.shape[1] - CROP) // STRIDE + 1
    with torch.inference_mode():
        if policy.name != "standardize":
            logits = net.dense(torch.from_numpy(policy.image(image))[None, None].to(device))[0]
        else:
            x = torch.from_numpy(np.ascontiguousarray(image))[None, None].to(device)
            win = F.unfold(x, CROP, stride=STRIDE)[0].T.reshape(-1, 1, CROP, CROP)
            win = standardize_windows(win, eps=BENCH_STANDARDIZE_EPS)
            logits = torch.cat([net(win[i : i + _BATCH]) for i in range(0, len(win), _BATCH)]).T.reshape(-1, hd, wd)
        return F.softmax(logits[:, :hd, :wd], dim=0).cpu().numpy()


def _all_score_maps(
    net: nn.Module, images: list[np.ndarray], policy: InputPolicy, device: str, batch: int = 8
) -> list[np.ndarray]:
    """:func:`score_maps` of many images; dense policies run images of equal size in batches."""
    if policy.name == "standardize":
        return [score_maps(net, img, policy, device) for img in images]
    import torch
    import torch.nn.functional as F

    out: list[np.ndarray | None] = [None] * len(images)
    by_shape: dict[tuple[int, ...], list[int]] = {}
    for k, img in enumerate(images):
        by_shape.setdefault(img.shape, []).append(k)
    for (h, w), ids in by_shape.items():
        hd, wd = (h - CROP) // STRIDE + 1, (w - CROP) // STRIDE + 1
        for i in range(0, len(ids), batch):
            chunk = ids[i : i + batch]
            x = torch.from_numpy(np.stack([policy.image(images[k]) for k in chunk]))[:, None].to(device)
            with torch.inference_mode():
                p = F.softmax(net.dense(x)[:, :, :hd, :wd], dim=1).cpu().numpy()
            for k, pk in zip(chunk, p):
                out[k] = pk
    return out  # type: ignore[return-value]


def fixed_boxes(centres: np.ndarray, side_x: float, side_y: float) -> np.ndarray:
    """Boxes ``[x, y, w, h]`` of a fixed size centred on ``(n, 2)`` centres (pixel-edge coordinates)."""
    centres = np.asarray(centres, np.float64).reshape(-1, 2)
    return np.column_stack(
        [
            centres[:, 0] - side_x / 2,
            centres[:, 1] - side_y / 2,
            np.full(len(centres), side_x),
            np.full(len(centres), side_y),
        ]
    )


def detect_in_image(
    probs: np.ndarray, label: int, sx: float, sy: float, box_size: float, nms_iou: float, max_detections: int
) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-size detections of one class in one image, after non-maximum suppression.

    Args:
        probs: output of :func:`score_maps`.
        label: the class.
        sx, sy: working-scale factors in x and y.
        box_size: box side at the working scale.

    Returns:
        ``(boxes (k, 4) in full-resolution pixels, scores (k,))``.
    """
    p = probs[label]
    flat = p.reshape(-1)
    top = np.argsort(-flat, kind="stable")[: max(10 * max_detections, 200)]
    i, j = np.unravel_index(top, p.shape)
    centres = np.column_stack([(STRIDE * j + CROP / 2) / sx, (STRIDE * i + CROP / 2) / sy])
    boxes = fixed_boxes(centres, box_size / sx, box_size / sy)
    keep = nms(boxes, flat[top], nms_iou, max_detections)
    return boxes[keep], flat[top][keep]


def _context(method: str, policy: str) -> int:
    """Pixels of surroundings the method's network takes around a window under ``policy``."""
    return RESNET_CONTEXT if method in RESNETS and policy != "standardize" else 0


def _make_net(method: str, num_classes: int, config: tuple[int, int] | None = None, context: int = 0) -> nn.Module:
    if method == "cnn":
        from alcn_cv.bench.deep_baselines import PlainCNN

        depth, width = config or (2, 32)
        return PlainCNN(num_classes, depth=depth, width=width)
    if method in RESNETS:
        from alcn_cv.bench import deep_baselines

        return getattr(deep_baselines, method)(num_classes, context=context)
    from alcn_cv.nets import Detector

    return Detector(num_classes)


def create_normalization(method: str, params: dict[str, Any] | None = None) -> Normalization:
    """The normalization a benchmark's windows and test images go through: ``method`` is a spec
    (``NAME[:KEY=VALUE...]``), ``params`` (tuned ones) fill what it does not give; a deep baseline's is ``none``."""
    name, _ = parse_spec(method)
    if name in DEEP_BASELINES:
        return from_spec("none")
    params = params or {}
    if name == "alcn":  # windows and test images are already at the working scale
        params = {"scale": 1.0, **params}
    return from_spec(method, **params)


def window_agreement(
    norm: Normalization,
    images: list[np.ndarray],
    normalized: list[np.ndarray],
) -> float | None:
    """How closely what the detector trains on matches what it is tested on, for one method.

    The detector trains on 64x64 windows normalized alone
    (:meth:`~alcn_cv.enhance.base.Normalization.normalize_windows`) and is tested on whole
    normalized images: a method that looks further than the window (a wide context, a global
    statistic) gives the window's centre another response than the same pixels get in the whole
    image. Both input policies pass that difference on to the detector. It is measured on
    :data:`AGREEMENT_WINDOWS` windows drawn at random (uniformly over images and positions, seed 0).

    Args:
        norm: the method.
        images: ``(H, W)`` float32 test images at the working scale (each at least 64x64).
        normalized: ``norm.normalize`` of each image.

    Returns:
        The Pearson correlation, pooled over every pixel of the 32x32 centres, between the
        windows normalized alone and the same pixels of the normalized images (1: the same);
        None without an image of 64x64 or more.
    """
    usable = [k for k, im in enumerate(images) if min(im.shape) >= WINDOW]
    if not usable:
        return None
    rng = np.random.default_rng(0)
    o = (WINDOW - CROP) // 2
    windows, references = [], []
    for k in rng.choice(usable, AGREEMENT_WINDOWS):
        h, w = images[k].shape
        y, x = int(rng.integers(0, h - WINDOW + 1)), int(rng.integers(0, w - WINDOW + 1))
        windows.append(images[k][y : y + WINDOW, x : x + WINDOW])
        references.append(normalized[k][y + o : y + o + CROP, x + o : x + o + CROP])
    alone = norm.normalize_windows(np.stack(windows))[:, o : o + CROP, o : o + CROP]
    return float(np.corrcoef(alone.ravel(), np.stack(references).ravel())[0, 1])


def _train(
    method: str,
    train: np.ndarray,
    labels: np.ndarray,
    num_classes: int,
    settings: DetectSettings,
    seed: int,
    val: tuple[np.ndarray, np.ndarray],
    config: tuple[int, int] | None = None,
) -> nn.Module:
    import torch

    from alcn_cv.train.stage2 import train_detector

    with torch.random.fork_rng(devices=[]):  # the seed, not the runs before, sets the initial weights
        torch.manual_seed(seed)
        net = _make_net(method, num_classes, config, context=(train.shape[-1] - CROP) // 2)
    return train_detector(
        train,
        labels,
        num_classes,
        epochs=settings.epochs,
        batch_size=settings.batch_size,
        lr=settings.lr,
        seed=seed,
        val=val,
        progress=False,
        net=net,
        device=settings.device,
    )


def _train_cnn_sweep(
    train: np.ndarray,
    labels: np.ndarray,
    num_classes: int,
    settings: DetectSettings,
    seed: int,
    val: tuple[np.ndarray, np.ndarray],
) -> tuple[nn.Module, dict[str, Any]]:
    from alcn_cv.train.stage2 import evaluate_detector

    best, sweep = None, []
    for depth, width in settings.cnn_sweep:
        net = _train("cnn", train, labels, num_classes, settings, seed, val, (depth, width))
        loss, acc = evaluate_detector(net, *val)
        sweep.append({"depth": depth, "width": width, "val_loss": loss, "val_acc": acc})
        if best is None or (acc, -loss) > (best[1]["val_acc"], -best[1]["val_loss"]):
            best = (net, sweep[-1])
    assert best is not None
    return best[0], {"sweep": sweep, "chosen": {"depth": best[1]["depth"], "width": best[1]["width"]}}


def _evaluate(
    data: DetectData,
    coco: CocoDataset,
    images: list[ScaledImage],
    net: nn.Module,
    policy: InputPolicy,
    settings: DetectSettings,
) -> dict[str, Any]:
    """AUC and precision-recall per object of a trained network on normalized images of ``coco`` (the test or the
    validation set)."""
    probs = _all_score_maps(net, [t.image for t in images], policy, settings.device)
    per_object = {}
    for label, cat in enumerate(data.categories, start=1):
        scores, tps, n_gt = [], [], 0
        for t, p in zip(images, probs):
            gt = [a for a in coco.annotations_for(t.id) if a.category_id == cat]
            n_gt += len(gt)
            boxes, s = detect_in_image(p, label, t.sx, t.sy, data.box_size, settings.nms_iou, settings.max_detections)
            gt_centres = np.array([[a.bbox[0] + a.bbox[2] / 2, a.bbox[1] + a.bbox[3] / 2] for a in gt]).reshape(-1, 2)
            gt_boxes = fixed_boxes(gt_centres, data.box_size / t.sx, data.box_size / t.sy)
            scores.append(s)
            tps.append(match_detections(boxes, s, gt_boxes, settings.match_iou))
        scores_all, tp_all = np.concatenate(scores), np.concatenate(tps)
        if n_gt == 0:
            per_object[data.name(cat)] = {"auc": None, "num_gt": 0}
            continue
        precision, recall = precision_recall(scores_all, tp_all, n_gt)
        step = max(1, len(precision) // 300)
        per_object[data.name(cat)] = {
            "auc": pr_auc(precision, recall),
            "num_gt": n_gt,
            "num_detections": int(len(scores_all)),
            "max_recall": float(recall[-1]) if len(recall) else 0.0,
            "pr": {"precision": precision[::step].round(4).tolist(), "recall": recall[::step].round(4).tolist()},
        }
    return per_object


def _mean_auc(objects: dict[str, Any]) -> float | None:
    """The mean AUC over the objects that have one (``None`` when none has)."""
    aucs = [o["auc"] for o in objects.values() if o["auc"] is not None]
    return float(np.mean(aucs)) if aucs else None


def summarize(runs: dict[str, Any], settings: DetectSettings, names: list[str]) -> dict[str, Any]:
    """AUC per object and its mean over objects, as mean and standard deviation over the seeds.

    Returns:
        ``{"METHOD|N|POLICY": {"seeds": [...], "failed_seeds": [...], "objects": {name: {"mean",
        "std", "values"}}, "mean": {...}}}``; a cell whose every seed failed holds ``error``.
    """
    summary: dict[str, Any] = {}
    for method in settings.methods:
        for n_real in settings.real_images:
            for policy in settings.policies:
                seeded = [
                    (seed, runs.get(run_key(method, n_real, policy, seed), {"error": "not run"}))
                    for seed in settings.seeds
                ]
                done = [(seed, r) for seed, r in seeded if "error" not in r]
                cell: dict[str, Any] = {
                    "seeds": [seed for seed, _ in done],
                    "failed_seeds": [seed for seed, r in seeded if "error" in r],
                }
                if not done:
                    cell["error"] = seeded[0][1]["error"]
                else:
                    cell["objects"] = {}
                    for name in names:
                        aucs = [r["objects"][name]["auc"] for _, r in done if r["objects"][name]["auc"] is not None]
                        cell["objects"][name] = spread(aucs)
                    cell["mean"] = spread([m for _, r in done if (m := _mean_auc(r["objects"])) is not None])
                summary[f"{method}|{n_real}|{policy}"] = cell
    return summary


@dataclass
class _Run:
    """What the runs of a benchmark share and gather: data, test images, the normalizations (built once per method
    and parameters), training sets (built once per seed and number of real images, shared by every method), tuned
    parameters (and the validation images they were chosen on), results."""

    data: DetectData
    settings: DetectSettings
    test_images: list[ScaledImage]
    norms: dict[tuple[str, str], Normalization] = field(default_factory=dict)
    training_sets: dict[tuple[int, int], TrainingSet] = field(default_factory=dict)
    tuned: dict[int, dict[str, Any]] = field(default_factory=dict)
    val_images: list[int] = field(default_factory=list)
    runs: dict[str, Any] = field(default_factory=dict)
    cnn: dict[str, Any] = field(default_factory=dict)
    agreement: dict[str, dict[str, float | None]] = field(default_factory=dict)
    alcn_trained: bool | None = None

    def training(self, seed: int, n_real: int) -> TrainingSet:
        if (seed, n_real) not in self.training_sets:
            self.training_sets[seed, n_real] = training_set(self.data, n_real, self.settings, seed)
        return self.training_sets[seed, n_real]


def _params_key(params: dict[str, Any]) -> str:
    """A key of tuned parameters, the same whatever their order."""
    return repr(sorted(params.items()))


def _normalization(state: _Run, method: str, params: dict[str, Any]) -> Normalization:
    """``method`` with its tuned ``params`` (:func:`create_normalization`), built once per method and parameters:
    a normalization holds no state between calls, so every seed's runs share it."""
    key = (method, _params_key(params))
    if key not in state.norms:
        state.norms[key] = create_normalization(method, params)
    return state.norms[key]


def _normalize_training(norm: Normalization, ts: TrainingSet) -> tuple[np.ndarray, np.ndarray, float]:
    """The training and validation windows normalized by ``norm``, and the seconds it took."""
    t0 = time.perf_counter()
    return norm.normalize_windows(ts.windows), norm.normalize_windows(ts.val_windows), time.perf_counter() - t0


def _normalize_images(norm: Normalization, images: list[ScaledImage]) -> list[ScaledImage]:
    """Whole images normalized by ``norm``."""
    return [ScaledImage(t.id, norm.normalize(t.image), t.sx, t.sy) for t in images]


def _fit(
    state: _Run,
    method: str,
    n_real: int,
    policy_name: str,
    seed: int,
    normalized: tuple[np.ndarray, np.ndarray, float],
) -> tuple[nn.Module, InputPolicy, tuple[np.ndarray, np.ndarray]]:
    """The detector of one run, trained on the normalized windows under a policy; its input policy and the detector
    inputs of the relit held-out windows."""
    settings, ts = state.settings, state.training(seed, n_real)
    train_windows, val_windows, _ = normalized
    policy = InputPolicy(policy_name, train_windows)
    size = CROP + 2 * _context(method, policy_name)
    train, val = policy.windows(train_windows, size), (policy.windows(val_windows, size), ts.val_labels)
    num_classes = len(state.data.categories) + 1
    if method == "cnn":
        net, state.cnn[f"{n_real}|{policy_name}|{seed}"] = _train_cnn_sweep(
            train, ts.labels, num_classes, settings, seed, val
        )
    else:
        net = _train(method, train, ts.labels, num_classes, settings, seed, val)
    return net, policy, val


def _train_and_score(
    state: _Run,
    method: str,
    n_real: int,
    policy_name: str,
    seed: int,
    params: dict[str, Any],
    normalized: tuple[np.ndarray, np.ndarray, float],
    test_cache: dict[str, list[ScaledImage]],
) -> dict[str, Any]:
    """One run: the detector trained on the normalized windows under a policy, scored on the test images."""
    from alcn_cv.train.stage2 import evaluate_detector

    t0 = time.perf_counter()
    settings, ts = state.settings, state.training(seed, n_real)
    norm = _normalization(state, method, params)  # built by the caller
    t_norm = normalized[2]
    if isinstance(norm, ALCN):
        state.alcn_trained = norm.trained if state.alcn_trained is None else state.alcn_trained and norm.trained
    t1 = time.perf_counter()
    net, policy, val = _fit(state, method, n_real, policy_name, seed, normalized)
    t_train = time.perf_counter() - t1
    cache_key = _params_key(params)
    if cache_key not in test_cache:  # test images do not depend on the seed
        test_cache[cache_key] = _normalize_images(norm, state.test_images)
        state.agreement.setdefault(method, {})[cache_key] = window_agreement(
            norm, [t.image for t in state.test_images], [t.image for t in test_cache[cache_key]]
        )
    return {
        "method": method,
        "real_images": n_real,
        "policy": policy.to_dict(),
        "seed": seed,
        "params": params,
        "images_used": ts.images_used,
        "objects": _evaluate(state.data, state.data.test, test_cache[cache_key], net, policy, settings),
        "val_relit_acc": evaluate_detector(net, *val)[1],
        "seconds": {"normalize_train": t_norm, "train": t_train, "total": t_norm + time.perf_counter() - t0},
    }


def _tuned_methods(settings: DetectSettings) -> list[str]:
    """The methods ``--tune`` tunes: those of :data:`TUNING_GRIDS` the run lists by bare name (none without it)."""
    return [m for m in TUNING_GRIDS if m in settings.methods] if settings.tune else []


def _validation_aucs(
    state: _Run, method: str, n_real: int, params: dict[str, Any], val_images: list[ScaledImage]
) -> dict[str, float | None]:
    """The mean AUC over objects on the validation images (``val_images``, normalized with ``params``) of the
    detector trained as in the first seed's runs on the windows normalized with ``params``, per input policy."""
    seed = state.settings.seeds[0]
    normalized = _normalize_training(_normalization(state, method, params), state.training(seed, n_real))
    assert state.data.val is not None  # main refuses to tune without it
    aucs = {}
    for policy_name in state.settings.policies:
        net, policy, _ = _fit(state, method, n_real, policy_name, seed, normalized)
        aucs[policy_name] = _mean_auc(_evaluate(state.data, state.data.val, val_images, net, policy, state.settings))
    return aucs


def _tune(state: _Run, progress: bool) -> None:
    """Choose the parameters of the tuned methods per number of real images by detection on the validation images
    (see the module docstring); ``state.tuned[n][method]`` holds the chosen ``params`` and every setting's
    ``trials``."""
    settings, data = state.settings, state.data
    methods = _tuned_methods(settings)
    if not methods:
        return
    assert data.val is not None  # main refuses to tune without it
    val_images = read_images(data.val, data.working_scale)
    state.val_images = [t.id for t in val_images]
    with tqdm(
        total=sum(len(TUNING_GRIDS[m]) for m in methods) * len(settings.real_images),
        desc="detect tuning",
        unit="setting",
        disable=not progress,
    ) as bar:
        for method in methods:
            normalized_val: dict[str, list[ScaledImage]] = {}  # per setting, shared by the numbers of real images
            for n_real in settings.real_images:
                trials = []
                for params in TUNING_GRIDS[method]:
                    key = _params_key(params)
                    bar.set_postfix(setting=format_spec(method, params), real=n_real)
                    if key not in normalized_val:
                        normalized_val[key] = _normalize_images(_normalization(state, method, params), val_images)
                    by_policy = _validation_aucs(state, method, n_real, params, normalized_val[key])
                    done = [a for a in by_policy.values() if a is not None]
                    auc = float(np.mean(done)) if done else None
                    trials.append({"params": params, "val_auc": auc, "val_auc_by_policy": by_policy})
                    bar.update()
                best = best_trial(trials)
                state.tuned.setdefault(n_real, {})[method] = {"params": dict(best["params"]), "trials": trials}
                logger.info(
                    "tuned %s for %d real image(s): %s (validation AUC %s)",
                    method,
                    n_real,
                    best["params"],
                    best["val_auc"],
                )


def _run_method(state: _Run, method: str, out: Path, bar: tqdm) -> None:
    """Every run of one method (seeds, real images, policies); a failing run is recorded with its error."""
    test_cache: dict[str, list[ScaledImage]] = {}
    for seed, n_real in ((seed, n) for seed in state.settings.seeds for n in state.settings.real_images):
        params = state.tuned.get(n_real, {}).get(method, {}).get("params", {})
        normalized: tuple[np.ndarray, np.ndarray, float] | Exception | None = None
        for policy_name in state.settings.policies:
            key = run_key(method, n_real, policy_name, seed)
            bar.set_postfix(run=key)
            try:
                if normalized is None:  # once per method and training set, shared by the policies
                    try:
                        normalized = _normalize_training(
                            _normalization(state, method, params), state.training(seed, n_real)
                        )
                    except Exception as exc:
                        normalized = exc
                if isinstance(normalized, Exception):
                    raise normalized
                state.runs[key] = _train_and_score(
                    state, method, n_real, policy_name, seed, params, normalized, test_cache
                )
            except Exception as exc:  # its spec was built up front: what fails here is the run's, reported
                logger.error(
                    "run %s failed: %s: %s", key, type(exc).__name__, exc, exc_info=logger.isEnabledFor(logging.DEBUG)
                )
                state.runs[key] = {
                    "method": method,
                    "real_images": n_real,
                    "policy": policy_name,
                    "seed": seed,
                    "error": f"{type(exc).__name__}: {exc}",
                }
            bar.update()
            write_json(
                out / "detect.partial.json", {"runs": state.runs, "tuned": {str(k): v for k, v in state.tuned.items()}}
            )


def _result(state: _Run, command: str, seconds: float) -> dict[str, Any]:
    """The contents of ``detect.json`` (without the figures)."""
    data, settings = state.data, state.settings
    return {
        "benchmark": "detect",
        "data": str(data.root.resolve()),
        "command": command,
        "working_scale": data.working_scale,
        "box_size": data.box_size,
        "test_images": [t.id for t in state.test_images],
        "val_images": state.val_images,
        "settings": asdict(settings),
        "tuned": {str(k): v for k, v in state.tuned.items()},
        "cnn": state.cnn,
        "window_agreement": state.agreement,
        "alcn_trained": state.alcn_trained,
        "machine": machine(),
        "runs": state.runs,
        "summary": summarize(state.runs, settings, [data.name(c) for c in data.categories]),
        "seconds": seconds,
    }


@holds_out_dir
def main(
    data_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    settings: DetectSettings | None = None,
    working_scale: float | None = None,
    box_size: float | None = None,
    progress: bool = True,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run the detection benchmark (see the module docstring) and write its outputs.

    Args:
        data_dir: benchmark folder (``train.json``, ``test.json``, ``manifest.json``; ``val.json`` to tune).
        out_dir: output folder (created).
        settings: the run's settings; default :class:`~alcn_cv.bench.detect_settings.DetectSettings`. Their
            methods, None (the default's), are :func:`~alcn_cv.bench.detect_settings.default_methods` at the start.
        working_scale, box_size: see :func:`~alcn_cv.bench.detect_data.load_data`.
        progress: progress bar across runs.
        overwrite: replace the report of an earlier run in ``out_dir``.

    Returns:
        The dictionary written to ``detect.json``. A run that fails once its method is built (out of
        memory, a device error) is recorded with its error and the benchmark continues.

    Raises:
        InputError: bad settings (a device torch does not have among them), a method that cannot be built (a bad
            parameter or weight file), tuning on data without validation objects, or an ``out_dir`` that holds an
            earlier run's report (without ``overwrite``), before any work.
    """
    import torch

    from alcn_cv.nets.device import torch_device

    settings = (settings or DetectSettings()).resolved()  # the methods registered now, for the default's
    settings.check()
    torch_device(settings.device, "--device")  # every run would fail on it, each after its windows are made
    check_no_earlier_output([Path(out_dir) / "detect.json", Path(out_dir) / "detect.md"], overwrite)
    # a bad spec or weight file: one line before any work; the untuned runs use these
    built = build_methods(settings.methods, create_normalization)
    if settings.threads:
        torch.set_num_threads(settings.threads)
    start = time.perf_counter()
    data = load_data(data_dir, working_scale, box_size)
    if _tuned_methods(settings) and (data.val is None or not data.val.annotations):
        raise InputError(
            f"{data.root}: {'no val.json' if data.val is None else 'no object in val.json'}, the validation images "
            "--tune scores its settings on: render the data again with `alcn data detect`, or add test-like images of "
            "the objects as val.json (COCO, as test.json)"
        )
    if not data.test.images:
        raise InputError(f"{data.root}: no test image in test.json: render the data again with `--n-test` 1 or more")
    out = Path(out_dir)
    make_folder(out)
    norms = {(spec, _params_key({})): norm for spec, norm in built.items()}
    state = _Run(data, settings, read_images(data.test, data.working_scale, settings.max_test_images), norms)
    logger.info("read %d test images", len(state.test_images))
    _tune(state, progress)
    with tqdm(
        total=len(settings.methods) * len(settings.seeds) * len(settings.real_images) * len(settings.policies),
        desc="detect benchmark",
        unit="run",
        disable=not progress,
    ) as bar:
        for method in settings.methods:
            _run_method(state, method, out, bar)

    result = _result(
        state, detect_command(data_dir, out_dir, settings, working_scale, box_size), time.perf_counter() - start
    )
    names = [data.name(c) for c in data.categories]
    result["figures"] = figures = pr_figure_names(names, settings.real_images)
    # all or none: an interrupt leaves an earlier report whole, its curves included; an earlier run's curves of
    # other objects go with it
    report = [out / "detect.json", out / "detect.md", *(out / f for f in figures)]
    with atomic_paths(*report, stale=out.glob("pr_*real.png")) as (json_path, md, *pngs):
        plot_pr_curves(result, names, pngs)
        result["seconds"] = time.perf_counter() - start
        write_json(json_path, result)
        atomic_write(md, detect_markdown(result, names))
    (out / "detect.partial.json").unlink(missing_ok=True)
    logger.info("detection benchmark written to %s in %.0f s", out, result["seconds"])
    return result
