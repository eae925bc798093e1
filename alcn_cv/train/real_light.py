r"""Training the gain Normalizer on light changes of registered scenes (real cameras, or photographs relit).

ALCN's Eq. 2 needs labels; on a registered multi-illumination set (one folder of frames per
scene, the camera fixed, the light changing: the ``webcam`` layout; or a photograph relit several times,
:func:`~alcn_cv.data.permissive_images.relit_scenes`) a textured location is an
"object", its index the label, seen under every frame's light. A step draws a scene, two of its
frames and ``locations`` textured locations (at least ``min_distance`` apart), crops ``crop x
crop`` windows around them in both frames, normalizes them with
:class:`~alcn_cv.nets.gain.GainNormalizer` (its maps on the grid of its stride, interpolated,
Eq. 3 at full resolution on the centre, the equalization) and classifies each central
``patch x patch`` of one frame among the locations of the other by normalized cross-correlation
(zero mean, unit norm, cosine over a temperature, symmetric cross-entropy). This is the task of
patch identification under a change of light, made differentiable. Two terms ask the same of the output
everywhere a detector looks: its consistency (:func:`consistency_loss`) and that of a keypoint detector's
response to it (:func:`repeatability_loss`).

The network sees the whole crop, which holds its receptive field; the mixture runs only where
the central ``patch`` needs it (:class:`CentreDenseMixture`: ``patch`` plus the widest kernel's
radius on every side, so no border rule is involved), with the same result as the whole
normalization there.

Outputs in the run folder: ``train.log``, ``history.json``, ``checkpoint.pt`` (atomic, every
``save_every`` steps and on Ctrl-C), ``gain_normalizer_step{N}.npz`` at those steps and
``gain_normalizer.npz`` (:mod:`alcn_cv.weight_file`, ``architecture: "gain"``) at the end.

Command (the ``gain`` preset reads photographs that permit any use; the webcam scenes, which
``--set scenes=[...]`` adds, are for academic research only, see ``shared/data/README.md``)::

    alcn train-real-light --conf gain   # the shipped alcn_normalizer_gain.npz
"""

from __future__ import annotations

import collections
import contextlib
import copy
import functools
import hashlib
import json
import logging
import re
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
import torch.nn.functional as F
from torch import nn
from tqdm import tqdm
from tqdm.contrib.logging import logging_redirect_tqdm

from alcn_cv.data.permissive_images import (
    Photograph,
    folder_photographs,
    photo_files,
    relit_scenes,
    training_photographs,
)
from alcn_cv.data.scenes import Scene, load_scenes, scene_dirs
from alcn_cv.errors import DatasetError, InputError, WeightFileError
from alcn_cv.filters.gaussian_mixture import kernel_radius
from alcn_cv.filters.torch_divisive import gaussian_blur, gaussian_energy, inverse_divisor
from alcn_cv.io import atomic_write, held_folder, interrupts_deferred, sigint_as_keyboard_interrupt, to_gray, write_json
from alcn_cv.nets.gain import GainNormalizer
from alcn_cv.presets import with_settings
from alcn_cv.report import log_to, provenance
from alcn_cv.shared_data import shared_data_dir
from alcn_cv.train.checkpoint import (
    REAL_LIGHT_CHECKPOINT_FORMAT,
    check_checkpoint,
    check_run_folder,
    checkpoint_header,
    load_checkpoint,
    run_folder,
)
from alcn_cv.train.config import RealLightConfig
from alcn_cv.train.models import CentreMixture
from alcn_cv.weight_file import save_normalizer_file

__all__ = [
    "REFERENCE_STEPS",
    "TEXTURED_SHARE",
    "TEXTURE_LEVELS",
    "CentreDenseMixture",
    "RealLightConfig",
    "consistency_loss",
    "TrainingInterrupted",
    "TrainingScene",
    "crop_windows",
    "data_record",
    "draw_step",
    "fit",
    "anywhere_locations",
    "check_photographs",
    "identification_loss",
    "initial_network",
    "harris_response",
    "objective",
    "pair_loss",
    "repeatability_loss",
    "resumed_config",
    "sample_locations",
    "source_scenes",
    "textured_locations",
    "textured_share",
    "train_real_light",
    "training_scene",
    "training_run",
    "training_scenes",
]

logger = logging.getLogger(__name__)


@dataclass
class TrainingScene:
    """A scene (:class:`alcn_cv.data.scenes.Scene`) ready for training: ``frames`` ``(T, H, W)``
    float32 in [0, 1], reflect-101 padded by ``pad`` on every side, and ``candidates`` ``(K, 2)``
    textured centres ``(y, x)`` in padded coordinates."""

    name: str
    frames: np.ndarray
    candidates: np.ndarray
    pad: int


