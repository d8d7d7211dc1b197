"""A tiny dataset with every modality, built once per test session for the tools' tests."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pandas as pd

from tests.tiny_dataset import tiny_root


def tiny_dataset(tmp_path_factory) -> Path:
    """Root of the shared dataset (read only: its files are hard links into the stage cache)."""
    return tiny_root(tmp_path_factory) / "dataset"


def copy_dataset(src: Path, dst: Path) -> Path:
    """A private, writable copy (real copies, not links) to corrupt."""
    shutil.copytree(src, dst, copy_function=shutil.copy2)
    return dst


def manifest(root: Path) -> pd.DataFrame:
    return pd.read_csv(root / "manifest.csv", keep_default_na=False)


def write_metadata(root: Path, drop: tuple[int, ...] = (), override: dict[int, int] | None = None) -> dict[int, int]:
    """Edit the published ``<garden>/scene.json``: ``drop`` leaves instance ids out, ``override`` changes
    their class id. Returns {id: class id} as published before the edit."""
    rows = manifest(root)
    classes = {}
    for garden in rows.garden.unique():
        path = root / garden / "scene.json"
        scene = json.loads(path.read_text())
        classes.update({int(i["id"]): int(i["class_id"]) for i in scene["instances"]})
        kept = [i for i in scene["instances"] if int(i["id"]) not in drop]
        for inst in kept:
            if int(inst["id"]) in (override or {}):
                inst["class_id"] = int(override[int(inst["id"])])
        scene["instances"] = kept
        path.write_text(json.dumps(scene))
    return classes
