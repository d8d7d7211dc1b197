"""The EDEN paper's metrics: semantic mIoU over the 3DRMS classes and monocular depth errors.

Argument order is (prediction, ground truth) everywhere, as in torchmetrics.

Semantic segmentation
    ``confusion_matrix(pred, gt)`` counts pixels into a K x K int64 matrix,
    rows = ground truth, columns = prediction, K = 10 (``labels.NAMES``).
    Pixels whose ground truth is void (id 0) are dropped; a prediction of
    void on a labelled pixel stays in the matrix and counts as a miss of the
    true class. Ids outside 0..K-1 raise ``ValueError``.
    ``iou_per_class(conf)`` = TP / (TP + FP + FN) per class, NaN for void and
    for classes absent from both ground truth and prediction (no pixel in
    their row or column). ``mean_iou`` averages the non-NaN entries, so an
    absent class neither helps nor hurts; this equals torchmetrics'
    ``MulticlassJaccardIndex(num_classes=10, ignore_index=0, average="macro")``.
    Matrices add up, so accumulate over a dataset by summing (or with
    ``SegmentationMeter``): the dataset mIoU comes from the summed matrix,
    not from per-image means.

Depth (metres)
    On valid ground-truth pixels (g > 0 and finite, optionally g <= max_depth,
    and within ``mask`` when given), with predictions clamped to
    ``min_pred`` (1e-3 m; NaN predictions count as ``min_pred``):

        abs_rel = mean(|d - g| / g)
        log10   = mean(|log10 d - log10 g|)
        rms     = sqrt(mean((d - g)^2))
        delta1/2/3 = fraction of pixels with max(d/g, g/d) < 1.25, 1.25^2, 1.25^3

    Accumulation over images is pixel-weighted: ``DepthMeter`` sums the
    per-pixel terms and the pixel count over all images and divides once
    (so rms is the root of the mean over all pixels, not a mean of per-image
    rms). ``depth_metrics(pred, gt)`` is one image (or a stack) alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from eden_pipe import labels

NUM_CLASSES = len(labels.NAMES)
IGNORE_INDEX = labels.VOID
DELTA_BASE = 1.25
MIN_PRED = 1e-3


# ------------------------------------------------------------------ semantic
def confusion_matrix(pred, gt, num_classes: int = NUM_CLASSES, ignore_index: int | None = IGNORE_INDEX) -> np.ndarray:
    """(K, K) int64 counts, rows = ground truth, columns = prediction; pixels with gt == ignore_index are dropped."""
    p = np.asarray(pred)
    g = np.asarray(gt)
    if p.shape != g.shape:
        raise ValueError(f"prediction shape {p.shape} != ground-truth shape {g.shape}")
    if not (np.issubdtype(p.dtype, np.integer) and np.issubdtype(g.dtype, np.integer)):
        raise TypeError(f"label maps must be integer arrays, got {p.dtype} and {g.dtype}")
    p = p.ravel().astype(np.int64)
    g = g.ravel().astype(np.int64)
    if ignore_index is not None:
        keep = g != ignore_index
        p, g = p[keep], g[keep]
    for name, a in (("prediction", p), ("ground truth", g)):
        if a.size and (a.min() < 0 or a.max() >= num_classes):
            raise ValueError(f"{name} has ids outside 0..{num_classes - 1}")
    return np.bincount(g * num_classes + p, minlength=num_classes * num_classes).reshape(num_classes, num_classes)


def iou_per_class(conf: np.ndarray, ignore_index: int | None = IGNORE_INDEX) -> np.ndarray:
    """float64 (K,) IoU per class; NaN for ``ignore_index`` and for classes with no gt and no predicted pixel."""
    conf = np.asarray(conf, np.float64)
    tp = np.diag(conf)
    union = conf.sum(0) + conf.sum(1) - tp
    iou = np.full(conf.shape[0], np.nan)
    present = (conf.sum(0) + conf.sum(1)) > 0
    iou[present] = tp[present] / union[present]
    if ignore_index is not None and 0 <= ignore_index < conf.shape[0]:
        iou[ignore_index] = np.nan
    return iou


def mean_iou(conf: np.ndarray, ignore_index: int | None = IGNORE_INDEX) -> float:
    """Mean of the defined per-class IoUs (absent classes and void excluded); NaN when none is defined."""
    iou = iou_per_class(conf, ignore_index)
    return float(np.nanmean(iou)) if np.any(~np.isnan(iou)) else float("nan")


@dataclass
class SegmentationMeter:
    """Accumulates a confusion matrix over images: ``update(pred, gt)``, then ``compute()``."""

    num_classes: int = NUM_CLASSES
    ignore_index: int | None = IGNORE_INDEX
    confusion: np.ndarray = field(init=False)

    def __post_init__(self):
        self.confusion = np.zeros((self.num_classes, self.num_classes), np.int64)

    def update(self, pred, gt) -> SegmentationMeter:
        self.confusion += confusion_matrix(pred, gt, self.num_classes, self.ignore_index)
        return self

    def merge(self, other: SegmentationMeter) -> SegmentationMeter:
        self.confusion += other.confusion
        return self

    def compute(self) -> dict:
        """{"miou": float, "iou": {class name: IoU or NaN}, "pixels": labelled pixels counted}."""
        iou = iou_per_class(self.confusion, self.ignore_index)
        names = labels.NAMES if self.num_classes == NUM_CLASSES else [str(i) for i in range(self.num_classes)]
        return {
            "miou": mean_iou(self.confusion, self.ignore_index),
            "iou": {n: float(v) for n, v in zip(names, iou, strict=True)},
            "pixels": int(self.confusion.sum()),
        }


# --------------------------------------------------------------------- depth
_SUM_KEYS = ("abs_rel", "log10", "sq", "delta1", "delta2", "delta3")


def _depth_sums(pred, gt, mask=None, min_pred: float = MIN_PRED, max_depth: float | None = None) -> tuple[dict, int]:
    d = np.asarray(pred, np.float64)
    g = np.asarray(gt, np.float64)
    if d.shape != g.shape:
        raise ValueError(f"prediction shape {d.shape} != ground-truth shape {g.shape}")
    valid = np.isfinite(g) & (g > 0)
    if max_depth is not None:
        valid &= g <= max_depth
    if mask is not None:
        mask = np.asarray(mask, bool)
        if mask.shape != g.shape:
            raise ValueError(f"mask shape {mask.shape} != ground-truth shape {g.shape}")
        valid &= mask
    g = g[valid]
    d = np.maximum(np.nan_to_num(d[valid], nan=min_pred), min_pred)
    ratio = np.maximum(d / g, g / d)
    sums = {
        "abs_rel": float(np.sum(np.abs(d - g) / g)),
        "log10": float(np.sum(np.abs(np.log10(d) - np.log10(g)))),
        "sq": float(np.sum((d - g) ** 2)),
        "delta1": float(np.sum(ratio < DELTA_BASE)),
        "delta2": float(np.sum(ratio < DELTA_BASE**2)),
        "delta3": float(np.sum(ratio < DELTA_BASE**3)),
    }
    return sums, int(g.size)


def _finish(sums: dict, n: int) -> dict:
    if n == 0:
        out = {k: float("nan") for k in ("abs_rel", "log10", "rms", "delta1", "delta2", "delta3")}
    else:
        out = {
            "abs_rel": sums["abs_rel"] / n,
            "log10": sums["log10"] / n,
            "rms": math.sqrt(sums["sq"] / n),
            "delta1": sums["delta1"] / n,
            "delta2": sums["delta2"] / n,
            "delta3": sums["delta3"] / n,
        }
    out["pixels"] = n
    return out


def depth_metrics(pred, gt, mask=None, min_pred: float = MIN_PRED, max_depth: float | None = None) -> dict:
    """abs_rel, log10, rms, delta1..3 and the valid pixel count for one image (or any stack, pixel-weighted)."""
    sums, n = _depth_sums(pred, gt, mask, min_pred, max_depth)
    return _finish(sums, n)


@dataclass
class DepthMeter:
    """Pixel-weighted accumulation of the depth metrics over images: ``update(pred, gt)``, then ``compute()``."""

    min_pred: float = MIN_PRED
    max_depth: float | None = None
    sums: dict = field(default_factory=lambda: dict.fromkeys(_SUM_KEYS, 0.0))
    pixels: int = 0

    def update(self, pred, gt, mask=None) -> DepthMeter:
        sums, n = _depth_sums(pred, gt, mask, self.min_pred, self.max_depth)
        for k in _SUM_KEYS:
            self.sums[k] += sums[k]
        self.pixels += n
        return self

    def merge(self, other: DepthMeter) -> DepthMeter:
        for k in _SUM_KEYS:
            self.sums[k] += other.sums[k]
        self.pixels += other.pixels
        return self

    def compute(self) -> dict:
        return _finish(self.sums, self.pixels)