def _window_texture(frames: np.ndarray, patch: int, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The centres ``ys``, ``xs`` of the ``patch x patch`` windows of a grid of ``step`` over ``(T, H, W)`` float32
    frames, and each window's texture: the median over frames of its mean gradient energy (Sobel's, squared)."""
    h, w = frames.shape[1:]
    half = patch // 2
    ys, xs = np.meshgrid(np.arange(half, h - half + 1, step), np.arange(half, w - half + 1, step), indexing="ij")
    energies = []
    for frame in frames:
        energy = cv2.Sobel(frame, cv2.CV_32F, 1, 0) ** 2 + cv2.Sobel(frame, cv2.CV_32F, 0, 1) ** 2
        energies.append(cv2.boxFilter(energy, -1, (patch, patch), normalize=True)[ys, xs])
    return ys, xs, np.median(np.stack(energies), axis=0)


def textured_locations(frames: np.ndarray, patch: int, step: int = 4, quantile: float = 0.5) -> np.ndarray:
    """Centres ``(K, 2)`` ``(y, x)`` of the ``patch x patch`` windows of a grid of ``step`` whose
    texture (the median over frames of the window's gradient energy, robust to what moves) is at
    least the ``quantile`` of all windows', and not zero.

    Args:
        frames: ``(T, H, W)`` float32.
    """
    if frames.ndim != 3:
        raise InputError(f"frames must be (T, H, W), got {frames.shape}")
    h, w = frames.shape[1:]
    if min(h, w) < patch:
        raise InputError(f"frames of {w}x{h} are smaller than the {patch}x{patch} patches")
    ys, xs, texture = _window_texture(frames, patch, step)
    score = texture.ravel()
    keep = (score >= np.quantile(score, quantile)) & (score > 0)
    return np.stack([ys.ravel()[keep], xs.ravel()[keep]], axis=1)


#: A window of a photograph is textured when its RMS gradient (Sobel's, per pixel) reaches this many grey levels of
#: 255 (:func:`textured_share`).
TEXTURE_LEVELS = 1.0

#: A photograph of the user's with a smaller share of textured windows (:func:`textured_share`) is warned about.
TEXTURED_SHARE = 0.1


def textured_share(image: np.ndarray, patch: int, step: int = 4) -> float:
    """The share of the ``patch x patch`` windows of a grid of ``step`` over a uint8 photograph (gray ``HxW`` or BGR
    ``HxWx3``, at least ``patch`` on a side) whose RMS gradient reaches :data:`TEXTURE_LEVELS` grey levels per pixel:
    0 for a uniform image or a smooth ramp, close to 1 for a photograph textured all over."""
    gray = to_gray(image)
    _, _, energy = _window_texture(gray[None].astype(np.float32) / 255, patch, step)
    # Sobel's 3x3 kernel answers 8 to a ramp of 1 per pixel; the box filter's rounding can leave tiny negatives
    levels = np.sqrt(np.maximum(energy, 0)) / 8 * 255
    return float((levels >= TEXTURE_LEVELS).mean())


def sample_locations(candidates: np.ndarray, count: int, min_distance: int, rng: np.random.Generator) -> np.ndarray:
    """Up to ``count`` candidates in random order, each at least ``min_distance`` (Chebyshev)
    from those drawn before it: ``(n, 2)``."""
    chosen: list[np.ndarray] = []
    for i in rng.permutation(len(candidates)):
        c = candidates[i]
        if all(np.abs(c - o).max() >= min_distance for o in chosen):
            chosen.append(c)
            if len(chosen) == count:
                break
    return np.stack(chosen) if chosen else np.zeros((0, 2), np.int64)


def training_scene(scene: Scene, pad: int, patch: int, crop: int | None = None) -> TrainingScene:
    """The scene's frames in [0, 1], reflect-101 padded by ``pad``, and its textured locations.

    Raises:
        DatasetError: frames smaller than the ``crop x crop`` training window, or than the ``patch x patch`` patches
            (the scene and the minimum size named); fewer than 2 textured locations (a flat scene): nothing to
            identify, and with none the identification loss would be NaN.
    """
    h, w = scene.frames.shape[1:]
    least = max(patch, crop or 0)
    if min(h, w) < least:
        what = f"the training crop (crop={crop})" if least == crop else f"the {patch}x{patch} patches"
        raise DatasetError(
            f"scene {scene.name!r}: frames of {w}x{h} are smaller than {what}: frames need at least {least}x{least} "
            "pixels"
        )
    stack = scene.unit_frames()
    candidates = textured_locations(stack, patch) + pad
    if len(candidates) < 2:
        raise DatasetError(
            f"scene {scene.name!r} has {len(candidates)} textured {patch}x{patch} location(s); training needs 2 or "
            "more (frames with texture)"
        )
    padded = np.stack([cv2.copyMakeBorder(f, pad, pad, pad, pad, cv2.BORDER_REFLECT_101) for f in stack])
    return TrainingScene(scene.name, padded, candidates, pad)


def crop_windows(frame: np.ndarray, centres: np.ndarray, size: int) -> torch.Tensor:
    """The ``size x size`` windows of ``frame`` (padded ``(H, W)`` float32) centred on ``centres`` ``(n, 2)``
    ``(y, x)``: ``(n, 1, size, size)``."""
    half = size // 2
    return torch.from_numpy(
        np.stack([frame[y - half : y - half + size, x - half : x - half + size] for y, x in centres])
    )[:, None]


def identification_loss(a: torch.Tensor, b: torch.Tensor, temperature: float) -> torch.Tensor:
    """Symmetric cross-entropy of identifying each patch of ``a`` among those of ``b`` (and back)
    by cosine similarity of the zero-mean patches (normalized cross-correlation).

    Args:
        a, b: ``(n, 1, P, P)``, patch ``i`` of ``a`` and of ``b`` at the same location.
        temperature: the softmax's temperature.

    Returns:
        A scalar tensor.
    """
    va = a.flatten(1)
    vb = b.flatten(1)
    va = F.normalize(va - va.mean(1, keepdim=True), dim=1, eps=1e-6)
    vb = F.normalize(vb - vb.mean(1, keepdim=True), dim=1, eps=1e-6)
    logits = va @ vb.T / temperature
    target = torch.arange(len(va), device=va.device)
    return 0.5 * (F.cross_entropy(logits, target) + F.cross_entropy(logits.T, target))


def consistency_loss(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """How much the output changes with the light, relative to its energy:
    ``sum (a - b)^2 / sum (a^2 + b^2)`` over all the patches together.

    Identification ignores each patch's mean and scale; detectors compare responses across the
    image, so this term asks for the same output in absolute terms (0 when equal, about 1 when unrelated).

    Args:
        a, b: ``(n, 1, P, P)``, the same locations under two lights.

    Returns:
        A scalar tensor in [0, 2].
    """
    return (a - b).square().sum() / (a.square().sum() + b.square().sum()).clamp_min(1e-12)


def harris_response(x: torch.Tensor, sigma: float = 1.5, k: float = 0.04) -> torch.Tensor:
    """Harris's corner response ``det(M) - k trace(M)^2`` of ``(n, 1, P, P)`` images (``M`` the structure tensor:
    central-difference gradients, their products blurred by ``G_sigma``, reflect-101 borders): ``(n, 1, P, P)``.
    What ORB ranks its FAST corners by, differentiable."""
    # One pad per difference term: the order of the float operations the shipped file was trained with.
    gx = (F.pad(x, (1, 1, 0, 0), mode="reflect")[..., 2:] - F.pad(x, (1, 1, 0, 0), mode="reflect")[..., :-2]) / 2
    gy = (F.pad(x, (0, 0, 1, 1), mode="reflect")[..., 2:, :] - F.pad(x, (0, 0, 1, 1), mode="reflect")[..., :-2, :]) / 2
    sxx, syy, sxy = (gaussian_blur(t, sigma) for t in (gx * gx, gy * gy, gx * gy))
    return sxx * syy - sxy * sxy - k * (sxx + syy) ** 2


def repeatability_loss(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """:func:`consistency_loss` of the :func:`harris_response` of the outputs: a keypoint detector fed them
    must respond alike under both lights (noise lifted to contrast in one frame is not in the other).

    Args:
        a, b: ``(n, 1, P, P)``, the same locations under two lights.

    Returns:
        A scalar tensor in [0, 2].
    """
    return consistency_loss(harris_response(a), harris_response(b))


class CentreDenseMixture(nn.Module):
    """Eq. 3 on the centre of a crop, from the maps on the grid of the network's stride.

    The maps are interpolated bilinearly from the grid (as :meth:`GainNormalizer.dense`) onto
    the ``size + 2 * radius`` pixels around the centre (``radius`` the widest kernel's
    half-width), and Eq. 3 on that region's centre is :meth:`alcn_cv.train.models.CentreMixture.dense`
    (banded matrices: far cheaper on a CPU than depthwise convolutions). Equal to the centre of
    :meth:`GainNormalizer.response` on the crop.

    Args:
        sigmas: the mixture's sigmas (pixels).
        crop: side of the crops (pixels).
        size: side of the centre (pixels).
        stride: the grid's stride; ``(crop - 2 * size) / 2`` and ``2 * size`` must be multiples of it.

    Shape:
        crops ``(B, 1, crop, crop)``, grid ``(B, N, gh, gw)`` (on the whole crop) -> ``(B, 1, size, size)``.
    """

    def __init__(self, sigmas: Sequence[float], crop: int, size: int, stride: int) -> None:
        super().__init__()
        self.radius = max(kernel_radius(s) for s in sigmas)
        lo = (crop - 2 * size) // 2
        if lo < 0 or lo % stride or (2 * size) % stride or self.radius > size // 2:
            raise InputError(
                f"crop {crop}, centre {size} and stride {stride} do not fit: (crop - 2 * size) / 2 and 2 * size "
                "must be multiples of the stride, the widest kernel within size / 2"
            )
        side = size + 2 * self.radius
        self.first = lo + size // 2 - self.radius  # first pixel of the region around the centre
        self.side, self.size, self.crop = side, size, crop
        cells = 2 * size // stride
        self.cells = slice(lo // stride, lo // stride + cells + 1)
        # Bilinear weights (align_corners) from the grid points of the central 2 * size onto the region.
        pixels = np.arange(side) + (size // 2 - self.radius)
        position = pixels / stride
        left = np.minimum(np.floor(position).astype(int), cells - 1)
        frac = position - left
        interp = np.zeros((side, cells + 1), np.float32)
        interp[np.arange(side), left] = 1 - frac
        interp[np.arange(side), left + 1] += frac
        self.register_buffer("interp", torch.from_numpy(interp), persistent=False)
        self.mixture = CentreMixture(tuple(sigmas), window=side, size=size)

    def forward(self, crops: torch.Tensor, grid: torch.Tensor) -> torch.Tensor:
        if crops.shape[-2:] != (self.crop, self.crop):
            raise InputError(f"crops must be {self.crop}x{self.crop}, got {tuple(crops.shape[-2:])}")
        maps = self.interp @ grid[..., self.cells, self.cells] @ self.interp.T
        region = crops[..., self.first : self.first + self.side, self.first : self.first + self.side]
        return self.mixture.dense(region, maps)


@functools.lru_cache(maxsize=4)
def _centre_mixture(sigmas: tuple[float, ...], crop: int, size: int, stride: int) -> CentreDenseMixture:
    return CentreDenseMixture(sigmas, crop, size, stride)


def _normalized_centres(
    net: GainNormalizer, crops: torch.Tensor, patch: int, frames: Sequence[tuple[slice, slice]] = ()
) -> torch.Tensor:
    """The network's output on the central ``patch x patch`` of each crop ``(B, 1, crop, crop)``:
    the network on the whole crop, Eq. 3 on the centre (:class:`CentreDenseMixture`), the
    divisive normalization (:mod:`alcn_cv.filters.torch_divisive`) and the equalization.

    The divisive normalization needs the response the Gaussian's radius around the centre and the mean
    energy of the whole frame, which the centres of the crops of each frame drawn anywhere estimate:
    ``frames`` holds, per frame, the slice of its crops and the slice of those drawn anywhere (all of its
    crops when none is given).
    """
    grid = net.dense_grid(crops)
    crop = crops.shape[-1]
    s = net.stride
    if patch % (2 * s) or (crop - patch) % (2 * s):
        raise InputError(f"the divisive gain needs patch and (crop - patch) / 2 multiples of the stride {s}")
    radius = kernel_radius(net.divisive_sigma)
    step = s // 2 if s % 2 == 0 else s  # the centre mixture's side needs 2 * margin a multiple of s
    margin = -(-radius // step) * step
    response = _centre_mixture(net.sigmas, crop, patch + 2 * margin, s)(crops, grid)
    trim = margin - radius
    energy = gaussian_energy(response, net.divisive_sigma, pad=False)[..., trim : trim + patch, trim : trim + patch]
    floor = torch.empty(len(crops), 1, 1, 1, dtype=crops.dtype)
    for rows, sample in frames or [(slice(None), slice(None))]:
        floor[rows] = net.floor_scale * energy[sample].mean()
    centre = response[..., margin : margin + patch, margin : margin + patch]
    return net.equalize(centre * inverse_divisor(energy, floor))


def source_scenes(
    scenes: Sequence[str],
    relit: int,
    seed: int,
    light: str,
    jitter: float = 0.0,
    *,
    photos: Sequence[str] = (),
    shipped_photos: bool = True,
    min_side: int = 0,
    patch: int = RealLightConfig.patch,
    rendered_fraction: float = 0.0,
) -> list[Scene]:
    """The registered scenes a gain Normalizer learns from: those of ``scenes`` (folders, or names of the shared
    ``webcam`` scenes) and, unless ``relit`` is 0, each photograph relit ``relit`` times
    (:func:`~alcn_cv.data.permissive_images.relit_scenes` with ``seed``, ``light`` and ``jitter``): the permissive
    ones (:func:`~alcn_cv.data.permissive_images.training_photographs`, unless ``shipped_photos`` is False), then those
    of the folders ``photos`` (:func:`~alcn_cv.data.permissive_images.folder_photographs`, each side at least
    ``min_side``), so that adding photos leaves the permissive ones' copies as they were.

    The photographs of ``photos`` are checked as they are read (:func:`check_photographs`, the windows of the side
    ``patch``): a warning for one with almost no texture, one of the same pixels as another, and a single one (with
    ``rendered_fraction``, the share of the steps that draw a rendered scene instead of one of these).

    Raises:
        InputError: as :func:`~alcn_cv.data.permissive_images.folder_photographs`, or a photograph of ``photos``
            without texture (:func:`check_photographs`).
    """
    sources = load_scenes(scene_dirs(scenes)) if scenes else []
    if not relit:
        return sources
    mine = folder_photographs(photos, min_side) if photos else []  # read first: a bad file fails before any relighting
    shipped = training_photographs(shared_data_dir()) if shipped_photos else []
    if mine:
        check_photographs(mine, shipped, patch, others=len(sources), rendered_fraction=rendered_fraction)
    return sources + relit_scenes(shipped + mine, relit, seed, light, jitter)


def check_photographs(
    mine: Sequence[Photograph],
    shipped: Sequence[Photograph],
    patch: int,
    others: int = 0,
    rendered_fraction: float = 0.0,
) -> None:
    """Check the user's photographs ``mine`` before they are relit: an error for one without texture, a warning (a
    line of log naming the file) for one with almost none, for one of the same pixels as another of ``mine`` or of
    ``shipped`` (the permissive photographs of the run), and for a single one.

    A photograph is without texture where fewer than 2 of its ``patch x patch`` windows hold any gradient (the rule of
    :func:`training_scene`, which the noise of a relit copy would hide); with almost none where fewer than
    :data:`TEXTURED_SHARE` of its windows are textured (:func:`textured_share`). Each photograph is a scene of its own,
    drawn as often as any other: a copy makes its photograph count twice. For the warning about a single one:
    ``others``, the scenes besides the photographs (registered scenes), and ``rendered_fraction``, the share of the
    steps that draw a rendered scene instead (:func:`draw_step`; 0: none).

    Raises:
        InputError: a photograph without texture, its file named.
    """
    seen = {_pixels_hash(p.image): f"the shipped photograph {p.name}" for p in shipped}
    for photo in mine:
        gray = to_gray(photo.image)
        if len(textured_locations(gray[None].astype(np.float32), patch)) < 2:
            raise InputError(
                f"photos: {photo.source}: no texture: its pixels are alike all over (fewer than 2 of its "
                f"{patch}x{patch} windows hold any gradient), and the training identifies locations by their texture; "
                "remove it"
            )
        share = textured_share(gray, patch)
        if share < TEXTURED_SHARE:
            logger.warning(
                "photos: %s: almost no texture: %.0f%% of its %dx%d windows reach an RMS gradient of %g grey level per "
                "pixel (warned below %.0f%%), and the training identifies locations by their texture",
                photo.source,
                100 * share,
                patch,
                patch,
                TEXTURE_LEVELS,
                100 * TEXTURED_SHARE,
            )
        key = _pixels_hash(photo.image)
        if key in seen:
            logger.warning(
                "photos: %s: the same pixels as %s: each copy is a scene of its own, drawn as often as any other "
                "photograph",
                photo.source,
                seen[key],
            )
        seen.setdefault(key, photo.source)
    if len(mine) == 1:
        total = len(shipped) + others + 1
        same = "the same scene, its relit copies (shipped_photos=false and no scenes)"
        if rendered_fraction:
            steps = f"the steps that draw no rendered scene ({1 - rendered_fraction:.0%} of them)"
            detail = f"one of the {total} scenes {steps} draw from" if total > 1 else f"{steps} all draw {same}"
        else:
            detail = f"one of the {total} scenes each step draws from" if total > 1 else f"every step draws {same}"
        logger.warning("photos: a single photograph of yours, %s: %s", mine[0].source, detail)


def _pixels_hash(image: np.ndarray) -> str:
    """A digest of an image's pixels, its shape and type: equal for the same pixels."""
    digest = hashlib.sha256(repr((image.shape, image.dtype.str)).encode())
    digest.update(np.ascontiguousarray(image).tobytes())
    return digest.hexdigest()


