"""Shards for streaming a dataset (docs/exports.md, Shards): WebDataset tars and a Hugging Face ``datasets`` folder.

    python -m eden_pipe.tools.export DATASET --format {webdataset,hf} --out DIR [--shard-size N|SIZE] [--seed S]

Both hold every manifest row of the selection once, split by the manifest's ``split`` column, each split in an
order drawn from ``--seed``. Files go in as the bytes the dataset stores (PNG, EXR, KITTI flow PNG ...), so a
reader decodes them with the modality table's own readers and gets the folder's arrays exactly
(:class:`eden_pipe.data.shards.EdenShards`). The names and the sample layout live in
:mod:`eden_pipe.data.shard_layout`.

The WebDataset writer is the standard library's ``tarfile`` (members with mtime 0, so equal inputs give equal
bytes); the Hugging Face one needs ``datasets`` (the ``[shards]`` extra).
"""

from __future__ import annotations

import io
import json
import math
import os
import re
import tarfile
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from eden_pipe import modalities
from eden_pipe.data import shard_layout as layout
from eden_pipe.rng import rng_for

SHARD_FORMATS = ("webdataset", "hf")
# Hugging Face's own default shard size for save_to_disk; within the 100 MB - 1 GB WebDataset advises.
DEFAULT_SHARD_SIZE = "500MB"
UNITS = {"B": 1, "KB": 10**3, "MB": 10**6, "GB": 10**9, "TB": 10**12, "KIB": 2**10, "MIB": 2**20, "GIB": 2**30}
TAR_BLOCK = 512


@dataclass(frozen=True)
class ShardSize:
    """At most ``samples`` samples, or at most ``bytes`` bytes, per shard (exactly one is set)."""

    samples: int | None = None
    bytes: int | None = None


def parse_shard_size(text: str | int) -> ShardSize:
    """``--shard-size``: a plain count is samples per shard (``1000``), a number with a unit is bytes
    (``500MB``, ``1GiB``; units B, KB, MB, GB, TB powers of 1000, KiB, MiB, GiB of 1024)."""
    match = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([A-Za-z]*)\s*", str(text))
    unit = match.group(2).upper() if match else ""
    if match and not unit and "." not in match.group(1) and int(match.group(1)) > 0:
        return ShardSize(samples=int(match.group(1)))
    if match and unit in UNITS and float(match.group(1)) * UNITS[unit] >= 1:
        return ShardSize(bytes=int(float(match.group(1)) * UNITS[unit]))
    raise ValueError(
        f"--shard-size {text!r}: expected a positive sample count (e.g. 1000) or a size with a unit "
        "(e.g. 500MB, 1GiB; units B, KB, MB, GB, TB in powers of 1000, KiB, MiB, GiB in powers of 1024)"
    )


def check_arguments(fmt: str, out, shard_size: str | int | None, seed: int) -> ShardSize:
    """Every shard argument checked before any work: the format, the size, the seed and an empty ``out``."""
    if fmt not in SHARD_FORMATS:
        raise ValueError(f"unknown shard format {fmt!r}; one of {', '.join(SHARD_FORMATS)}")
    size = parse_shard_size(DEFAULT_SHARD_SIZE if shard_size is None else shard_size)
    if fmt == "hf":
        layout.hf_library()
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"--seed {seed!r}: expected a non-negative integer")
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise ValueError(f"--out {out}: must be a new or empty folder (shards of another export would mix in)")
    return size


def split_order(rows: pd.DataFrame, split: str, seed: int) -> pd.DataFrame:
    """The split's rows in the order they are written: the selection's order (garden, lighting, camera, frame)
    permuted by numpy's PCG64 from ``rng_for(seed, "shards", split)`` (the same on every machine)."""
    group = rows[rows["split"].astype(str) == split].reset_index(drop=True)
    return group.iloc[rng_for(seed, "shards", split).permutation(len(group))].reset_index(drop=True)


def _files(root: Path, rec: dict) -> dict[str, tuple[str, bytes]]:
    return {c: (layout.extension(rec[c]), (root / rec[c]).read_bytes()) for c in layout.file_columns(rec)}


def _splits(rows: pd.DataFrame) -> list[str]:
    return sorted(rows["split"].astype(str).unique())


# ---------------------------------------------------------------------- WebDataset
def _tar_bytes(members: list[tuple[str, bytes]]) -> int:
    """Bytes the members take in a tar: a header block each and the data padded to whole blocks."""
    return sum(TAR_BLOCK + math.ceil(len(data) / TAR_BLOCK) * TAR_BLOCK for _, data in members)


class _ShardWriter:
    """One split's shards: a new shard starts when the next sample would pass the size (a sample bigger than
    a byte size still gets a shard, alone)."""

    def __init__(self, out: Path, split: str, size: ShardSize):
        self.out, self.split, self.size = out, split, size
        self.names: list[str] = []
        self.tar: tarfile.TarFile | None = None
        self.samples = self.bytes = 0

    def _full(self, extra: int) -> bool:
        if self.size.samples is not None:
            return self.samples >= self.size.samples
        return self.samples > 0 and self.bytes + extra > (self.size.bytes or 0)

    def add(self, members: list[tuple[str, bytes]]) -> None:
        extra = _tar_bytes(members)
        if self.tar is None or self._full(extra):
            self.close()
            self.names.append(layout.shard_name(self.split, len(self.names)))
            self.tar = tarfile.open(self.out / (self.names[-1] + ".tmp"), "w", format=tarfile.PAX_FORMAT)
            self.samples = self.bytes = 0
        for name, data in members:
            info = tarfile.TarInfo(name)
            info.size, info.mtime, info.mode = len(data), 0, 0o444
            self.tar.addfile(info, io.BytesIO(data))
        self.samples += 1
        self.bytes += extra

    def close(self) -> None:
        if self.tar is not None:
            self.tar.close()
            os.replace(self.out / (self.names[-1] + ".tmp"), self.out / self.names[-1])
            self.tar = None


