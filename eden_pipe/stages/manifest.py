"""Manifest stage: one CSV row per (garden, lighting, frame, camera), and publishing.

The stage artifact ``stages/manifest/<key>/rows.csv`` holds the job's rows.
Publishing hard-links the render files into the stable dataset root
(``<dataset>/<garden>/<lighting>/cam<k>/<column>/<frame>.<ext>``, no extra
disk; copies where links are impossible), writes the job's
``<garden>/<lighting>/manifest.csv`` and merges every job manifest under the
root into ``<dataset>/manifest.csv`` under a lock. Files are only (re)written
when their content would change, so an identical rerun rewrites nothing.
Inputs: the typed ``SplitConfig`` and ``CameraConfig`` slices and the
lighting's name; garden id and seed come from the scene description.
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from eden_pipe import modalities
from eden_pipe.camera.rig import rotation_to_quaternion
from eden_pipe.config import CameraConfig, SplitConfig
from eden_pipe.io.atomic import link_or_copy, write_if_changed
from eden_pipe.scene.description import SceneDescription, read_scene
from eden_pipe.splits import manifest_row_ids, split_for, test_subsample, write_sample_list
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash, file_lock
from eden_pipe.stages.describe import MANIFEST_LOCK, TEST_SUBSAMPLE_FILE, is_job_metadata, subsample_settings
from eden_pipe.stages.trajectory import load_poses

INFO_COLUMNS = [
    "garden",
    "seed",
    "lighting",
    "frame",
    "timestamp",
    "camera",
    "split",
    "width",
    "height",
    "fx",
    "fy",
    "cx",
    "cy",
    "baseline",
    "qw",
    "qx",
    "qy",
    "qz",
    "tx",
    "ty",
    "tz",
    "exposure",
]
PATH_COLUMNS = modalities.PATH_COLUMNS  # one per modality file, in the modality table's order (kept current)


def columns(written: Iterable[str] = ()) -> list[str]:
    """The manifest's columns: the row's facts, then one path column per modality file, those of
    modalities listed only when written (``Modality.listed_when_written``) where in ``written``."""
    shown = set(written)
    return INFO_COLUMNS + [c for c in PATH_COLUMNS if c not in modalities.LISTED_WHEN_WRITTEN or c in shown]


JOB_MANIFEST = "manifest.csv"


def assign_split(garden_id: str, seed: int, split_cfg) -> str:
    """Split by garden (eden_pipe.splits): pinned by ``split.overrides``, else the preset's rule."""
    return split_for(garden_id, seed, split_cfg)


def build_rows(
    split_cfg: SplitConfig,
    cam: CameraConfig,
    lighting: str,
    scene: SceneDescription,
    render_art: Artifact,
    traj_art: Artifact,
) -> pd.DataFrame:
    poses = load_poses(traj_art)
    garden_id = scene.garden_id
    prefix = f"{garden_id}/{lighting}"
    split = assign_split(garden_id, scene.seed, split_cfg)
    exposure = float(render_art.marker()["exposure"])
    rows = []
    markers = sorted((render_art.path / "frames").glob("*.json"))
    for marker_path in markers:
        marker = json.loads(marker_path.read_text())
        f = int(marker["frame"])
        for k_str, files in marker["files"].items():
            k = int(k_str)
            pose = poses[f, k, 0]
            q = rotation_to_quaternion(pose[:3, :3])
            row = {
                "garden": garden_id,
                "seed": scene.seed,
                "lighting": lighting,
                "frame": f,
                "timestamp": round(float(marker["time"]), 6),
                "camera": k,
                "split": split,
                "width": int(cam.width),
                "height": int(cam.height),
                "fx": float(cam.fx),
                "fy": float(cam.fy),
                "cx": float(cam.cx),
                "cy": float(cam.cy),
                "baseline": float(cam.baseline_m),
                "qw": q[0],
                "qx": q[1],
                "qy": q[2],
                "qz": q[3],
                "tx": pose[0, 3],
                "ty": pose[1, 3],
                "tz": pose[2, 3],
                "exposure": exposure,
            }
            for column in PATH_COLUMNS:
                row[column] = f"{prefix}/{files[column]}" if column in files else ""
            rows.append(row)
    written = {c for row in rows for c in modalities.LISTED_WHEN_WRITTEN if row[c]}
    frame = pd.DataFrame(rows, columns=columns(written))
    return frame.sort_values(["frame", "camera"], kind="stable").reset_index(drop=True)


def to_csv_bytes(frame: pd.DataFrame) -> bytes:
    buf = io.StringIO()
    frame.to_csv(buf, index=False, float_format="%.9g")
    return buf.getvalue().encode()


