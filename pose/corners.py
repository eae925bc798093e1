"""Learned part detector: a CNN that finds the box's corners, edge middles and face centres in normalized images.

The Box experiment of Rad, Roth & Lepetit (BMVC 2017, Sec. 4.4) detects the corners of a box
with the part-based method of Crivellaro et al. ("A Novel Representation of Parts for Accurate
3D Object Detection and Tracking in Monocular Images", ICCV 2015) after contrast normalization.
This module is that detector, kept small and real-time. Its parts are the points of the box's
surface at half steps along its edges (:func:`pose.box.box_parts`: 8 corners, 12 edge
middles, 6 face centres), where the paper's are the 8 corners (``divisions=1`` here): a face
centre's window shows mostly the box's own texture, a corner's mostly the table.

* **Training data** (:func:`pose.corner_data.build_frames`): every view of a registered
  training sequence, downscaled by ``scale``, and copies of it seen from nearby viewpoints (each
  face of the box warped by its own plane's homography) and warped by random homographies, with
  new backgrounds and intensity changes; each normalized whole and labelled on the network's
  output grid: the cells whose
  window centre is within 4 pixels of a visible part are that part's, with the part's
  offset from the centre as a regression target; far cells are background.
* **Network** (:class:`pose.corner_net.CornerNet`): the geometry of the paper's detector
  (:class:`alcn_cv.nets.Detector`, a 32x32 window per output cell at stride 4) with ``1 + n``
  class logits and ``n`` sub-stride offsets per cell, trained densely on crops of the frames
  (:func:`pose.corner_train.train_corners`).
* **Export** (:func:`pose.corner_train.export_onnx`): ONNX (``(1, 1, H, W)`` -> ``(1, 3n + 1, gh, gw)``)
  with the parts, the box corners, units, scale and normalization in its ``metadata_props`` (key ``alcn_cv``),
  so the ``.onnx`` file is the whole detector.
* **Inference** (:class:`CornerDetector`): ``cv2.dnn`` runs it once on the padded, normalized
  frame (no torch import); per part, the local maxima of its softmax score above
  ``min_score``, the ``top_k`` best, each placed at the score-weighted mean of the positions
  its 3x3 neighbourhood's offsets vote for. With the pose predicted from the previous frames,
  only candidates within ``gate`` pixels of the part's predicted projection are kept
  (:meth:`CornerDetector.detect`); the tracker searches the whole frame again when that gives no
  pose. The candidates are the 2D-3D correspondences of :class:`pose.solver.PoseSolver`.
* **Verification** (:meth:`CornerDetector.verify`): a pose the solver accepts is kept only when
  the network scores the parts it shows highly enough where it shows them
  (:meth:`CornerDetector.support`); a wrong pose from a few chance inliers among the candidates
  of a whole frame does not survive it, and is not the next frame's prior (see :data:`MIN_SUPPORT`).
* **Proposals** (:meth:`CornerDetector.propose`): for a frame where RANSAC over the candidates
  gives no pose that survives, poses from thousands of P3P triples of the whole frame's
  candidates are scored by that same support, every part they show counted; the best, when it
  stands out (:data:`MAX_RIVAL_RATIO`), is searched around as a prediction and verified again.
  Lost frames under strong light changes are mostly frames where a few right candidates hide
  among 130, too few for RANSAC's consensus but enough for a triple.
* **Refinement** (:attr:`CornerDetector.refine_search_scale`): once a frame has a verified pose,
  its parts are searched again in gates of half the width around that pose itself, and the pose
  solved from them replaces it when verified (see :data:`REFINE_SEARCH_SCALE`).
* **Edge middles** (:func:`pose.box.edge_directions`): a candidate of an edge's middle carries
  the edge's direction, along which the network places it about 3 times less precisely than
  across; the solver weighs its error along the edge down accordingly (:data:`pose.solver.ALONG_SIGMA`).

Speed: ``alcn pose bench-corners``; measurements behind the design and the constants below:
``docs/journal.md``.
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
from alcn_cv.io import to_gray
from alcn_cv.weight_file import ONNX_METADATA_KEY, check_header
from pose.box import NUM_CORNERS, edge_directions, part_visibility, parts_per_face
from pose.parts import Correspondences, same_frame

logger = logging.getLogger(__name__)

__all__ = ["CornerDetector", "normalization_for", "read_metadata"]

FORMAT_NAME = "alcn-corner-detector"
FORMAT_VERSION = 4
#: Version 3 names the normalization ``normalizer``; :func:`read_metadata` renames it.
READABLE_VERSIONS = (3, 4)
# alcn_cv.nets.Detector's input window and output stride (a test checks they agree; importing
# alcn_cv.nets here would import torch, which the tracking path must not need).
WINDOW = 32
STRIDE = 4
PAD = WINDOW // 2
#: The lowest :meth:`CornerDetector.support` of a pose the tracker keeps (the most correct poses on Table 1 of
#: those tried; ``docs/journal.md`` has the measurements).
MIN_SUPPORT = 0.15
#: :meth:`CornerDetector.propose`: candidate triples drawn, and the lowest support of the pose it proposes.
PROPOSALS = 2000
MIN_PROPOSAL_SUPPORT = 0.3
#: A proposed pose is unique when every pose whose parts project farther than ``RIVAL_DISTANCE``
#: pixels (mean, full frame) from its own scores at most ``MAX_RIVAL_RATIO`` of its support.
RIVAL_DISTANCE = 20.0
MAX_RIVAL_RATIO = 0.85
#: The gate of the tracker's second search of a frame's parts, around the frame's own verified
#: pose, as a share of :attr:`CornerDetector.gate` (:attr:`CornerDetector.refine_search_scale`);
#: it costs no network run and no peak search: the frame's maps and local maxima are kept.
REFINE_SEARCH_SCALE = 0.5


def normalization_for(spec: str) -> Normalization:
    """The normalization ``spec`` (``NAME[:KEY=VALUE...]``,
    :func:`alcn_cv.enhance.registry.from_spec`) applied at the detector's (already downscaled)
    resolution.

    ALCN runs at working scale 1 on the downscaled frame; without a ``backend`` in ``spec``,
    through its torch-free ``cv2.dnn`` backend where its weights have an ONNX twin (every
    shipped model has one), else ALCN's default backend. Every other name is built as
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


