"""The few-shot detection benchmark of ALCN (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3, Fig. 5).

For every method and for 1 and 10 real training images per object:

1. **Training windows.** The first ``n`` training images of each object (COCO ``train.json``),
   resized to the working scale (``cv2.INTER_AREA``), give the paper's simple synthetic images
   (:func:`alcn_cv.data.synthetic.augment`: background replaced, small affine changes of
   intensity, noise, small geometric jitter) and background windows
   (:func:`~alcn_cv.data.synthetic.sample_negatives`), 64x64 each. They are drawn once per
   ``n`` with a fixed seed, so every method trains on the same windows.
2. **Normalization.** Each window is normalized with the method (``normalize`` on the 64x64
   window; ALCN with ``scale=1``, the window being already at the working scale, and Eq. 1 as in
   the paper's second stage, see :func:`normalize_windows`) and its 32x32 centre kept. Global methods (``ns``, ``he``, ``whitening``, ...) therefore see the window at
   training time and the whole image at test time, as a user would apply them.
3. **Input policy**, the same for every method: ``raw`` -- a fixed affine map, the training
   windows' mean and standard deviation (one scalar each, so all methods reach the detector
   with unit variance, without changing the method's response); ``standardize`` -- each 32x32
   window to zero mean and unit variance (per-window standardization; at test time every
   window is standardized and scored alone, about 10 times the cost of ``raw``); ``local`` --
   every pixel standardized by the mean and deviation of the 31x31 box around it
   (:func:`local_standardize`, an image operation, so the detector still runs densely; close
   to ``standardize`` at the window's centre).
4. **Detector.** The same network (:class:`alcn_cv.nets.Detector`, Sec. 4.2) trained in the
   same way (:func:`alcn_cv.train.stage2.train_detector`: Adam, same epochs, batch, rate and
   seed). The deep baselines of Sec. 4.3.1 train their own networks on the same windows
   without normalization: ``cnn`` (the plain CNN of :mod:`alcn_cv.nets.plain` whose depth and
   width, from a small sweep, scores best on relit held-out training windows), ``resnet20``
   and ``resnet56`` (:mod:`alcn_cv.nets.resnet`). The Detector and the plain CNN have valid
   convolutions: their dense scores equal scoring every window alone. The ResNets' padded
   convolutions see the image around a window in a dense run, so with the dense input
   policies they are trained on the 32x32 windows with :data:`RESNET_CONTEXT` pixels of their
   surroundings and classify from the central 32x32's feature cells, which is what their dense
   run pools (see :mod:`alcn_cv.nets.resnet`).
5. **Test.** Every test image is resized to the working scale, normalized whole, and every
   32x32 window at stride 4 is scored (``dense``; with ``standardize`` each window is
   standardized and scored alone). Per object: a fixed-size square box (``box_size`` at the
   working scale) centred on each window, greedy non-maximum suppression, and the PASCAL
   criterion (IoU >= 0.8) against fixed-size boxes of the same size centred on the ground
   truth. Precision-recall over all test images, and its area (AUC, PASCAL VOC average
   precision).

A method may carry parameters, ``NAME:KEY=VALUE[:KEY=VALUE...]`` (``alcn:model=lite:mixture=pyramid``
compares the real-time ALCN with the exact one, ``dog:sigma2=2``), and every run may be repeated
over several seeds (``--seeds 0,1,2``): a single seed's AUC moves by several hundredths with the
training windows and the detector's initialisation, so differences between methods are only
read against the spread over seeds.

With ``--tune``, DoG, SLCN and DLCN are first tuned on the training windows
(:mod:`alcn_cv.bench.tuning`); by default they keep their defaults, because on the data
engine's benchmark the tuned settings scored lower than the defaults (see the tuning module).

Outputs: ``detect.json`` (every number, PR curves, settings, tuned parameters, timings,
machine), ``detect.md`` (AUC tables) and
``pr_<object>_<n>real.png`` (precision-recall, all methods).
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import cv2
import numpy as np
from tqdm.auto import tqdm

from alcn_cv.bench import tuning
from alcn_cv.bench.metrics import match_detections, nms, pr_auc, precision_recall
from alcn_cv.report import machine, markdown_table, new_figure, save_figure, write_json
from alcn_cv.io import atomic_write
from alcn_cv.io import read_json
from alcn_cv.enhance.alcn import ALCN
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import available, create, parse_spec
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.filters.gaussian_mixture import alcn_filter
from alcn_cv.formats.coco import CocoDataset, load_coco

if TYPE_CHECKING:
    from torch import nn

__all__ = ["DEEP_BASELINES", "POLICIES", "DetectData", "DetectSettings", "default_methods", "load_data", "main"]

logger = logging.getLogger(__name__)

#: Deep baselines (own networks, no normalization) of Sec. 4.3.1.
DEEP_BASELINES = ("cnn", "resnet20", "resnet56")
RESNETS = ("resnet20", "resnet56")
POLICIES = ("raw", "standardize", "local")
WINDOW = 64
CROP = 32
STRIDE = 4
LOCAL_BOX = 31
#: Pixels of surroundings around the 32x32 window in the ResNets' training inputs (dense policies):
#: the whole 64x64 training window.
RESNET_CONTEXT = (WINDOW - CROP) // 2
_BATCH = 1024


def default_methods() -> list[str]:
    """Every registered normalization, then the deep baselines but ResNet-56, which alone would
    take most of the default run's half-hour budget on 2 CPU cores (``--methods`` adds it)."""
    return list(available()) + [m for m in DEEP_BASELINES if m != "resnet56"]