def run_manifest_stage(
    split_cfg: SplitConfig,
    camera_cfg: CameraConfig,
    lighting: str,
    scene_art: Artifact,
    render_art: Artifact,
    traj_art: Artifact,
    cache: StageCache,
) -> Artifact:
    """(split and camera configs, lighting name, upstream artifacts) -> artifact with the job's rows.csv."""
    scene = read_scene(scene_art)
    lighting = str(lighting)
    split = {
        "preset": split_cfg.preset,
        "train": split_cfg.train,
        "val": split_cfg.val,
        "test": split_cfg.test,
        "overrides": dict(split_cfg.overrides or {}),
    }
    key = config_hash(render_art.key, traj_art.key, split, lighting, code_fingerprint(__name__))

    def builder(folder: Path) -> dict:
        frame = build_rows(split_cfg, camera_cfg, lighting, scene, render_art, traj_art)
        (folder / "rows.csv").write_bytes(to_csv_bytes(frame))
        return {"rows": len(frame), "garden": scene.garden_id, "lighting": lighting}

    return cache.build("manifest", key, builder)


# ------------------------------------------------------------------ publishing
def publish(manifest_art: Artifact, render_art: Artifact, dataset_root: str | os.PathLike) -> dict:
    """Place the job's files and manifest under the dataset root and merge the root manifest."""
    root = Path(dataset_root)
    rows = pd.read_csv(manifest_art.path / "rows.csv", keep_default_na=False, dtype=dict.fromkeys(PATH_COLUMNS, str))
    written = 0
    if len(rows) == 0:
        return {"files_written": 0, "root_rows": 0}
    garden, lighting = rows["garden"].iloc[0], rows["lighting"].iloc[0]
    job_dir = root / garden / lighting
    expected = set()
    prefix_len = len(f"{garden}/{lighting}/")
    for column in (c for c in PATH_COLUMNS if c in rows.columns):
        for rel in rows[column]:
            if rel:
                expected.add(rel)
                written += link_or_copy(render_art.path / rel[prefix_len:], root / rel)
    # Files of an earlier, different render of this (garden, lighting) that the manifest no longer lists.
    if job_dir.is_dir():
        for path in job_dir.rglob("*"):
            if (
                path.is_file()
                and path.name != JOB_MANIFEST
                and not is_job_metadata(path, job_dir)
                and str(path.relative_to(root)) not in expected
            ):
                path.unlink()
                written += 1
    written += write_if_changed(job_dir / JOB_MANIFEST, (manifest_art.path / "rows.csv").read_bytes())
    total, changed = merge_manifests(root)
    return {"files_written": written + changed, "root_rows": total}


def merge_manifests(root: str | os.PathLike) -> tuple[int, bool]:
    """Rewrite ``<root>/manifest.csv`` from every job manifest; returns (rows, changed).

    When dataset.json asks for a test subsample (``split.test_subsample``), it is drawn here, over
    every test row of the merged dataset (EDEN: a uniform 20K of ~60K), marked in a ``test_subsample``
    column and listed in ``test_subsample.txt``; the draw depends only on the row ids and the seed."""
    root = Path(root)
    root.mkdir(parents=True, exist_ok=True)
    with file_lock(root / MANIFEST_LOCK):
        parts = [
            pd.read_csv(p, keep_default_na=False, dtype=dict.fromkeys(PATH_COLUMNS, str))
            for p in sorted(root.glob(f"*/*/{JOB_MANIFEST}"))
        ]
        merged = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=columns())
        # A column some jobs list and others do not (listed only when written): empty in the others.
        listed = [c for c in columns(merged.columns) if c in merged.columns]
        merged = merged[listed + [c for c in merged.columns if c not in listed]]
        merged[[c for c in PATH_COLUMNS if c in merged.columns]] = merged[
            [c for c in PATH_COLUMNS if c in merged.columns]
        ].fillna("")
        merged = merged.sort_values(["garden", "lighting", "frame", "camera"], kind="stable").reset_index(drop=True)
        changed = False
        settings = subsample_settings(root)
        if settings is not None:
            ids = manifest_row_ids(merged)
            test_ids = [i for i, split in zip(ids, merged["split"], strict=True) if split == "test"]  # one id a row
            count = None if settings.get("count") is None else min(int(settings["count"]), len(test_ids))
            chosen = test_subsample(
                test_ids,
                count=count,
                fraction=None if count is not None else settings["fraction"],
                seed=int(settings.get("seed", 0)),
            )
            chosen_set = set(chosen)
            merged["test_subsample"] = [int(i in chosen_set) for i in ids]
            changed |= write_sample_list(root / TEST_SUBSAMPLE_FILE, chosen)
        data = to_csv_bytes(merged)
        changed |= write_if_changed(root / "manifest.csv", data)
        return len(merged), changed
