"""Evaluation: the EDEN paper's semantic and depth metrics (``eden_pipe.eval.metrics``)."""

from eden_pipe.eval.metrics import (
    DepthMeter,
    SegmentationMeter,
    confusion_matrix,
    depth_metrics,
    iou_per_class,
    mean_iou,
)

__all__ = ["DepthMeter", "SegmentationMeter", "confusion_matrix", "depth_metrics", "iou_per_class", "mean_iou"]
