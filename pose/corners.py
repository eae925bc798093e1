"""Learned part detector: a CNN that finds the 8 box corners in normalized images.

The Box experiment of Rad, Roth & Lepetit (BMVC 2017, Sec. 4.4) detects the corners of a box
with the part-based method of Crivellaro et al. ("A Novel Representation of Parts for Accurate
3D Object Detection and Tracking in Monocular Images", ICCV 2015) after contrast normalization.
This module is that detector, kept small:

* **Training data** (:func:`pose.corner_data.build_dataset`): every frame of a registered training sequence is
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
* **Export** (:func:`pose.corner_train.export_onnx`): the dense network (``(1, 1, H, W)`` -> ``(1, 9, gh, gw)``
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
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from alcn_cv.enhance.base import Normalization
from alcn_cv.enhance.registry import from_spec, parse_spec
from alcn_cv.errors import InputError, WeightFileError
from pose.parts import Correspondences, to_gray

logger = logging.getLogger(__name__)

__all__ = ["CornerDetector", "normalization_for", "read_metadata"]

FORMAT_NAME = "alcn-corner-detector"
FORMAT_VERSION = 1
METADATA_KEY = "alcn_cv"
NUM_CORNERS = 8
# alcn_cv.nets.Detector's input window and output stride (a test checks they agree; importing
# alcn_cv.nets here would import torch, which the tracking path must not need).
WINDOW = 32
STRIDE = 4
PAD = WINDOW // 2


def normalization_for(spec: str) -> Normalization:
    """The normalization ``spec`` (``NAME[:KEY=VALUE...]``,
    :func:`alcn_cv.enhance.registry.from_spec`) applied at the detector's (already downscaled)
    resolution.

    ALCN runs at working scale 1 on the downscaled frame; without a ``backend`` in ``spec``,
    through its torch-free ``cv2.dnn`` backend where its weights have an ONNX twin (the
    paper's model), else ALCN's default backend (the lite model). Every other name is built as
    ``from_spec(spec)``.
    """
    name, params = parse_spec(spec)
    if name != "alcn":
        return from_spec(spec)
    if "backend" not in params:
        try:
            return from_spec(spec, scale=1.0, backend="opencv")
        except WeightFileError as exc:
            logger.info("ALCN through its default backend: %s", exc)
    return from_spec(spec, scale=1.0)


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
        self.normalization = normalization_for(self.normalizer_name)
        self.top_k, self.min_score, self.subdivide = top_k, min_score, subdivide

    def normalize(self, image: np.ndarray) -> np.ndarray:
        """The downscaled, normalized, standardized float32 frame the network sees."""
        small = downscale(to_gray(image), self.scale)
        normed = self.normalization.normalize(small.astype(np.float32) / np.float32(255))
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
