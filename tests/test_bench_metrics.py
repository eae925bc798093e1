"""Detection metrics against hand-computed cases."""

from __future__ import annotations

import numpy as np
import pytest

from alcn_cv.bench.metrics import box_iou, match_detections, nms, pr_auc, precision_recall
from alcn_cv.errors import InputError


def test_box_iou_by_hand():
    iou = box_iou([[0, 0, 2, 2]], [[1, 1, 2, 2], [0, 0, 2, 2], [5, 5, 1, 1], [0, 0, 1, 2]])
    np.testing.assert_allclose(iou, [[1 / 7, 1.0, 0.0, 0.5]])
    assert box_iou(np.zeros((0, 4)), [[0, 0, 1, 1]]).shape == (0, 1)


def test_nms_by_hand():
    boxes = [[0, 0, 10, 10], [1, 0, 10, 10], [20, 20, 10, 10], [0, 1, 10, 10]]
    scores = [0.9, 0.8, 0.7, 0.95]
    # IoU(box0, box1) = 90 / 110 = 0.818; IoU(box3, box1) = 81 / 119 = 0.681; IoU(box3, box0) = 0.818
    np.testing.assert_array_equal(nms(boxes, scores, 0.5), [3, 2])
    np.testing.assert_array_equal(nms(boxes, scores, 0.7), [3, 1, 2])
    np.testing.assert_array_equal(nms(boxes, scores, 0.85), [3, 0, 1, 2])
    np.testing.assert_array_equal(nms(boxes, scores, 0.85, max_detections=2), [3, 0])
    assert nms(np.zeros((0, 4)), [], 0.5).size == 0


def test_match_detections_by_hand():
    gt = [[0, 0, 10, 10], [50, 50, 10, 10]]
    det = [[1, 0, 10, 10], [0, 0, 10, 10], [50, 52, 10, 10], [100, 100, 10, 10]]
    scores = [0.6, 0.9, 0.8, 0.99]
    # det1 takes gt0 first (higher score); det0 is a duplicate; det2 IoU 80/120 = 0.667
    np.testing.assert_array_equal(match_detections(det, scores, gt, 0.8), [False, True, False, False])
    np.testing.assert_array_equal(match_detections(det, scores, gt, 0.6), [False, True, True, False])
    assert not match_detections(det, scores, np.zeros((0, 4)), 0.5).any()


def test_precision_recall_and_auc_by_hand():
    p, r = precision_recall([0.6, 0.9, 0.7, 0.8], [False, True, True, False], num_positives=3)
    # by decreasing score: 0.9 TP, 0.8 FP, 0.7 TP, 0.6 FP
    np.testing.assert_allclose(p, [1, 1 / 2, 2 / 3, 1 / 2])
    np.testing.assert_allclose(r, [1 / 3, 1 / 3, 2 / 3, 2 / 3])
    # envelope 1 up to recall 1/3, 2/3 up to recall 2/3, nothing beyond
    assert pr_auc(p, r) == pytest.approx(1 / 3 + (1 / 3) * (2 / 3))
    assert pr_auc([], []) == 0.0
    perfect = precision_recall([3, 2, 1], [True, True, True], 3)
    assert pr_auc(*perfect) == pytest.approx(1.0)


def test_bad_arguments():
    with pytest.raises(InputError):
        box_iou([[0, 0, 1]], [[0, 0, 1, 1]])
    with pytest.raises(InputError):
        nms([[0, 0, 1, 1]], [0.5, 0.4], 0.5)
    with pytest.raises(InputError):
        nms([[0, 0, 1, 1]], [0.5], 1.0)
    with pytest.raises(InputError):
        precision_recall([0.5], [True], 0)
    with pytest.raises(InputError):
        pr_auc([1.0, 1.0], [0.5, 0.2])


def test_thresholds_are_inclusive_as_documented():
    boxes = [[0, 0, 10, 10], [0, 0, 10, 8]]
    assert box_iou(boxes[:1], boxes[1:])[0, 0] == 0.8  # 80 / 100, exactly
    # nms removes only a box overlapping the kept one with IoU strictly above the threshold
    np.testing.assert_array_equal(nms(boxes, [0.9, 0.8], 0.8), [0, 1])
    # PASCAL: a detection whose IoU equals the threshold is a true positive
    np.testing.assert_array_equal(match_detections(boxes[1:], [1.0], boxes[:1], 0.8), [True])


def test_auc_takes_the_interpolated_envelope():
    # by decreasing score TP, FP, TP, TP of 3 positives: precision 1, 1/2, 2/3, 3/4 at recall 1/3, 1/3, 2/3, 1
    p, r = precision_recall([4, 3, 2, 1], [True, False, True, True], 3)
    # the envelope: 1 up to recall 1/3, then 3/4 (the precision at recall 1, above the 2/3 before it)
    assert pr_auc(p, r) == pytest.approx(1 / 3 + (2 / 3) * (3 / 4))