@dataclass
class DetectSettings:
    """Settings of a benchmark run (all recorded in ``detect.json``).

    Attributes:
        methods: registered normalization names, each optionally with parameters
            (``NAME[:KEY=VALUE...]``, e.g. ``alcn:model=lite:mixture=pyramid``), and/or
            :data:`DEEP_BASELINES`.
        real_images: numbers of real training images per object.
        policies: detector input policies (:data:`POLICIES`).
        positives_per_object: synthetic object windows per object.
        negatives_ratio: background windows per object window.
        epochs, batch_size, lr: detector training (the same for every method).
        seeds: one repetition of every run per seed (training windows, detector
            initialisation and batch order); the tables give the mean and spread over seeds.
        tune: tune DoG, SLCN and DLCN on the training windows (:mod:`alcn_cv.bench.tuning`).
        cnn_sweep: ``(depth, width)`` of the plain CNNs tried for ``cnn``.
        nms_iou: IoU above which non-maximum suppression removes a box.
        match_iou: PASCAL criterion (the paper: 0.8).
        max_detections: boxes kept per object and image after suppression.
        max_test_images: use only the first test images (``None``: all).
        threads: torch threads (``None``: torch's default).
        device: torch device.
    """

    methods: list[str] = field(default_factory=default_methods)
    real_images: list[int] = field(default_factory=lambda: [1, 10])
    policies: list[str] = field(default_factory=lambda: ["local"])
    positives_per_object: int = 300
    negatives_ratio: float = 2.0
    epochs: int = 6
    batch_size: int = 64
    lr: float = 1e-3
    seeds: list[int] = field(default_factory=lambda: [0])
    tune: bool = False
    cnn_sweep: list[tuple[int, int]] = field(default_factory=lambda: [(1, 32), (2, 32), (3, 32)])
    nms_iou: float = 0.3
    match_iou: float = 0.8
    max_detections: int = 20
    max_test_images: int | None = None
    threads: int | None = None
    device: str = "cpu"

    def check(self) -> None:
        known = set(available()) | set(DEEP_BASELINES)
        specs = [parse_spec(m) for m in self.methods]
        unknown = [m for m, (name, _) in zip(self.methods, specs) if name not in known]
        if unknown or not self.methods:
            raise InputError(f"unknown or no method(s) {unknown}; available: {', '.join(sorted(known))}")
        if any(name in DEEP_BASELINES and params for name, params in specs):
            raise InputError(f"the deep baselines {', '.join(DEEP_BASELINES)} take no parameters")
        if len(set(self.methods)) != len(self.methods):
            raise InputError(f"a method is listed twice: {self.methods}")
        if not self.seeds or len(set(self.seeds)) != len(self.seeds):
            raise InputError(f"seeds must be distinct and at least one, got {self.seeds}")
        if not self.real_images or min(self.real_images) < 1:
            raise InputError(f"real_images must be positive integers, got {self.real_images}")
        bad = [p for p in self.policies if p not in POLICIES]
        if bad or not self.policies:
            raise InputError(f"unknown or no policy {bad}; choose from {', '.join(POLICIES)}")
        if self.positives_per_object < 1 or self.negatives_ratio < 0 or self.epochs < 1 or self.batch_size < 1:
            raise InputError("positives_per_object, epochs and batch_size must be >= 1 and negatives_ratio >= 0")
        if not 0 <= self.nms_iou < 1 or not 0 < self.match_iou <= 1:
            raise InputError(f"need 0 <= nms_iou < 1 and 0 < match_iou <= 1, got {self.nms_iou}, {self.match_iou}")
        if not self.cnn_sweep:
            raise InputError("cnn_sweep needs at least one (depth, width)")


@dataclass
class DetectData:
    """A COCO detection benchmark: training and test sets and their working scale."""

    root: Path
    train: CocoDataset
    test: CocoDataset
    working_scale: float
    box_size: float

    @property
    def categories(self) -> list[int]:
        return sorted(c.id for c in self.test.categories)

    def name(self, category: int) -> str:
        return self.test.category(category).name


