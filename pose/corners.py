"""Learned part detector: a CNN that finds the 8 box corners in normalized images.

The Box experiment of Rad, Roth & Lepetit (BMVC 2017, Sec. 4.4) detects the corners of a box
with the part-based method of Crivellaro et al. ("A Novel Representation of Parts for Accurate
3D Object Detection and Tracking in Monocular Images", ICCV 2015) after contrast normalization.
This module is that detector, kept small:

* **Training data** (:func:`build_dataset`): every frame of a registered training sequence is
  downscaled by ``scale`` and normalized (the normalizer at the downscaled resolution, so a
  32x32 window sees 32/``scale`` input pixels around a corner). The box corners are projected
  with the known poses; a corner is *visible* when it is in front of the camera, inside the
  image, on a face turned towards the camera and, where the BOP ``mask_visib`` is there, not
  hidden by clutter. Windows centred within ``pos_radius`` pixels of visible corner ``k`` are
  class ``k + 1``; windows centred farther than ``neg_radius`` from every visible corner
  (on the object and elsewhere) are background (class 0). Besides these crops of the
  normalized frames and of copies of them with the background (outside the BOP
  ``mask_visib``) replaced by random textures, the data engine's simple synthetic augmentation
  (:func:`alcn_cv.data.synthetic.augment`: intensity changes ``a I + b``, noise, small
  rotations and scalings) makes more windows around the same points from the *raw* frame,
  normalized afterwards (:func:`alcn_cv.train.stage2.normalize_windows`), so that the
  detector sees the normalizer's output under other lights.
* **Network**: the paper's :class:`alcn_cv.nets.Detector` (its fully connected layer as a
  convolution) with 9 classes, trained by :func:`alcn_cv.train.stage2.train_detector`.
* **Export** (:func:`export_onnx`): the dense network (``(1, 1, H, W)`` -> ``(1, 9, gh, gw)``
  logits at stride 4) as ONNX, with the corners, units, scale and normalizer in its
  ``metadata_props`` (key ``alcn_cv``), so the ``.onnx`` file is the whole detector.
* **Inference** (:class:`CornerDetector`): ``cv2.dnn`` runs the ONNX model on the padded,
  normalized frame (no torch import), by default also on the frame shifted by half the
  stride, for a score grid of step 2 (``subdivide``); per corner class, the local maxima of
  the softmax score (non-maximum suppression over one stride) above ``min_score`` are kept,
  the ``top_k`` best, each refined to sub-grid precision by the score-weighted centroid of
  its 3x3 neighbourhood. The candidates are the 2D-3D correspondences handed to
  :class:`pose.solver.PoseSolver` (RANSAC, 5000 iterations since few of the candidates are
  right, chooses among them; fewer than ``min_inliers`` consistent corners: the frame is lost).

Measured on the data engine's sequences #1-#8 (no normalization, % correct poses by the 2D
projection metric, 2-core CPU shared with other jobs): the first version (channels 16/32, 4
epochs, score grid step 4, 2 candidates above 0.3 per corner, no new backgrounds) 6.7 0 0 0 0 0
0 0; with new backgrounds 10.0 0 0 26.7 0 0 0 0; plus channels 32/64, 6 epochs and the step-2
grid 26.7 3.3 13.3 33.3 0 3.3 3.3 0; plus 4 candidates above 0.1 per corner and 5000 instead
of 500 RANSAC iterations 40.0 0 20.0 40.0 0 3.3 6.7 0 (3.8 frames per second). Its recall
stays low (40-50% of the visible corners within 5 px on #1, #3, #6): 30 training views are too
few.
"""

from __future__ import annotations

import json
import logging
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv.errors import InputError, WeightFileError
from pose.parts import Correspondences, to_gray

logger = logging.getLogger(__name__)

__all__ = ["CornerDetector", "build_dataset", "corner_visibility", "export_onnx", "main", "normalizer_for",
           "replace_background", "train_corners"]

FORMAT_NAME = "alcn-corner-detector"
FORMAT_VERSION = 1
METADATA_KEY = "alcn_cv"
NUM_CORNERS = 8
# alcn_cv.nets.Detector's input window and output stride (a test checks they agree; importing
# alcn_cv.nets here would import torch, which the tracking path must not need).
WINDOW = 32
STRIDE = 4
PAD = WINDOW // 2


