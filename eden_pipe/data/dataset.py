"""Map-style ``torch.utils.data.Dataset`` over a dataset root's ``manifest.csv``.

Every file is read through :func:`eden_pipe.modalities.read_modality`, and the keys an item has and how each
is presented come from the modality table (each column's ``loader``), so a new layer or file format needs no
change here.

Item: a dict. Always present:

========================= ============ =========================================================
key                       dtype, shape meaning
========================= ============ =========================================================
``K``                     float32 3x3  intrinsics, pixel centres at integer coordinates (OpenCV)
``pose``                  float32 4x4  left camera-to-world, OpenCV camera axes, world Z up, metres
``garden``, ``lighting``, str          row identifiers (collated to lists of str)
``split``
``frame``, ``camera``,    int64        ``camera`` = stereo pair k (this row is its left camera);
``index``                              ``index`` = position in this dataset
``timestamp``             float64      seconds
========================= ============ =========================================================

Per requested modality (``modalities=``):

=================== =========================== ==============================================
modality            keys, dtype, shape          units / conventions
=================== =========================== ==============================================
``rgb``             ``rgb`` float32 (3,H,W)     sRGB in [0, 1] (the PNG / 255)
``semantic``        ``semantic`` int64 (H,W)    3DRMS ids 1..9 (eden_pipe.labels); void (0)
                                                becomes ``ignore_index`` (default 255)
``instance``        ``instance`` int64 (H,W)    instance id, 0 = none
``depth``           ``depth`` float32 (1,H,W)   z-depth in metres, 0 where invalid;
                    ``depth_valid`` bool        false for sky / missing / out of range
``normal``          ``normal`` float32 (3,H,W)  unit normal, camera frame (OpenCV axes), 0 on sky;
                    ``normal_valid`` bool       (1,H,W)
``flow_fwd``        ``flow_fwd`` float32 (2,H,W) (dx, dy) pixels from t to t+1, same camera;
                    ``flow_fwd_valid`` bool     (1,H,W) true where not occluded and inside the
                                                next image (from ``occ_fwd``)
``flow_bwd``        same with ``_bwd``          t to t-1
``albedo``,         float32 (3,H,W)             linear intrinsic layers (README Output)
``shading``, ...
``dynamic``         ``dynamic`` bool (1,H,W)    with wind: the surface seen moves
``motion_fwd``,     float32 (3,H,W)             with wind: the surface point's displacement to t+1
``motion_bwd``                                  (t-1), metres, camera frame
=================== =========================== ==============================================

``stereo=True`` adds ``rgb_right`` (3,H,W), ``pose_right`` (4x4, the left pose
shifted by +baseline along its x axis), ``baseline`` (float32 scalar, metres)
and, when ``depth`` is requested, ``depth_right`` / ``depth_right_valid``.

``pairs=True`` makes every item the pair (t, t+1) of the same garden,
lighting and camera: the item's own keys are frame t (with ``flow_fwd`` and
``flow_fwd_valid`` always included) and frame t+1's modalities and ``pose``
(and stereo keys) come under the prefix ``next_`` (``next_rgb``,
``next_pose``, ...).

Rows lacking a file for a requested modality (e.g. ``flow_fwd`` on the last
frame) or without a t+1 frame (``pairs``) are left out, so every item has the
same keys and default collation works.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from eden_pipe import modalities as modality_table
from eden_pipe.data.manifest_reader import filter_manifest, load_manifest, row_intrinsics, row_pose
from eden_pipe.modalities import read_modality

DEFAULT_IGNORE_INDEX = 255


def loader_columns() -> dict[str, str]:
    """Loader key -> manifest column, from the modality table: every left-camera column except the flows'
    masks (occlusion, read as flow validity); a modality with one such column is keyed by the modality's
    name (``rgb`` for ``rgb_left``), the others by the column's (``flow_fwd``, ``flow_bwd``; ``dynamic``,
    ``motion_fwd``, ``motion_bwd``)."""
    flow_masks = {c.mask for c in modality_table.COLUMNS.values() if c.mask}
    keys = {}
    for m in modality_table.TABLE:
        cols = [c for c in m.columns if c.camera == "left" and c.name not in flow_masks]
        keys.update({(m.name if len(cols) == 1 else c.name): c.name for c in cols})
    return keys


def aliases() -> dict[str, str]:
    """Other names a user may ask for: a column's own name, and a modality's name for its first column."""
    keys = loader_columns()
    out = {column: key for key, column in keys.items() if column != key}
    for m in modality_table.TABLE:
        first = next((c.name for c in m.columns if c.name in keys.values()), None)
        if m.name not in keys and first is not None:
            out[m.name] = next(k for k, c in keys.items() if c == first)
    return out


def _chw(array: np.ndarray) -> torch.Tensor:
    array = np.asarray(array)
    if array.ndim == 2:
        array = array[None]
    else:
        array = np.moveaxis(array, -1, 0)
    return torch.from_numpy(np.ascontiguousarray(array))


def resolve_modalities(modalities: Iterable[str], pairs: bool = False) -> tuple[str, ...]:
    """The loader keys asked for, aliases resolved, duplicates dropped (``flow_fwd`` added for ``pairs``);
    ValueError naming an unknown one."""
    columns, alias = loader_columns(), aliases()
    mods: list[str] = []
    for m in modalities:
        m = alias.get(m, m)
        if m not in columns:
            raise ValueError(f"unknown modality {m!r}; known: {', '.join(columns)} (aliases: {', '.join(alias)})")
        if m not in mods:
            mods.append(m)
    if pairs and "flow_fwd" not in mods:
        mods.append("flow_fwd")
    return tuple(mods)


class FrameTensors:
    """How a manifest row becomes an item (the module docstring), whatever holds its files: the folder
    (:class:`EdenDataset`) or shards (:class:`eden_pipe.data.shards.EdenShards`), so both give equal tensors.
    A row's path cells are read relative to the ``root`` each call passes."""

    columns: dict[str, str]
    modalities: tuple[str, ...]
    stereo: bool
    ignore_index: int
    transform: Callable[[dict], dict] | None

    def needed_columns(self) -> list[str]:
        """The path columns a row must fill to be an item."""
        needed = [self.columns[m] for m in self.modalities]
        if self.stereo:
            needed.append("rgb_right")
            if "depth" in self.modalities:
                needed.append("depth_right")
        return needed

    # ------------------------------------------------------------------ reading
    def _read(self, root: Path, rec: dict, column: str) -> np.ndarray:
        return read_modality(root / rec[column], column)

    def _depth(self, root: Path, rec: dict, column: str, out: dict, key: str) -> None:
        depth = np.asarray(self._read(root, rec, column), np.float32)
        valid = np.isfinite(depth) & (depth > 0)
        out[key] = _chw(np.where(valid, depth, np.float32(0.0)).astype(np.float32))
        out[key + "_valid"] = _chw(valid)

    def _view(self, root: Path, rec: dict, with_flow: bool) -> dict:
        out: dict = {
            "K": torch.from_numpy(row_intrinsics(rec).astype(np.float32)),
            "pose": torch.from_numpy(row_pose(rec).astype(np.float32)),
        }
        for m in self.modalities:
            column = modality_table.COLUMNS[self.columns[m]]
            kind = column.loader
            if kind == "image":
                out[m] = _chw(self._read(root, rec, column.name).astype(np.float32) / np.float32(255.0))
            elif kind == "labels":
                sem = self._read(root, rec, column.name).astype(np.int64)
                out[m] = torch.from_numpy(np.where(sem == 0, self.ignore_index, sem))
            elif kind == "ids":
                out[m] = torch.from_numpy(self._read(root, rec, column.name).astype(np.int64))
            elif kind == "depth":
                self._depth(root, rec, column.name, out, m)
            elif kind == "normal":
                n = np.asarray(self._read(root, rec, column.name), np.float32)
                out[m] = _chw(n)
                out[m + "_valid"] = _chw(np.any(n != 0, axis=-1))
            elif kind == "flow":
                if not with_flow:
                    continue
                flow = np.asarray(self._read(root, rec, column.name), np.float32)[..., :2]
                valid = np.all(np.isfinite(flow), axis=-1)
                if column.mask and rec.get(column.mask):
                    valid &= self._read(root, rec, column.mask) == 0
                out[m] = _chw(np.where(np.isfinite(flow), flow, np.float32(0.0)))
                out[m + "_valid"] = _chw(valid)
            elif kind == "mask":  # a mask of its own (the wind's dynamic pixels)
                out[m] = _chw(self._read(root, rec, column.name) != 0)
            else:  # float layers
                out[m] = _chw(np.asarray(self._read(root, rec, column.name), np.float32))
        if self.stereo:
            out["rgb_right"] = _chw(self._read(root, rec, "rgb_right").astype(np.float32) / np.float32(255.0))
            out["pose_right"] = torch.from_numpy(row_pose(rec, right=True).astype(np.float32))
            out["baseline"] = torch.tensor(float(rec["baseline"]), dtype=torch.float32)
            if "depth" in self.modalities:
                self._depth(root, rec, "depth_right", out, "depth_right")
        return out

    def item(self, root: Path, rec: dict, index: int, nxt: dict | None = None) -> dict:
        """Row ``rec``'s item (``nxt``: the t+1 row of ``pairs``), its files under ``root``."""
        item = self._view(root, rec, with_flow=True)
        item.update(
            {
                "garden": str(rec["garden"]),
                "lighting": str(rec["lighting"]),
                "split": str(rec["split"]),
                "frame": int(rec["frame"]),
                "camera": int(rec["camera"]),
                "index": int(index),
                "timestamp": float(rec.get("timestamp", 0.0) or 0.0),
            }
        )
        if nxt is not None:
            item.update({f"next_{k}": v for k, v in self._view(root, nxt, with_flow=False).items()})
        if self.transform is not None:
            item = self.transform(item)
        return item


