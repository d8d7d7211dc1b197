"""Export an eden-pipe dataset to other benchmarks' layouts (docs/exports.md).

    python -m eden_pipe.tools.export DATASET --format {3drms,coco,kitti_flow,nerfstudio,webdataset,hf} --out DIR
                                     [--split S] [--lighting L] [--garden G] [--stages DIR] [--points N]
                                     [--shard-size N|SIZE] [--seed S]

Every file is read through :func:`eden_pipe.io.formats.read_modality`; numpy,
OpenCV and Pillow only (pycocotools for ``coco``). Pixel centres are at integer
coordinates in the source (OpenCV); the exports keep that except nerfstudio,
whose principal point is shifted by +0.5 px (its pixel centres are at i + 0.5).
The shard formats (webdataset, hf) live in :mod:`eden_pipe.tools.shards`.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import sys
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
from PIL import Image

from eden_pipe import labels
from eden_pipe.data.manifest_reader import filter_manifest, load_manifest, rotation_to_quaternion, row_pose
from eden_pipe.io import kitti
from eden_pipe.io.formats import read_modality
from eden_pipe.tools.scene_geometry import load_geometry, locate_geometry, sample_points, write_ply
from eden_pipe.tools.shards import DEFAULT_SHARD_SIZE, SHARD_FORMATS, check_arguments, export_shards

FORMATS = ("3drms", "coco", "kitti_flow", "nerfstudio", *SHARD_FORMATS)
# The flip between OpenCV (x right, y down, z forward) and OpenGL (x right, y up, z back) camera axes.
CV_TO_GL = np.diag([1.0, -1.0, -1.0, 1.0])


def _log(msg: str) -> None:
    print(f"[eden-pipe export] {msg}", file=sys.stderr)


def _read(root: Path, rec, column: str) -> np.ndarray:
    return read_modality(root / rec[column], column)


def _copy_rgb(root: Path, rec, column: str, dst: Path) -> None:
    """Copy an sRGB image as PNG (byte copy when the source already is one)."""
    dst.parent.mkdir(parents=True, exist_ok=True)
    src = root / rec[column]
    if src.suffix.lower() == ".png":
        shutil.copyfile(src, dst)
    else:
        cv2.imwrite(str(dst), np.ascontiguousarray(_read(root, rec, column)[..., ::-1]))


def _finite_depth(depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    depth = np.asarray(depth, np.float64)
    valid = np.isfinite(depth) & (depth > 0)
    return np.where(valid, depth, 0.0), valid


def select_rows(root: str | os.PathLike, split=None, lighting=None, garden=None) -> pd.DataFrame:
    rows = filter_manifest(load_manifest(root), split=split, lighting=lighting, garden=garden)
    if rows.empty:
        raise SystemExit(f"no manifest rows in {root} match split={split} lighting={lighting} garden={garden}")
    return rows.sort_values(["garden", "lighting", "camera", "frame"]).reset_index(drop=True)


# ===================================================================== 3DRMS
def world_to_camera_line(pose_c2w: np.ndarray, rec) -> str:
    """``fx fy cx cy qw qx qy qz tx ty tz`` with (q, t) the world-to-camera transform (OpenCV axes)."""
    rot_wc = pose_c2w[:3, :3].T
    t_wc = -rot_wc @ pose_c2w[:3, 3]
    q = rotation_to_quaternion(rot_wc)
    values = [float(rec["fx"]), float(rec["fy"]), float(rec["cx"]), float(rec["cy"]), *q, *t_wc]
    return " ".join(f"{v:.9g}" for v in values) + "\n"


def write_dmap(path: Path, depth: np.ndarray) -> None:
    """float32 big-endian, H x W stored column-major; 0 where there is no surface (sky)."""
    d, _ = _finite_depth(depth)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.asarray(d, ">f4").ravel(order="F").tofile(path)


def write_indexed_labels(path: Path, ids: np.ndarray) -> None:
    img = Image.fromarray(np.asarray(ids, np.uint8), mode="P")
    img.putpalette(labels.palette_rgb().ravel().tolist())
    path.parent.mkdir(parents=True, exist_ok=True)
    img.save(path, format="PNG")


def export_3drms(root, out, rows: pd.DataFrame, *, stages=None, points: int = 1_000_000, seed: int = 0) -> dict:
    """``OUT/<garden>/<lighting>/vcam_X/vcam_X_fNNNNN_{undist.png,gtr.png,cam.txt,dmap.bin}`` and
    ``OUT/<garden>/<garden>_semantic.ply``. Pair k's left camera is vcam_{2k}, its right one vcam_{2k+1}.
    The point cloud samples the garden's published mesh (``<garden>/geometry.ply``); ``stages`` is only
    needed for datasets published without it."""
    root, out = Path(root), Path(out)
    facts: dict[str, Any] = {"images": 0, "ply": []}
    for rec in rows.to_dict("records"):
        base = out / rec["garden"] / rec["lighting"]
        k, frame = int(rec["camera"]), int(rec["frame"])
        for side, vcam in (("left", 2 * k), ("right", 2 * k + 1)):
            rgb_col, depth_col = ("rgb_left", "depth") if side == "left" else ("rgb_right", "depth_right")
            if not rec.get(rgb_col):
                continue
            stem = base / f"vcam_{vcam}" / f"vcam_{vcam}_f{frame:05d}"
            _copy_rgb(root, rec, rgb_col, Path(f"{stem}_undist.png"))
            Path(f"{stem}_cam.txt").write_text(world_to_camera_line(row_pose(rec, right=side == "right"), rec))
            if rec.get(depth_col):
                write_dmap(Path(f"{stem}_dmap.bin"), _read(root, rec, depth_col))
            if side == "left" and rec.get("semantic"):  # only the left camera has rendered labels
                write_indexed_labels(Path(f"{stem}_gtr.png"), _read(root, rec, "semantic"))
            facts["images"] += 1
    for garden in sorted(rows["garden"].unique()):
        geometry = locate_geometry(garden, dataset_root=root, stages=stages)
        if geometry is None:
            where = f"--stages {stages}" if stages else "no --stages given"
            _log(
                f"3drms: no scene geometry found for garden {garden} (no {garden}/geometry.ply in the dataset, "
                f"{where}); skipping its semantic point cloud"
            )
            continue
        sample = sample_points(load_geometry(geometry), points, seed=seed)
        ply = out / garden / f"{garden}_semantic.ply"
        write_ply(ply, sample["points"], sample["label"], sample["instance"])
        facts["ply"].append(str(ply))
    return facts


# ====================================================================== COCO
def coco_categories() -> list[dict]:
    return [
        {"id": i, "name": labels.NAMES[i], "supercategory": "garden"}
        for i in range(len(labels.NAMES))
        if i not in (labels.VOID, labels.BACKGROUND)
    ]


def majority_class(semantic: np.ndarray, mask: np.ndarray) -> int | None:
    """Most frequent semantic id under ``mask``, ignoring void and background; None if none."""
    counts = np.bincount(semantic[mask].astype(np.int64), minlength=len(labels.NAMES))
    counts[labels.VOID] = 0
    counts[labels.BACKGROUND] = 0
    return int(counts.argmax()) if counts.sum() > 0 else None


def export_coco(root, out, rows: pd.DataFrame, *, name: str = "all") -> dict:
    """``OUT/images/<garden>/<lighting>/cam<k>/<frame>.png`` + ``OUT/annotations/instances_<name>.json``."""
    from pycocotools import mask as mask_utils

    root, out = Path(root), Path(out)
    images: list[dict] = []
    annotations: list[dict] = []
    for rec in rows.to_dict("records"):
        if not (rec.get("instance") and rec.get("semantic") and rec.get("rgb_left")):
            continue
        rel = (
            Path("images")
            / rec["garden"]
            / rec["lighting"]
            / f"cam{int(rec['camera'])}"
            / f"{int(rec['frame']):05d}.png"
        )
        _copy_rgb(root, rec, "rgb_left", out / rel)
        inst = _read(root, rec, "instance").astype(np.int64)
        sem = _read(root, rec, "semantic")
        image_id = len(images) + 1
        h, w = inst.shape
        images.append(
            {
                "id": image_id,
                "file_name": rel.as_posix(),
                "width": int(w),
                "height": int(h),
                "garden": rec["garden"],
                "lighting": rec["lighting"],
                "camera": int(rec["camera"]),
                "frame": int(rec["frame"]),
            }
        )
        for inst_id in np.unique(inst):
            if inst_id == 0:
                continue
            mask = inst == inst_id
            cat = majority_class(sem, mask)
            if cat is None:
                continue
            rle = mask_utils.encode(np.asfortranarray(mask.astype(np.uint8)))
            area = float(mask_utils.area(rle))
            bbox = [float(v) for v in mask_utils.toBbox(rle)]
            rle["counts"] = rle["counts"].decode("ascii")
            annotations.append(
                {
                    "id": len(annotations) + 1,
                    "image_id": image_id,
                    "category_id": cat,
                    "segmentation": rle,
                    "area": area,
                    "bbox": bbox,
                    "iscrowd": 0,
                    "eden_instance_id": int(inst_id),
                }
            )
    data = {
        "info": {"description": "eden-pipe instance segmentation export", "version": "1.0"},
        "licenses": [],
        "images": images,
        "annotations": annotations,
        "categories": coco_categories(),
    }
    path = out / "annotations" / f"instances_{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))
    return {"images": len(images), "annotations": len(annotations), "json": str(path)}


# ================================================================ KITTI flow
def export_kitti_flow(root, out, rows: pd.DataFrame) -> dict:
    """KITTI 2015 style: image_2/NNNNNN_1{0,1}.png (left t, t+1), image_3 (right), flow_occ/ and flow_noc/
    NNNNNN_10.png (forward flow of the left camera), disp_occ_0/NNNNNN_10.png (left disparity at t),
    calib/NNNNNN.txt and index.csv (id -> garden, lighting, camera, frame)."""
    root, out = Path(root), Path(out)
    full = load_manifest(root)
    by_key = {(r["garden"], r["lighting"], int(r["camera"]), int(r["frame"])): r for r in full.to_dict("records")}
    index: list[dict] = []
    for rec in rows.to_dict("records"):
        nxt = by_key.get((rec["garden"], rec["lighting"], int(rec["camera"]), int(rec["frame"]) + 1))
        if not rec.get("flow_fwd") or nxt is None:
            continue
        n = len(index)
        name = f"{n:06d}"
        _copy_rgb(root, rec, "rgb_left", out / "image_2" / f"{name}_10.png")
        _copy_rgb(root, nxt, "rgb_left", out / "image_2" / f"{name}_11.png")
        if rec.get("rgb_right") and nxt.get("rgb_right"):
            _copy_rgb(root, rec, "rgb_right", out / "image_3" / f"{name}_10.png")
            _copy_rgb(root, nxt, "rgb_right", out / "image_3" / f"{name}_11.png")
        flow = _read(root, rec, "flow_fwd")
        occ = _read(root, rec, "occ_fwd") > 0 if rec.get("occ_fwd") else np.zeros(flow.shape[:2], bool)
        # The writer marks flow beyond KITTI's +-512 px invalid rather than clipping it.
        kitti.write_kitti_flow(out / "flow_occ" / f"{name}_10.png", flow)
        kitti.write_kitti_flow(out / "flow_noc" / f"{name}_10.png", flow, ~occ)
        if rec.get("depth"):
            depth, valid = _finite_depth(_read(root, rec, "depth"))
            disp = np.where(valid, float(rec["fx"]) * float(rec["baseline"]) / np.where(valid, depth, 1.0), 0.0)
            kitti.write_kitti_disparity(out / "disp_occ_0" / f"{name}_10.png", disp, disp <= kitti.DISP_MAX)
        (out / "calib").mkdir(parents=True, exist_ok=True)
        (out / "calib" / f"{name}.txt").write_text(
            f"K: {rec['fx']} 0 {rec['cx']} 0 {rec['fy']} {rec['cy']} 0 0 1\nbaseline: {rec['baseline']}\n"
        )
        index.append(
            {
                "id": name,
                "garden": rec["garden"],
                "lighting": rec["lighting"],
                "camera": int(rec["camera"]),
                "frame": int(rec["frame"]),
                "fx": rec["fx"],
                "baseline": rec["baseline"],
            }
        )
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "index.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=["id", "garden", "lighting", "camera", "frame", "fx", "baseline"])
        writer.writeheader()
        writer.writerows(index)
    return {"pairs": len(index)}


# ================================================================ nerfstudio
def opencv_to_nerfstudio(pose_c2w: np.ndarray) -> np.ndarray:
    """Camera-to-world with OpenCV camera axes -> nerfstudio's (OpenGL axes: flip the y and z columns)."""
    return np.asarray(pose_c2w, np.float64) @ CV_TO_GL


