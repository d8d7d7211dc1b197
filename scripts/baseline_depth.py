"""The depth task of ``scripts/train_baseline.py`` (``--task depth``): its data, loss, scores and table.

The network is the segmentation baseline's (``--model small|lraspp``) with one output channel, read as the
natural log of the z-depth in metres, trained with the scale-invariant log error of Eigen et al. (2014) on the
valid pixels of each image (sky and missing depth excluded):

    e = log d - log g,   loss = mean(e^2) - LAMBDA * mean(e)^2   (per image, then averaged over the batch)

LAMBDA = 0.5 keeps half of the absolute-scale term: the EDEN paper's depth table (rel, log10, rms) scores
metric depth without rescaling, so the network must learn the scale as well as the shape.

Scores are ``eden_pipe.eval.metrics.DepthMeter`` per lighting of the test images (pixel-weighted; valid
ground truth only) and its merge over all of them, in the dict shape of ``eden_pipe.eval.cli.evaluate``'s
depth entry, printed by ``eden_pipe.eval.cli.format_tables``; ``--pred-out`` writes float32 ``.npy`` metres
at the manifest's depth paths, which ``python -m eden_pipe.eval --task depth`` scores to the same numbers
(docs/evaluation.md).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from eden_pipe.data import EdenDataset
from eden_pipe.eval.cli import format_tables
from eden_pipe.eval.metrics import DepthMeter

LAMBDA = 0.5  # Eigen et al.'s scale-invariant weight (module docstring)
MAX_LOG_DEPTH = math.log(1e4)  # a bound on the predicted log-depth, so exp never overflows to inf


def load_depth_split(root, split: str, lightings=None, size=None) -> dict:
    """Every row of ``split`` (and ``lightings``) with rgb and depth, in memory.

    Returns {"rgb": float32 (N,3,H,W) in [0,1], "depth": float32 (N,1,H,W) metres with 0 where invalid,
    "lighting": [str], "depth_path": [relative path]}; ``size`` = (W, H) resizes (depth nearest, so no
    valid pixel is blended with the sky's 0).
    """
    ds = EdenDataset(root, ("rgb", "depth"), split=split, lighting=lightings)
    if len(ds) == 0:
        raise SystemExit(
            f"no {split} rows with rgb and depth in {root}"
            + (f" for lighting(s) {', '.join(lightings)}" if lightings else "")
        )
    items = [ds[i] for i in range(len(ds))]
    rgb = torch.stack([item["rgb"] for item in items])
    depth = torch.stack([item["depth"] for item in items])
    if size is not None and tuple(rgb.shape[-2:]) != (size[1], size[0]):
        hw = (size[1], size[0])
        rgb = F.interpolate(rgb, size=hw, mode="bilinear", align_corners=False, antialias=True)
        depth = F.interpolate(depth, size=hw, mode="nearest")
    return {
        "rgb": rgb,
        "depth": depth,
        "lighting": [str(item["lighting"]) for item in items],
        "depth_path": [str(rec["depth"]) for rec in ds.records],
    }


def log_depth_loss(out: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Scale-invariant log error (module docstring) of log-depth ``out`` (N,1,H,W) against metres ``target``
    (N,1,H,W; 0 = invalid, excluded); an image without a valid pixel adds 0."""
    valid = target > 0
    e = torch.where(valid, out - torch.log(torch.where(valid, target, torch.ones_like(target))), 0.0)
    n = valid.sum(dim=(1, 2, 3)).clamp_min(1)
    mean = e.sum(dim=(1, 2, 3)) / n
    mean_sq = (e * e).sum(dim=(1, 2, 3)) / n
    return (mean_sq - LAMBDA * mean * mean).mean()


def depth_from_output(out: torch.Tensor) -> torch.Tensor:
    """Metres (N,H,W) from the network's log-depth (N,1,H,W)."""
    return torch.exp(out[:, 0].clamp(max=MAX_LOG_DEPTH))


def score_depth(pred: torch.Tensor, data: dict, order=()) -> dict:
    """``DepthMeter`` per lighting (listed in ``order``, then any other) and overall, in the shape of
    ``eden_pipe.eval.cli.evaluate(...)["depth"]``."""
    meters: dict[str, DepthMeter] = {}
    images: dict[str, int] = {}
    gt = data["depth"][:, 0].numpy()
    for d, g, light in zip(pred.numpy(), gt, data["lighting"], strict=True):  # one of each per image
        meters.setdefault(light, DepthMeter()).update(d, g)
        images[light] = images.get(light, 0) + 1
    total = DepthMeter()
    for m in meters.values():
        total.merge(m)
    ranked = sorted(meters, key=lambda name: (list(order) + [name]).index(name))
    return {
        "images": len(gt),
        "missing": 0,
        "missing_files": [],
        "no_ground_truth": 0,
        "per_lighting": {k: {**meters[k].compute(), "images": images[k]} for k in ranked},
        "overall": {**total.compute(), "images": len(gt)},
    }


def write_depth_predictions(pred: torch.Tensor, data: dict, pred_dir) -> None:
    """float32 metres as ``.npy`` at each manifest depth path (the eval CLI tries ``.npy`` after ``.png``)."""
    for d, rel in zip(pred.numpy(), data["depth_path"], strict=True):  # pred: one per image of data
        path = (Path(pred_dir) / rel).with_suffix(".npy")
        path.parent.mkdir(parents=True, exist_ok=True)
        np.save(path, d.astype(np.float32))


def format_depth_table(train_set: str, result: dict) -> str:
    """The eval CLI's depth table of one model, titled with its training set."""
    return f"train: {train_set}; " + format_tables({"depth": result}).strip()
