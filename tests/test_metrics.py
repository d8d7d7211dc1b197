"""Semantic mIoU against torchmetrics, depth metrics against hand-computed values."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.eval import DepthMeter, SegmentationMeter, confusion_matrix, depth_metrics, iou_per_class, mean_iou


def _torch_miou(preds, targets):
    torch = pytest.importorskip("torch", reason="the reference is torchmetrics: pip install -e '.[test,test-torch]'")
    pytest.importorskip("torchmetrics", reason="pip install -e '.[test,test-torch]'")
    from torchmetrics.classification import MulticlassJaccardIndex

    metric = MulticlassJaccardIndex(num_classes=10, ignore_index=0, average="macro")
    for p, t in zip(preds, targets, strict=True):
        metric.update(torch.from_numpy(p.astype(np.int64)), torch.from_numpy(t.astype(np.int64)))
    return float(metric.compute())


def test_miou_matches_torchmetrics_on_random_data():
    rng = np.random.default_rng(0)
    for _ in range(5):
        # some classes absent from both gt and prediction (torchmetrics drops them from the macro mean too),
        # voids in the gt, void predicted on labelled pixels, noisy predictions
        classes = rng.choice(np.arange(1, 10), size=rng.integers(3, 9), replace=False)
        gts = [rng.choice(np.r_[0, classes], size=(24, 32)).astype(np.uint8) for _ in range(3)]
        preds = []
        for g in gts:
            p = g.copy()
            flip = rng.random(g.shape) < 0.3
            p[flip] = rng.choice(np.r_[0, classes], size=int(flip.sum()))
            preds.append(p)
        meter = SegmentationMeter()
        for p, g in zip(preds, gts, strict=True):
            meter.update(p, g)
        ours = meter.compute()["miou"]
        assert ours == pytest.approx(_torch_miou(preds, gts), abs=1e-6)
        absent = [c for c in range(1, 10) if c not in classes]
        assert all(math.isnan(meter.compute()["iou"][labels.NAMES[c]]) for c in absent)


def test_class_predicted_only_is_present_with_zero_iou():
    gt = np.array([[1, 1, 2, 0]])
    pred = np.array([[1, 3, 2, 5]])  # 5 falls on a void pixel: dropped, so class 5 stays absent
    conf = confusion_matrix(pred, gt)
    iou = iou_per_class(conf)
    assert iou[1] == 0.5 and iou[2] == 1.0 and iou[3] == 0.0 and np.isnan(iou[5]) and np.isnan(iou[0])
    assert mean_iou(conf) == pytest.approx(0.5)
    assert mean_iou(conf) == pytest.approx(_torch_miou([pred], [gt]), abs=1e-6)


def test_confusion_matrix_layout_and_errors():
    conf = confusion_matrix(np.array([0, 2, 2]), np.array([1, 1, 2]))
    assert conf[1, 0] == 1 and conf[1, 2] == 1 and conf[2, 2] == 1 and conf.sum() == 3
    with pytest.raises(ValueError):
        confusion_matrix(np.array([10]), np.array([1]))
    with pytest.raises(ValueError):
        confusion_matrix(np.array([1, 2]), np.array([1]))
    assert math.isnan(mean_iou(confusion_matrix(np.array([3]), np.array([0]))))


def test_depth_metrics_hand_computed():
    gt = np.array([[1.0, 2.0], [4.0, 10.0]])
    pred = np.array([[1.1, 1.0], [4.0, 20.0]])
    m = depth_metrics(pred, gt)
    assert m["pixels"] == 4
    assert m["abs_rel"] == pytest.approx((0.1 + 0.5 + 0.0 + 1.0) / 4)
    assert m["log10"] == pytest.approx((math.log10(1.1) + math.log10(2) + 0 + math.log10(2)) / 4)
    assert m["rms"] == pytest.approx(math.sqrt((0.01 + 1 + 0 + 100) / 4))
    # ratios 1.1, 2, 1, 2: < 1.25 twice, < 1.5625 twice, < 1.953125 twice
    assert (m["delta1"], m["delta2"], m["delta3"]) == (0.5, 0.5, 0.5)
    m = depth_metrics(np.array([1.9, 1.6, 1.3]), np.array([1.0, 1.0, 1.0]))
    assert (m["delta1"], m["delta2"], m["delta3"]) == pytest.approx((0.0, 1 / 3, 1.0))


def test_depth_invalid_gt_and_clamped_predictions():
    gt = np.array([0.0, np.inf, np.nan, -1.0, 2.0, 1.0])
    pred = np.array([5.0, 5.0, 5.0, 5.0, 0.0, np.nan])  # 0 and NaN predictions count as min_pred
    m = depth_metrics(pred, gt)
    assert m["pixels"] == 2
    assert m["abs_rel"] == pytest.approx(((2 - 1e-3) / 2 + (1 - 1e-3) / 1) / 2)
    assert m["log10"] == pytest.approx((math.log10(2 / 1e-3) + 3.0) / 2)
    assert m["delta3"] == 0.0
    assert depth_metrics(pred, gt, mask=np.array([1, 1, 1, 1, 0, 1], bool))["pixels"] == 1
    assert depth_metrics(np.ones(3), np.array([1.0, 50.0, 100.0]), max_depth=80)["pixels"] == 2
    empty = depth_metrics(np.ones(2), np.zeros(2))
    assert empty["pixels"] == 0 and math.isnan(empty["rms"])


def test_depth_accumulation_is_pixel_weighted():
    a_gt, a_pred = np.array([1.0]), np.array([2.0])  # 1 pixel, abs_rel 1, sq 1
    b_gt, b_pred = np.full(3, 2.0), np.full(3, 2.0)  # 3 pixels, exact
    meter = DepthMeter().update(a_pred, a_gt).update(b_pred, b_gt)
    m = meter.compute()
    assert m["pixels"] == 4 and m["abs_rel"] == pytest.approx(0.25) and m["rms"] == pytest.approx(0.5)
    assert m["delta1"] == pytest.approx(0.75)
    joint = depth_metrics(np.r_[a_pred, b_pred], np.r_[a_gt, b_gt])
    assert all(m[k] == pytest.approx(joint[k]) for k in m)
    other = DepthMeter().update(a_pred, a_gt)
    merged = other.merge(DepthMeter().update(b_pred, b_gt)).compute()
    assert merged == pytest.approx(m)


def test_segmentation_meter_merge_equals_one_pass():
    rng = np.random.default_rng(5)
    gts = [rng.integers(0, 10, (8, 8)) for _ in range(4)]
    preds = [rng.integers(0, 10, (8, 8)) for _ in range(4)]
    one = SegmentationMeter()
    for p, g in zip(preds, gts, strict=True):
        one.update(p, g)
    a, b = SegmentationMeter(), SegmentationMeter()
    for i, (p, g) in enumerate(zip(preds, gts, strict=True)):
        (a if i % 2 else b).update(p, g)
    assert np.array_equal(a.merge(b).confusion, one.confusion)
    assert one.compute()["pixels"] == sum(int((g != 0).sum()) for g in gts)