def export_nerfstudio(root, out, rows: pd.DataFrame, *, right: bool = True) -> dict:
    """One scene per garden and lighting: ``OUT/<garden>/<lighting>/transforms.json``, ``images/``, ``depths/``
    (16-bit PNG millimetres, 0 = invalid; nerfstudio's depth_unit_scale_factor 0.001)."""
    root, out = Path(root), Path(out)
    facts: dict[str, list[str]] = {"scenes": []}
    for (garden, lighting), group in rows.groupby(["garden", "lighting"], sort=True):
        scene = out / garden / lighting
        frames = []
        first = group.iloc[0]
        intr_cols = ["fx", "fy", "cx", "cy", "width", "height"]
        uniform = bool((group[intr_cols].nunique() == 1).all())

        def intrinsics(rec) -> dict:
            return {
                "fl_x": float(rec["fx"]),
                "fl_y": float(rec["fy"]),
                "cx": float(rec["cx"]) + 0.5,
                "cy": float(rec["cy"]) + 0.5,
                "w": int(rec["width"]),
                "h": int(rec["height"]),
            }

        for rec in group.to_dict("records"):
            sides = [("l", "rgb_left", "depth", False)] + ([("r", "rgb_right", "depth_right", True)] if right else [])
            for tag, rgb_col, depth_col, is_right in sides:
                if not rec.get(rgb_col):
                    continue
                stem = f"cam{int(rec['camera'])}{tag}_{int(rec['frame']):05d}"
                _copy_rgb(root, rec, rgb_col, scene / "images" / f"{stem}.png")
                frame = {
                    "file_path": f"images/{stem}.png",
                    "transform_matrix": opencv_to_nerfstudio(row_pose(rec, right=is_right)).tolist(),
                }
                if rec.get(depth_col):
                    depth, valid = _finite_depth(_read(root, rec, depth_col))
                    mm = np.where(valid, np.round(depth * 1000.0), 0.0)
                    mm = np.where(mm > 65535, 0.0, mm).astype(np.uint16)
                    (scene / "depths").mkdir(parents=True, exist_ok=True)
                    cv2.imwrite(str(scene / "depths" / f"{stem}.png"), mm)
                    frame["depth_file_path"] = f"depths/{stem}.png"
                if not uniform:
                    frame.update(intrinsics(rec))
                frames.append(frame)
        data = {
            "camera_model": "OPENCV",
            **(intrinsics(first) if uniform else {}),
            "k1": 0.0,
            "k2": 0.0,
            "p1": 0.0,
            "p2": 0.0,
            "frames": frames,
        }
        scene.mkdir(parents=True, exist_ok=True)
        (scene / "transforms.json").write_text(json.dumps(data, indent=1))
        facts["scenes"].append(str(scene / "transforms.json"))
    return facts