class EdenDataset(FrameTensors, Dataset):
    """Frames of an eden-pipe dataset root as dicts of tensors (see the module docstring).

    Args:
        root: dataset root (holds ``manifest.csv``).
        modalities: any of ``rgb semantic instance depth normal flow_fwd flow_bwd``
            and the float layers (``flow`` = ``flow_fwd``).
        split, lighting, garden, cameras: filters (one value or an iterable; None = all).
        subsample: False, True (``test_subsample`` else ``subsample`` column) or a
            bool column name; ValueError when the column is absent.
        stereo, pairs: see the module docstring.
        ignore_index: what void (class 0) becomes in ``semantic``.
        transform: optional callable applied to the item dict.
    """

    def __init__(
        self,
        root: str | os.PathLike,
        modalities: Iterable[str] = ("rgb",),
        *,
        split=None,
        lighting=None,
        garden=None,
        cameras=None,
        subsample: bool | str = False,
        stereo: bool = False,
        pairs: bool = False,
        ignore_index: int = DEFAULT_IGNORE_INDEX,
        transform: Callable[[dict], dict] | None = None,
    ):
        self.root = Path(root)
        self.columns = loader_columns()
        self.modalities = resolve_modalities(modalities, pairs)
        self.stereo, self.pairs = bool(stereo), bool(pairs)
        self.ignore_index = int(ignore_index)
        self.transform = transform

        full = load_manifest(self.root)
        rows = filter_manifest(
            full, split=split, lighting=lighting, garden=garden, cameras=cameras, subsample=subsample
        )
        needed = self.needed_columns()
        missing = [c for c in needed if c not in full.columns]
        if missing:
            raise ValueError(f"the manifest has no column(s) {', '.join(missing)} for the requested modalities")
        next_needed = [c for c in needed if c not in ("flow_fwd", "occ_fwd")]

        def complete(rec, cols) -> bool:
            return all(rec[c] for c in cols)

        by_key = {(r["garden"], r["lighting"], int(r["camera"]), int(r["frame"])): r for r in full.to_dict("records")}
        self.records: list[dict] = []
        self.next_records: list[dict | None] = []
        for rec in rows.to_dict("records"):
            if not complete(rec, needed):
                continue
            nxt = None
            if self.pairs:
                nxt = by_key.get((rec["garden"], rec["lighting"], int(rec["camera"]), int(rec["frame"]) + 1))
                if nxt is None or not complete(nxt, next_needed):
                    continue
            self.records.append(rec)
            self.next_records.append(nxt)

    def __len__(self) -> int:
        return len(self.records)

    def __getitem__(self, index: int) -> dict:
        if index < 0:
            index += len(self)
        return self.item(self.root, self.records[index], index, self.next_records[index])

    def __repr__(self) -> str:
        return (
            f"EdenDataset({str(self.root)!r}, {len(self)} items, modalities={list(self.modalities)}, "
            f"stereo={self.stereo}, pairs={self.pairs})"
        )