def load_data(data_dir: str | os.PathLike, working_scale: float | None = None, box_size: float | None = None) -> DetectData:
    """Read ``train.json``, ``test.json`` and (when present) ``manifest.json`` of a benchmark folder.

    Args:
        data_dir: the folder (the data engine's ``alcn data detect`` output, or any COCO set
            laid out the same way).
        working_scale, box_size: override (or, without a manifest, give) the scale to the
            detector's resolution and the side of the fixed-size boxes at that scale.

    Raises:
        DatasetError: missing or malformed files, no working scale or box size, test categories
            that the training set lacks.
    """
    root = Path(data_dir)
    manifest_path = root / "manifest.json"
    manifest = read_json(manifest_path) if manifest_path.is_file() else {}
    if not isinstance(manifest, dict):
        raise DatasetError(f"{manifest_path}: expected a JSON object")
    scale = working_scale if working_scale is not None else manifest.get("working_scale")
    box = box_size if box_size is not None else manifest.get("box_size")
    if scale is None or box is None:
        raise DatasetError(f"{manifest_path}: fields 'working_scale' and 'box_size' are needed "
                           "(or pass --working-scale and --box-size)")
    scale, box = float(scale), float(box)
    if not 0 < scale <= 4 or not box > 0:
        raise DatasetError(f"{manifest_path}: working_scale {scale} must be in (0, 4] and box_size {box} positive")
    train = load_coco(root / "train.json")
    test = load_coco(root / "test.json")
    train_ids = {c.id for c in train.categories}
    missing = [c.name for c in test.categories if c.id not in train_ids]
    if missing:
        raise DatasetError(f"{root / 'train.json'}: field categories: no training category for {missing}")
    return DetectData(root, train, test, scale, box)


def _working_gray(ds: CocoDataset, image: Any, scale: float) -> tuple[np.ndarray, float, float]:
    """The image in grayscale at the working scale (uint8) and the actual x and y factors."""
    gray = cv2.cvtColor(ds.read_image(image), cv2.COLOR_BGR2GRAY)
    h, w = gray.shape
    size = (max(CROP, round(w * scale)), max(CROP, round(h * scale)))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    return cv2.resize(gray, size, interpolation=interp), size[0] / w, size[1] / h


@dataclass
class TrainingSet:
    windows: np.ndarray  # (n, 64, 64) uint8
    labels: np.ndarray  # (n,) int64
    val_windows: np.ndarray  # relit held-out windows (float32 in [0, 1]) for model selection
    val_labels: np.ndarray
    images_used: dict[str, int]