def grid_shape(height: int, width: int) -> tuple[int, int]:
    """The network's output grid for a ``height x width`` frame padded by :data:`PAD`."""
    return (height + 2 * PAD - WINDOW) // STRIDE + 1, (width + 2 * PAD - WINDOW) // STRIDE + 1


def grid_centres(shape: tuple[int, int]) -> np.ndarray:
    """``(gh, gw, 2)`` float64: the window centre (x, y, pixels of the unpadded frame) of every grid cell."""
    gy, gx = np.mgrid[: shape[0], : shape[1]].astype(np.float64)
    return np.stack([gx, gy], -1) * STRIDE + (WINDOW / 2 - 0.5 - PAD)


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


def scaled_camera(K: np.ndarray, scale_x: float, scale_y: float | None = None) -> np.ndarray:
    """The intrinsics ``(3, 3)`` float64 of the image resized by ``scale_x`` across and ``scale_y``
    (default ``scale_x``) down, as ``cv2.resize`` maps the pixels (:func:`to_scaled`: OpenCV pixel
    centres, so the principal point moves by ``0.5 * scale - 0.5`` besides its scaling)."""
    scale_y = scale_x if scale_y is None else scale_y
    K = np.array(K, np.float64)
    K[0] *= scale_x
    K[1] *= scale_y
    K[0, 2] += 0.5 * scale_x - 0.5
    K[1, 2] += 0.5 * scale_y - 0.5
    return K


def grid_cell(uv: np.ndarray) -> np.ndarray:
    """``(..., 2)`` int: the column and row of the grid cell whose window is centred nearest to
    each point ``uv (..., 2)`` (x, y pixels of the downscaled frame, :func:`grid_centres`)."""
    return np.rint((np.asarray(uv, np.float64) - grid_centres((1, 1))[0, 0]) / STRIDE).astype(int)


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
        meta = json.loads(props[ONNX_METADATA_KEY])
    except (KeyError, json.JSONDecodeError):
        raise WeightFileError(f"{path}: no '{ONNX_METADATA_KEY}' metadata; not a corner detector") from None
    check_header(
        meta,
        path,
        FORMAT_NAME,
        READABLE_VERSIONS,
        what="corner detector",
        again="train it again with `alcn pose train-corners`",
    )
    if meta["version"] == 3 and "normalizer" in meta:
        meta["normalization"] = meta.pop("normalizer")
    return meta


