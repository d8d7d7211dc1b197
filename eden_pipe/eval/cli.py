"""Score a folder of predictions against a dataset: ``python -m eden_pipe.eval DATASET --pred DIR``.

Prediction folder convention
    ``DIR/<relative path>`` where ``<relative path>`` is the manifest's
    ``semantic`` (or ``depth``) entry of the row, e.g.
    ``DIR/small-s3/clear/cam0/semantic/00002.png``.

    * semantic: a PNG of class ids 0..9 (``eden_pipe.labels``): a palette PNG
      (the indices are the ids, as the dataset writes them), a grayscale uint8
      or uint16 PNG (the values are the ids), or an RGB PNG in the 3DRMS
      colours (mapped back to ids; any other colour is an error).
    * depth: z-depth as a PNG uint16 in millimetres or a ``.npy`` float array
      in metres. The file named by the manifest is looked for first, then the
      same stem with the other extension (``.png`` <-> ``.npy``). In a
      prediction PNG, 0 mm means 0 m (clamped to 1 mm by the metrics), not
      "invalid": the ground truth alone decides which pixels count.

Scoring
    Every selected row (``--split``, ``--lighting``, ``--subsample``) whose
    ground-truth file exists is scored. A missing prediction is an error
    naming the file (exit code 2), unless ``--allow-missing``: then the row
    is skipped and counted (``missing`` in the JSON). The metrics are those of
    :mod:`eden_pipe.eval.metrics`: mIoU from the confusion matrix summed over
    all scored images (void ground truth ignored), depth errors pixel-weighted
    over all valid ground-truth pixels. Results are given per lighting and
    overall (all selected lightings together).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from PIL import Image

from eden_pipe import labels
from eden_pipe.data import manifest_reader
from eden_pipe.eval.metrics import DepthMeter, SegmentationMeter
from eden_pipe.io.formats import read_modality

TASKS = {"semantic": ("semantic",), "depth": ("depth",), "both": ("semantic", "depth")}
DEPTH_KEYS = ("abs_rel", "log10", "rms", "delta1", "delta2", "delta3")


class EvalError(Exception):
    """A user-facing error: bad arguments, a missing or unreadable prediction."""


# ------------------------------------------------------------------ reading
def load_manifest(root: Path) -> pd.DataFrame:
    try:
        return manifest_reader.load_manifest(root)
    except FileNotFoundError as exc:
        raise EvalError(str(exc)) from exc


def select_rows(df: pd.DataFrame, split: str | None = "test", lightings=None, subsample: bool = False) -> pd.DataFrame:
    """Rows of ``split`` ("all" or None = every split), of the given lightings, and of the test subsample if asked."""
    if lightings:
        known = set(df["lighting"].astype(str))
        unknown = [name for name in lightings if name not in known]
        if unknown:
            raise EvalError(f"lighting(s) {', '.join(unknown)} not in the manifest (has: {', '.join(sorted(known))})")
    try:
        return manifest_reader.filter_manifest(
            df, split=None if split in (None, "", "all") else split, lighting=lightings or None, subsample=subsample
        )
    except ValueError as exc:  # a subsample asked of a manifest without the column
        raise EvalError(str(exc)) from exc


def read_semantic_prediction(path: Path) -> np.ndarray:
    """Class ids (int64) from a palette, grayscale or 3DRMS-colour RGB PNG."""
    with Image.open(path) as img:
        mode = img.mode
        if mode in ("P", "L"):
            return np.asarray(img, dtype=np.int64)
        if mode.startswith("I"):
            return np.asarray(img).astype(np.int64)
        if mode in ("RGB", "RGBA"):
            rgb = np.asarray(img.convert("RGB"), dtype=np.int64)
        else:
            raise EvalError(f"{path}: unsupported PNG mode {mode} for a semantic prediction")
    code = (rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]
    colours = labels.COLORS.astype(np.int64)
    table = {int((r << 16) | (g << 8) | b): i for i, (r, g, b) in enumerate(colours)}
    out = np.full(code.shape, -1, np.int64)
    for c, i in table.items():
        out[code == c] = i
    if np.any(out < 0):
        bad = rgb[out < 0][0]
        raise EvalError(f"{path}: colour {tuple(int(v) for v in bad)} is not a 3DRMS class colour")
    return out


def read_depth_prediction(path: Path) -> np.ndarray:
    """Metres: ``.npy`` as is, PNG uint16 millimetres / 1000 (0 stays 0)."""
    if path.suffix == ".npy":
        arr = np.load(path)
        if arr.ndim == 3 and arr.shape[-1] == 1:
            arr = arr[..., 0]
        return np.asarray(arr)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise EvalError(f"cannot read depth prediction {path}")
    if img.ndim != 2 or img.dtype != np.uint16:
        raise EvalError(
            f"{path}: a depth prediction PNG must be single-channel uint16 millimetres, "
            f"got {img.dtype} with shape {img.shape}"
        )
    return img.astype(np.float32) / np.float32(1000.0)  # as the dataset's own reader, so a copied PNG is exact


def prediction_path(pred_dir: Path, rel: str, task: str) -> Path | None:
    """The prediction file for ground truth ``rel`` (None when absent); depth also tries the other extension."""
    p = Path(pred_dir) / rel
    if p.is_file():
        return p
    if task == "depth":
        alt = p.with_suffix(".npy" if p.suffix != ".npy" else ".png")
        if alt.is_file():
            return alt
    return None


# ------------------------------------------------------------------ scoring
def evaluate(
    dataset,
    pred_dir,
    split: str | None = "test",
    lightings=None,
    subsample: bool = False,
    task: str = "both",
    allow_missing: bool = False,
    max_depth: float | None = None,
) -> dict:
    """Score ``pred_dir`` against ``dataset``; returns the result dict written as JSON (NaN kept as float)."""
    root, pred_dir = Path(dataset), Path(pred_dir)
    if task not in TASKS:
        raise EvalError(f"unknown task {task!r}; one of {', '.join(TASKS)}")
    if not pred_dir.is_dir():
        raise EvalError(f"prediction folder {pred_dir} does not exist")
    df = load_manifest(root)
    rows = select_rows(df, split, lightings, subsample)
    if len(rows) == 0:
        raise EvalError(
            f"no manifest row selected (split {split!r}, lightings {lightings or 'all'}, "
            f"subsample {bool(subsample)}); splits present: {', '.join(sorted(set(df['split'].astype(str))))}"
        )
    result: dict = {
        "dataset": str(root),
        "pred": str(pred_dir),
        "split": split or "all",
        "subsample": bool(subsample),
        "lightings": sorted(set(rows["lighting"])) if len(rows) else [],
        "rows_selected": int(len(rows)),
    }
    for t in TASKS[task]:
        if t not in df.columns:
            raise EvalError(f"the manifest has no {t!r} column")
        meters: dict[str, Any] = {}  # per lighting, the task's meter (SegmentationMeter or DepthMeter)
        images: dict[str, int] = {}
        scored, missing, no_gt = 0, [], 0
        for rec in rows.to_dict("records"):
            rel = str(rec[t]).strip()
            gt_path = root / rel
            if not rel or not gt_path.is_file():
                no_gt += 1
                continue
            pp = prediction_path(pred_dir, rel, t)
            if pp is None:
                if not allow_missing:
                    raise EvalError(
                        f"missing {t} prediction {pred_dir / rel} (for ground truth {gt_path}); "
                        f"use --allow-missing to skip such rows"
                    )
                missing.append(rel)
                continue
            light = str(rec["lighting"])
            if t == "semantic":
                gt = read_modality(gt_path, "semantic").astype(np.int64)
                pred = read_semantic_prediction(pp)
                meter = meters.setdefault(light, SegmentationMeter())
            else:
                gt = read_modality(gt_path, "depth")
                pred = read_depth_prediction(pp)
                meter = meters.setdefault(light, DepthMeter(max_depth=max_depth))
            if pred.shape != gt.shape:
                raise EvalError(f"{pp}: prediction shape {pred.shape} != ground-truth shape {gt.shape}")
            try:
                meter.update(pred, gt)
            except ValueError as exc:
                raise EvalError(f"{pp}: {exc}") from exc
            scored += 1
            images[light] = images.get(light, 0) + 1
        total = SegmentationMeter() if t == "semantic" else DepthMeter(max_depth=max_depth)
        for m in meters.values():
            total.merge(m)
        result[t] = {
            "images": scored,
            "missing": len(missing),
            "missing_files": missing,
            "no_ground_truth": no_gt,
            "per_lighting": {k: {**meters[k].compute(), "images": images[k]} for k in sorted(meters)},
            "overall": {**total.compute(), "images": scored},
        }
    return result


# ------------------------------------------------------------------ output
def _fmt(v, pct: bool = False) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "-"
    return f"{100 * v:.1f}" if pct else f"{v:.4f}"


def format_tables(result: dict) -> str:
    """Markdown tables: semantic (mIoU and per-class IoU, %) and depth, one row per lighting plus overall."""
    out = []
    if "semantic" in result:
        sem = result["semantic"]
        classes = [n for i, n in enumerate(labels.NAMES) if i != labels.VOID]
        head = ["lighting", "images", "mIoU", *classes]
        out.append(f"semantic segmentation ({sem['images']} images, {sem['missing']} missing predictions), IoU in %")
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "---|" * len(head))
        entries = [*sem["per_lighting"].items(), ("overall", sem["overall"])]
        for name, r in entries:
            cells = [
                name if name != "overall" else "**overall**",
                str(r["images"]),
                _fmt(r["miou"], True),
                *(_fmt(r["iou"][c], True) for c in classes),
            ]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    if "depth" in result:
        dep = result["depth"]
        head = ["lighting", "images", "abs rel", "log10", "rms (m)", "delta1", "delta2", "delta3"]
        out.append(f"depth ({dep['images']} images, {dep['missing']} missing predictions)")
        out.append("| " + " | ".join(head) + " |")
        out.append("|" + "---|" * len(head))
        for name, r in [*dep["per_lighting"].items(), ("overall", dep["overall"])]:
            cells = [name if name != "overall" else "**overall**", str(r["images"]), *(_fmt(r[k]) for k in DEPTH_KEYS)]
            out.append("| " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def _jsonable(obj):
    if isinstance(obj, float):
        return None if math.isnan(obj) or math.isinf(obj) else obj
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    return obj


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m eden_pipe.eval",
        description="Score semantic and/or depth predictions against an eden-pipe dataset "
        "(EDEN metrics: mIoU, per-class IoU; abs rel, log10, rms, delta1..3).",
    )
    p.add_argument("dataset", help="dataset root (holds manifest.csv)")
    p.add_argument("--pred", required=True, help="prediction folder mirroring the manifest's relative paths")
    p.add_argument("--split", default="test", help="split to score: train, val, test or all (default: test)")
    p.add_argument("--subsample", action="store_true", help="only rows whose test_subsample column is 1")
    p.add_argument(
        "--lighting",
        action="append",
        default=None,
        help="lighting(s) to score (repeat or comma-separate; default: all)",
    )
    p.add_argument("--task", choices=tuple(TASKS), default="both")
    p.add_argument("--allow-missing", action="store_true", help="skip (and count) rows without a prediction")
    p.add_argument("--max-depth", type=float, default=None, help="ignore ground-truth depth beyond this (metres)")
    p.add_argument("--out", default=None, help="write the scores as JSON here")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    lightings = None
    if args.lighting:
        lightings = [name.strip() for item in args.lighting for name in item.split(",") if name.strip()]
    try:
        result = evaluate(
            args.dataset,
            args.pred,
            split=args.split,
            lightings=lightings,
            subsample=args.subsample,
            task=args.task,
            allow_missing=args.allow_missing,
            max_depth=args.max_depth,
        )
    except (EvalError, FileNotFoundError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(format_tables(result))
    if args.out:
        out = Path(args.out)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(_jsonable(result), indent=2) + "\n", encoding="utf-8")
        print(f"scores written to {out}")
    return 0
