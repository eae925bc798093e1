"""``alcn bench relight``: the normalizations on real changes of light, with a fixed camera.

Every method normalizes whole grayscale frames through its own ``apply`` (uint8 in, float32
out, the method's fixed output map), once per scene; the normalized frames are then reused by
every protocol and seed. Scenes are registered multi-light scenes
(:mod:`alcn_cv.data.scenes`): the outdoor webcams of TILDE (Verdie et al., CVPR 2015)
and photometric-stereo objects. Per scene and seed, ``gallery`` frames are drawn and each is
paired with every other frame of the scene (at most ``max_pairs`` pairs, drawn at random).

* **identification** (%): ``patches`` textured ``patch x patch`` locations of the gallery frame
  (drawn among the more textured half of a half-overlapping grid, by gradient energy of the
  raw frame) are identified in the other frame by normalized cross-correlation against the
  patches at all the same locations (chance ``1 / patches``; fewer where a scene's frames hold fewer: the
  result's ``fewest_patches``), the pair registered to the pixel first by the one move of at most ``shift_px``
  pixels that best aligns the pair's patches on the method's output: the frames of a fixed outdoor camera are 1-3 px
  apart (mexico's and frankfurt's webcams), where a smooth output, which tolerates the shift, would otherwise be
  rewarded rather than a method's treatment of the light.
* **matching** (%, ORB and SIFT): keypoints on the normalized frames (``apply``'s uint8
  output), Lowe's ratio test, each keypoint in at most one match (:func:`one_to_one_matches`), a
  match is correct when its keypoints are within ``match_px``
  (the frames are registered); score = correct matches / the smaller keypoint count
  (Mikolajczyk & Schmid, PAMI 2005's matching score). The score divides by the keypoint count,
  so a method that finds keypoints in more of the frame scores lower for the same quality of
  match; the report also gives the mean number of **correct matches** per pair (a count), which
  does not.
* **pose** (%, ORB and SIFT): a RANSAC homography (``cv2.findHomography``, ``ransac_px``) from
  those matches; a success when it moves each corner of the frame less than
  ``pose_px`` (the identity is the truth): the 2D-projection criterion of Rad et al., BMVC
  2017, Sec. 5, on real light.

Parameters of CLAHE, DoG, SLCN, DLCN, SQI, Tan-Triggs and DoG + local standardization are tuned on the
training scenes only, each over a grid of the same size (:data:`TUNING_GRIDS`), scored by
identification on a subsample; the report holds both the default and the tuned rows. With
``leave_one_out``, each scene is evaluated with the parameters tuned on the others.

Beside each row's mean and spread over seeds, the report gives each row's difference from the first row, paired by
seed (:func:`paired_differences`): whether two methods differ by more than the seeds' draws.

The split (:func:`split_scenes`): without ``data`` and without ``test_scenes``, the published one
(:data:`~alcn_cv.data.scenes.TEST_SCENES` evaluated, :data:`~alcn_cv.data.scenes.TRAIN_SCENES` tuned on and
evaluated too, tuned or not). Tuning needs training scenes: the default ones, looked up in ``data``, unless
``train_scenes`` names others. Without tuning, training scenes are optional: none unless named when ``data`` or
``test_scenes`` is given, so only the test scenes are evaluated (``data`` without ``test_scenes``: every scene of
``data``).

A method whose weight file records training scenes (``training.config.scenes``, ``rendered`` and ``photos``,
``distillation.settings.scenes``; :func:`trained_scenes`) among the test scenes of the run is scored there all the
same, with a warning; its row records them (``trained_on`` and ``note``, "trained on: mexico").

A spec ending in ``+lstd`` (``dog+lstd``) is the method followed by a per-pixel local
standardization (:class:`LocallyStandardized`, the detection benchmark's
:func:`~alcn_cv.bench.policies.local_standardize`).
"""

from __future__ import annotations

import itertools
import logging
import os
import time
import zlib
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path, PureWindowsPath
from typing import Any

import cv2
import numpy as np
from tqdm.auto import tqdm

from alcn_cv.bench.methods import build_methods
from alcn_cv.bench.policies import LOCAL_BOX, local_standardize
from alcn_cv.bench.relight_report import write_report
from alcn_cv.bench.relight_settings import CONFS, Settings
from alcn_cv.checks import check_seeds
from alcn_cv.data.scenes import (
    TEST_SCENES,
    TRAIN_SCENES,
    Scene,
    load_scenes,
    scene_names,
    select_scenes,
)
from alcn_cv.enhance.alcn import ALCN
from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import format_spec, from_spec, parse_spec
from alcn_cv.errors import DatasetError, InputError
from alcn_cv.io import check_no_earlier_output, holds_out_dir, make_folder
from alcn_cv.report import can_draw, machine, sample_std
from alcn_cv.shared_data import default_folder

__all__ = [
    "DEFAULT_METHODS",
    "DEFAULT_SEEDS",
    "COUNT_METRICS",
    "METRICS",
    "TUNING_GRIDS",
    "LocallyStandardized",
    "backend_of",
    "build_method",
    "evaluate_scene",
    "identification",
    "main",
    "one_to_one_matches",
    "paired_differences",
    "patch_locations",
    "plan_pairs",
    "split_scenes",
    "trained_scenes",
    "tune",
]