class CornerDetector:
    """The corner detector run by ``cv2.dnn``: frame -> corner candidates -> correspondences.

    Same interface as :class:`pose.parts.FeaturePartDetector` (``detect(image, prior)``).

    Args:
        onnx_path: a file written by :func:`pose.corner_train.train_corners` (``alcn pose train-corners``).
        top_k: candidates kept per part in the whole frame (RANSAC picks among them).
        min_score: lowest softmax score of a candidate in the whole frame.
        gate: with a prior pose, candidates farther than this (pixels of the full frame, times
            the tracker's ``search_scale``) from the part's predicted projection are dropped.
        gated_top_k, gated_min_score: ``top_k`` and ``min_score`` inside the gates (each gate's cells scored
            by their probability of being the gate's part; ``docs/journal.md`` has why not by that of being any
            part).
        min_support: the lowest :meth:`support` of a pose that :meth:`verify` keeps.
        proposals, min_proposal_support: how many candidate triples :meth:`propose` draws (0: it
            proposes nothing), and the lowest support of the pose it proposes.
        refine_search_scale: the gate of the tracker's second search around a frame's own pose,
            as a share of ``gate`` (0: none). A pose solved from the whole frame's candidates
            (the ``top_k`` above ``min_score``), or around a prediction that was some pixels off,
            is a better centre for the parts' gates than the prediction was: searched again in a
            narrower gate, the parts give more right candidates and fewer wrong ones.

    Attributes:
        parts: ``(n, 3)`` float64 the parts found (object frame, :attr:`units`).
        corners: ``(8, 3)`` float64 box corners (the outline of :class:`pose.solver.PoseSolver`).
        normalization_spec, scale, input_mean, input_std: from the file.
    """

    uses_prior = True

    def __init__(
        self,
        onnx_path: str | Path,
        *,
        top_k: int = 5,
        min_score: float = 0.05,
        gate: float = 20.0,
        gated_top_k: int = 2,
        gated_min_score: float = 0.02,
        min_support: float = MIN_SUPPORT,
        proposals: int = PROPOSALS,
        min_proposal_support: float = MIN_PROPOSAL_SUPPORT,
        refine_search_scale: float = REFINE_SEARCH_SCALE,
    ) -> None:
        self.path = Path(onnx_path)
        self.meta = read_metadata(self.path)
        if self.meta["window"] != WINDOW or self.meta["stride"] != STRIDE or self.meta["pad"] != PAD:
            raise WeightFileError(
                f"{self.path}: window/stride/pad {self.meta['window']}/{self.meta['stride']}/"
                f"{self.meta['pad']}, expected {WINDOW}/{STRIDE}/{PAD}"
            )
        if min(top_k, gated_top_k) < 1 or not (0 <= min_score < 1 and 0 <= gated_min_score < 1) or gate <= 0:
            raise InputError(
                f"need top_k, gated_top_k >= 1, min_score, gated_min_score in [0, 1) and gate > 0, "
                f"got {top_k}, {gated_top_k}, {min_score}, {gated_min_score}, {gate}"
            )
        if not (0 <= min_support < 1 and 0 <= min_proposal_support < 1) or proposals < 0 or refine_search_scale < 0:
            raise InputError(
                f"need min_support and min_proposal_support in [0, 1), proposals >= 0 and "
                f"refine_search_scale >= 0, got {min_support}, {min_proposal_support}, {proposals} "
                f"and {refine_search_scale}"
            )
        try:
            self.net = cv2.dnn.readNetFromONNX(str(self.path))
        except cv2.error as exc:
            raise WeightFileError(f"OpenCV cannot read {self.path}: {exc.err}") from None
        self.parts = np.asarray(self.meta["parts"], np.float64).reshape(-1, 3)
        self.corners = np.asarray(self.meta["corners"], np.float64).reshape(NUM_CORNERS, 3)
        if self.meta["config"].get("num_parts") != len(self.parts):
            raise WeightFileError(
                f"{self.path}: {len(self.parts)} parts but a network for {self.meta['config'].get('num_parts')}"
            )
        self.units = str(self.meta["units"])
        self.scale = float(self.meta["scale"])
        self.normalization_spec = str(self.meta["normalization"])
        self.input_mean, self.input_std = float(self.meta["input_mean"]), float(self.meta["input_std"])
        self.normalization = normalization_for(self.normalization_spec)
        self.top_k, self.min_score, self.gate = top_k, min_score, gate
        self.gated_top_k, self.gated_min_score = gated_top_k, gated_min_score
        self.min_support = min_support
        self.proposals, self.min_proposal_support = proposals, min_proposal_support
        self.refine_search_scale = refine_search_scale
        self._face_parts = parts_per_face(self.corners, self.parts)
        self._directions = edge_directions(self.corners, self.parts).astype(np.float32)
        self._rng = np.random.default_rng(0)  # the proposals' draws: the same results on every run
        self._cache: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._pooled: tuple[np.ndarray, np.ndarray] | None = None
        self._maxima: tuple[np.ndarray, list[tuple[np.ndarray, np.ndarray]]] | None = None

    def normalize(self, image: np.ndarray) -> np.ndarray:
        """The downscaled, normalized, standardized float32 frame the network sees."""
        small = downscale(to_gray(image), self.scale)
        normed = self.normalization.normalize(small.astype(np.float32) / np.float32(255))
        return (normed - np.float32(self.input_mean)) / np.float32(self.input_std)

    def outputs(self, normalized: np.ndarray) -> np.ndarray:
        """``(3n + 1, gh, gw)``: ``1 + n`` logits (background, the parts) then the ``n`` parts'
        offsets ``(dx, dy)`` in strides; cell ``(i, j)`` is the window centred on :func:`grid_centres`."""
        padded = cv2.copyMakeBorder(
            np.ascontiguousarray(normalized, np.float32), PAD, PAD, PAD, PAD, cv2.BORDER_REFLECT_101
        )
        self.net.setInput(padded[None, None])
        try:
            out = self.net.forward()
        except cv2.error as exc:
            raise WeightFileError(f"{self.path}: OpenCV cannot run its network ({exc.err})") from None
        maps = 3 * len(self.parts) + 1
        if out.ndim != 4 or out.shape[:2] != (1, maps):
            # a graph from another file under this one's metadata: its maps would be read as the wrong parts
            raise WeightFileError(
                f"{self.path}: its network gives outputs of shape {out.shape}, not the (1, {maps}, h, w) maps of "
                f"{len(self.parts)} parts its metadata names"
            )
        return np.ascontiguousarray(out[0], np.float32)

    def maps(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Softmax scores ``(1 + n, gh, gw)`` (class 0: background) and per part the position each
        cell votes for ``(n, gh, gw, 2)`` (x, y, downscaled pixels) of a BGR or gray uint8 frame.
        The last frame's are kept, so the tracker's second search of a frame costs nothing.

        The one comparison of ``image`` with the last frame (by content, :func:`pose.parts.same_frame`): each
        public method calls it once and hands its maps to the internal ones."""
        if self._cache is not None and same_frame(self._cache[0], image):
            return self._cache[1], self._cache[2]
        out = self.outputs(self.normalize(image))
        n = len(self.parts)
        z = out[: n + 1]
        e = np.exp(z - z.max(0, keepdims=True))
        prob = e / e.sum(0, keepdims=True)
        off = out[n + 1 :].reshape(n, 2, *z.shape[1:]).transpose(0, 2, 3, 1)
        votes = grid_centres(z.shape[1:])[None] + STRIDE * off.astype(np.float64)
        self._cache = (image.copy(), prob, votes)
        return prob, votes

    def peaks(
        self, image: np.ndarray, predicted: np.ndarray | None = None, radius: float | None = None
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per part, ``(xy (m, 2) float64 full-image pixels, scores (m,))``, best first.

        Without ``predicted``: the ``top_k`` local maxima above ``min_score``; with ``predicted``
        ``(n, 2)`` full-image pixels: the ``gated_top_k`` above ``gated_min_score`` within
        ``radius`` pixels (default :attr:`gate`) of the part's prediction."""
        return self._peaks(self.maps(image), predicted, radius)

    def _peaks(
        self,
        maps: tuple[np.ndarray, np.ndarray],
        predicted: np.ndarray | None = None,
        radius: float | None = None,
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """:meth:`peaks` of a frame's :meth:`maps`."""
        radius = self.gate if radius is None else radius
        out = []
        for k, (xy, sc) in enumerate(self._local_maxima(maps)):
            if predicted is None:
                above, keep = sc >= self.min_score, self.top_k
            else:
                above = (sc >= self.gated_min_score) & (np.linalg.norm(xy - predicted[k], axis=1) <= radius)
                keep = self.gated_top_k
            xy, sc = xy[above], sc[above]
            order = np.argsort(-sc, kind="stable")[:keep]
            out.append((xy[order], sc[order]))
        return out

    def _local_maxima(self, maps: tuple[np.ndarray, np.ndarray]) -> list[tuple[np.ndarray, np.ndarray]]:
        """Per part, every local maximum of its score (3x3) in a frame's :meth:`maps` above the lower of
        ``min_score`` and ``gated_min_score``: ``(xy (m, 2) full-image pixels, scores (m,))``. The last frame's
        are kept: the tracker searches a frame up to four times (guided, whole frame, around a proposal, around
        its own pose)."""
        prob, votes = maps
        if self._maxima is not None and self._maxima[0] is prob:
            return self._maxima[1]
        low = min(self.min_score, self.gated_min_score)
        pooled = self._pooled_scores(prob)
        maxima = []
        for k in range(len(self.parts)):
            p = prob[k + 1]
            ii, jj = np.nonzero((p >= pooled[k]) & (p >= low))
            maxima.append((from_scaled(vote_positions(p, votes[k], ii, jj), self.scale), p[ii, jj].astype(np.float64)))
        self._maxima = (prob, maxima)
        return maxima

    def support(self, image: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray) -> float:
        """How much the network's scores of ``image`` agree with the pose ``(rvec, tvec)`` (``K``:
        the intrinsics of ``image``): the mean, over the parts the pose shows
        (:func:`pose.box.part_visibility`), of each part's best score among the 3x3 cells around
        its projection; 0 when it shows none. In ``[0, 1]``."""
        R = cv2.Rodrigues(np.asarray(rvec, np.float64))[0]
        t = np.asarray(tvec, np.float64).reshape(1, 3)
        return float(self._supports(self.maps(image)[0], image.shape[:2], R[None], t, K)[0][0])

    def _supports(
        self, prob: np.ndarray, shape: tuple[int, int], R: np.ndarray, t: np.ndarray, K: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`support` of ``b`` poses ``R (b, 3, 3)``, ``t (b, 3)`` at once in the frame of shape ``shape``
        (``(h, w)``) and scores ``prob`` (:meth:`maps`), ``(b,)`` the number of distinct grid cells the parts
        each pose shows fall in, and ``(b, n, 2)`` the parts' projections."""
        uv, visible = part_visibility(self.corners, R, t, np.asarray(K, np.float64), shape, parts=self.parts)
        pooled = self._pooled_scores(prob)
        gh, gw = pooled.shape[1:]
        ij = grid_cell(to_scaled(uv, self.scale))
        j, i = np.clip(ij[..., 0], 0, gw - 1), np.clip(ij[..., 1], 0, gh - 1)
        scores = np.where(visible, pooled[np.arange(len(self.parts)), i, j], 0.0)
        shown = visible.sum(1)
        # the hidden parts all get cell -1, counted once and taken off
        cells = np.sort(np.where(visible, i * gw + j, -1), 1)
        distinct = 1 + (np.diff(cells, axis=1) != 0).sum(1) - (~visible).any(1)
        return scores.sum(1) / np.maximum(shown, 1), distinct, uv

    def _pooled_scores(self, prob: np.ndarray) -> np.ndarray:
        """``(n, gh, gw)``: each part's best score in ``prob`` (:meth:`maps`) among the 3x3 cells around every
        cell (kept for the last frame's maps)."""
        if self._pooled is None or self._pooled[0] is not prob:
            kernel = np.ones((3, 3), np.uint8)
            self._pooled = (prob, np.stack([cv2.dilate(p, kernel) for p in prob[1:]]))
        return self._pooled[1]

    def propose(self, image: np.ndarray, K: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """A pose of the box in ``image`` found by the network's scores alone, for a frame where
        RANSAC over the candidates found none (``None`` when none scores well enough).

        Draws :attr:`proposals` triples of the whole frame's candidates (:meth:`peaks`), three
        different parts each, parts and candidates in proportion to their scores; each triple's
        P3P poses (AP3P, up to 4) are scored by :meth:`support`, which looks at every part the pose
        shows, not only at the candidates. Of the poses whose parts fall in at least as many grid
        cells as a face has parts (a far, tiny box would otherwise score its few cells), the best
        is returned when its support is at least :attr:`min_proposal_support` and no pose
        elsewhere in the image comes near it (:data:`MAX_RIVAL_RATIO`): in a cluttered frame
        where the network sees no box, thousands of draws find several poses of about equal
        support, none of them right.

        Returns:
            ``(rvec, tvec)``, ``(3, 1)`` float64 each, or ``None``.
        """
        if self.proposals == 0:
            return None
        maps = self.maps(image)
        peaks = self._peaks(maps)
        parts = np.array([k for k, (xy, _) in enumerate(peaks) if len(xy)], np.int64)
        if len(parts) < 3:
            return None
        found = [peaks[k] for k in parts]
        xy = np.zeros((len(found), self.top_k, 2))
        cumulative = np.ones((len(found), self.top_k))  # beyond a part's last candidate: never drawn
        for a, (p, sc) in enumerate(found):
            xy[a, : len(p)] = p
            cumulative[a, : len(sc) - 1] = np.cumsum(sc)[:-1] / sc.sum()  # the last stays 1: no draw passes it
        # three parts per triple without repeats, each in proportion to its best score (Gumbel top-k)
        best = np.array([sc[0] for _, sc in found])
        keys = np.log(best) + self._rng.gumbel(size=(self.proposals, len(found)))
        picks = np.argsort(-keys, 1)[:, :3]
        drawn = (cumulative[picks] < self._rng.random((self.proposals, 3, 1))).sum(-1)
        image_points, object_points = xy[picks, drawn], self.parts[parts[picks]]
        K = np.asarray(K, np.float64)
        R, t = [], []
        for obj, img in zip(object_points, image_points):
            _, rvecs, tvecs = cv2.solveP3P(obj, img, K, None, flags=cv2.SOLVEPNP_AP3P)
            R.extend(cv2.Rodrigues(r)[0] for r in rvecs)
            t.extend(tv.reshape(3) for tv in tvecs)
        if not R:
            return None
        support, cells, uv = self._supports(maps[0], image.shape[:2], np.array(R), np.array(t), K)
        support[cells < self._face_parts] = 0.0
        b = int(np.argmax(support))
        elsewhere = np.linalg.norm(uv - uv[b], axis=-1).mean(-1) > RIVAL_DISTANCE
        rival = support[elsewhere].max(initial=0.0)
        if support[b] < self.min_proposal_support or rival > MAX_RIVAL_RATIO * support[b]:
            return None
        return cv2.Rodrigues(R[b])[0], t[b].reshape(3, 1).copy()

    def verify(
        self, image: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, K: np.ndarray, *, proposed: bool = False
    ) -> str:
        """``""`` when the pose's :meth:`support` is at least :attr:`min_support` (at least
        :attr:`min_proposal_support` for a pose ``proposed`` by :meth:`propose`: chosen among
        thousands for its support, it is held to the bar it was proposed at), else why not."""
        s = self.support(image, rvec, tvec, K)
        need = self.min_proposal_support if proposed else self.min_support
        return "" if s >= need else f"support {s:.2f} of the network's scores (need {need})"

    def detect(
        self,
        image: np.ndarray,
        prior: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
        *,
        search_scale: float = 1.0,
    ) -> Correspondences:
        """Part candidates of ``image`` as 2D-3D correspondences; with ``prior = (rvec, tvec, K)``
        only those within ``gate * search_scale`` pixels of the part's projection by it. Each
        carries its part's edge direction (:func:`pose.box.edge_directions`), for the solver."""
        predicted = None
        if prior is not None:
            rvec, tvec, K = prior
            predicted = cv2.projectPoints(
                self.parts, np.asarray(rvec, np.float64), np.asarray(tvec, np.float64), np.asarray(K, np.float64), None
            )[0].reshape(-1, 2)
        peaks = self.peaks(image, predicted, self.gate * search_scale)
        part = np.repeat(np.arange(len(self.parts)), [len(xy) for xy, _ in peaks])
        img = np.concatenate([xy for xy, _ in peaks]).astype(np.float32).reshape(-1, 2)
        return Correspondences(self.parts[part].astype(np.float32), img, len(img), self._directions[part])


def vote_positions(score: np.ndarray, votes: np.ndarray, ii: np.ndarray, jj: np.ndarray) -> np.ndarray:
    """``(m, 2)``: at the cells ``(ii, jj)`` (``(m,)`` each), the ``score (gh, gw)``-weighted mean
    of the positions ``votes (gh, gw, 2)`` of the cell's 3x3 neighbourhood (only the candidates'
    neighbourhoods: the whole grid's box filters cost 26 parts 2.8 ms a frame)."""
    p = np.pad(score.astype(np.float64), 1)
    v = np.pad(votes, ((1, 1), (1, 1), (0, 0)))
    num, den = np.zeros((len(ii), 2)), np.full(len(ii), 1e-12)
    for di in range(3):
        for dj in range(3):
            w = p[ii + di, jj + dj]
            num += w[:, None] * v[ii + di, jj + dj]
            den += w
    return num / den[:, None]
