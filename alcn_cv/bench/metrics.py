"""Detection metrics of the benchmark: non-maximum suppression, PASCAL matching, precision-recall, AUC.

Boxes are ``[x, y, w, h]`` in pixels (COCO's convention: top-left corner, width, height), as
float arrays of shape ``(n, 4)``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from alcn_cv.errors import InputError

__all__ = ["box_iou", "match_detections", "nms", "pr_auc", "precision_recall"]


def _boxes(boxes: object, what: str) -> np.ndarray:
    arr = np.asarray(boxes, dtype=np.float64)
    if arr.size == 0:
        return arr.reshape(0, 4)
    if arr.ndim != 2 or arr.shape[1] != 4:
        raise InputError(f"{what} must have shape (n, 4) as [x, y, w, h], got {arr.shape}")
    if not np.isfinite(arr).all() or (arr[:, 2:] <= 0).any():
        raise InputError(f"{what} must be finite with positive width and height")
    return arr


def box_iou(a: object, b: object) -> np.ndarray:
    """Intersection over union of every box of ``a`` with every box of ``b``.

    Args:
        a: ``(n, 4)`` boxes ``[x, y, w, h]``.
        b: ``(m, 4)`` boxes.

    Returns:
        ``(n, m)`` float64 in [0, 1].
    """
    a, b = _boxes(a, "boxes a"), _boxes(b, "boxes b")
    ax2, ay2 = a[:, 0] + a[:, 2], a[:, 1] + a[:, 3]
    bx2, by2 = b[:, 0] + b[:, 2], b[:, 1] + b[:, 3]
    iw = np.clip(np.minimum(ax2[:, None], bx2[None]) - np.maximum(a[:, None, 0], b[None, :, 0]), 0, None)
    ih = np.clip(np.minimum(ay2[:, None], by2[None]) - np.maximum(a[:, None, 1], b[None, :, 1]), 0, None)
    inter = iw * ih
    union = (a[:, 2] * a[:, 3])[:, None] + (b[:, 2] * b[:, 3])[None] - inter
    return inter / union


def nms(boxes: object, scores: object, iou_threshold: float, max_detections: int | None = None) -> np.ndarray:
    """Greedy non-maximum suppression.

    Keeps the highest-scoring box, removes every remaining box overlapping it with IoU
    strictly above ``iou_threshold``, and repeats.

    Args:
        boxes: ``(n, 4)`` boxes ``[x, y, w, h]``.
        scores: ``(n,)`` scores (higher is more confident).
        iou_threshold: in [0, 1).
        max_detections: stop after this many kept boxes (default: no limit).

    Returns:
        Indices of the kept boxes, by decreasing score (int64). Ties keep the lower index.
    """
    boxes = _boxes(boxes, "boxes")
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    if scores.shape[0] != boxes.shape[0]:
        raise InputError(f"{boxes.shape[0]} boxes but {scores.shape[0]} scores")
    if not 0 <= iou_threshold < 1:
        raise InputError(f"iou_threshold must be in [0, 1), got {iou_threshold}")
    order = np.argsort(-scores, kind="stable")
    keep: list[int] = []
    limit = len(order) if max_detections is None else max_detections
    while order.size and len(keep) < limit:
        best = order[0]
        keep.append(int(best))
        rest = order[1:]
        if rest.size:
            rest = rest[box_iou(boxes[best : best + 1], boxes[rest])[0] <= iou_threshold]
        order = rest
    return np.asarray(keep, dtype=np.int64)


def match_detections(det_boxes: object, det_scores: object, gt_boxes: object, iou_threshold: float = 0.5) -> np.ndarray:
    """PASCAL VOC matching of one image's detections to its ground truth.

    Detections are taken by decreasing score; each is a true positive when its best-overlapping
    ground-truth box has IoU >= ``iou_threshold`` and was not matched by a higher-scoring
    detection; otherwise a false positive (Everingham et al., IJCV 2010).

    Args:
        det_boxes: ``(n, 4)`` detected boxes ``[x, y, w, h]``.
        det_scores: ``(n,)`` scores.
        gt_boxes: ``(m, 4)`` ground-truth boxes of the same class.
        iou_threshold: the overlap a true positive needs (the benchmark uses 0.8).

    Returns:
        ``(n,)`` bool, true positive or not, in the order of ``det_boxes``.
    """
    det = _boxes(det_boxes, "detections")
    gt = _boxes(gt_boxes, "ground truth")
    scores = np.asarray(det_scores, dtype=np.float64).reshape(-1)
    if scores.shape[0] != det.shape[0]:
        raise InputError(f"{det.shape[0]} detections but {scores.shape[0]} scores")
    tp = np.zeros(len(det), bool)
    if not len(det) or not len(gt):
        return tp
    iou = box_iou(det, gt)
    used = np.zeros(len(gt), bool)
    for i in np.argsort(-scores, kind="stable"):
        j = int(np.argmax(iou[i]))
        if iou[i, j] >= iou_threshold and not used[j]:
            used[j] = True
            tp[i] = True
    return tp


def precision_recall(scores: object, true_positive: object, num_positives: int) -> tuple[np.ndarray, np.ndarray]:
    """Precision and recall at every score threshold.

    Args:
        scores: ``(n,)`` detection scores pooled over all images.
        true_positive: ``(n,)`` bool from :func:`match_detections`.
        num_positives: number of ground-truth objects (>= 1).

    Returns:
        ``(precision, recall)``, each ``(n,)`` float64, the detections taken by decreasing score.
    """
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    tp = np.asarray(true_positive, dtype=bool).reshape(-1)
    if scores.shape != tp.shape:
        raise InputError(f"{scores.shape[0]} scores but {tp.shape[0]} true-positive flags")
    if num_positives < 1:
        raise InputError(f"num_positives must be >= 1, got {num_positives}")
    order = np.argsort(-scores, kind="stable")
    ctp = np.cumsum(tp[order])
    precision = ctp / np.arange(1, len(order) + 1)
    recall = ctp / float(num_positives)
    return precision, recall


def pr_auc(precision: Sequence[float] | np.ndarray, recall: Sequence[float] | np.ndarray) -> float:
    """Area under the precision-recall curve (PASCAL VOC 2010+ average precision).

    The precision is replaced by its running maximum from the right (the interpolated,
    monotone envelope), and the area is summed over the recall steps, starting from recall 0.
    No detection gives 0.

    Args:
        precision: ``(n,)`` from :func:`precision_recall`.
        recall: ``(n,)``, non-decreasing.

    Returns:
        The area, in [0, 1].
    """
    p = np.asarray(precision, dtype=np.float64).reshape(-1)
    r = np.asarray(recall, dtype=np.float64).reshape(-1)
    if p.shape != r.shape:
        raise InputError(f"precision {p.shape} and recall {r.shape} differ")
    if not p.size:
        return 0.0
    if (np.diff(r) < 0).any():
        raise InputError("recall must be non-decreasing (detections sorted by decreasing score)")
    r = np.concatenate([[0.0], r])
    p = np.concatenate([[0.0], p])
    envelope = np.maximum.accumulate(p[::-1])[::-1]
    return float(np.sum((r[1:] - r[:-1]) * envelope[1:]))
