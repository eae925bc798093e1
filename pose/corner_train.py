"""Training of the corner detector (torch) and its export to ONNX: ``alcn pose train-corners``."""

from __future__ import annotations

import logging
import time
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv.errors import InputError
from pose.corner_data import CornerDataset, build_dataset, crop_windows
from pose.corners import FORMAT_NAME, FORMAT_VERSION, NUM_CORNERS, PAD, STRIDE, WINDOW

logger = logging.getLogger(__name__)


def export_onnx(net, out: str | Path, meta: dict[str, Any]) -> Path:
    """Write the dense corner network as ONNX with ``meta`` in its ``metadata_props`` (atomically).

    Graph: input ``"image"`` ``(1, 1, H, W)`` float32 (the normalized, downscaled frame padded
    by 16 pixels on every side), output ``"logits"`` ``(1, 9, (H-32)//4+1, (W-32)//4+1)``.
    """
    import io as _io
    import warnings

    import torch

    from alcn_cv.io import atomic_write
    from alcn_cv.train.export import OPSET, _with_metadata

    class _Dense(torch.nn.Module):
        def __init__(self, det) -> None:
            super().__init__()
            self.det = det

        def forward(self, image: torch.Tensor) -> torch.Tensor:
            return self.det.classifier(self.det.features(image))

    out = Path(out)
    if out.suffix != ".onnx":
        raise InputError(f"the ONNX output must end in .onnx, got {out}")
    buffer = _io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # see alcn_cv.train.export
        torch.onnx.export(_Dense(net.eval()), (torch.rand(1, 1, WINDOW + 12, WINDOW + 20),), buffer,
                          input_names=["image"], output_names=["logits"],
                          dynamic_axes={"image": {2: "height", 3: "width"}, "logits": {2: "gh", 3: "gw"}},
                          opset_version=OPSET, dynamo=False)
    data = _with_metadata(buffer.getvalue(), meta)
    out.parent.mkdir(parents=True, exist_ok=True)
    atomic_write(out, data)
    logger.info("corner detector written to %s (%d kB)", out, len(data) // 1024)
    return out


def mine_hard_negatives(net, data: CornerDataset, per_frame: int = 100, neg_radius: float = 5.0) -> int:
    """Add to ``data`` the background windows the network ``net`` scores highest as a corner.

    The network runs densely on every training frame; grid points farther than ``neg_radius``
    (downscaled pixels) from the frame's visible corners, whose background score is below 0.5,
    are false positives: the ``per_frame`` worst of each frame become background windows
    (hard-negative mining). Returns how many were added.
    """
    import torch

    added = 0
    offset = WINDOW / 2 - 0.5 - PAD
    for f, (normed, suv) in enumerate(zip(data.normalized, data.visible)):
        padded = cv2.copyMakeBorder(normed, PAD, PAD, PAD, PAD, cv2.BORDER_REFLECT_101)
        with torch.no_grad():
            p0 = torch.softmax(net.dense(torch.from_numpy(padded)[None, None]), 1)[0, 0].numpy()
        gy, gx = np.mgrid[: p0.shape[0], : p0.shape[1]]
        centers = np.stack([gx.ravel(), gy.ravel()], 1) * STRIDE + offset
        far = np.ones(len(centers), bool) if not len(suv) else (
            np.linalg.norm(centers[:, None] - suv[None], axis=2).min(1) > neg_radius)
        bad = np.flatnonzero(far & (p0.ravel() < 0.5))
        bad = bad[np.argsort(p0.ravel()[bad])[:per_frame]]
        if len(bad):
            data.add_negatives(crop_windows(normed, centers[bad], WINDOW), centers[bad], np.full(len(bad), f, np.int64))
            added += len(bad)
    logger.info("hard-negative mining: %d false positives added", added)
    return added


def train_corners(sequence_dir: str | Path, corners: np.ndarray, out: str | Path, *, normalizer: str = "none",
                  units: str = "mm", obj_id: int | None = None, scale: float = 0.5,
                  channels: tuple[int, int] = (32, 64), hidden: int = 128, epochs: int = 6, rounds: int = 2,
                  mined_per_frame: int = 100, batch_size: int = 128, lr: float = 2e-3, seed: int = 0,
                  progress: bool = True, **dataset_kw: Any) -> Path:
    """Train the corner detector on a registered sequence and export it to ``out`` (``.onnx``).

    Args:
        sequence_dir: a registered training sequence (anything :func:`pose.sequence.load_sequence`
            reads; the BOP ``mask_visib`` is used when present).
        corners: ``(8, 3)`` box corners in the object (world) frame, in ``units``.
        out: the ``.onnx`` file to write.
        normalizer: the normalizer applied first (stored in the file; tracking uses the same).
        scale: downscaling of the frames (stored in the file).
        channels, hidden: widths of the detector's convolutions and fully connected layer.
        epochs: epochs per round.
        rounds: training rounds; before each round after the first, the false positives of
            the network on the training frames are added (:func:`mine_hard_negatives`,
            ``mined_per_frame`` per frame).
        batch_size, lr, seed: see :func:`alcn_cv.train.stage2.train_detector`.
        **dataset_kw: see :func:`build_dataset`.

    Returns:
        The written path.
    """
    import torch

    from alcn_cv.nets.detector import Detector
    from alcn_cv.train.stage2 import evaluate_detector, train_detector
    from pose.sequence import load_sequence

    corners = np.asarray(corners, np.float64)
    if corners.shape != (NUM_CORNERS, 3) or not np.isfinite(corners).all():
        raise InputError(f"corners must be a finite (8, 3) array, got shape {corners.shape}")
    if not 0 < scale <= 2:
        raise InputError(f"scale must be in (0, 2], got {scale}")
    t0 = time.perf_counter()
    seq = load_sequence(sequence_dir, obj_id=obj_id)
    data = build_dataset(seq, corners, normalizer, scale=scale, seed=seed, **dataset_kw)
    t1 = time.perf_counter()
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        net = Detector(NUM_CORNERS + 1, channels=channels, hidden=hidden)
    for r in range(rounds):
        if r:
            mine_hard_negatives(net, data, mined_per_frame, dataset_kw.get("neg_radius", 5.0))
        net = train_detector(data.windows, data.labels, NUM_CORNERS + 1, epochs=epochs, batch_size=batch_size,
                             lr=lr, seed=seed + r, progress=progress, net=net)
    loss, acc = evaluate_detector(net, data.windows, data.labels)
    meta = {"format": FORMAT_NAME, "version": FORMAT_VERSION, "normalizer": normalizer, "scale": scale,
            "input_mean": data.input_mean, "input_std": data.input_std,
            "corners": corners.tolist(), "units": units, "window": WINDOW, "stride": STRIDE, "pad": PAD,
            "config": net.config, "source": str(sequence_dir),
            "fit": {"windows": len(data.labels), "corner_windows": int((data.labels > 0).sum()),
                    "epochs": epochs, "rounds": rounds, "seed": seed, "train_loss": loss, "train_accuracy": acc}}
    path = export_onnx(net, out, meta)
    logger.info("corner detector (%s): %d windows in %.1f s, training %.1f s, train accuracy %.3f", normalizer,
                len(data.labels), t1 - t0, time.perf_counter() - t1, acc)
    return path


def main(sequence_dir: str | Path, out: str | Path, *, box_ply: str | Path | None = None,
         model: str | Path | None = None, **kwargs: Any) -> Path:
    """``alcn pose train-corners``: the box corners from ``box_ply`` (a cuboid mesh, mm) or a part
    model (``model``, its units), then :func:`train_corners`."""
    from pose import model as part_model

    if (box_ply is None) == (model is None):
        raise InputError("give the box as either box_ply (a .ply cuboid) or model (a part model .npz)")
    if box_ply is not None:
        corners, units = part_model.read_box_corners(box_ply), "mm"
    else:
        pm = part_model.load(model)
        corners, units = pm.corners, pm.units
    return train_corners(sequence_dir, corners, out, units=units, **kwargs)