def training_scenes(cfg: RealLightConfig) -> tuple[list[TrainingScene], list[TrainingScene]]:
    """The two groups of scenes a run draws from, ready for training (padded by ``cfg.crop // 2``, each frame at
    least ``cfg.crop`` on a side): ``cfg.scenes`` with the ``cfg.relit`` copies of the permissive photographs and of
    ``cfg.photos``, and ``cfg.rendered``."""
    sources = source_scenes(
        cfg.scenes,
        cfg.relit,
        cfg.seed,
        cfg.light,
        cfg.jitter,
        photos=cfg.photos,
        shipped_photos=cfg.shipped_photos,
        min_side=cfg.crop,
        patch=cfg.patch,
        rendered_fraction=cfg.rendered_fraction if cfg.rendered else 0.0,  # as draw_step draws
    )
    scenes = [training_scene(s, cfg.crop // 2, cfg.patch, cfg.crop) for s in sources]
    rendered = [training_scene(s, cfg.crop // 2, cfg.patch, cfg.crop) for s in load_scenes(cfg.rendered)]
    for scene in scenes + rendered:
        logger.info("scene %s: %d frames, %d textured locations", scene.name, len(scene.frames), len(scene.candidates))
    return scenes, rendered


def anywhere_locations(scene: TrainingScene, count: int, rng: np.random.Generator) -> np.ndarray:
    """``(count, 2)`` centres ``(y, x)`` drawn uniformly over the frame (padded coordinates)."""
    _, h, w = scene.frames.shape
    p = scene.pad
    return np.stack([rng.integers(p, h - p, count), rng.integers(p, w - p, count)], axis=1)


def objective(a: torch.Tensor, b: torch.Tensor, textured: int, cfg: RealLightConfig) -> torch.Tensor:
    """The training objective on the outputs ``(m, 1, P, P)`` of the same ``m`` locations under two lights, the
    first ``textured`` of them the classes: :func:`identification_loss` of those, plus ``cfg.consistency`` times
    :func:`consistency_loss` and ``cfg.repeatability`` times :func:`repeatability_loss` over all ``m``."""
    loss = identification_loss(a[:textured], b[:textured], cfg.temperature)
    if cfg.consistency:
        loss = loss + cfg.consistency * consistency_loss(a, b)
    if cfg.repeatability:
        loss = loss + cfg.repeatability * repeatability_loss(a, b)
    return loss


#: What a training step sees (:func:`draw_step`): a scene, two of its frames, textured centres and centres drawn
#: anywhere (or None).
Draw = tuple[TrainingScene, tuple[int, int], np.ndarray, np.ndarray | None]


def draw_step(
    scenes: Sequence[TrainingScene], rendered: Sequence[TrainingScene], cfg: RealLightConfig, rng: np.random.Generator
) -> Draw:
    """What one training step sees: a scene (from ``rendered`` with probability ``cfg.rendered_fraction``), two
    of its frames, ``cfg.locations`` textured centres and ``cfg.anywhere`` centres drawn anywhere (or None)."""
    group = rendered if rendered and rng.random() < cfg.rendered_fraction else scenes
    scene = group[rng.integers(len(group))]
    fa, fb = rng.choice(len(scene.frames), 2, replace=False)
    centres = sample_locations(scene.candidates, cfg.locations, cfg.min_distance, rng)
    anywhere = anywhere_locations(scene, cfg.anywhere, rng) if cfg.anywhere else None
    return scene, (int(fa), int(fb)), centres, anywhere


def pair_loss(
    net: nn.Module,
    scene: TrainingScene,
    frames: tuple[int, int],
    centres: np.ndarray,
    cfg: RealLightConfig,
    anywhere: np.ndarray | None = None,
    normalize: Callable[..., torch.Tensor] | None = None,
) -> torch.Tensor:
    """The objective on one pair of frames of a scene: :func:`identification_loss` of the
    normalized centres of the crops around the textured ``centres`` ``(n, 2)`` (padded
    coordinates), plus ``cfg.consistency`` times :func:`consistency_loss` and ``cfg.repeatability`` times
    :func:`repeatability_loss` over those and the ``anywhere`` ``(m, 2)`` locations.

    ``normalize(net, crops, patch, frames)`` gives the network's output on the central ``patch`` of each crop
    (``frames``: per frame, the slice of its crops and of those drawn anywhere); default: the gain
    Normalizer's, whose divisive floor is estimated from those drawn anywhere."""
    fa, fb = frames
    every = centres if anywhere is None or not len(anywhere) else np.concatenate([centres, anywhere])
    crops = torch.cat([crop_windows(scene.frames[f], every, cfg.crop) for f in (fa, fb)])
    m, n = len(every), len(centres)
    drawn = (lambda first: slice(first + n, first + m)) if m > n else (lambda first: slice(first, first + m))
    outputs = (normalize or _normalized_centres)(
        net, crops, cfg.patch, [(slice(0, m), drawn(0)), (slice(m, 2 * m), drawn(m))]
    )
    return objective(outputs[:m], outputs[m:], n, cfg)


#: The last steps of each logged block whose draws :func:`fit` scores the untrained start on, for reference.
REFERENCE_STEPS = 10


def _reference(
    initial: nn.Module,
    step_loss: Callable[..., torch.Tensor],
    history: Sequence[dict],
    draws: Sequence[Draw],
    cfg: RealLightConfig,
) -> str:
    """``" (steps A-B: L; the untrained start on the same draws: U)"``: the training's mean loss over the last steps of
    the block (those of ``draws``, at most the block's) and the untrained start's on their draws."""
    n = min(len(draws), (history[-1]["step"] - 1) % cfg.save_every + 1)  # the block's, drawn in this process
    with torch.no_grad():
        start = float(np.mean([step_loss(initial, d[0], d[1], d[2], cfg, d[3]).item() for d in list(draws)[-n:]]))
    trained = float(np.mean([h["loss"] for h in history[-n:]]))
    first, last = history[-n]["step"], history[-1]["step"]
    steps = f"steps {first}-{last}" if n > 1 else f"step {last}"
    return f" ({steps}: {trained:.4f}; the untrained start on the same draws: {start:.4f})"


#: The warning of a block in which no weight got a gradient (its steps, the learning rate).
_DEAD = (
    "no weight of the network got a gradient in the last %d steps: every hidden unit is off (its ReLUs died), so "
    "its output no longer depends on the image and the weight file normalizes every image with one fixed filter; "
    "train again with a lower learning rate than %g (--set lr=...)"
)


class TrainingInterrupted(KeyboardInterrupt):
    """Ctrl-C or SIGTERM (its ``__cause__``) stopped :func:`fit`, which saved the steps done first.

    Attributes:
        step: the steps done (0: none).
        checkpoint: whether the run folder's ``checkpoint.pt`` holds them, for a resumed run to go on from
            (:func:`train_real_light` after its first step; :func:`~alcn_cv.train.unet.train_unet` writes none).
    """

    def __init__(self, step: int, checkpoint: bool = True) -> None:
        super().__init__(f"interrupted at step {step}")
        self.step = step
        self.checkpoint = checkpoint and step > 0


def _save_weights(
    net: GainNormalizer, path: Path, cfg: RealLightConfig, step: int, seconds: float, record: dict[str, Any]
) -> Path:
    config = asdict(cfg.shareable())  # a file users share: the folders as given, the home folder written ~
    meta = net.file_meta(
        trained=step > 0,
        description="gain Normalizer trained to identify locations across light changes (its data, relit "
        "photographs and/or registered scenes: training.config)",
        training={
            **provenance(record.get("command", ""), record.get("conf")),
            "config": config,
            "step": step,
            "seconds": round(seconds, 1),
        },
    )
    return save_normalizer_file(path, net.state_arrays(), meta)


def train_real_light(
    cfg: RealLightConfig,
    out: str | Path,
    *,
    command: str = "",
    conf: str | None = None,
    progress: bool = True,
    resume: bool = False,
    overwrite: bool = False,
    checkpoint: dict[str, Any] | None = None,
) -> Path:
    """Train a :class:`~alcn_cv.nets.gain.GainNormalizer` on registered scenes (see the module).

    What can fail before training is checked before the run folder is touched: the settings, the folder (an earlier
    run's is replaced only with ``overwrite``), the checkpoint to resume and the scenes, loaded first (their lines of
    log go into ``train.log`` all the same). An error after that is written into ``train.log`` before it propagates.

    Args:
        cfg: the settings (the ``gain`` preset of :data:`~alcn_cv.train.config.REAL_LIGHT_CONFS`, overridden or not).
            The checkpoint records its folders absolute (:meth:`~alcn_cv.train.config.RealLightConfig.resolved`), so
            that ``resume`` works from any working folder; the weight file, which users share, records them as given,
            the home folder written ``~`` (:meth:`~alcn_cv.train.config.RealLightConfig.shareable`; a run resumed
            with the checkpoint's settings, their absolute folders so written).
        out: the run folder.
        command, conf: the command line and the preset's name, recorded in the weight file with ``cfg`` (a resumed
            run given neither records its checkpoint's).
        progress: show a progress bar.
        resume: go on from ``out/checkpoint.pt`` (written every ``cfg.save_every`` steps and on Ctrl-C), as if never
            stopped: the same weights as an uninterrupted run. ``cfg`` is the checkpoint's (:func:`resumed_config`)
            but for a larger ``steps`` (training longer); the data must be those the checkpoint records (the
            folders, resolved, and the files of ``photos``). A finished run resumed to a larger ``steps`` loses its
            final weight file (a later stop would leave it beside a later checkpoint).
        overwrite: replace the earlier run that ``out`` holds (its checkpoint, history and weight files).
        checkpoint: with ``resume``, ``out/checkpoint.pt`` read already (:func:`resumed_config`'s), not read again.

    Returns:
        The final weight file ``out/gain_normalizer.npz``.

    Raises:
        InputError: settings out of range; ``out`` holds another run (without ``resume`` or ``overwrite``) or
            other files, or is a file; a folder of ``photos`` missing, or a photograph unreadable, smaller than the
            crop or without texture (:func:`check_photographs`).
        DatasetError: a scene missing or unfit for training (frames smaller than the crop, no texture).
        WeightFileError: ``resume`` without a checkpoint, or with one of other settings (each named, both values)
            or other data (what changed named).
        TrainingInterrupted: Ctrl-C or SIGTERM; the checkpoint holds the last step done (:func:`fit`).
    """
    out = Path(out)
    _check_settings(cfg)
    check_run_folder(out, resume=resume, overwrite=overwrite)
    data = data_record(cfg)
    start = None
    if resume:
        path = out / "checkpoint.pt"
        if checkpoint is None:
            start = load_checkpoint(path, cfg)
        else:
            start = checkpoint
            check_checkpoint(start, path, cfg)
        _check_data(_recorded(start, path)["data"], data, path)
    record: dict[str, Any] = {"command": command, "conf": conf}
    if start is not None and not command:
        record.update(start["record"])
    with _log_kept() as kept:
        scenes = training_scenes(cfg)
    with training_run(cfg, out, resume, kept=kept, check=False) as folder:
        if start is None:
            _remove_final(folder, "of an earlier run")
        elif cfg.steps > start["step"]:
            _remove_final(folder, f"of step {start['step']}: the run goes on to step {cfg.steps}")
        return _train(cfg, folder, record, progress, start, scenes, data)


def data_record(cfg: RealLightConfig) -> dict[str, Any]:
    """What a run of ``cfg`` reads, as its checkpoint records it for a resumed run to find again: the folders of
    ``cfg.scenes`` and ``cfg.rendered``, resolved, and, where relit, those of ``cfg.photos`` with the name and size of
    each of their images (a photograph added or removed changes the next ones' draws). The weight file records the
    settings as a file users share (:meth:`~alcn_cv.train.config.RealLightConfig.shareable`)."""
    photos = [Path(p).expanduser().resolve() for p in cfg.photos] if cfg.relit else []
    return {
        "scenes": [str(p.resolve()) for p in scene_dirs(cfg.scenes)],
        "rendered": [str(Path(p).expanduser().resolve()) for p in cfg.rendered],
        "photos": [[str(p), [[f.name, f.stat().st_size] for f in photo_files([p])]] for p in photos],
    }


def _recorded(ckpt: dict[str, Any], path: Path) -> dict[str, Any]:
    """The checkpoint ``ckpt`` (read from ``path``), which must record its data and its command (``data``,
    ``record``).

    Raises:
        WeightFileError: a checkpoint of an earlier alcn-cv, which recorded neither: it does not resume.
    """
    missing = [key for key in ("data", "record") if key not in ckpt]
    if missing:
        raise WeightFileError(
            f"checkpoint {path} was written by an earlier alcn-cv (it records no {' and no '.join(missing)}): start a "
            "new run folder"
        )
    return ckpt


def _check_data(saved: dict[str, Any], now: dict[str, Any], path: Path) -> None:
    """Raise :class:`WeightFileError` naming what changed from the data the checkpoint ``path`` records (``saved``)
    to those of now (:func:`data_record`)."""
    changes = [
        f"{key} {saved.get(key)} in the checkpoint, {now[key]} now"
        for key in ("scenes", "rendered")
        if saved.get(key) != now[key]
    ]
    before, after = dict(saved.get("photos") or []), dict(now["photos"])
    if list(before) != list(after):
        changes.append(f"photos {list(before)} in the checkpoint, {list(after)} now")
    else:
        for folder in after:
            old, new = dict(before[folder]), dict(after[folder])
            named = {
                "added": [n for n in new if n not in old],
                "removed": [n for n in old if n not in new],
                "resized": [n for n in new if n in old and new[n] != old[n]],
            }
            changes += [f"photos {folder}: {what} {', '.join(names)}" for what, names in named.items() if names]
    if changes:
        raise WeightFileError(
            f"checkpoint {path} was written on other data: {'; '.join(changes)}; resume with its data as they were, "
            "or start a new run folder"
        )


def resumed_config(
    out: str | Path, settings: Sequence[str | dict[str, Any]] = (), *, checkpoint: dict[str, Any] | None = None
) -> tuple[RealLightConfig, dict[str, Any]]:
    """The settings of the run in the folder ``out`` (its checkpoint's) with ``settings`` applied
    (:func:`~alcn_cv.presets.with_settings`; a resumed run takes a larger ``steps`` and nothing else), and what
    its weight file records besides (``command`` and ``conf``).
    ``checkpoint``: ``out/checkpoint.pt`` read already (:func:`~alcn_cv.train.checkpoint.load_checkpoint`), for
    :func:`train_real_light` to take too.

    Raises:
        WeightFileError: no readable checkpoint of ``alcn train-real-light`` in ``out``, one of unknown settings, or
            one of an earlier alcn-cv (:func:`_recorded`).
        InputError: a setting unknown or of the wrong type.
    """
    path = Path(out) / "checkpoint.pt"
    ckpt = load_checkpoint(path) if checkpoint is None else checkpoint
    if ckpt["format"] != REAL_LIGHT_CHECKPOINT_FORMAT:
        raise WeightFileError(f"{path} is not a checkpoint of alcn train-real-light")
    saved = copy.deepcopy(ckpt["config"])
    unknown = sorted(set(saved) - {f.name for f in fields(RealLightConfig)})
    if unknown:
        raise WeightFileError(f"checkpoint {path} holds settings this alcn-cv does not know: {', '.join(unknown)}")
    return with_settings(RealLightConfig(**saved), settings), dict(_recorded(ckpt, path)["record"])


def _check_settings(cfg: RealLightConfig) -> None:
    """The settings' ranges (:meth:`RealLightConfig.check <alcn_cv.train.config.RealLightConfig.check>`) and the
    network's needs: a crop of two patches at least, the widest kernel within half a patch."""
    cfg.check()
    if cfg.crop < 2 * cfg.patch:
        raise InputError(f"need crop >= 2 * patch, got crop {cfg.crop} and patch {cfg.patch}")
    with torch.random.fork_rng(devices=[]):  # the caller's draws untouched
        sigmas = GainNormalizer(**cfg.net).sigmas
    if max(kernel_radius(s) for s in sigmas) > cfg.patch // 2:
        raise InputError(f"patch {cfg.patch} is too small for sigma {max(sigmas)}: the kernels must fit in patch / 2")


def _remove_final(folder: Path, whose: str) -> None:
    """Remove the final weight file and its export of an earlier run (or of the run resumed to train longer): a run
    stopped before its end would leave them beside its own checkpoint; ``whose``, for the log."""
    for name in ("gain_normalizer.npz", "gain_normalizer.onnx"):
        path = folder / name
        if path.is_file():
            path.unlink()
            logger.warning("removed %s %s", path, whose)


class _Kept(logging.Handler):
    """Keeps the records it is given."""

    def __init__(self) -> None:
        super().__init__(logging.INFO)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)


@contextlib.contextmanager
def _log_kept() -> Iterator[list[logging.LogRecord]]:
    """The records of the ``alcn_cv`` loggers (INFO at least, :func:`~alcn_cv.report.log_to`) while the block runs,
    for a run's ``train.log`` not yet open (:func:`training_run`'s ``kept``); they reach the console as ever."""
    handler = _Kept()
    with log_to(handler):
        yield handler.records


@contextlib.contextmanager
def _run_log_only() -> Iterator[None]:
    """The records of the block reach the ``alcn_cv`` logger's handlers (the run's ``train.log``,
    :func:`~alcn_cv.report.log_to`), not the root logger's (the console, which has them already)."""
    top = logging.getLogger("alcn_cv")
    previous = top.propagate
    top.propagate = False
    try:
        yield
    finally:
        top.propagate = previous


@contextlib.contextmanager
def training_run(
    cfg: RealLightConfig,
    out: str | Path,
    resume: bool = False,
    *,
    kept: Sequence[logging.LogRecord] = (),
    check: bool = True,
) -> Iterator[Path]:
    """The run of any network on ``cfg``'s draws: checks the settings (:meth:`RealLightConfig.check
    <alcn_cv.train.config.RealLightConfig.check>`; with ``check`` False, the caller has), makes the run folder ``out``
    and copies the log into its ``train.log`` (:func:`alcn_cv.report.log_to`), after ``kept``, the records of the work
    done before the folder was touched (:func:`train_real_light` loads its scenes first). An error of the block is
    written into ``train.log`` before it propagates. The folder is held for the block (:func:`alcn_cv.io.held_folder`):
    a second run into it meanwhile is refused. A folder holds one run: an earlier run's ``train.log`` is replaced,
    its step snapshots (``*_step{N}.npz``), checkpoint and history removed, unless the run is resumed (its log goes on);
    whether an earlier run may be replaced is for the caller to check first
    (:func:`~alcn_cv.train.checkpoint.check_run_folder`).

    Yields:
        The run folder.
    """
    if check:
        cfg.check()
    with held_folder(run_folder(out)) as folder:
        # an earlier run's snapshots, which this run's would not all replace, and its checkpoint, which a --resume
        # of a run stopped before its first save would take for its own (a resumed run's are its own)
        earlier = [] if resume else [p for p in folder.glob("*_step*.npz") if re.search(r"_step\d+\.npz$", p.name)]
        for path in earlier:
            path.unlink()
        if not resume:
            (folder / "checkpoint.pt").unlink(missing_ok=True)
            (folder / "history.json").unlink(missing_ok=True)
        with log_to(folder / "train.log", append=resume):
            with _run_log_only():
                for record in kept:
                    logging.getLogger(record.name).handle(record)
            if earlier:
                logger.warning("removed %d step snapshots of an earlier run in %s", len(earlier), folder)
            try:
                yield folder
            except Exception as exc:
                with _run_log_only():
                    logger.error("the run failed: %s", exc, exc_info=True)
                raise


def initial_network(seed: int, net: dict[str, Any]) -> GainNormalizer:
    """The network a run of ``seed`` starts from, before any step (a run saves no step 0): a
    :class:`~alcn_cv.nets.gain.GainNormalizer` of the arguments ``net`` (``RealLightConfig.net``), its weights drawn
    after ``torch.manual_seed(seed)``, as :func:`train_real_light` draws them. It seeds torch's global generator
    (``torch.manual_seed(seed)``: the whole process's, CUDA's included, not a generator of its own), as training
    needs, the weights being drawn from it; a caller whose own torch draws must stay untouched wraps the call in
    ``torch.random.fork_rng()``. The untrained start of a shipped file:
    ``initial_network(**{k: meta["training"]["config"][k] for k in ("seed", "net")})``."""
    torch.manual_seed(seed)
    return GainNormalizer(**net)


def _train(
    cfg: RealLightConfig,
    out: Path,
    record: dict[str, Any],
    progress: bool,
    start: dict[str, Any] | None,
    scenes_drawn: tuple[list[TrainingScene], list[TrainingScene]],
    data: dict[str, Any],
) -> Path:
    rng = np.random.default_rng(cfg.seed)
    net = initial_network(cfg.seed, cfg.net)
    initial = copy.deepcopy(net)  # the untrained start, the log's reference (fit)
    if start is not None:
        logger.info("resuming from step %d of %d", start["step"], cfg.steps)
        net.load_state_dict(start["net"])
    scenes, rendered = scenes_drawn

    def save(step: int, seconds: float, opt: torch.optim.Optimizer, history: list[dict]) -> None:
        _save_weights(net, out / f"gain_normalizer_step{step}.npz", cfg, step, seconds, record)
        state = {
            **checkpoint_header(cfg),
            "net": net.state_dict(),
            "opt": opt.state_dict(),
            "step": step,
            "seconds": seconds,
            "history": history,
            "draws": json.dumps(rng.bit_generator.state),  # the next step's draws, as an uninterrupted run's
            "torch_rng": torch.get_rng_state(),
            "record": record,  # what the weight file of a run resumed with the checkpoint's settings records
            "data": data,  # what a resumed run must read again (data_record)
        }
        atomic_write(out / "checkpoint.pt", lambda f, state=state: torch.save(state, f))

    seconds = fit(net, pair_loss, scenes, rendered, cfg, rng, out, save, "real-light", progress, start, initial)
    return _save_weights(net, out / "gain_normalizer.npz", cfg, cfg.steps, seconds, record)


def fit(
    net: nn.Module,
    step_loss: Callable[..., torch.Tensor],
    scenes: Sequence[TrainingScene],
    rendered: Sequence[TrainingScene],
    cfg: RealLightConfig,
    rng: np.random.Generator,
    out: Path,
    save: Callable[[int, float, torch.optim.Optimizer, list[dict]], None] | None,
    desc: str,
    progress: bool = True,
    start: dict[str, Any] | None = None,
    initial: nn.Module | None = None,
) -> float:
    """The training loop of the gain Normalizer and of its baselines: ``cfg.steps`` steps of Adam at ``cfg.lr`` on
    ``step_loss(net, scene, frames, centres, cfg, anywhere)`` of :func:`draw_step`'s draws, gradients clipped to norm 5;
    every ``cfg.save_every`` steps and at the end, ``save(step, seconds, optimizer, history)`` (None: no checkpoint), a
    line of log and ``out/history.json``; ``start``, a checkpoint's state
    (:func:`~alcn_cv.train.checkpoint.load_checkpoint`), goes on after its step. Leaves ``net`` in eval mode. A block
    in which no weight (a parameter of two or more dimensions) got a gradient logs a warning: the network died. The
    progress bar shows the mean loss of the last ``cfg.save_every`` steps (the logged one); lines of log print above it.

    Each step's loss is on a pair drawn afresh, so the logged mean moves with the block's draws as well as with the
    training. For a reference, given ``initial`` (the untrained start, left as it is), each line of log also gives the
    mean loss of the block's last :data:`REFERENCE_STEPS` steps (at most; those of this process) and the untrained
    start's on the same draws (without gradients: the training's draws and weights are untouched).

    Ctrl-C and SIGTERM wait while a step updates the weights and while a save writes
    (:func:`~alcn_cv.io.interrupts_deferred`); then the steps done since the last save are saved as
    the periodic saves are (the next step's draws those of an uninterrupted run) and :class:`TrainingInterrupted`
    is raised (its ``checkpoint`` whether ``save`` saved them).

    Returns:
        The seconds it took (with the checkpoint's).
    """
    opt = torch.optim.Adam(net.parameters(), lr=cfg.lr)
    history: list[dict] = []
    first, before = 1, 0.0
    if start is not None:
        opt.load_state_dict(start["opt"])
        history, first, before = list(start["history"]), start["step"] + 1, start["seconds"]
        rng.bit_generator.state = json.loads(start["draws"])
        torch.set_rng_state(start["torch_rng"])
    began = time.perf_counter() - before
    net.train()
    done = saved = first - 1
    # the generators' states before the draws of the step under way: a run stopped within it does it again
    step_start: tuple[Any, torch.Tensor] | None = None

    def save_all(step: int) -> None:
        nonlocal saved
        with interrupts_deferred():  # the checkpoint, the snapshot and the history of one step, whole
            if save is not None:
                save(step, time.perf_counter() - began, opt, history)
            write_json(out / "history.json", history)
            saved = step  # within: a Ctrl-C held by the save is raised after it, not saved again

    recent_draws: collections.deque[Draw] = collections.deque(maxlen=REFERENCE_STEPS)  # for the reference
    # the weights (not the biases): when none of them gets a gradient, every hidden ReLU is off for every input
    weights = [p for p in net.parameters() if p.ndim >= 2]
    learning, block = False, 0  # whether a weight got a gradient in the block under way, and its steps so far
    logger.info(
        "the loss of each step is on a pair drawn afresh: a block's mean moves with its draws%s",
        f"; each line compares its last steps ({REFERENCE_STEPS} at most) with the untrained start on the same draws"
        if initial is not None
        else "",
    )
    bar = tqdm(
        range(first, cfg.steps + 1), desc=desc, unit="step", initial=first - 1, total=cfg.steps, disable=not progress
    )
    try:
        with sigint_as_keyboard_interrupt(), logging_redirect_tqdm() if progress else contextlib.nullcontext():
            for step in bar:
                step_start = (rng.bit_generator.state, torch.get_rng_state())
                scene, frames, centres, anywhere = draw_step(scenes, rendered, cfg, rng)
                recent_draws.append((scene, frames, centres, anywhere))
                loss = step_loss(net, scene, frames, centres, cfg, anywhere)
                opt.zero_grad()
                loss.backward()
                learning = learning or any(p.grad is not None and bool(p.grad.any()) for p in weights)
                block += 1
                torch.nn.utils.clip_grad_norm_(net.parameters(), 5.0)
                # a Ctrl-C between the update and its entry would save the step's weights as those of the step before
                with interrupts_deferred():
                    opt.step()
                    history.append({"step": step, "scene": scene.name, "loss": loss.item()})
                    done, step_start = step, None
                recent = [h["loss"] for h in history[-cfg.save_every :]]
                mean = float(np.mean(recent))
                bar.set_postfix_str(f"mean loss {mean:.3f}")
                if step % cfg.save_every == 0 or step == cfg.steps:
                    reference = "" if initial is None else _reference(initial, step_loss, history, recent_draws, cfg)
                    logger.info(
                        "step %d: mean loss %.4f over the last %d steps, %.0f s%s",
                        step,
                        mean,
                        len(recent),
                        time.perf_counter() - began,
                        reference,
                    )
                    if weights and not learning:
                        logger.warning(_DEAD, block, cfg.lr)
                    learning, block = False, 0
                    save_all(step)
    except KeyboardInterrupt as exc:
        bar.close()
        if step_start is not None:
            rng.bit_generator.state, _ = step_start
            torch.set_rng_state(step_start[1])
        if done > saved:
            save_all(done)
        logger.warning("interrupted at step %d of %d", done, cfg.steps)
        raise TrainingInterrupted(done, checkpoint=save is not None) from exc
    seconds = time.perf_counter() - began
    logger.info("trained %d steps in %.0f s", cfg.steps, seconds)
    net.eval()
    return seconds
