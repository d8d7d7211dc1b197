"""A tiny dataset with every modality, built once per test session for the tools' tests."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
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
    """Write ``<garden>/scene.json`` with an instance table derived from the images themselves.

    Each instance id gets the semantic class it shows on most of its pixels; ``drop`` leaves ids
    out, ``override`` changes their class.
    """
    from eden_pipe.io.formats import read_modality

    rows = manifest(root)
    votes: dict[tuple[str, int], np.ndarray] = {}
    for row in rows.itertuples():
        inst = read_modality(root / row.instance, "instance").ravel()
        sem = read_modality(root / row.semantic, "semantic").ravel()
        for i in np.unique(inst):
            if i:
                v = votes.setdefault((row.garden, int(i)), np.zeros(10, np.int64))
                v += np.bincount(sem[inst == i], minlength=10)[:10]
    classes = {}
    for garden in rows.garden.unique():
        table = {i: int(v.argmax()) for (g, i), v in votes.items() if g == garden and i not in drop}
        table.update(override or {})
        instances = [{"id": i, "class_id": c, "class": "whatever"} for i, c in sorted(table.items())]
        (root / garden / "scene.json").write_text(json.dumps({"garden_id": garden, "instances": instances}))
        classes.update(table)
    return classes