logger = logging.getLogger(__name__)

DEFAULT_METHODS = ("none", "clahe", "dog", "slcn", "dlcn", "sqi", "tantriggs", "dog+lstd", "alcn", "alcn:model=lite")
DEFAULT_LEAVE_ONE_OUT = ("courbevoie", "frankfurt", "mexico", "panorama")
DEFAULT_SEEDS = (0, 1, 2)
DETECTORS = ("orb", "sift")
#: Every reported number: percentages, except :data:`COUNT_METRICS`.
METRICS = ("identification", "matching_orb", "matching_sift", "pose_orb", "pose_sift", "correct_orb", "correct_sift")
#: Reported as a mean count per frame pair, not in percent.
COUNT_METRICS = ("correct_orb", "correct_sift")
LSTD = "+lstd"

_DOG_GRID = [(0.5, 1.5), (0.5, 3.0), (1.0, 2.0), (1.0, 3.0), (1.0, 4.0), (1.5, 3.0), (2.0, 4.0), (2.0, 6.0)]
_LCN_GRID = [2.0, 1.0, 1.5, 3.0, 4.0, 6.0, 8.0, 12.0]
#: Settings searched per tuned method, the same number (8) for each; the default comes first, so
#: a tie keeps it.
TUNING_GRIDS: dict[str, list[dict[str, Any]]] = {
    "dog": [{"sigma1": a, "sigma2": b} for a, b in _DOG_GRID],
    "slcn": [{"sigma": s} for s in _LCN_GRID],
    "dlcn": [{"sigma": s} for s in _LCN_GRID],
    "tantriggs": [
        {"gamma": g, "sigma0": a, "sigma1": b}
        for g, a, b in [
            (0.2, 1.0, 2.0),
            (0.1, 1.0, 2.0),
            (0.4, 1.0, 2.0),
            (0.2, 0.5, 1.5),
            (0.2, 0.5, 2.0),
            (0.2, 1.0, 3.0),
            (0.2, 1.5, 3.0),
            (0.2, 2.0, 4.0),
        ]
    ],
    "dog+lstd": [{"sigma1": a, "sigma2": b} for a, b in _DOG_GRID],
    "sqi": [
        {"sigmas": s, "eps": e}
        for s, e in [
            ((1.0, 2.0, 4.0), 0.01),
            ((1.0, 2.0, 4.0), 0.003),
            ((1.0, 2.0, 4.0), 0.03),
            ((0.5, 1.0, 2.0), 0.01),
            ((2.0, 4.0, 8.0), 0.01),
            ((4.0, 8.0, 16.0), 0.01),
            ((1.0, 4.0, 16.0), 0.01),
            ((2.0, 4.0, 8.0), 0.03),
        ]
    ],
    # clip 4 on 8x8 tiles: Jenicek & Chum, "No Fear of the Dark", ICCV 2019
    "clahe": [
        {"clipLimit": c, "tileGridSize": (t, t)}
        for c, t in [(2.0, 8), (4.0, 8), (1.0, 8), (8.0, 8), (2.0, 4), (4.0, 4), (2.0, 16), (4.0, 16)]
    ],
}


class LocallyStandardized(Normalization):
    """A normalization followed by a per-pixel local standardization of its raw response.

    Each pixel is standardized by the mean and standard deviation of the ``size x size`` box
    around it (:func:`alcn_cv.bench.policies.local_standardize`, the detection benchmark's
    ``local`` input policy), so a detector that needs it gets it through ``apply`` as every
    other method.

    Args:
        inner: the normalization applied first.
        size: the box side (odd, pixels).
    """

    output_range = (-3.0, 3.0)

    def __init__(self, inner: Normalization, size: int = LOCAL_BOX) -> None:
        self.inner = inner
        self.size = int(size)
        self.name = f"{inner.name}{LSTD}"

    def _normalize(self, gray: np.ndarray) -> np.ndarray:
        return local_standardize(self.inner.normalize(gray), self.size)


def build_method(spec: str) -> Normalization:
    """The normalization of a spec ``NAME[:KEY=VALUE...][+lstd]`` (:func:`~alcn_cv.enhance.registry.from_spec`),
    or ``unet:weights=PATH``, the lab's free-form baseline (:class:`~alcn_cv.bench.unet.UNetNormalization`)."""
    if spec.endswith(LSTD):
        return LocallyStandardized(build_method(spec[: -len(LSTD)]))
    name, params = parse_spec(spec)
    if name == "unet":
        if set(params) != {"weights"}:
            raise InputError(f"bad method {spec!r}; the U-Net is unet:weights=PATH")
        from alcn_cv.bench.unet import UNetNormalization  # torch, only for this method

        return UNetNormalization(str(params["weights"]))
    return from_spec(spec)