def training_set(data: DetectData, n_real: int, settings: DetectSettings, seed: int = 0) -> TrainingSet:
    """The synthetic training windows from the first ``n_real`` images of each object (see the module docstring)."""
    from alcn_cv.data.synthetic import augment, sample_negatives

    rng = np.random.default_rng([seed, n_real])
    windows, labels, val_windows, val_labels = [], [], [], []
    sources, boxes, used = [], [], {}
    images = {im.id: im for im in data.train.images}
    for label, cat in enumerate(data.categories, start=1):
        anns = sorted((a for a in data.train.annotations if a.category_id == cat), key=lambda a: (a.image_id, a.id))
        chosen, seen = [], set()
        for a in anns:
            if a.image_id not in seen:
                seen.add(a.image_id)
                chosen.append(a)
            if len(chosen) == n_real:
                break
        if not chosen:
            raise DatasetError(f"{data.train.path}: no training image of category {data.name(cat)!r}")
        used[data.name(cat)] = len(chosen)
        per_image = -(-settings.positives_per_object // len(chosen))
        n_val = max(1, per_image // 4)
        pos, val = [], []
        for a in chosen:
            gray, sx, sy = _working_gray(data.train, images[a.image_id], data.working_scale)
            box = a.bbox * np.array([sx, sy, sx, sy])
            sources.append(gray)
            boxes.append(box)
            w = augment(gray, box, per_image + n_val, rng, extent=None)
            pos.append(w[:per_image])
            val.append(w[per_image:])
        windows.append(np.concatenate(pos)[: settings.positives_per_object])
        labels.append(np.full(len(windows[-1]), label))
        val_windows.append(np.concatenate(val))
        val_labels.append(np.full(len(val_windows[-1]), label))
    n_pos = sum(len(w) for w in windows)
    n_neg = int(round(settings.negatives_ratio * n_pos))
    n_val_neg = int(round(settings.negatives_ratio * sum(len(w) for w in val_windows)))
    neg = sample_negatives(sources, boxes, n_neg + n_val_neg, rng, extent=None)
    windows.append(neg[:n_neg])
    labels.append(np.zeros(n_neg))
    val_windows.append(neg[n_neg:])
    val_labels.append(np.zeros(n_val_neg))
    val = np.concatenate(val_windows).astype(np.float32) / np.float32(255)
    return TrainingSet(
        np.concatenate(windows), np.concatenate(labels).astype(np.int64),
        tuning.relight(val, np.random.default_rng([seed, n_real, 1])), np.concatenate(val_labels).astype(np.int64),
        used,
    )


def normalize_windows(norm: Normalization, windows: np.ndarray) -> np.ndarray:
    """Normalize every ``(S, S)`` window (uint8 or float32 in [0, 1]).

    ALCN uses Eq. 1 on training windows, as in the paper's second stage: one weight vector per
    window, predicted by the Normalizer from the window's central 48x48, then the Gaussian
    mixture over the window (test images use Eq. 3, per-pixel weights, through ``normalize``).

    Returns:
        ``(n, S, S)`` float32 (the caller crops the centre, see :meth:`InputPolicy.windows`).
    """
    scale = np.float32(1 / 255) if windows.dtype == np.uint8 else np.float32(1)
    unit = windows.astype(np.float32) * scale
    if isinstance(norm, ALCN):
        import torch

        from alcn_cv.nets.normalizer import WINDOW as NORMALIZER_WINDOW

        x = torch.from_numpy(np.ascontiguousarray(tuning.centre_windows(unit, NORMALIZER_WINDOW)))[:, None]
        with torch.inference_mode():
            weights = torch.cat([norm.net(x[i : i + _BATCH]) for i in range(0, len(x), _BATCH)]).numpy()
        out = [alcn_filter(w, wt, norm.full_res_sigmas) for w, wt in zip(unit, weights)]
    else:
        out = [norm.normalize(w) for w in unit]
    return np.stack(out)


def local_standardize(image: np.ndarray, size: int = LOCAL_BOX, eps: float = 1e-6) -> np.ndarray:
    """Standardize every pixel by the mean and standard deviation of the ``size x size`` box around it.

    Box filters with reflect-101 borders. An image operation, so a detector runs densely on
    its output; close to per-window standardization at a window's centre.

    Args:
        image: ``(H, W)`` float32.
        size: odd box side in pixels (default 31, the detector window's size made odd).
        eps: added to the standard deviation.

    Returns:
        ``(H, W)`` float32.
    """
    box = (size, size)
    mean = cv2.boxFilter(image, cv2.CV_32F, box, borderType=cv2.BORDER_REFLECT_101)
    sq = cv2.boxFilter(image * image, cv2.CV_32F, box, borderType=cv2.BORDER_REFLECT_101)
    std = np.sqrt(np.maximum(sq - mean * mean, 0.0))
    return ((image - mean) / (std + np.float32(eps))).astype(np.float32)


class InputPolicy:
    """The detector's input policy (:data:`POLICIES`, see the module docstring).

    Args:
        name: ``raw``, ``standardize`` or ``local``.
        train_windows: ``(n, S, S)`` normalized training windows (``raw`` fits its mean and
            standard deviation on their 32x32 centres).
    """

    def __init__(self, name: str, train_windows: np.ndarray) -> None:
        if name not in POLICIES:
            raise InputError(f"unknown input policy {name!r}; choose from {', '.join(POLICIES)}")
        self.name = name
        centres = tuning.centre_windows(train_windows, CROP)
        self.mean = float(centres.mean())
        self.std = float(centres.std()) or 1.0

    def windows(self, windows: np.ndarray, size: int = CROP) -> np.ndarray:
        """``(n, S, S)`` normalized windows -> ``(n, size, size)`` detector inputs (their centres;
        ``size`` larger than 32 only with the dense policies, for networks that take context)."""
        if self.name == "local":
            return tuning.centre_windows(np.stack([local_standardize(w) for w in windows]), size)
        if self.name == "standardize" and size != CROP:
            raise InputError("per-window standardization scores bare 32x32 windows; it takes no context")
        centres = tuning.centre_windows(windows, size)
        if self.name == "standardize":
            return tuning.standardize_windows(centres)
        return ((centres - np.float32(self.mean)) / np.float32(self.std)).astype(np.float32)

    def image(self, image: np.ndarray) -> np.ndarray:
        """A whole normalized image -> the detector's dense input (``raw`` and ``local``)."""
        if self.name == "local":
            return local_standardize(image)
        if self.name == "raw":
            return ((image - np.float32(self.mean)) / np.float32(self.std)).astype(np.float32)
        raise InputError("per-window standardization has no whole-image form; score windows one by one")

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "mean": self.mean, "std": self.std} if self.name == "raw" else {"name": self.name}


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
            mean = win.mean((2, 3), keepdim=True)
            std = win.std((2, 3), keepdim=True, unbiased=False)
            win = (win - mean) / (std + 1e-6)
            logits = torch.cat([net(win[i : i + _BATCH]) for i in range(0, len(win), _BATCH)]).T.reshape(-1, hd, wd)
        return F.softmax(logits[:, :hd, :wd], dim=0).cpu().numpy()


def _all_score_maps(net: nn.Module, images: list[np.ndarray], policy: InputPolicy, device: str, batch: int = 8) -> list[np.ndarray]:
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
    return np.column_stack([centres[:, 0] - side_x / 2, centres[:, 1] - side_y / 2,
                            np.full(len(centres), side_x), np.full(len(centres), side_y)])


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
        from alcn_cv.nets.plain import PlainCNN

        depth, width = config or (2, 32)
        return PlainCNN(num_classes, depth=depth, width=width)
    if method in RESNETS:
        from alcn_cv.nets import resnet

        return getattr(resnet, method)(num_classes, context=context)
    from alcn_cv.nets import Detector

    return Detector(num_classes)


def _create_normalization(method: str, params: dict[str, Any]) -> Normalization:
    """``method`` is a spec (``NAME[:KEY=VALUE...]``); ``params`` (tuned ones) are added to its own."""
    name, own = parse_spec(method)
    params = {**own, **params}
    if name in DEEP_BASELINES:
        return create("none")
    if name == "alcn":
        params.setdefault("scale", 1.0)  # windows and test images are already at the working scale
    return create(name, **params)


def _train(
    method: str, train: np.ndarray, labels: np.ndarray, num_classes: int, settings: DetectSettings, seed: int,
    val: tuple[np.ndarray, np.ndarray], config: tuple[int, int] | None = None,
) -> nn.Module:
    import torch

    from alcn_cv.train.stage2 import train_detector

    with torch.random.fork_rng(devices=[]):  # the seed, not the runs before, sets the initial weights
        torch.manual_seed(seed)
        net = _make_net(method, num_classes, config, context=(train.shape[-1] - CROP) // 2)
    return train_detector(
        train, labels, num_classes, epochs=settings.epochs, batch_size=settings.batch_size, lr=settings.lr,
        seed=seed, val=val, progress=False, net=net, device=settings.device,
    )


def _train_cnn_sweep(
    train: np.ndarray, labels: np.ndarray, num_classes: int, settings: DetectSettings, seed: int,
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
    data: DetectData, test_images: list[tuple[int, np.ndarray, float, float]], net: nn.Module,
    policy: InputPolicy, settings: DetectSettings,
) -> dict[str, Any]:
    probs = _all_score_maps(net, [img for _, img, _, _ in test_images], policy, settings.device)
    per_object = {}
    for label, cat in enumerate(data.categories, start=1):
        scores, tps, n_gt = [], [], 0
        for (image_id, _, sx, sy), p in zip(test_images, probs):
            gt = [a for a in data.test.annotations_for(image_id) if a.category_id == cat]
            n_gt += len(gt)
            boxes, s = detect_in_image(p, label, sx, sy, data.box_size, settings.nms_iou, settings.max_detections)
            gt_centres = np.array([[a.bbox[0] + a.bbox[2] / 2, a.bbox[1] + a.bbox[3] / 2] for a in gt]).reshape(-1, 2)
            gt_boxes = fixed_boxes(gt_centres, data.box_size / sx, data.box_size / sy)
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


def run_key(method: str, n_real: int, policy: str, seed: int) -> str:
    """Key of one run in ``detect.json``'s ``runs``."""
    return f"{method}|{n_real}|{policy}|{seed}"


def _spread(values: list[float]) -> dict[str, Any]:
    return {"mean": float(np.mean(values)), "std": float(np.std(values)), "values": values}


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
                seeded = [(seed, runs.get(run_key(method, n_real, policy, seed), {"error": "not run"})) for seed in settings.seeds]
                done = [(seed, r) for seed, r in seeded if "error" not in r]
                cell: dict[str, Any] = {"seeds": [seed for seed, _ in done],
                                        "failed_seeds": [seed for seed, r in seeded if "error" in r]}
                if not done:
                    cell["error"] = seeded[0][1]["error"]
                else:
                    cell["objects"] = {}
                    for name in names:
                        aucs = [r["objects"][name]["auc"] for _, r in done if r["objects"][name]["auc"] is not None]
                        cell["objects"][name] = _spread(aucs) if aucs else None
                    means = [float(np.mean(v)) for v in
                             ([o["auc"] for o in r["objects"].values() if o["auc"] is not None] for _, r in done) if v]
                    cell["mean"] = _spread(means) if means else None
                summary[f"{method}|{n_real}|{policy}"] = cell
    return summary


def _plot_pr(results: dict[str, Any], data: DetectData, out: Path, settings: DetectSettings) -> list[str]:
    written = []
    for cat in data.categories:
        name = data.name(cat)
        for n_real in settings.real_images:
            plt, fig, axes = new_figure(1, len(settings.policies), figsize=(5.2 * len(settings.policies), 4.6))
            for ax, policy in zip(axes[0], settings.policies):
                cmap = plt.get_cmap("tab20")
                for k, method in enumerate(settings.methods):
                    run = results.get(run_key(method, n_real, policy, settings.seeds[0]), {})
                    obj = run.get("objects", {}).get(name)
                    if not obj or obj.get("auc") is None:
                        continue
                    style = "-" if k < 10 else "--"
                    lw = 2.4 if method == "alcn" else 1.2
                    ax.plot(obj["pr"]["recall"], obj["pr"]["precision"], style, color=cmap(k % 20), lw=lw,
                            label=f"{method} ({obj['auc']:.3f})")
                ax.set_xlim(0, 1)
                ax.set_ylim(0, 1.02)
                ax.set_xlabel("recall")
                ax.set_ylabel("precision")
                ax.set_title(f"{name}, {n_real} real image(s), input {policy}, seed {settings.seeds[0]}", fontsize=10)
                ax.grid(alpha=0.3)
                if ax.get_legend_handles_labels()[0]:
                    ax.legend(fontsize=7, loc="upper right")
            fig.tight_layout()
            path = out / f"pr_{name}_{n_real}real.png"
            save_figure(plt, fig, path)
            written.append(path.name)
    return written


def _markdown(result: dict[str, Any], data: DetectData, settings: DetectSettings) -> str:
    names = [data.name(c) for c in data.categories]
    lines = [
        f"# Detection benchmark ({data.root.name})\n",
        f"{len(result['test_images'])} test images at working scale {data.working_scale} (box {data.box_size} px); "
        f"PASCAL IoU >= {settings.match_iou} with fixed-size boxes; AUC = area under precision-recall. "
        f"Same detector and training for every normalization ({settings.epochs} epochs, batch {settings.batch_size}, "
        f"lr {settings.lr}, {settings.positives_per_object} object windows per object, "
        f"{settings.negatives_ratio}x background windows). Total time {result['seconds']:.0f} s.\n",
    ]
    alcn_note = result.get("alcn_trained")
    if alcn_note is False:
        lines.append("**The `alcn` row used UNTRAINED Normalizer weights** (the shipped file's `trained` flag is false).\n")
    seeds = settings.seeds
    if len(seeds) > 1:
        lines.append(f"Every cell: mean +- standard deviation over {len(seeds)} seeds ({', '.join(map(str, seeds))}); "
                     "a seed draws other training windows, detector initialisation and batch order.\n")

    def cell(spread: dict[str, Any] | None) -> str | None:
        if spread is None:
            return None
        return f"{spread['mean']:.3f}" + (f" +- {spread['std']:.3f}" if len(spread["values"]) > 1 else "")

    for n_real in settings.real_images:
        for policy in settings.policies:
            rows = []
            for method in settings.methods:
                summary = result["summary"][f"{method}|{n_real}|{policy}"]
                if "error" in summary:
                    rows.append([method] + ["failed"] * (len(names) + 1))
                    continue
                failed = f" ({len(summary['failed_seeds'])} seed(s) failed)" if summary["failed_seeds"] else ""
                rows.append([method + failed] + [cell(summary["objects"][n]) for n in names] + [cell(summary["mean"])])
            lines.append(f"\n## {n_real} real image(s) per object, input policy `{policy}`\n")
            lines.append(markdown_table(["method"] + names + ["mean"], rows))
    failures = [f"- `{k}`: {v['error']}" for k, v in result["runs"].items() if "error" in v]
    if failures:
        lines.append("\n## Failures\n\n" + "\n".join(failures) + "\n")
    if result.get("tuned"):
        lines.append("\n## Tuned parameters (relit 1-NN accuracy on the training windows)\n")
        for n_real, tuned in result["tuned"].items():
            for m, t in tuned.items():
                best = max(t["trials"], key=lambda x: x["score"])
                lines.append(f"- {n_real} real: `{m}` {t['params']} ({best['score']:.3f})")
        lines.append("")
    if result.get("cnn"):
        lines.append("\n## Plain CNN sweep (chosen by accuracy on relit held-out training windows)\n")
        for key, c in result["cnn"].items():
            lines.append(f"- {key}: chosen depth {c['chosen']['depth']} width {c['chosen']['width']}; "
                         + ", ".join(f"{s['depth']}x{s['width']}: {s['val_acc']:.3f}" for s in c["sweep"]))
        lines.append("")
    return "\n".join(lines) + "\n"


def main(
    data_dir: str | os.PathLike,
    out_dir: str | os.PathLike,
    settings: DetectSettings | None = None,
    working_scale: float | None = None,
    box_size: float | None = None,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the detection benchmark (see the module docstring) and write its outputs.

    Args:
        data_dir: benchmark folder (``train.json``, ``test.json``, ``manifest.json``).
        out_dir: output folder (created).
        settings: the run's settings; default :class:`DetectSettings`.
        working_scale, box_size: see :func:`load_data`.
        progress: progress bar across runs.

    Returns:
        The dictionary written to ``detect.json``. A method that fails is recorded with its
        error and the run continues.
    """
    import torch

    settings = settings or DetectSettings()
    settings.check()
    if settings.threads:
        torch.set_num_threads(settings.threads)
    start = time.perf_counter()
    data = load_data(data_dir, working_scale, box_size)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    num_classes = len(data.categories) + 1
    test_meta = data.test.images[: settings.max_test_images] if settings.max_test_images else data.test.images
    logger.info("reading %d test images", len(test_meta))
    test_gray = []
    for im in test_meta:
        gray, sx, sy = _working_gray(data.test, im, data.working_scale)
        test_gray.append((im.id, gray.astype(np.float32) / np.float32(255), sx, sy))

    sets: dict[tuple[int, int], TrainingSet] = {}

    def training(seed: int, n_real: int) -> TrainingSet:
        if (seed, n_real) not in sets:
            sets[seed, n_real] = training_set(data, n_real, settings, seed)
        return sets[seed, n_real]

    tuned: dict[int, dict[str, Any]] = {}
    if settings.tune:  # on the first seed's windows; the chosen parameters serve every seed
        to_tune = [m for m in tuning.GRIDS if m in settings.methods]
        for n in settings.real_images:
            if to_tune:
                ts = training(settings.seeds[0], n)
                tuned[n] = tuning.tune_all(ts.windows, ts.labels, settings.seeds[0], to_tune)

    from alcn_cv.train.stage2 import evaluate_detector

    runs: dict[str, Any] = {}
    cnn_info: dict[str, Any] = {}
    alcn_trained = None
    total = len(settings.methods) * len(settings.seeds) * len(settings.real_images) * len(settings.policies)
    bar = tqdm(total=total, desc="detect benchmark", unit="run", disable=not progress)
    for method in settings.methods:
        test_cache: dict[str, list[tuple[int, np.ndarray, float, float]]] = {}  # test images do not depend on the seed
        for seed, n_real in ((seed, n) for seed in settings.seeds for n in settings.real_images):
            params = tuned.get(n_real, {}).get(method, {}).get("params", {})
            ts = training(seed, n_real)
            normalized: tuple[Normalization, np.ndarray, np.ndarray, float] | Exception | None = None
            for policy_name in settings.policies:
                key = run_key(method, n_real, policy_name, seed)
                bar.set_postfix(run=key)
                t0 = time.perf_counter()
                try:
                    if normalized is None:  # once per method and training set, shared by the policies
                        try:
                            norm = _create_normalization(method, params)
                            normalized = (norm, normalize_windows(norm, ts.windows),
                                          normalize_windows(norm, ts.val_windows), time.perf_counter() - t0)
                        except Exception as exc:
                            normalized = exc
                    if isinstance(normalized, Exception):
                        raise normalized
                    norm, train_windows, val_windows, t_norm = normalized
                    if isinstance(norm, ALCN):
                        alcn_trained = norm.trained if alcn_trained is None else alcn_trained and norm.trained
                    policy = InputPolicy(policy_name, train_windows)
                    size = CROP + 2 * _context(method, policy_name)
                    train, val = policy.windows(train_windows, size), (policy.windows(val_windows, size), ts.val_labels)
                    t1 = time.perf_counter()
                    if method == "cnn":
                        net, cnn_info[f"{n_real}|{policy_name}|{seed}"] = _train_cnn_sweep(
                            train, ts.labels, num_classes, settings, seed, val)
                    else:
                        net = _train(method, train, ts.labels, num_classes, settings, seed, val)
                    t_train = time.perf_counter() - t1
                    cache_key = repr(sorted(params.items()))
                    if cache_key not in test_cache:
                        test_cache[cache_key] = [(i, norm.normalize(g), sx, sy) for i, g, sx, sy in test_gray]
                    runs[key] = {
                        "method": method, "real_images": n_real, "policy": policy.to_dict(), "seed": seed,
                        "params": params, "images_used": ts.images_used,
                        "objects": _evaluate(data, test_cache[cache_key], net, policy, settings),
                        "val_relit_acc": evaluate_detector(net, *val)[1],
                        "seconds": {"normalize_train": t_norm, "train": t_train, "total": time.perf_counter() - t0},
                    }
                except Exception as exc:  # one method failing is reported, not the end of the run
                    logger.error("run %s failed: %s: %s", key, type(exc).__name__, exc, exc_info=logger.isEnabledFor(logging.DEBUG))
                    runs[key] = {"method": method, "real_images": n_real, "policy": policy_name, "seed": seed,
                                 "error": f"{type(exc).__name__}: {exc}"}
                bar.update()
                write_json(out / "detect.partial.json", {"runs": runs, "tuned": {str(k): v for k, v in tuned.items()}})
    bar.close()

    settings_dict = asdict(settings)
    result = {
        "benchmark": "detect",
        "data": str(data.root.resolve()),
        "working_scale": data.working_scale,
        "box_size": data.box_size,
        "test_images": [m.id for m in test_meta],
        "settings": settings_dict,
        "tuned": {str(k): v for k, v in tuned.items()},
        "cnn": cnn_info,
        "alcn_trained": alcn_trained,
        "machine": machine(),
        "runs": runs,
        "summary": summarize(runs, settings, [data.name(c) for c in data.categories]),
        "seconds": time.perf_counter() - start,
    }
    result["figures"] = _plot_pr(runs, data, out, settings)
    result["seconds"] = time.perf_counter() - start
    write_json(out / "detect.json", result)
    atomic_write(out / "detect.md", _markdown(result, data, settings))
    (out / "detect.partial.json").unlink(missing_ok=True)
    logger.info("detection benchmark written to %s in %.0f s", out, result["seconds"])
    return result


def _list(kind: type) -> Any:
    def parse(text: str) -> list:
        try:
            return [kind(v) for v in text.split(",") if v.strip()]
        except ValueError:
            raise InputError(f"expected a comma-separated list of {kind.__name__}, got {text!r}") from None

    return parse


def _sweep(text: str) -> list[tuple[int, int]]:
    try:
        return [tuple(int(v) for v in item.lower().split("x")) for item in text.split(",") if item.strip()]  # type: ignore[misc]
    except ValueError:
        raise InputError(f"--cnn-sweep expects DEPTHxWIDTH,... (e.g. 1x32,2x32), got {text!r}") from None


def presets() -> dict[str, DetectSettings]:
    """Named settings: ``default`` (the benchmark) and ``small`` (a quick end-to-end check, for
    ``make demo`` and tests: fewer windows and epochs, one plain CNN, no ResNet-56)."""
    return {
        "default": DetectSettings(),
        "small": DetectSettings(
            methods=list(available()) + ["cnn", "resnet20"], positives_per_object=30, epochs=2, cnn_sweep=[(1, 16)]
        ),
    }


def add_cli(subparsers: Any) -> None:
    """Add ``alcn bench detect`` to the ``bench`` sub-subcommands."""
    d = DetectSettings()
    p = subparsers.add_parser(
        "detect",
        help="few-shot detection benchmark: every normalization with the same detector (AUC, PR curves)",
        description="For each method, train the same detector on windows normalized by it, built from 1 and 10 real "
        "images per object (simple synthetic images), run it on every window of every test image, and score with "
        "the PASCAL criterion (IoU 0.8, fixed-size boxes). Writes detect.md, detect.json and PR curves (PNG). "
        "--size picks a preset; the other options override it.",
    )
    p.add_argument("--data", required=True, type=Path, help="benchmark folder: train.json, test.json, manifest.json "
                   "(e.g. from `alcn data detect`)")
    p.add_argument("--out", required=True, type=Path, help="output folder")
    p.add_argument("--size", choices=("default", "small"), default="default",
                   help="preset: default (the benchmark) or small (a quick end-to-end run)")
    p.add_argument("--methods", type=_list(str), help="comma-separated methods, each NAME or NAME:KEY=VALUE[:KEY=VALUE...] "
                   f"(e.g. alcn:model=lite:mixture=pyramid; default: all: {','.join(d.methods)})")
    p.add_argument("--real-images", type=_list(int), help="real training images per object (default 1,10)")
    p.add_argument("--policy", type=_list(str), dest="policies",
                   help=f"detector input policies: raw, standardize, local (default {','.join(d.policies)})")
    p.add_argument("--positives", type=int, dest="positives_per_object",
                   help=f"synthetic windows per object (default {d.positives_per_object})")
    p.add_argument("--negatives-ratio", type=float, help=f"background windows per object window (default {d.negatives_ratio})")
    p.add_argument("--epochs", type=int, help=f"detector training epochs (default {d.epochs})")
    p.add_argument("--batch-size", type=int, help=f"default {d.batch_size}")
    p.add_argument("--lr", type=float, help=f"Adam learning rate (default {d.lr})")
    p.add_argument("--seeds", type=_list(int), help="repeat every run with each of these seeds and report mean +- "
                   "standard deviation (default 0)")
    p.add_argument("--tune", dest="tune", action="store_const", const=True,
                   help="tune DoG, SLCN and DLCN on the training windows first (default: their defaults)")
    p.add_argument("--cnn-sweep", type=_sweep, help="plain CNNs tried, DEPTHxWIDTH,... (default 1x32,2x32,3x32)")
    p.add_argument("--nms-iou", type=float, help=f"default {d.nms_iou}")
    p.add_argument("--match-iou", type=float, help=f"PASCAL criterion (default {d.match_iou})")
    p.add_argument("--max-test-images", type=int, help="only the first N test images (default: all)")
    p.add_argument("--working-scale", type=float, default=None, help="override the manifest's working_scale")
    p.add_argument("--box-size", type=float, default=None, help="override the manifest's box_size (pixels at the working scale)")
    p.add_argument("--threads", type=int, help="torch threads (default: torch's choice)")
    p.add_argument("--device", help="torch device (default cpu)")
    p.set_defaults(func=_run_cli)


def _run_cli(args: Any) -> int:
    settings = presets()[args.size]
    for name in DetectSettings.__dataclass_fields__:
        value = getattr(args, name, None)
        if value is not None:
            setattr(settings, name, value)
    result = main(args.data, args.out, settings, args.working_scale, args.box_size)
    print((Path(args.out) / "detect.md").read_text(encoding="utf-8"))
    return 1 if all("error" in r for r in result["runs"].values()) else 0