def normalizer_for(spec: str):
    """The normalizer ``spec`` (``NAME[:KEY=VALUE...]``, see :func:`pose.parts.get_normalizer`)
    applied at the detector's (already downscaled) resolution.

    ALCN runs at working scale 1 on the downscaled frame; without a ``backend`` in ``spec``,
    through its torch-free ``cv2.dnn`` backend where its weights have an ONNX twin (the
    paper's model), else ALCN's default backend (the lite model). Every other name is
    ``alcn_cv.create(name, **params)``.
    """
    import alcn_cv
    from alcn_cv.enhance.registry import parse_spec

    name, params = parse_spec(spec)
    if name != "alcn":
        return alcn_cv.create(name, **params)
    params = {"scale": 1.0, **params}
    if "backend" not in params:
        try:
            return alcn_cv.create(name, backend="opencv", **params)
        except WeightFileError as exc:
            logger.info("ALCN through its default backend: %s", exc)
    return alcn_cv.create(name, **params)


def downscale(gray: np.ndarray, scale: float) -> np.ndarray:
    """``gray`` uint8 resized by ``scale`` (area interpolation when shrinking)."""
    if scale == 1.0:
        return gray
    h, w = gray.shape
    size = (max(1, round(w * scale)), max(1, round(h * scale)))
    return cv2.resize(gray, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)


def to_scaled(uv: np.ndarray, scale: float) -> np.ndarray:
    """Pixel coordinates (OpenCV centres) of the full image -> of the image resized by ``scale``."""
    return (np.asarray(uv, np.float64) + 0.5) * scale - 0.5


def from_scaled(uv: np.ndarray, scale: float) -> np.ndarray:
    """Inverse of :func:`to_scaled`."""
    return (np.asarray(uv, np.float64) + 0.5) / scale - 0.5