def backend_of(norm: Normalization) -> str | None:
    """The backend an ALCN runs on (:attr:`ALCN.backend <alcn_cv.enhance.alcn.ALCN>`, also under ``+lstd``): its
    ms/frame depend on it (a user's weight file runs on ``fast``, the shipped files on ``opencv``); None for the
    other methods, which have one implementation."""
    inner = norm.inner if isinstance(norm, LocallyStandardized) else norm
    return inner.backend if isinstance(inner, ALCN) else None


def _spec(method: str, params: dict[str, float]) -> str:
    base = method[: -len(LSTD)] if method.endswith(LSTD) else method
    return format_spec(base, params) + (LSTD if method.endswith(LSTD) else "")


# ---------------------------------------------------------------------------------------------
# Protocols


@dataclass(frozen=True)
class PairPlan:
    """What one seed draws for a scene: gallery frames, their patch locations, the frame pairs."""

    gallery: tuple[int, ...]
    locations: dict[int, np.ndarray]
    pairs: tuple[tuple[int, int], ...]


def patch_locations(frame: np.ndarray, size: int, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` textured ``size x size`` patch locations of a frame.

    Candidates lie on a grid of stride ``size // 2``; the more textured half (gradient energy,
    the sum of squared Sobel derivatives over the patch, at least the median and non-zero)
    is kept and ``count`` of them are drawn without replacement (all when fewer).

    Returns:
        ``(n, 2)`` int64 top-left corners ``(y, x)``, ``n <= count``.
    """
    g = frame.astype(np.float32)
    energy = cv2.Sobel(g, cv2.CV_32F, 1, 0) ** 2 + cv2.Sobel(g, cv2.CV_32F, 0, 1) ** 2
    integral = cv2.integral(energy, sdepth=cv2.CV_64F)
    h, w = frame.shape
    if h < size or w < size:
        raise InputError(f"frames of {w}x{h} are smaller than the {size}x{size} patches")
    stride = max(1, size // 2)
    ys, xs = np.meshgrid(np.arange(0, h - size + 1, stride), np.arange(0, w - size + 1, stride), indexing="ij")
    ys, xs = ys.ravel(), xs.ravel()
    sums = integral[ys + size, xs + size] - integral[ys, xs + size] - integral[ys + size, xs] + integral[ys, xs]
    keep = np.flatnonzero((sums >= np.median(sums)) & (sums > 0))
    chosen = np.sort(rng.choice(keep, size=min(count, len(keep)), replace=False))
    return np.stack([ys[chosen], xs[chosen]], axis=1).astype(np.int64)


def _patch_vectors(image: np.ndarray, locations: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Zero-mean, unit-norm patch vectors ``(n, size^2)`` and whether each had any contrast."""
    offsets = np.arange(size)
    rows = locations[:, 0, None, None] + offsets[None, :, None]
    cols = locations[:, 1, None, None] + offsets[None, None, :]
    vectors = image[rows, cols].reshape(len(locations), -1).astype(np.float32)
    vectors -= vectors.mean(axis=1, keepdims=True)
    norms = np.linalg.norm(vectors, axis=1)
    valid = norms > 1e-6
    vectors[valid] /= norms[valid, None]
    vectors[~valid] = 0.0
    return vectors, valid


def identification(gallery: np.ndarray, query: np.ndarray, locations: np.ndarray, size: int, shift: int = 0) -> float:
    """Fraction of the gallery's patches whose best normalized cross-correlation in ``query``,
    over the patches at all ``locations``, is at their own location (a patch without any
    contrast counts as not identified), with ``query`` registered to the pixel first: its patches are taken at
    ``locations`` moved by the one move of at most ``shift`` pixels along each axis (kept inside the frame) that
    gives the gallery's patches the highest mean correlation with their own (no move where none does better)."""
    a, valid = _patch_vectors(gallery, locations, size)
    top = np.array(query.shape[:2]) - size
    moves = sorted(itertools.product(range(-shift, shift + 1), repeat=2), key=lambda m: abs(m[0]) + abs(m[1]))
    candidates = (_patch_vectors(query, np.clip(locations + move, 0, top), size)[0] for move in moves)
    b = max(candidates, key=lambda c: float(np.einsum("ij,ij->", a, c)))  # the first of equals: no move
    best = np.argmax(a @ b.T, axis=1)
    return float(np.mean((best == np.arange(len(locations))) & valid))


def _fewest_sampled(plans: list[PairPlan]) -> tuple[int, int]:
    """The fewest patch locations of a gallery frame and the fewest gallery frames over a scene's ``plans`` (one per
    seed): the settings' ``patches`` and ``gallery`` unless its frames are too small or too few."""
    return min(len(loc) for plan in plans for loc in plan.locations.values()), min(len(p.gallery) for p in plans)


def plan_pairs(scene: Scene, seed: int, settings: Settings) -> PairPlan:
    """The gallery frames, their patch locations and the frame pairs of one seed (the same for every method).

    Raises:
        DatasetError: a gallery frame with fewer than 2 textured patch locations (a flat frame), where identification
            has nothing to tell apart.
    """
    rng = np.random.default_rng([seed, zlib.crc32(scene.name.encode())])
    n = len(scene.frames)
    gallery = tuple(sorted(int(i) for i in rng.choice(n, size=min(settings.gallery, n), replace=False)))
    try:
        locations = {g: patch_locations(scene.frames[g], settings.patch, settings.patches, rng) for g in gallery}
    except InputError as exc:  # frames smaller than the patches
        raise InputError(f"scene {scene.name!r}: {exc}") from None
    flat = [g for g in gallery if len(locations[g]) < 2]
    if flat:
        raise DatasetError(
            f"scene {scene.name!r}: frame {scene.files[flat[0]]} has {len(locations[flat[0]])} textured "
            f"{settings.patch}x{settings.patch} patch location(s); identification needs 2 or more"
        )
    pairs = [(g, f) for g in gallery for f in range(n) if f != g]
    if settings.max_pairs is not None and len(pairs) > settings.max_pairs:
        pick = np.sort(rng.choice(len(pairs), size=settings.max_pairs, replace=False))
        pairs = [pairs[i] for i in pick]
    return PairPlan(gallery, locations, tuple(pairs))


def _detector(kind: str, n: int) -> tuple[Any, int]:
    if kind == "orb":
        return cv2.ORB_create(nfeatures=n), cv2.NORM_HAMMING
    return cv2.SIFT_create(nfeatures=n), cv2.NORM_L2


def one_to_one_matches(d1: np.ndarray | None, d2: np.ndarray | None, norm: int, ratio: float) -> np.ndarray:
    """``(n, 2)`` int64 index pairs ``(i1, i2)``: each descriptor of ``d1`` matched to its nearest of ``d2`` when
    it is nearer than ``ratio`` times the second nearest (Lowe's ratio test), then each of ``d2`` kept in at most
    one match, its nearest (Mikolajczyk & Schmid's matching score counts a keypoint once: ORB's pyramid finds one
    corner at several levels, whose keypoints would all match the same one). In the order of ``d1``."""
    if d1 is None or d2 is None or len(d1) < 1 or len(d2) < 2:
        return np.zeros((0, 2), np.int64)
    knn = cv2.BFMatcher(norm).knnMatch(d1, d2, k=2)
    best = [m[0] for m in knn if len(m) == 2 and m[0].distance < ratio * m[1].distance]
    if not best:
        return np.zeros((0, 2), np.int64)
    pairs = np.array([(m.queryIdx, m.trainIdx) for m in best], np.int64)
    nearest_first = np.argsort([m.distance for m in best], kind="stable")
    _, first = np.unique(pairs[nearest_first, 1], return_index=True)
    return pairs[np.sort(nearest_first[first])]


def keypoint_scores(
    kp1: tuple[np.ndarray, np.ndarray | None],
    kp2: tuple[np.ndarray, np.ndarray | None],
    norm: int,
    shape: tuple[int, int],
    settings: Settings,
) -> tuple[float, float, int]:
    """(matching score, pose success, correct matches) of a frame pair from its keypoints
    ``(points, descriptors)``."""
    (p1, d1), (p2, d2) = kp1, kp2
    idx = one_to_one_matches(d1, d2, norm, settings.ratio)
    if not len(idx):
        return 0.0, 0.0, 0
    src, dst = p1[idx[:, 0]], p2[idx[:, 1]]
    correct = np.count_nonzero(np.linalg.norm(src - dst, axis=1) <= settings.match_px)
    score = correct / min(len(p1), len(p2))
    if len(idx) < 4:
        return score, 0.0, correct
    homography, _ = cv2.findHomography(src, dst, cv2.RANSAC, settings.ransac_px)
    if homography is None:
        return score, 0.0, correct
    h, w = shape
    corners = np.array([[[0, 0]], [[w - 1, 0]], [[w - 1, h - 1]], [[0, h - 1]]], np.float64)
    moved = cv2.perspectiveTransform(corners, homography) - corners
    return score, float(np.linalg.norm(moved, axis=2).max() < settings.pose_px), correct


def evaluate_scene(norm: Normalization, scene: Scene, plans: Sequence[PairPlan], settings: Settings) -> dict[str, Any]:
    """Every protocol on one scene for one method, one value per plan (seed) and metric.

    The frames are normalized once (``apply``, float32) and reused by every plan; keypoints are
    detected once per frame. ``ms_per_frame`` times the frames after the first, whose call is left out (a method
    built once serves every scene: its first call's set-up, cv2.dnn's allocations or torch's start, is not a scene's
    time).

    Returns:
        ``{"metrics": {metric: [value per plan]}, "ms_per_frame": float}``, each value the mean over the plan's
        pairs, in percent but for :data:`COUNT_METRICS` (a count per pair).
    """
    normalized = [norm.apply(scene.frames[0], out_dtype=np.float32)]
    start = time.perf_counter()
    normalized += [norm.apply(frame, out_dtype=np.float32) for frame in scene.frames[1:]]
    ms_per_frame = 1000 * (time.perf_counter() - start) / max(len(normalized) - 1, 1)
    detectors = {k: _detector(k, settings.keypoints) for k in DETECTORS} if settings.keypoint_protocols else {}
    keypoints: dict[tuple[str, int], tuple[np.ndarray, np.ndarray | None]] = {}

    def features(kind: str, i: int) -> tuple[np.ndarray, np.ndarray | None]:
        if (kind, i) not in keypoints:
            frame = np.rint(normalized[i] * np.float32(255)).astype(np.uint8)  # apply()'s uint8 output
            kps, desc = detectors[kind][0].detectAndCompute(frame, None)
            keypoints[kind, i] = (np.array([k.pt for k in kps], np.float32).reshape(-1, 2), desc)
        return keypoints[kind, i]

    metrics: dict[str, list[float]] = {m: [] for m in METRICS if settings.keypoint_protocols or m == "identification"}
    for plan in plans:
        values: dict[str, list[float]] = {m: [] for m in metrics}
        for g, f in plan.pairs:
            locations = plan.locations[g]
            values["identification"].append(
                identification(normalized[g], normalized[f], locations, settings.patch, settings.shift_px)
            )
            for kind, (_, kind_norm) in detectors.items():
                pair = features(kind, g), features(kind, f)
                score, success, correct = keypoint_scores(*pair, kind_norm, scene.frames.shape[1:], settings)
                values[f"matching_{kind}"].append(score)
                values[f"pose_{kind}"].append(success)
                values[f"correct_{kind}"].append(correct)
        for m, v in values.items():
            metrics[m].append((1.0 if m in COUNT_METRICS else 100.0) * float(np.mean(v)))
    return {"metrics": metrics, "ms_per_frame": ms_per_frame}


# ---------------------------------------------------------------------------------------------
# Tuning


def _subsample(scene: Scene, frames: int) -> Scene:
    keep = np.unique(np.linspace(0, len(scene.frames) - 1, min(frames, len(scene.frames))).round().astype(int))
    return Scene(scene.name, scene.group, scene.frames[keep], tuple(scene.files[i] for i in keep))


def tune(
    method: str,
    scenes: Sequence[Scene],
    settings: Settings,
    seed: int = 0,
    frames: int = 8,
    progress: Callable[[], None] | None = None,
) -> dict[str, Any]:
    """Choose ``method``'s setting among :data:`TUNING_GRIDS` by identification on ``scenes``.

    Each setting is scored by the mean identification (%) over the scenes, each subsampled to
    ``frames`` evenly spaced frames, for one ``seed``; the first best setting wins.

    Returns:
        ``{"chosen": spec, "scores": {spec: percent}}``.
    """
    small = [_subsample(s, frames) for s in scenes]
    fast = replace(settings, keypoint_protocols=False)
    plans = {s.name: plan_pairs(s, seed, fast) for s in small}
    scores: dict[str, float] = {}
    for params in TUNING_GRIDS[method]:
        spec = _spec(method, params)
        norm = build_method(spec)
        per_scene = [evaluate_scene(norm, s, [plans[s.name]], fast)["metrics"]["identification"][0] for s in small]
        scores[spec] = float(np.mean(per_scene))
        if progress is not None:
            progress()
    chosen = max(scores, key=lambda k: scores[k])  # the first of equal maxima
    logger.info("%s tuned on %s: %s (%.1f%%)", method, ", ".join(s.name for s in scenes), chosen, scores[chosen])
    return {"chosen": chosen, "scores": scores}


# ---------------------------------------------------------------------------------------------
# The benchmark


def _entry_names(entry: str, subfolders: bool = True) -> set[str]:
    """The names of the scenes a trainer's entry (a folder, or the name of a shared ``webcam`` scene) stands for:
    its last part (a path recorded on Windows read as one), and where it is a folder here, the scenes
    :func:`~alcn_cv.data.scenes.scene_names` finds in it (file names only, no image read). A folder that cannot be
    listed is logged and skipped: the check is a warning, not a reason to stop the benchmark."""
    names = {PureWindowsPath(entry).name if "\\" in entry else Path(entry).name}
    try:
        names.update(scene_names(Path(entry).expanduser(), subfolders))
    except (OSError, RuntimeError) as exc:  # RuntimeError: ~user of no home folder
        logger.warning(
            "%s: cannot list the folder a weight file was trained on (%s); its scene names unchecked", entry, exc
        )
    return names


def trained_scenes(spec: str, norm: Normalization | None = None) -> set[str]:
    """The registered scenes the weight file of ``spec`` (``alcn:weights=PATH``, ``unet:weights=PATH``, a shipped
    ALCN model) was trained on, by scene name: its header's ``training.config.scenes`` and ``rendered`` (folders or
    shared ``webcam`` scene names: each one's last part, and the scenes in it where it is a folder here),
    ``training.config.photos`` (folders of photographs relit: each one's name, and the scenes of its own images) and
    ``distillation.settings.scenes``; empty for a method without a weight file, or one that records none.

    ``norm``: the method built from ``spec`` (default: built here); the header is the one it read (its
    ``weights_meta``), the file is not read again."""
    norm = build_method(spec) if norm is None else norm
    inner = norm.inner if isinstance(norm, LocallyStandardized) else norm
    meta = getattr(inner, "weights_meta", None)
    if meta is None:
        return set()

    def strings(value: Any) -> list[str]:
        return [v for v in value if isinstance(v, str)] if isinstance(value, list) else []

    config = (meta.get("training") or {}).get("config") or {}
    names = {n for e in strings(config.get("scenes")) + strings(config.get("rendered")) for n in _entry_names(e)}
    names |= {n for e in strings(config.get("photos")) for n in _entry_names(e, subfolders=False)}
    return names | set(strings(((meta.get("distillation") or {}).get("settings") or {}).get("scenes")))


def split_scenes(
    scenes: Sequence[Scene],
    train_scenes: Sequence[str] | None,
    test_scenes: Sequence[str] | None,
    tuned: Sequence[str],
    roots: Sequence[Path] | None,
) -> tuple[list[Scene], list[Scene]]:
    """The training and test scenes of a train/test run (see the module docstring).

    Args:
        scenes: every scene read.
        train_scenes, test_scenes: scene or data-set names; None: the default.
        tuned: the methods to tune (training scenes needed).
        roots: the folders given (``data``); None: the shared data's default.

    Raises:
        InputError: a name matches no scene; tuning without training scenes (naming the default ones looked for);
            a scene both a training and a test scene while tuning; no test scene.
    """
    if train_scenes is None:
        if tuned or (roots is None and test_scenes is None):  # the published split, tuned or not
            missing = [n for n in TRAIN_SCENES if not any(n in (s.name, s.group) for s in scenes)]
            if tuned and missing:
                where = ", ".join(str(r) for r in roots) if roots is not None else "the shared data"
                raise InputError(
                    f"tuning ({', '.join(tuned)}) needs training scenes: looked for the default "
                    f"{', '.join(TRAIN_SCENES)} in {where}, {', '.join(missing)} not found; give --train-scenes "
                    "(train_scenes), or --no-tune (tuning=False) to evaluate the test scenes only"
                )
            train_scenes = TRAIN_SCENES
        else:
            train_scenes = ()
    train = select_scenes(scenes, train_scenes)
    if test_scenes is not None:
        test = select_scenes(scenes, test_scenes)
    elif roots is None:
        test = select_scenes(scenes, TEST_SCENES)
    else:
        test = [s for s in scenes if all(s is not t for t in train)]
    both = [s.name for s in train if any(s is t for t in test)]
    if both and tuned:
        raise InputError(
            f"{', '.join(both)}: both a training and a test scene; tuning on a test scene would score the tuned "
            "methods on their own tuning data (give other --train-scenes, or --no-tune to evaluate it as a test scene)"
        )
    if both:  # no tuning: a training scene is only evaluated, as a test scene it is evaluated once
        logger.info("%s: a test scene, not also a training scene (no tuning)", ", ".join(both))
        train = [s for s in train if s.name not in both]
    if not test:
        raise InputError("no test scene: every scene is a training scene; give --test-scenes (test_scenes)")
    return train, test


def _summary(values: Sequence[float]) -> dict[str, Any]:
    """The seeds' values, their mean and their :func:`~alcn_cv.report.sample_std`."""
    return {"seeds": [float(v) for v in values], "mean": float(np.mean(values)), "std": sample_std(values)}


#: How :func:`paired_differences` pairs, as the report says it.
PAIRING = "by seed, on the means over the test scenes"


def paired_differences(methods: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """Every row of ``methods`` (``relight.json``'s ``methods``) after the first, minus the first, paired by seed.

    For a seed, every method is scored on the same frames, patches and pairs: the difference of two methods' means
    over the test scenes (``mean_test``) for that seed is free of the sampling both share, and the spread of these
    differences over the seeds says whether the two differ by more than the seeds' draws.

    Returns:
        ``{"reference", "pairing", "methods"}``: the first row's label, :data:`PAIRING`, and for each later row with
        test means, each metric both have: the per-seed differences (``seeds``, in the order of the run's seeds),
        their mean and :func:`~alcn_cv.report.sample_std` (0 for one seed). Empty when the first row has no test
        means (it failed) or no other row has.
    """
    labels = [label for label, r in methods.items() if "mean_test" in r]
    first = next(iter(methods), None)
    if first is None or first not in labels or len(labels) < 2:
        return {}
    reference = methods[first]["mean_test"]
    rows = {
        label: {
            m: _summary(np.subtract(methods[label]["mean_test"][m]["seeds"], reference[m]["seeds"]))
            for m in reference
            if m in methods[label]["mean_test"]
        }
        for label in labels[1:]
    }
    return {"reference": first, "pairing": PAIRING, "methods": rows}


@holds_out_dir
def main(
    out_dir: str | os.PathLike,
    data: Sequence[str | os.PathLike] | None = None,
    methods: Sequence[str] = DEFAULT_METHODS,
    train_scenes: Sequence[str] | None = None,
    test_scenes: Sequence[str] | None = None,
    leave_one_out: Sequence[str] | None = None,
    seeds: Sequence[int] = DEFAULT_SEEDS,
    settings: Settings = Settings(),  # noqa: B008 -- frozen: one default shared by every call is safe
    max_frames: int | None = CONFS["default"].max_frames,
    tuning: bool = True,
    tune_frames: int = 8,
    progress: bool = True,
    command: str | None = None,
    overwrite: bool = False,
) -> dict[str, Any]:
    """Run the benchmark and write ``relight.md``, ``relight.json`` and (with matplotlib) ``relight.png`` into
    ``out_dir``.

    Args:
        out_dir: output folder (created).
        data: folders of registered multi-light scenes (default: the shared ``webcam`` and ``psm``).
        methods: specs ``NAME[:KEY=VALUE...]`` (:func:`~alcn_cv.enhance.registry.from_spec`),
            optionally ending in ``+lstd`` (:class:`LocallyStandardized`).
        train_scenes: scenes (or data-set names) the parameters are tuned on, evaluated too; None: the default
            (:func:`split_scenes`: :data:`~alcn_cv.data.scenes.TRAIN_SCENES` when tuning or when neither ``data``
            nor ``test_scenes`` is given, else none).
        test_scenes: scenes (or data-set names) evaluated only; None: :data:`~alcn_cv.data.scenes.TEST_SCENES`,
            or with ``data`` every scene of it that is not a training scene.
        leave_one_out: if given, instead of the split (``train_scenes`` and ``test_scenes`` must be None): each of
            these scenes is evaluated with the parameters tuned on the others; empty: :data:`DEFAULT_LEAVE_ONE_OUT`, or
            with ``data`` every scene of it.
        seeds: one run per seed (gallery frames, patch locations and pairs change); the report
            gives the mean and the standard deviation over seeds.
        settings: the protocols' parameters.
        max_frames: at most this many frames per scene, evenly spaced (``None``: all).
        tuning: tune the methods of :data:`TUNING_GRIDS` that ``methods`` lists and add their rows.
        tune_frames: frames per training scene the tuning scores on.
        progress: show progress bars.
        command: the command line, for the report.
        overwrite: replace the report of an earlier run in ``out_dir``.

    Returns:
        The results also written to ``relight.json``.

    Raises:
        InputError: before any work: ``out_dir`` holds an earlier run's report (without ``overwrite``); bad
            settings, methods or scenes (:func:`split_scenes`).
    """
    start = time.perf_counter()
    check_no_earlier_output([Path(out_dir) / "relight.json", Path(out_dir) / "relight.md"], overwrite)
    settings = settings.check()
    methods = list(methods)
    if not methods:
        raise InputError("no method to compare: give --methods, e.g. none,alcn")
    # Built once for the run: a method keeps nothing from one image to the next (ALCN's divisive floors of an image's
    # strips live in a context variable for that image), so every scene of a spec is normalized by one instance.
    built = build_methods(methods, build_method)
    trained_on = {spec: trained_scenes(spec, norm) for spec, norm in built.items()}
    seeds = check_seeds(seeds)
    roots = [Path(p) for p in data] if data else [default_folder("webcam"), default_folder("psm")]
    scenes = load_scenes(roots, max_frames)
    tuned = [m for m in methods if m in TUNING_GRIDS] if tuning else []
    if leave_one_out is not None:
        if train_scenes is not None or test_scenes is not None:
            raise InputError(
                "leave-one-out replaces the split: give no --train-scenes or --test-scenes (train_scenes, test_scenes) "
                "with it"
            )
        everything = DEFAULT_LEAVE_ONE_OUT if not data else [s.name for s in scenes]
        evaluated = select_scenes(scenes, leave_one_out or everything)
        if len(evaluated) < 2:
            raise InputError("leave-one-out needs at least two scenes")
        folds = {s.name: [o for o in evaluated if o is not s] for s in evaluated}
        test, train = evaluated, []
    else:
        train, test = split_scenes(scenes, train_scenes, test_scenes, tuned, None if not data else roots)
        evaluated = test + train
        folds = {"all": train}
    if tuned and not all(folds.values()):
        raise InputError("tuning needs training scenes: none given (give --train-scenes, or --no-tune)")
    leaks = {spec: sorted(names & {s.name for s in test}) for spec, names in trained_on.items()}
    leaks = {spec: names for spec, names in leaks.items() if names}
    for spec, names in leaks.items():
        logger.warning(
            "%s was trained on the test scene(s) %s (its weight file's training scenes): its scores there are not "
            "held out",
            spec,
            ", ".join(names),
        )
    # drawn before any work: a scene whose frames cannot be sampled is refused before the tuning's minutes
    plans = {s.name: [plan_pairs(s, seed, settings) for seed in seeds] for s in evaluated}
    sampled = {name: _fewest_sampled(plan) for name, plan in plans.items()}
    for name, (locations, gallery) in sampled.items():
        short = []
        if locations < settings.patches:
            short.append(
                f"as few as {locations} textured patch locations of the {settings.patches} asked (chance "
                f"{100 / locations:.1f}%)"
            )
        if gallery < settings.gallery:
            short.append(f"{gallery} gallery frames of {settings.gallery}")
        if short:
            logger.warning("scene %s: %s: its frames hold no more", name, ", ".join(short))
    make_folder(out_dir)  # before the benchmark, not after it
    draw = can_draw("alcn bench relight")  # said before the benchmark's minutes, not after them

    bar = tqdm(
        total=len(folds) * sum(len(TUNING_GRIDS[m]) for m in tuned),
        desc="relight tuning",
        unit="setting",
        disable=not progress or not tuned,
    )
    tuning_result: dict[str, dict[str, Any]] = {m: {} for m in tuned}
    for fold, fold_train in folds.items():
        for m in tuned:
            tuning_result[m][fold] = tune(
                m, fold_train, settings, seed=min(seeds), frames=tune_frames, progress=bar.update
            )
    bar.close()

    rows: dict[str, dict[str, str]] = {m: {s.name: m for s in evaluated} for m in methods}
    for m in tuned:
        fold_of = {s.name: s.name if leave_one_out is not None else "all" for s in evaluated}
        rows[f"{m} (tuned)"] = {name: tuning_result[m][fold]["chosen"] for name, fold in fold_of.items()}

    jobs = [(s, spec) for s in evaluated for spec in dict.fromkeys(r[s.name] for r in rows.values())]
    cache: dict[tuple[str, str], dict[str, Any]] = {}
    backends: dict[str, str] = {}
    for scene, spec in tqdm(jobs, desc="relight", unit="method x scene", disable=not progress):
        try:
            if spec not in built:  # a tuned spec: built at its first scene, reused for every scene with the same spec
                built[spec] = build_method(spec)
            norm = built[spec]
            if (backend := backend_of(norm)) is not None:
                backends[spec] = backend
            cache[scene.name, spec] = evaluate_scene(norm, scene, plans[scene.name], settings)
        except Exception as exc:  # one method failing is reported, not the end of the run
            logger.exception("%s failed on %s", spec, scene.name)
            cache[scene.name, spec] = {"error": f"{type(exc).__name__}: {exc}"}

    method_results: dict[str, Any] = {}
    for label, specs in rows.items():
        per_scene = {name: cache[name, spec] for name, spec in specs.items()}
        errors = {n: r["error"] for n, r in per_scene.items() if "error" in r}
        entry: dict[str, Any] = {"specs": specs, "tuned": label.endswith("(tuned)")}
        if ran_on := [backends[spec] for spec in specs.values() if spec in backends]:
            entry["backend"] = ran_on[0]  # the specs of a row differ in parameters only, not in backend
        if errors:
            entry["errors"] = errors
        if label in leaks:
            entry["trained_on"] = leaks[label]  # test scenes its weights were trained on
            entry["note"] = f"trained on: {', '.join(leaks[label])}"
        ok = {n: r for n, r in per_scene.items() if "error" not in r}
        entry["scenes"] = {
            n: {"ms_per_frame": r["ms_per_frame"], **{m: _summary(v) for m, v in r["metrics"].items()}}
            for n, r in ok.items()
        }
        for key, group in (("mean_test", test), ("mean_train", train)):
            names = [s.name for s in group]
            if names and all(n in ok for n in names):
                metrics = ok[names[0]]["metrics"]
                entry[key] = {m: _summary(np.mean([ok[n]["metrics"][m] for n in names], axis=0)) for m in metrics}
        method_results[label] = entry

    result = {
        "benchmark": "relight",
        "command": command,
        "data": [str(r.resolve()) for r in roots],
        "split": {
            "mode": "leave-one-out" if leave_one_out is not None else "train/test",
            "train": [s.name for s in train],
            "test": [s.name for s in test],
        },
        "scenes": {
            s.name: {
                "group": s.group,
                "frames": len(s.frames),
                "size": [int(s.frames.shape[2]), int(s.frames.shape[1])],
                "files": list(s.files),
                # what the frames held of what was asked (settings' patches and gallery): the fewest over the seeds
                "fewest_patches": sampled[s.name][0],
                "fewest_gallery_frames": sampled[s.name][1],
            }
            for s in evaluated
        },
        "settings": {
            **asdict(settings),
            "seeds": list(seeds),
            "max_frames": max_frames,
            "methods": methods,
            # what was done beside what was asked: methods without a grid are not tuned even when tuning is asked
            "tuning": bool(tuned),
            "tuning_requested": tuning,
            "tune_frames": tune_frames,
            "tune_seed": min(seeds),
            "tuning_grids": {m: [_spec(m, p) for p in TUNING_GRIDS[m]] for m in tuned},
        },
        "metrics": {
            "identification": "% of gallery patches whose best NCC match among all sampled locations is their own, "
            "the pair first registered to the pixel (the move of at most shift_px that best matches its patches)",
            "matching": "% correct one-to-one ratio-test matches (within match_px) per min(#keypoints), ORB and SIFT",
            "pose": "% of pairs whose RANSAC homography moves every frame corner less than pose_px",
            "correct": "mean count of correct one-to-one ratio-test matches (within match_px) per pair, ORB and SIFT",
        },
        "tuning": tuning_result,
        "machine": machine(),
        "methods": method_results,
        "paired_differences": paired_differences(method_results),
        "seconds": time.perf_counter() - start,
    }
    write_report(result, Path(out_dir), draw)
    logger.info("relight benchmark written to %s in %.0f s", out_dir, result["seconds"])
    return result
