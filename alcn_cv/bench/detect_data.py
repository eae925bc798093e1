"""Data of the detection benchmark: the COCO sets at the working scale and the synthetic training windows.

The sets (:func:`load_data`): ``train.json``, ``test.json`` and, when present, ``val.json``, test-like images
that ``alcn bench detect --tune`` chooses parameters on.

Training windows (Rad, Roth & Lepetit, BMVC 2017, Sec. 4.3): the first ``n`` training images of
each object (COCO ``train.json``), resized to the working scale (``cv2.INTER_AREA``), give the
paper's simple synthetic images (:func:`alcn_cv.data.synthetic.augment`: background replaced,
small affine changes of intensity, noise, small geometric jitter) and background windows
(:func:`~alcn_cv.data.synthetic.sample_negatives`), 64x64 each. They are drawn once per ``n``
and seed, so every method trains on the same windows. About a quarter as many held-out windows, relit
synthetically (:func:`relight_windows`), choose the plain CNN's depth and width.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv.bench.detect_settings import CROP, DetectSettings
from alcn_cv.errors import DatasetError
from alcn_cv.formats.coco import CocoDataset, load_coco
from alcn_cv.io import read_json

__all__ = [
    "DetectData",
    "ScaledImage",
    "TrainingSet",
    "load_data",
    "read_images",
    "relight_windows",
    "training_set",
    "working_gray",
]


@dataclass
class DetectData:
    """A COCO detection benchmark: training, test and (``None`` without ``val.json``) validation sets, and their
    working scale."""

    root: Path
    train: CocoDataset
    test: CocoDataset
    val: CocoDataset | None
    working_scale: float
    box_size: float

    @property
    def categories(self) -> list[int]:
        return sorted(c.id for c in self.test.categories)

    def name(self, category: int) -> str:
        return self.test.category(category).name


def load_data(
    data_dir: str | os.PathLike, working_scale: float | None = None, box_size: float | None = None
) -> DetectData:
    """Read ``train.json``, ``test.json`` and (when present) ``val.json`` and ``manifest.json`` of a benchmark folder.

    Args:
        data_dir: the folder (the data engine's ``alcn data detect`` output, or any COCO set
            laid out the same way).
        working_scale, box_size: override (or, without a manifest, give) the scale to the
            detector's resolution and the side of the fixed-size boxes at that scale.

    Raises:
        DatasetError: missing or malformed files, another data set of ``alcn data`` (its manifest's ``kind``), no
            working scale or box size, test or validation categories that the training set lacks.
    """
    root = Path(data_dir)
    if not root.is_dir():
        raise DatasetError(f"{root}: not a folder (the detection benchmark's data: `alcn data detect --out DIR`)")
    manifest_path = root / "manifest.json"
    if not manifest_path.is_file() and not (root / "train.json").is_file():  # a folder of another kind altogether
        raise DatasetError(
            f"{root}: no train.json nor manifest.json: not a detection set (the benchmark's data: `alcn data detect "
            "--out DIR`, or a COCO set with train.json and test.json)"
        )
    manifest = read_json(manifest_path) if manifest_path.is_file() else {}
    if not isinstance(manifest, dict):
        raise DatasetError(f"{manifest_path}: expected a JSON object")
    # another set of `alcn data` (a COCO set laid out the same way has a manifest of its own, or none)
    if manifest.get("generator") == "alcn_cv.data" and manifest.get("kind") != "detect":
        raise DatasetError(
            f"{root}: not a detection set (its manifest.json says kind {manifest.get('kind')!r}): make one with "
            "`alcn data detect`"
        )
    scale = working_scale if working_scale is not None else manifest.get("working_scale")
    box = box_size if box_size is not None else manifest.get("box_size")
    if scale is None or box is None:
        raise DatasetError(
            f"{manifest_path}: fields 'working_scale' and 'box_size' are needed "
            "(or pass --working-scale and --box-size)"
        )
    scale, box = float(scale), float(box)
    if not 0 < scale <= 4 or not box > 0:
        raise DatasetError(f"{manifest_path}: working_scale {scale} must be in (0, 4] and box_size {box} positive")
    train = load_coco(root / "train.json")
    test = load_coco(root / "test.json")
    val = load_coco(root / "val.json") if (root / "val.json").is_file() else None
    train_ids = {c.id for c in train.categories}
    named = {c.id: c.name for ds in (test, val) if ds is not None for c in ds.categories}
    missing = [name for cid, name in named.items() if cid not in train_ids]
    if missing:
        raise DatasetError(f"{root / 'train.json'}: field categories: no training category for {missing}")
    return DetectData(root, train, test, val, scale, box)


def working_gray(ds: CocoDataset, image: Any, scale: float) -> tuple[np.ndarray, float, float]:
    """The image in grayscale at the working scale (uint8) and the actual x and y factors."""
    gray = cv2.cvtColor(ds.read_image(image), cv2.COLOR_BGR2GRAY)
    h, w = gray.shape
    size = (max(CROP, round(w * scale)), max(CROP, round(h * scale)))
    interp = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
    return cv2.resize(gray, size, interpolation=interp), size[0] / w, size[1] / h


@dataclass
class ScaledImage:
    """A test image at the working scale: its COCO id, float32 intensities in [0, 1] (or a
    normalized image), and the x and y factors from full resolution."""

    id: int
    image: np.ndarray
    sx: float
    sy: float


def read_images(ds: CocoDataset, working_scale: float, max_images: int | None = None) -> list[ScaledImage]:
    """The images of a set (the first ``max_images`` when given) in grayscale at the working scale, in [0, 1]."""
    meta = ds.images[:max_images] if max_images else ds.images
    out = []
    for im in meta:
        gray, sx, sy = working_gray(ds, im, working_scale)
        out.append(ScaledImage(im.id, gray.astype(np.float32) / np.float32(255), sx, sy))
    return out


def relight_windows(windows: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Synthetic changes of light of windows: per window a gain (log-uniform in [0.15, 3]), a gamma (log-uniform in
    [0.5, 2]), a linear brightness gradient across the window (up to a factor 3 end to end), an offset and noise.

    Args:
        windows: ``(n, S, S)`` float32 in [0, 1].
        rng: random generator.

    Returns:
        ``(n, S, S)`` float32 in [0, 1], quantized to 8 bits like a camera image.
    """
    n, h, w = windows.shape
    gain = np.exp(rng.uniform(np.log(0.15), np.log(3.0), n))[:, None, None]
    gamma = np.exp(rng.uniform(np.log(0.5), np.log(2.0), n))[:, None, None]
    angle = rng.uniform(0, 2 * np.pi, n)
    strength = np.log(rng.uniform(1.0, 3.0, n))
    y, x = np.mgrid[0:h, 0:w]
    t = ((x - w / 2)[None] * np.cos(angle)[:, None, None] + (y - h / 2)[None] * np.sin(angle)[:, None, None]) / max(
        h, w
    )
    gradient = np.exp(strength[:, None, None] * t)
    offset = rng.uniform(-0.03, 0.03, n)[:, None, None]
    out = gain * np.power(np.clip(windows, 0, 1), gamma) * gradient + offset
    out += rng.normal(0, 0.01, out.shape)
    return (np.rint(np.clip(out, 0, 1) * 255) / 255).astype(np.float32)


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
            gray, sx, sy = working_gray(data.train, images[a.image_id], data.working_scale)
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
        np.concatenate(windows),
        np.concatenate(labels).astype(np.int64),
        relight_windows(val, np.random.default_rng([seed, n_real, 1])),
        np.concatenate(val_labels).astype(np.int64),
        used,
    )