def corner_visibility(corners: np.ndarray, R: np.ndarray, t: np.ndarray, K: np.ndarray, shape: tuple[int, int],
                      mask: np.ndarray | None = None, mask_tolerance: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Projections of the box corners and which of them are visible.

    Args:
        corners: ``(8, 3)`` corners in the order of :func:`pose.model.box_corners` (corner ``i``
            is at the far end of the x edge when bit 2 of ``i`` is set, y: bit 1, z: bit 0); any
            parallelepiped in that order.
        R, t: object-to-camera pose (``x_cam = R x + t``).
        K: ``(3, 3)`` intrinsics.
        shape: ``(H, W)`` of the image.
        mask: optional ``(H, W)`` visible-object mask (BOP ``mask_visib``); a corner farther
            than ``mask_tolerance`` pixels from it is hidden by something else.

    Returns:
        ``uv (8, 2)`` float64 pixels and ``visible (8,)`` bool: in front of the camera, inside
        the image, on at least one face turned towards the camera, and on the mask.
    """
    corners = np.asarray(corners, np.float64).reshape(NUM_CORNERS, 3)
    R, t = np.asarray(R, np.float64).reshape(3, 3), np.asarray(t, np.float64).reshape(3)
    cam = corners @ R.T + t
    z = np.maximum(cam[:, 2], 1e-9)
    uv = np.stack([K[0, 0] * cam[:, 0] / z + K[0, 2], K[1, 1] * cam[:, 1] / z + K[1, 2]], 1)
    h, w = shape
    visible = (cam[:, 2] > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    # box coordinates of the camera centre: a face is turned towards the camera when the centre
    # lies beyond its plane
    axes = np.stack([corners[4] - corners[0], corners[2] - corners[0], corners[1] - corners[0]], 1)
    a = np.linalg.solve(axes, -R.T @ t - corners[0])
    bits = (np.arange(NUM_CORNERS)[:, None] >> np.array([2, 1, 0])) & 1
    visible &= np.where(bits == 1, a > 1, a < 0).any(1)
    if mask is not None:
        near = cv2.dilate((mask > 0).astype(np.uint8), np.ones((2 * mask_tolerance + 1,) * 2, np.uint8))
        ij = np.clip(np.round(uv).astype(int), 0, [w - 1, h - 1])
        visible &= near[ij[:, 1], ij[:, 0]] > 0
    return uv, visible


def _crops(image: np.ndarray, centers: np.ndarray, size: int) -> np.ndarray:
    """``(n, size, size)`` float32 windows of ``image`` centred on ``centers (n, 2)`` (bilinear)."""
    out = np.empty((len(centers), size, size), np.float32)
    for i, (x, y) in enumerate(centers):
        out[i] = cv2.getRectSubPix(image, (size, size), (float(x), float(y)))
    return out


def _sample_negatives(rng: np.random.Generator, n: int, shape: tuple[int, int], corners_uv: np.ndarray,
                      mask: np.ndarray | None, radius: float) -> np.ndarray:
    """``n`` window centres farther than ``radius`` from every ``corners_uv``; half on ``mask``."""
    h, w = shape
    on = np.argwhere(mask > 0)[:, ::-1].astype(np.float64) if mask is not None and mask.any() else None
    out = []
    for _ in range(20):
        m = 2 * n
        pts = rng.uniform([0, 0], [w - 1, h - 1], (m, 2))
        if on is not None:
            k = m // 2
            pts[:k] = on[rng.integers(len(on), size=k)] + rng.uniform(-0.5, 0.5, (k, 2))
        if len(corners_uv):
            d = np.linalg.norm(pts[:, None] - corners_uv[None], axis=2).min(1)
            pts = pts[d > radius]
        out.append(pts)
        if sum(len(p) for p in out) >= n:
            break
    pts = np.concatenate(out)
    return pts[rng.permutation(len(pts))[:n]]


def _read_mask(path: Path, shape: tuple[int, int]) -> np.ndarray | None:
    if not path.is_file():
        return None
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    return m if m is not None and m.shape == shape else None


def replace_background(gray: np.ndarray, mask: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``gray`` uint8 with the pixels outside ``mask`` (uint8, 255 = object; intermediate
    values blend) replaced by a random texture (:func:`alcn_cv.data.textures.display_texture`,
    gamma-encoded like a photograph)."""
    from alcn_cv.data.textures import display_texture

    texture = display_texture(rng, gray.shape, gray=True)
    alpha = mask.astype(np.float32) / np.float32(255)
    out = alpha * gray.astype(np.float32) + (1 - alpha) * np.float32(255) * texture
    return np.clip(out + 0.5, 0, 255).astype(np.uint8)


@dataclass
class CornerDataset:
    """Training windows of the corner detector.

    Attributes:
        windows: ``(n, 32, 32)`` float32 normalized windows, standardized by
            ``(x - input_mean) / input_std`` (constants over the training frames).
        labels: ``(n,)`` int64; 0 background, ``k + 1`` corner ``k``.
        centers: ``(n, 2)`` float64 window centres, pixels of the downscaled frame.
        frames: ``(n,)`` int64 index into :attr:`normalized` of the frame each window comes
            from (a training view or one of its copies with a new background).
        augmented: ``(n,)`` bool: made by :func:`alcn_cv.data.synthetic.augment`.
        normalized: per frame (each training view, then its copies with new backgrounds), the
            downscaled normalized frame ``(h, w)`` float32, standardized like the windows.
        visible: per frame, ``(m, 2)`` downscaled pixels of its visible corners.
    """

    windows: np.ndarray
    labels: np.ndarray
    centers: np.ndarray
    frames: np.ndarray
    augmented: np.ndarray
    normalized: list[np.ndarray]
    visible: list[np.ndarray]
    input_mean: float
    input_std: float

    def add_negatives(self, windows: np.ndarray, centers: np.ndarray, frames: np.ndarray) -> None:
        """Append background windows (e.g. mined hard negatives)."""
        self.windows = np.concatenate([self.windows, windows])
        self.labels = np.concatenate([self.labels, np.zeros(len(windows), np.int64)])
        self.centers = np.concatenate([self.centers, centers])
        self.frames = np.concatenate([self.frames, frames])
        self.augmented = np.concatenate([self.augmented, np.zeros(len(windows), bool)])


def build_dataset(sequence, corners: np.ndarray, normalizer: str = "none", *, scale: float = 0.5,
                  jitter: int = 6, pos_radius: float = 1.0, neg_radius: float = 5.0, negatives_per_frame: int = 200,
                  augment_per_corner: int = 16, backgrounds: int = 2, seed: int = 0) -> CornerDataset:
    """Corner windows from a registered training sequence (:func:`pose.build.load_sequence`).

    Args:
        sequence: a :class:`pose.build.Sequence` with poses (world = object frame).
        corners: ``(8, 3)`` box corners in the object frame (:func:`pose.model.box_corners` order).
        normalizer: a name for :func:`normalizer_for`.
        scale: downscaling of the frames before normalization and detection.
        jitter: positive windows per visible corner, centred within ``pos_radius`` (downscaled
            pixels) of it.
        pos_radius, neg_radius: see the module docstring (downscaled pixels).
        negatives_per_frame: background windows per frame, half of them on the object's mask
            when there is one.
        augment_per_corner: synthetic windows (:func:`alcn_cv.data.synthetic.augment`) per
            visible corner, and as many background ones per frame.
        backgrounds: where the view has a ``mask_visib``, this many copies of it with the
            background replaced (:func:`replace_background`) give windows too: half of a
            corner's window is background, which the 30 views of a training sequence show
            in few variations.
        seed: random seed.

    Raises:
        InputError: no training view with a visible corner, or an unregistered sequence.
    """
    from alcn_cv import io
    from alcn_cv.data.synthetic import augment
    from alcn_cv.train.stage2 import normalize_windows

    if not sequence.registered:
        raise InputError("the training sequence must be registered (a pose for every image)")
    norm = normalizer_for(normalizer)
    rng = np.random.default_rng(seed)
    parts: dict[str, list] = {k: [] for k in ("windows", "labels", "centers", "frames", "augmented")}

    def add(windows, labels, centers, frame, augmented):
        parts["windows"].append(windows)
        parts["labels"].append(np.asarray(labels, np.int64))
        parts["centers"].append(np.asarray(centers, np.float64).reshape(-1, 2))
        parts["frames"].append(np.full(len(windows), frame, np.int64))
        parts["augmented"].append(np.full(len(windows), augmented, bool))

    normalized_frames, visible_corners = [], []
    mask_dir = sequence.image_dir.parent / "mask_visib"
    aug_kw = {"extent": None, "replace_background": 0.0, "intensity_scale": (0.4, 1.6), "intensity_offset": 0.2,
              "noise": 0.03, "max_shift": pos_radius, "max_rotation_deg": 25.0, "max_scale_change": 0.2}
    for view in sequence.views:
        gray = to_gray(io.read_image(sequence.image_dir / view.name))
        mask = _read_mask(mask_dir / f"{Path(view.name).stem}_000000.png", gray.shape)
        uv, vis = corner_visibility(corners, view.R_w2c, view.t_w2c, view.K, gray.shape, mask)
        small = downscale(gray, scale)
        small_mask = None if mask is None else downscale(mask, scale)
        suv = to_scaled(uv[vis], scale)
        labels = np.flatnonzero(vis) + 1
        variants = [small] + ([] if small_mask is None else
                              [replace_background(small, small_mask, rng) for _ in range(backgrounds)])
        for image in variants:
            f = len(normalized_frames)  # this frame's index in `normalized` and `visible`
            normed = norm.normalize(image.astype(np.float32) / np.float32(255))
            normalized_frames.append(normed)
            visible_corners.append(suv)
            if len(suv):
                a = rng.uniform(0, 2 * np.pi, (len(suv), jitter))
                r = pos_radius * np.sqrt(rng.uniform(0, 1, (len(suv), jitter)))
                centers = (suv[:, None] + np.stack([r * np.cos(a), r * np.sin(a)], 2)).reshape(-1, 2)
                add(_crops(normed, centers, WINDOW), np.repeat(labels, jitter), centers, f, False)
            neg = _sample_negatives(rng, negatives_per_frame, image.shape, suv, small_mask, neg_radius)
            add(_crops(normed, neg, WINDOW), np.zeros(len(neg), np.int64), neg, f, False)
            if augment_per_corner:
                # the data engine's simple synthetic images around each point, normalized afterwards
                aug_neg = neg[: augment_per_corner]
                for label, (x, y) in [*zip(labels, suv), *zip(np.zeros(len(aug_neg), np.int64), aug_neg)]:
                    n = augment_per_corner if label else 1
                    raw = augment(image, [x, y, 1.0, 1.0], n, rng, **aug_kw)
                    add(normalize_windows(raw, norm, policy="raw"), np.full(n, label), np.tile([x, y], (n, 1)), f,
                        True)
    if not any(len(lab) and lab.max() > 0 for lab in parts["labels"]):
        raise InputError("no box corner is visible in any training image")
    # one fixed affine map for every input (the normalizers' output ranges differ widely)
    mean = float(np.mean([im.mean() for im in normalized_frames]))
    std = float(np.sqrt(np.mean([im.var() for im in normalized_frames]))) + 1e-6

    def standardize(x: np.ndarray) -> np.ndarray:
        return ((x - mean) / std).astype(np.float32)

    data = CornerDataset(**{k: np.concatenate(v) for k, v in parts.items()},
                         normalized=[standardize(im) for im in normalized_frames], visible=visible_corners,
                         input_mean=mean, input_std=std)
    data.windows = standardize(data.windows)
    logger.info("corner dataset: %d windows (%d corner, %d augmented) from %d frames (%d with new backgrounds)",
                len(data.labels), int((data.labels > 0).sum()), int(data.augmented.sum()), len(sequence.views),
                len(normalized_frames) - len(sequence.views))
    return data


# --------------------------------------------------------------------------------------------
# training and export (torch)
# --------------------------------------------------------------------------------------------


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
    out.chmod(0o644)  # a model file others read (the temporary file was private)
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
            data.add_negatives(_crops(normed, centers[bad], WINDOW), centers[bad], np.full(len(bad), f, np.int64))
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
        sequence_dir: a registered training sequence (anything :func:`pose.build.load_sequence`
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
    from pose.build import load_sequence

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


# --------------------------------------------------------------------------------------------
# inference (cv2.dnn, no torch)
# --------------------------------------------------------------------------------------------


def read_metadata(path: str | Path) -> dict[str, Any]:
    """The ``alcn_cv`` metadata of a corner-detector ONNX file.

    Raises:
        WeightFileError: missing file, not ONNX, or not a corner detector of this version.
    """
    import onnx

    path = Path(path)
    if not path.is_file():
        raise WeightFileError(f"corner detector not found: {path} (write one with `alcn pose train-corners`)")
    try:
        model = onnx.load(str(path), load_external_data=False)
    except Exception as exc:  # protobuf raises its own DecodeError
        raise WeightFileError(f"{path}: not an ONNX model ({exc})") from None
    props = {p.key: p.value for p in model.metadata_props}
    try:
        meta = json.loads(props[METADATA_KEY])
    except (KeyError, json.JSONDecodeError):
        raise WeightFileError(f"{path}: no '{METADATA_KEY}' metadata; not a corner detector") from None
    if meta.get("format") != FORMAT_NAME:
        raise WeightFileError(f"{path}: field 'format' is {meta.get('format')!r}, expected {FORMAT_NAME!r}")
    if meta.get("version") != FORMAT_VERSION:
        raise WeightFileError(f"{path}: field 'version' is {meta.get('version')!r}; this code reads version "
                              f"{FORMAT_VERSION}")
    return meta


class CornerDetector:
    """The corner detector run by ``cv2.dnn``: frame -> corner candidates -> correspondences.

    Same interface as :class:`pose.parts.FeaturePartDetector` (``detect(image, prior)``).

    Args:
        onnx_path: a file written by :func:`train_corners` (``alcn pose train-corners``).
        top_k: candidates kept per corner (RANSAC picks among them).
        min_score: lowest softmax score of a candidate.
        subdivide: the score grid's step is the network's stride (4 downscaled pixels) divided
            by this (1, 2 or 4; the network runs ``subdivide**2`` times).

    Attributes:
        corners: ``(8, 3)`` float64 box corners (object frame, :attr:`units`).
        normalizer_name, scale, input_mean, input_std: from the file.
    """

    uses_prior = False

    def __init__(self, onnx_path: str | Path, *, top_k: int = 4, min_score: float = 0.1, subdivide: int = 2) -> None:
        self.path = Path(onnx_path)
        self.meta = read_metadata(self.path)
        if self.meta["window"] != WINDOW or self.meta["stride"] != STRIDE or self.meta["pad"] != PAD:
            raise WeightFileError(f"{self.path}: window/stride/pad {self.meta['window']}/{self.meta['stride']}/"
                                  f"{self.meta['pad']}, expected {WINDOW}/{STRIDE}/{PAD}")
        if top_k < 1 or not 0 <= min_score < 1:
            raise InputError(f"need top_k >= 1 and min_score in [0, 1), got {top_k}, {min_score}")
        if subdivide not in (1, 2, 4):
            raise InputError(f"subdivide must be 1, 2 or 4 (a divisor of the stride {STRIDE}), got {subdivide}")
        try:
            self.net = cv2.dnn.readNetFromONNX(str(self.path))
        except cv2.error as exc:
            raise WeightFileError(f"OpenCV cannot read {self.path}: {str(exc).strip()}") from None
        self.corners = np.asarray(self.meta["corners"], np.float64)
        self.units = str(self.meta["units"])
        self.scale = float(self.meta["scale"])
        self.normalizer_name = str(self.meta["normalizer"])
        self.input_mean, self.input_std = float(self.meta["input_mean"]), float(self.meta["input_std"])
        self.normalizer = normalizer_for(self.normalizer_name)
        self.top_k, self.min_score, self.subdivide = top_k, min_score, subdivide

    def normalize(self, image: np.ndarray) -> np.ndarray:
        """The downscaled, normalized, standardized float32 frame the network sees."""
        small = downscale(to_gray(image), self.scale)
        normed = self.normalizer.normalize(small.astype(np.float32) / np.float32(255))
        return (normed - np.float32(self.input_mean)) / np.float32(self.input_std)

    def logits(self, normalized: np.ndarray) -> np.ndarray:
        """``(9, gh, gw)`` logits; grid point ``(i, j)`` scores the window centred on downscaled
        pixel ``(4j - 0.5, 4i - 0.5)`` (x, y)."""
        padded = cv2.copyMakeBorder(np.ascontiguousarray(normalized, np.float32), PAD, PAD, PAD, PAD,
                                    cv2.BORDER_REFLECT_101)
        self.net.setInput(padded[None, None])
        return np.ascontiguousarray(self.net.forward()[0], np.float32)

    def scores(self, image: np.ndarray) -> np.ndarray:
        """``(9, gh * s, gw * s)`` softmax scores of a BGR or gray uint8 frame (class 0:
        background), ``s`` = :attr:`subdivide`; grid point ``(i, j)`` scores the window centred
        on downscaled pixel ``(j, i) * STRIDE / s - 0.5``. The network runs on the ``s * s``
        frames shifted by multiples of ``STRIDE / s`` pixels."""
        normalized = self.normalize(image)
        step = STRIDE // self.subdivide
        out = None
        for dy in range(self.subdivide):
            for dx in range(self.subdivide):
                z = self.logits(normalized[dy * step:, dx * step:])
                e = np.exp(z - z.max(0, keepdims=True))
                p = e / e.sum(0, keepdims=True)
                if out is None:  # the unshifted frame has the most grid points
                    out = np.zeros((p.shape[0], p.shape[1] * self.subdivide, p.shape[2] * self.subdivide), np.float32)
                    out[0] = 1.0  # background where a shifted frame has no grid point (last row / column)
                view = out[:, dy::self.subdivide, dx::self.subdivide]
                h, w = min(view.shape[1], p.shape[1]), min(view.shape[2], p.shape[2])
                view[:, :h, :w] = p[:, :h, :w]
        return out

    def peaks(self, image: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per corner, ``(xy (m, 2) float64 full-image pixels, scores (m,))``, best first, ``m <= top_k``."""
        prob = self.scores(image)
        out = []
        offset = WINDOW / 2 - 0.5 - PAD  # window centre of grid point 0
        step = STRIDE / self.subdivide
        nms = np.ones((2 * self.subdivide + 1,) * 2, np.uint8)  # one network stride around a peak
        for k in range(1, NUM_CORNERS + 1):
            p = prob[k]
            local_max = (p >= cv2.dilate(p, nms)) & (p >= self.min_score)
            ii, jj = np.nonzero(local_max)
            order = np.argsort(-p[ii, jj])[: self.top_k]
            xy, sc = [], []
            for i, j in zip(ii[order], jj[order]):
                i0, i1, j0, j1 = max(i - 1, 0), min(i + 2, p.shape[0]), max(j - 1, 0), min(j + 2, p.shape[1])
                w = p[i0:i1, j0:j1]
                gy, gx = np.mgrid[i0:i1, j0:j1]
                xy.append([(w * gx).sum() / w.sum(), (w * gy).sum() / w.sum()])
                sc.append(p[i, j])
            xy = np.asarray(xy, np.float64).reshape(-1, 2) * step + offset
            out.append((from_scaled(xy, self.scale), np.asarray(sc, np.float64)))
        return out

    def detect(self, image: np.ndarray, prior: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None, *,
               search_scale: float = 1.0) -> Correspondences:
        """Corner candidates of ``image`` as 2D-3D correspondences.

        ``prior`` and ``search_scale`` are not used: the solver takes the previous pose into
        account (gating the candidates by it gave no clear gain on the data engine's sequences
        and lost frames after large motions)."""
        obj, img = [], []
        for k, (xy, _) in enumerate(self.peaks(image)):
            obj.extend([self.corners[k]] * len(xy))
            img.extend(xy)
        return Correspondences(np.asarray(obj, np.float32).reshape(-1, 3), np.asarray(img, np.float32).reshape(-1, 2),
                               len(img))


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