# ======================================================================= CLI
def export(
    dataset,
    fmt: str,
    out,
    *,
    split=None,
    lighting=None,
    garden=None,
    stages=None,
    points: int = 1_000_000,
    shard_size: str | int | None = None,
    seed: int = 0,
) -> dict:
    if fmt in SHARD_FORMATS:
        check_arguments(fmt, out, shard_size, seed)  # before reading any row
    rows = select_rows(dataset, split=split, lighting=lighting, garden=garden)
    if fmt in SHARD_FORMATS:
        return export_shards(dataset, fmt, out, rows, shard_size=shard_size, seed=seed)
    if fmt == "3drms":
        return export_3drms(dataset, out, rows, stages=stages, points=points)
    if fmt == "coco":
        return export_coco(dataset, out, rows, name=split or "all")
    if fmt == "kitti_flow":
        return export_kitti_flow(dataset, out, rows)
    if fmt == "nerfstudio":
        return export_nerfstudio(dataset, out, rows)
    raise ValueError(f"unknown format {fmt!r}; one of {', '.join(FORMATS)}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m eden_pipe.tools.export", description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="dataset root (holds manifest.csv)")
    parser.add_argument("--format", required=True, choices=FORMATS)
    parser.add_argument("--out", required=True, help="output folder")
    parser.add_argument("--split")
    parser.add_argument("--lighting")
    parser.add_argument("--garden")
    parser.add_argument(
        "--stages",
        help="stage cache (3drms: the scene geometry of datasets published without <garden>/geometry.ply)",
    )
    parser.add_argument("--points", type=int, default=1_000_000, help="3drms point cloud size (default 1e6)")
    parser.add_argument(
        "--shard-size",
        help=f"webdataset/hf: samples per shard (1000) or bytes with a unit (1GiB); default {DEFAULT_SHARD_SIZE}",
    )
    parser.add_argument("--seed", type=int, default=0, help="webdataset/hf: seed of each split's order (default 0)")
    args = parser.parse_args(argv)
    if args.format in SHARD_FORMATS:
        try:
            check_arguments(args.format, args.out, args.shard_size, args.seed)
        except ValueError as err:
            parser.error(str(err))
    elif args.shard_size is not None:
        parser.error(f"--shard-size applies to the shard formats ({', '.join(SHARD_FORMATS)}), not {args.format}")
    facts = export(
        args.dataset,
        args.format,
        args.out,
        split=args.split,
        lighting=args.lighting,
        garden=args.garden,
        stages=args.stages,
        points=args.points,
        shard_size=args.shard_size,
        seed=args.seed,
    )
    _log(f"{args.format} -> {args.out}: {json.dumps(facts)}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