def export_webdataset(root, out, rows: pd.DataFrame, *, size: ShardSize, seed: int, shard_size: str) -> dict:
    """``OUT/<split>-NNNNNN.tar`` per split and ``OUT/shards.json``."""
    root, out = Path(root), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    index: dict[str, Any] = {"format": "webdataset", "seed": seed, "shard_size": str(shard_size), "splits": {}}
    for split in _splits(rows):
        group = split_order(rows, split, seed)
        writer = _ShardWriter(out, split, size)
        for rec in group.to_dict("records"):
            writer.add(layout.tar_members(layout.sample_key(rec), layout.metadata(rec), _files(root, rec)))
        writer.close()
        index["splits"][split] = {"shards": writer.names, "samples": len(group)}
    (out / layout.INDEX).write_text(json.dumps(index, indent=1) + "\n")
    return {split: {"shards": len(v["shards"]), "samples": v["samples"]} for split, v in index["splits"].items()}


# -------------------------------------------------------------------- Hugging Face
def hf_image_column(column: str, paths: pd.Series) -> bool:
    """Whether a column is stored as a ``datasets.Image``: its files are PNGs that Pillow (what ``Image``
    decodes with) reads exactly, i.e. one channel or 8 bits; Pillow reads a 16-bit three-channel PNG (normal,
    KITTI flow) as 8 bits, so those, like EXR, ``.npy`` and ``.flo``, are stored as bytes."""
    spec = modalities.COLUMNS[column]
    exts = {layout.extension(p) for p in paths if p}
    return exts == {"png"} and (spec.channels == 1 or spec.dtype == "uint8")


def hf_features(rows: pd.DataFrame):
    datasets = layout.hf_library()
    kinds = {"i": "int64", "u": "int64", "f": "float64", "b": "bool"}
    features: dict[str, Any] = {}
    for name in rows.columns:
        if name in modalities.COLUMNS:
            image = hf_image_column(name, rows[name])
            features[name] = datasets.Image(decode=True) if image else datasets.Value("binary")
            features[layout.hf_path_field(name)] = datasets.Value("string")
        else:
            features[name] = datasets.Value(kinds.get(rows[name].dtype.kind, "string"))
    features["pose"] = datasets.Array2D((4, 4), "float64")
    features["K"] = datasets.Array2D((3, 3), "float64")
    return datasets.Features(features)


def _hf_rows(root: str, records: list[dict], images: tuple[str, ...]):
    for rec in records:
        row = {k: v for k, v in layout.metadata(rec).items() if k not in modalities.COLUMNS}
        files = _files(Path(root), rec)
        for column in modalities.COLUMNS:
            if column in rec:
                data = files[column][1] if column in files else None
                row[column] = {"bytes": data, "path": None} if data is not None and column in images else data
                row[layout.hf_path_field(column)] = rec[column]
        yield row


def export_hf(root, out, rows: pd.DataFrame, *, size: ShardSize, seed: int) -> dict:
    """``OUT/`` a ``datasets.DatasetDict`` (one ``Dataset`` per split) written by ``save_to_disk``."""
    datasets = layout.hf_library()
    root, out = Path(root), Path(out)
    features = hf_features(rows)
    images = [name for name, f in features.items() if isinstance(f, datasets.Image)]
    out.parent.mkdir(parents=True, exist_ok=True)
    parts = {}
    # from_generator writes Arrow files into a cache; a private one, so no earlier export is reused.
    with tempfile.TemporaryDirectory(prefix=".hf-cache-", dir=out.parent) as cache:
        for split in _splits(rows):
            records = split_order(rows, split, seed).to_dict("records")
            parts[split] = datasets.Dataset.from_generator(
                _hf_rows,
                gen_kwargs={"root": str(root), "records": records, "images": tuple(images)},
                features=features,
                cache_dir=cache,
                split=datasets.Split(split),
            )
        dd = datasets.DatasetDict(parts)
        if size.samples is not None:
            dd.save_to_disk(
                str(out), num_shards={s: max(1, math.ceil(len(d) / size.samples)) for s, d in parts.items()}
            )
        else:
            dd.save_to_disk(str(out), max_shard_size=size.bytes)
    return {split: {"samples": len(d), "images": images} for split, d in parts.items()}


def export_shards(
    dataset, fmt: str, out, rows: pd.DataFrame, *, shard_size: str | int | None = None, seed: int = 0
) -> dict:
    size = check_arguments(fmt, out, shard_size, seed)
    text = DEFAULT_SHARD_SIZE if shard_size is None else str(shard_size)
    if fmt == "webdataset":
        return export_webdataset(dataset, out, rows, size=size, seed=seed, shard_size=text)
    return export_hf(dataset, out, rows, size=size, seed=seed)
