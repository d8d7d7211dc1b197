"""Manifest access without torch: load, filter, poses and intrinsics of rows.

Shared by :mod:`eden_pipe.data.dataset` (torch) and :mod:`eden_pipe.tools.export`
(numpy only). Conventions (docs/design.md, Frames and units and Dataset layout): a row's pose is the LEFT
camera of stereo pair ``camera``, camera-to-world, OpenCV camera axes (x right,
y down, z forward), world Z up, metres; the right camera is the left one
shifted by ``+baseline`` along its own x axis. Pixel centres sit at integer
coordinates (pixel (0, 0)'s centre is u = v = 0), as in OpenCV.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pandas as pd

from eden_pipe import modalities
from eden_pipe.camera.rig import quaternion_to_rotation, rotation_to_quaternion  # noqa: F401  (re-exported)

PATH_COLUMNS = modalities.PATH_COLUMNS  # the modality table's file columns
SUBSAMPLE_COLUMNS = ("test_subsample", "subsample")  # looked up in this order when subsample=True


def load_manifest(root: str | os.PathLike) -> pd.DataFrame:
    """``<root>/manifest.csv`` with path columns as strings ('' when absent) and string ids."""
    path = Path(root) / "manifest.csv"
    if not path.is_file():
        raise FileNotFoundError(f"no manifest.csv in dataset root {root}")
    header = pd.read_csv(path, nrows=0).columns
    text = {c: str for c in ("garden", "lighting", "split", *PATH_COLUMNS) if c in header}
    df = pd.read_csv(path, dtype=text, keep_default_na=False, na_values=[""])
    for col in PATH_COLUMNS:
        if col in df.columns:
            df[col] = df[col].astype(object).where(df[col].notna(), "").astype(str)
        else:  # a column the manifest does not list (the wind's, in still air; a layer newer than the dataset)
            df[col] = ""
    return df


def _as_set(value) -> set | None:
    if value is None:
        return None
    if isinstance(value, (str, int, np.integer)):
        return {value}
    return set(value)


def _as_bool(series: pd.Series) -> pd.Series:
    if series.dtype == bool:
        return series
    text = series.astype(str).str.strip().str.lower()
    return text.isin(("1", "true", "yes", "y", "t", "1.0"))


def filter_manifest(
    df: pd.DataFrame, *, split=None, lighting=None, garden=None, cameras=None, subsample: bool | str = False
) -> pd.DataFrame:
    """Rows matching every given filter (a value or an iterable of values; None = any).

    ``subsample``: False = all rows; True = rows whose ``test_subsample`` (else
    ``subsample``) column is true; a string = that bool column. Asking for a
    subsample column the manifest lacks raises a ValueError.
    """
    mask = np.ones(len(df), bool)
    for col, want in (("split", split), ("lighting", lighting), ("garden", garden)):
        values = _as_set(want)
        if values is not None:
            mask &= df[col].astype(str).isin({str(v) for v in values}).to_numpy()
    cams = _as_set(cameras)
    if cams is not None:
        mask &= df["camera"].astype(int).isin({int(c) for c in cams}).to_numpy()
    if subsample:
        names: tuple[str, ...]
        if isinstance(subsample, str):
            names = (subsample,)
        else:
            names = SUBSAMPLE_COLUMNS
        column = next((c for c in names if c in df.columns), None)
        if column is None:
            raise ValueError(
                f"subsample filter asked for, but the manifest has no {' or '.join(names)} column "
                f"(columns: {', '.join(df.columns)})"
            )
        mask &= _as_bool(df[column]).to_numpy()
    return df[mask].reset_index(drop=True)


def row_pose(row, right: bool = False) -> np.ndarray:
    """4x4 camera-to-world (float64, OpenCV camera axes) of the row's left (or right) camera."""
    pose = np.eye(4)
    pose[:3, :3] = quaternion_to_rotation([row["qw"], row["qx"], row["qy"], row["qz"]])
    pose[:3, 3] = [float(row["tx"]), float(row["ty"]), float(row["tz"])]
    if right:
        pose[:3, 3] += float(row["baseline"]) * pose[:3, 0]
    return pose


def row_intrinsics(row) -> np.ndarray:
    """3x3 K (float64), pixel centres at integer coordinates."""
    return np.array(
        [[float(row["fx"]), 0.0, float(row["cx"])], [0.0, float(row["fy"]), float(row["cy"])], [0.0, 0.0, 1.0]]
    )


def resolve(root: str | os.PathLike, rel: str) -> Path | None:
    """Absolute path of a manifest path cell, None when the cell is empty."""
    return Path(root) / rel if rel else None
