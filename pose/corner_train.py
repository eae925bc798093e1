"""Training of the corner detector (torch) and its export to ONNX: ``alcn pose train-corners``.

The recipe is one :class:`CornerRecipe`, recorded whole in the ONNX file's metadata; :data:`CONFS`
names the shipped ones (``box``: the box of ``alcn pose train-corners`` and ``alcn pose eval``;
``planar``: a planar target from one image, ``alcn pose planar``). The network
(:class:`pose.corner_net.CornerNet`) is trained densely on crops of ``cells x cells`` output cells
of the labelled frames of :mod:`pose.corner_data`: the cross-entropy of the cells' labels (part
cells weighted by ``corner_weight``, the cells between ``pos_radius`` and ``neg_radius`` of a part
ignored) plus the smooth L1 loss of the offsets. Measurements behind the recipe: ``docs/journal.md``.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from tqdm import tqdm

from alcn_cv import report
from alcn_cv.enhance.alcn import pin_default_model
from alcn_cv.errors import InputError
from alcn_cv.io import atomic_write, check_no_earlier_output, output_path, with_suffix
from pose.box import NUM_CORNERS, box_parts
from pose.corner_data import CornerFrames, build_frames, build_image_frames
from pose.corners import FORMAT_NAME, FORMAT_VERSION, PAD, STRIDE, WINDOW

if TYPE_CHECKING:
    import torch

    from pose.corner_net import CornerNet

logger = logging.getLogger(__name__)

__all__ = [
    "CornerRecipe",
    "CONFS",
    "CONF_SUMMARIES",
    "corner_loss",
    "export_onnx",
    "fit",
    "fit_and_export",
    "jitter_crops",
    "main",
    "sample_crops",
    "train_corners",
    "train_image_corners",
]


@dataclass
class CornerRecipe:
    """The corner detector's training recipe; the defaults are the ``box`` preset.

    Frames (:func:`pose.corner_data.build_frames`, :func:`~pose.corner_data.build_image_frames`):
        scale: downscaling of the frames before normalization and detection (0.75: a 32x32
            window is 43 pixels of a 640x480 frame).
        divisions: the box's parts, :func:`pose.box.box_parts` ``(corners, divisions)`` (2: the
            corners, the edges' middles and the faces' centres; 1: the 8 corners).
        copies: augmented copies of each view (homography, background, intensity), besides the view.
        novel_views: share of the copies first seen from a nearby viewpoint (:func:`pose.corner_data.novel_view`).
        novel_distance: ``[low, high]`` their camera distance, a factor of their view's (below 1:
            test views come nearer than the training views).
        backgrounds: share of the copies with a new background (where the view has a mask).
        intensity_scale, intensity_offset, noise: the copies' intensity change ``a I + b`` and noise
            (``[1, 1]`` and 0: the views' own intensities, the normalization the only invariance).
        pos_radius, neg_radius: part cells within ``pos_radius`` (downscaled pixels), the cells up
            to ``neg_radius`` ignored (:func:`pose.corner_data.label_grid`).
    Network (:class:`pose.corner_net.CornerNet`): ``channels``, ``hidden``, ``mixing``.
    Training (:func:`fit`):
        iterations, batch_size: Adam steps and crops per step (the rate divided by 10 for the last quarter).
        cells: the crops' side in output cells; ``lr``: Adam's learning rate.
        jitter: jitter each crop after the normalization (:func:`jitter_crops`).
        corner_weight, offset_weight: see :func:`corner_loss`.
    """

    scale: float = 0.75
    divisions: int = 2
    copies: int = 11
    novel_views: float = 0.6
    novel_distance: list[float] = dataclasses.field(default_factory=lambda: [0.7, 1.2])
    backgrounds: float = 0.8
    intensity_scale: list[float] = dataclasses.field(default_factory=lambda: [0.4, 1.6])
    intensity_offset: float = 0.2
    noise: float = 0.03
    pos_radius: float = 4.0
    neg_radius: float = 7.0
    channels: list[int] = dataclasses.field(default_factory=lambda: [16, 32])
    hidden: int = 128
    mixing: int = 1
    iterations: int = 4000
    batch_size: int = 64
    cells: int = 12
    lr: float = 3e-3
    jitter: bool = False
    corner_weight: float = 2.0
    offset_weight: float = 1.0

    def check(self) -> None:
        """Raise :class:`~alcn_cv.errors.InputError` naming the first impossible value."""
        lo, hi = self.novel_distance if len(self.novel_distance) == 2 else (0, -1)
        problems = {
            "scale": 0 < self.scale <= 2,
            "novel_views": 0 <= self.novel_views <= 1,
            "novel_distance": 0 < lo <= hi,
            "backgrounds": 0 <= self.backgrounds <= 1,
            "noise": self.noise >= 0,
            "pos_radius": 0 < self.pos_radius <= self.neg_radius,
            "intensity_scale": len(self.intensity_scale) == 2 and min(self.intensity_scale) > 0,
            "channels": len(self.channels) == 2 and min(self.channels) > 0,
            "hidden": self.hidden >= 1,
            "mixing": self.mixing >= 0,
            "divisions": self.divisions >= 1,
            "iterations": self.iterations >= 1,
            "batch_size": self.batch_size >= 1,
            "lr": self.lr > 0,
            "cells": self.cells >= 1,
            "copies": self.copies >= 0,
        }
        for key, ok in problems.items():
            if not ok:
                raise InputError(f"corner recipe key {key!r} is impossible: {getattr(self, key)!r}")


#: The shipped recipes: ``box`` (a box from a registered sequence) and ``planar`` (a planar
#: target from one image: more copies, no viewpoint or background changes, frames at half size).
CONFS: dict[str, CornerRecipe] = {
    "box": CornerRecipe(),
    "planar": CornerRecipe(scale=0.5, copies=59, novel_views=0.0, backgrounds=0.0),
}

#: One line per preset of :data:`CONFS`, for the ``--help`` of the commands that train the corner detector.
CONF_SUMMARIES: dict[str, str] = {
    "box": "a box from a registered sequence: its views and augmented copies (nearby viewpoints, new backgrounds, "
    "intensity changes)",
    "planar": "a planar target from one image: more copies, no viewpoint or background changes, frames at half size",
}


def export_onnx(net: CornerNet, out: str | Path, meta: dict[str, Any]) -> Path:
    """Write the corner network as ONNX with ``meta`` in its ``metadata_props`` (atomically).

    Graph: input ``"image"`` ``(1, 1, H, W)`` float32 (the normalized, downscaled frame padded
    by 16 pixels on every side), output ``"outputs"`` ``(1, 3n + 1, (H-32)//4+1, (W-32)//4+1)`` for the
    ``n`` parts of ``net`` (:meth:`pose.corners.CornerDetector.outputs`).
    """
    import io as _io
    import warnings

    import torch

    from alcn_cv.train.export import OPSET, with_metadata

    out = with_suffix(out, ".onnx", "a corner detector")
    buffer = _io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # see alcn_cv.train.export
        torch.onnx.export(
            net.eval(),
            (torch.rand(1, 1, WINDOW + 12, WINDOW + 20),),
            buffer,
            input_names=["image"],
            output_names=["outputs"],
            dynamic_axes={"image": {2: "height", 3: "width"}, "outputs": {2: "gh", 3: "gw"}},
            opset_version=OPSET,
            dynamo=False,
        )
    data = with_metadata(buffer.getvalue(), meta)
    atomic_write(out, data)  # its folder made when missing
    logger.info("corner detector written to %s (%d kB)", out, len(data) // 1024)
    return out


def sample_crops(
    frames: CornerFrames, rng: np.random.Generator, n: int, cells: int, near_corner: float = 0.7
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``n`` random crops of ``cells x cells`` output cells: images ``(n, 1, S, S)`` with
    ``S = 32 + 4 (cells - 1)``, labels ``(n, cells, cells)``, offsets ``(n, 2, cells, cells)`` and
    owners ``(n, cells, cells)``; a share ``near_corner`` of them contains a visible corner cell."""
    size = WINDOW + STRIDE * (cells - 1)
    _, gh, gw = frames.labels.shape
    if gh < cells or gw < cells:
        raise InputError(f"frames of {gh}x{gw} output cells are smaller than the crops ({cells}x{cells})")
    images = np.empty((n, 1, size, size), np.float32)
    labels = np.empty((n, cells, cells), np.int64)
    offsets = np.empty((n, 2, cells, cells), np.float32)
    owner = np.empty((n, cells, cells), np.int64)
    for b in range(n):
        f = int(rng.integers(len(frames.labels)))
        hits = np.argwhere(frames.labels[f] > 0)
        if len(hits) and rng.random() < near_corner:
            ci, cj = hits[rng.integers(len(hits))]
            i0 = int(np.clip(ci - rng.integers(cells), 0, gh - cells))
            j0 = int(np.clip(cj - rng.integers(cells), 0, gw - cells))
        else:
            i0, j0 = int(rng.integers(gh - cells + 1)), int(rng.integers(gw - cells + 1))
        images[b, 0] = frames.images[f, i0 * STRIDE : i0 * STRIDE + size, j0 * STRIDE : j0 * STRIDE + size]
        labels[b] = frames.labels[f, i0 : i0 + cells, j0 : j0 + cells]
        offsets[b] = frames.offsets[f, :, i0 : i0 + cells, j0 : j0 + cells]
        owner[b] = frames.owner[f, i0 : i0 + cells, j0 : j0 + cells]
    return images, labels, offsets, owner


def jitter_crops(
    images: np.ndarray,
    rng: np.random.Generator,
    *,
    contrast: float = 1.5,
    ramp: float = 0.4,
    offset: float = 0.3,
    noise: float = 0.15,
) -> np.ndarray:
    """Jitter the network's input after the normalization, in place: each crop ``x`` of ``images``
    ``(n, 1, S, S)`` float32 (standardized, as :func:`sample_crops` returns them) becomes
    ``exp(log a + gx u + gy v) x + b + n``, ``u, v`` in [-1, 1] across the crop: a contrast ``a``
    log-uniform in ``[1 / contrast, contrast]``, a gain ramp (``gx, gy`` uniform in ``+-ramp``), an
    offset ``b`` uniform in ``+-offset`` and Gaussian noise of a standard deviation uniform in
    ``[0, noise]``. The copies' intensity change ``a I + b`` gives the network without normalization
    this variety back where a normalization in front took it away."""
    size = images.shape[-1]
    u = np.linspace(-1, 1, size, dtype=np.float32)
    for b in range(len(images)):
        log_a = rng.uniform(-np.log(contrast), np.log(contrast))
        gx, gy = rng.uniform(-ramp, ramp, 2)
        gain = np.exp(log_a + gx * u[None, :] + gy * u[:, None]).astype(np.float32)
        images[b, 0] = (
            gain * images[b, 0]
            + rng.uniform(-offset, offset)
            + rng.normal(0, rng.uniform(0, noise), (size, size)).astype(np.float32)
        )
    return images


def corner_loss(
    out: torch.Tensor,
    labels: torch.Tensor,
    offsets: torch.Tensor,
    owner: torch.Tensor,
    corner_weight: float,
    offset_weight: float,
) -> torch.Tensor:
    """Cross-entropy of the cells (``-1`` ignored, part classes weighted by ``corner_weight``)
    plus ``offset_weight`` times the smooth L1 loss of the offsets of the owned cells; torch tensors
    as :func:`sample_crops` returns them and the network's ``(b, 3n + 1, cells, cells)`` output."""
    import torch
    import torch.nn.functional as F

    num_parts = (out.shape[1] - 1) // 3
    k = num_parts + 1
    weight = torch.full((k,), corner_weight, dtype=out.dtype, device=out.device)
    weight[0] = 1.0
    loss = F.cross_entropy(out[:, :k], labels, weight=weight, ignore_index=-1)
    own = owner >= 0
    if own.any():
        pred = out[:, k:].reshape(out.shape[0], num_parts, 2, *out.shape[2:])  # (b, n, 2, c, c)
        b, i, j = torch.nonzero(own, as_tuple=True)
        chosen = pred[b, owner[b, i, j], :, i, j]  # (m, 2)
        loss = loss + offset_weight * F.smooth_l1_loss(chosen, offsets[b, :, i, j], beta=0.1)
    return loss


def fit(
    net: CornerNet,
    frames: CornerFrames,
    recipe: CornerRecipe,
    *,
    seed: int = 0,
    progress: bool = True,
    device: str | None = None,
) -> dict[str, Any]:
    """Train ``net`` on crops of ``frames`` by ``recipe``'s training keys on ``device`` (a torch
    device; ``None``: CUDA where torch sees it, else the CPU), then leave it on the CPU.

    Returns:
        ``first_loss`` (mean of the first 10 steps), ``final_loss`` (of the last quarter, at most
        100 steps) and ``device``. Deterministic for a ``seed`` and a number of CPU threads.
    """
    import torch

    from alcn_cv.nets.device import torch_device

    device = torch_device(device, "the corner network's device")
    net.to(device)
    rng = np.random.default_rng(seed)
    jitter_rng = np.random.default_rng(seed + 1000)  # its own stream: the crops drawn do not depend on ``jitter``
    cells = min(recipe.cells, *frames.labels.shape[1:])
    optimiser = torch.optim.Adam(net.parameters(), lr=recipe.lr)
    schedule = torch.optim.lr_scheduler.MultiStepLR(optimiser, [int(0.75 * recipe.iterations)], 0.1)
    net.train()
    losses = []
    for _ in tqdm(range(recipe.iterations), desc="corners", unit="step", disable=not progress, leave=False):
        crops = sample_crops(frames, rng, recipe.batch_size, cells)
        if recipe.jitter:
            jitter_crops(crops[0], jitter_rng)
        images, labels, offsets, owner = (torch.from_numpy(a).to(device) for a in crops)
        loss = corner_loss(net(images), labels, offsets, owner, recipe.corner_weight, recipe.offset_weight)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        schedule.step()
        losses.append(loss.item())
    net.to("cpu").eval()
    return {
        "first_loss": float(np.mean(losses[:10])),
        "final_loss": float(np.mean(losses[-max(1, min(100, recipe.iterations // 4)) :])),
        "device": str(device),
    }


def train_corners(
    sequence_dir: str | Path,
    corners: np.ndarray,
    out: str | Path,
    recipe: CornerRecipe | None = None,
    *,
    normalization: str = "none",
    units: str = "mm",
    obj_id: int | None = None,
    seed: int = 0,
    device: str | None = None,
    conf: str | None = None,
    command: str = "",
    progress: bool = True,
) -> Path:
    """Train the corner detector of a box on a registered sequence and export it to ``out`` (``.onnx``).

    Args:
        sequence_dir: a registered training sequence (anything :func:`pose.sequence.load_sequence`
            reads; the BOP ``mask_visib`` is used when present).
        corners: ``(8, 3)`` box corners in the object (world) frame, in ``units``.
        out: the ``.onnx`` file to write.
        recipe: the recipe (default: ``CONFS["box"]``); ``conf``: its preset's name, recorded with it, and
            ``command``, the command line that makes it again (:func:`alcn_cv.report.provenance`).
        normalization: the normalization spec applied first (stored in the file; tracking uses the same).
        seed, device: of the frames and :func:`fit`.

    Returns:
        The written path.

    Raises:
        InputError: a sequence registered in arbitrary units (:func:`pose.sequence.check_known_units`), before the
            training.
    """
    from pose import model as part_model
    from pose.sequence import check_known_units, load_sequence

    recipe = recipe or CONFS["box"]
    recipe.check()
    output_path(out, ".onnx", "a corner detector")  # before the training, not after it
    corners = np.asarray(corners, np.float64)
    if corners.shape != (NUM_CORNERS, 3) or not np.isfinite(corners).all():
        raise InputError(f"corners must be a finite (8, 3) array, got shape {corners.shape}")
    t0 = time.perf_counter()
    seq = load_sequence(sequence_dir, obj_id=obj_id)
    check_known_units(seq, "a corner detector (its box projected by the poses)")
    # the box is projected by the poses: in their units (a registered sequence's are known, checked above; other
    # units are an error of unit_scale's)
    corners, units = corners * part_model.unit_scale(units, seq.units), seq.units
    frames = build_frames(seq, corners, normalization, recipe, seed=seed)
    provenance = {"source": str(sequence_dir), "views": len(seq.views), "data_seconds": time.perf_counter() - t0}
    return fit_and_export(
        frames,
        box_parts(corners, recipe.divisions),
        corners,
        out,
        recipe,
        normalization=normalization,
        units=units,
        provenance=provenance,
        seed=seed,
        device=device,
        conf=conf,
        command=command,
        progress=progress,
    )


def fit_and_export(
    frames: CornerFrames,
    parts: np.ndarray,
    corners: np.ndarray,
    out: str | Path,
    recipe: CornerRecipe,
    *,
    normalization: str,
    units: str,
    provenance: dict[str, Any],
    seed: int = 0,
    device: str | None = None,
    conf: str | None = None,
    command: str = "",
    progress: bool = True,
) -> Path:
    """Train a :class:`pose.corner_net.CornerNet` for ``parts (n, 3)`` on ``frames`` (:func:`fit`)
    and export it (:func:`export_onnx`) with its metadata: the whole ``recipe``, how it was made (``command``,
    ``conf``, the machine and the date: :func:`alcn_cv.report.provenance`), the normalization, ``corners (8, 3)`` in
    ``units`` and ``provenance`` (``source``, ``views``, ``data_seconds``) with the fit's record."""
    import torch

    from pose.corner_net import CornerNet

    t1 = time.perf_counter()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = CornerNet(len(parts), tuple(recipe.channels), recipe.hidden, recipe.mixing)
        fit_info = fit(net, frames, recipe, seed=seed, progress=progress, device=device)
    meta = {
        "format": FORMAT_NAME,
        "version": FORMAT_VERSION,
        "normalization": pin_default_model(normalization),
        "scale": recipe.scale,
        "input_mean": frames.input_mean,
        "input_std": frames.input_std,
        "parts": np.asarray(parts, np.float64).tolist(),
        "corners": np.asarray(corners, np.float64).tolist(),
        "units": units,
        "window": WINDOW,
        "stride": STRIDE,
        "pad": PAD,
        "config": net.config,
        "source": provenance.get("source", ""),
        **report.provenance(command, conf),
        "recipe": dataclasses.asdict(recipe),
        "fit": {
            "frames": len(frames.labels),
            "views": provenance.get("views"),
            "seed": seed,
            "data_seconds": provenance.get("data_seconds"),
            "train_seconds": time.perf_counter() - t1,
            **fit_info,
        },
    }
    path = export_onnx(net, out, meta)
    logger.info(
        "corner detector (%s): %d frames, training %.1f s on %s, final loss %.3f",
        normalization,
        len(frames.labels),
        time.perf_counter() - t1,
        fit_info["device"],
        fit_info["final_loss"],
    )
    return path


def train_image_corners(
    gray: np.ndarray,
    uv: np.ndarray,
    parts: np.ndarray,
    corners: np.ndarray,
    out: str | Path,
    recipe: CornerRecipe | None = None,
    *,
    normalization: str = "none",
    units: str = "mm",
    source: str = "",
    seed: int = 0,
    conf: str | None = None,
    progress: bool = True,
) -> Path:
    """Train the detector of the parts of one image (a planar target's, :mod:`pose.planar`) and export it.

    Args:
        gray: the training image, uint8 ``(H, W)``.
        uv: ``(n, 2)`` the parts' pixels in it; ``parts``: ``(n, 3)`` the same in the object frame (``units``).
        corners: ``(8, 3)`` the object's box (the pose solver's outline; a flat one for a plane).
        out: the ``.onnx`` file to write.
        recipe: the recipe (default: ``CONFS["planar"]``; ``divisions`` and the viewpoint keys unused).
        normalization, seed, conf: as :func:`train_corners`'s.
    """
    recipe = recipe or CONFS["planar"]
    recipe.check()
    parts = np.asarray(parts, np.float64)
    if parts.ndim != 2 or parts.shape != (len(uv), 3) or not np.isfinite(parts).all():
        raise InputError(f"parts must be a finite (n, 3) array for the n = {len(uv)} pixels, got shape {parts.shape}")
    t0 = time.perf_counter()
    frames = build_image_frames(gray, uv, normalization, recipe, seed=seed)
    provenance = {"source": source, "views": 1, "data_seconds": time.perf_counter() - t0}
    return fit_and_export(
        frames,
        parts,
        corners,
        out,
        recipe,
        normalization=normalization,
        units=units,
        provenance=provenance,
        seed=seed,
        conf=conf,
        progress=progress,
    )


def main(
    sequence_dir: str | Path,
    out: str | Path,
    recipe: CornerRecipe | None = None,
    *,
    box_ply: str | Path | None = None,
    model: str | Path | None = None,
    overwrite: bool = False,
    **kwargs: Any,
) -> Path:
    """``alcn pose train-corners``: the box corners from ``box_ply`` (a cuboid mesh, mm) or a part
    model (``model``, its units), then :func:`train_corners` (``kwargs``: its keywords).

    Args:
        overwrite: replace a corner detector of an earlier run at ``out``.

    Raises:
        InputError: the box given twice or not at all, or a file at ``out`` without ``overwrite`` (before the
            training); and :func:`train_corners`'s.
    """
    from pose import model as part_model

    if (box_ply is None) == (model is None):
        raise InputError("give the box as either box_ply (a .ply cuboid) or model (a part model .npz)")
    # the kind of file first: an existing folder is no detector that --overwrite would replace
    check_no_earlier_output([output_path(out, ".onnx", "a corner detector")], overwrite)
    if box_ply is not None:
        corners, units = part_model.read_box_corners(box_ply), "mm"
    else:
        pm = part_model.load(model)
        corners, units = pm.corners, pm.units
    return train_corners(sequence_dir, corners, out, recipe, units=units, **kwargs)
