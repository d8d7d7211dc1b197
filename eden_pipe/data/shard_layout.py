"""The shard layouts' names and samples, shared by their writer (:mod:`eden_pipe.tools.shards`) and the torch
reader (:mod:`eden_pipe.data.shards`); no torch, no webdataset or datasets import (docs/exports.md, Shards).

A sample is one manifest row: its metadata (the row's cells, ``pose`` and ``K``) and its files, each the stored
file's own bytes keyed by column with the file's own extension, so a shard reader decodes exactly what the
folder's reader decodes.

WebDataset: ``<split>-NNNNNN.tar``; a sample's members sit together, named ``<key>.json`` (metadata) and
``<key>.<column>.<ext>`` (``small-s0/clear/cam0/00003.rgb_left.png``), where the key is the row's place in the
dataset layout (``<garden>/<lighting>/cam<k>/<frame>``): WebDataset's key is the name up to the first dot of the
base name, and the keys of a dataset are unique. ``shards.json`` lists each split's shards and sample counts.

Hugging Face: one ``datasets`` row per sample with the manifest's columns as they are, except that a path
column holds its file (an ``Image`` or bytes) and ``<column>_path`` keeps the manifest's path (its extension
names the codec); ``pose`` and ``K`` as 4x4 and 3x3 arrays.
"""

from __future__ import annotations

import json
import tarfile
from collections.abc import Container, Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from eden_pipe import modalities
from eden_pipe.data.manifest_reader import row_intrinsics, row_pose

INDEX = "shards.json"  # a WebDataset export's splits, shards and counts
HF_INDEX = "dataset_dict.json"  # what datasets.DatasetDict.save_to_disk writes at the top
METADATA = "json"  # the metadata member's extension
PATH_SUFFIX = "_path"  # Hugging Face: the manifest's path of a file column

# A sample: (metadata, {column: (extension, file bytes)}).
Sample = tuple[dict[str, Any], dict[str, tuple[str, bytes]]]


def shard_name(split: str, number: int) -> str:
    return f"{split}-{number:06d}.tar"


def sample_key(row: dict) -> str:
    return f"{row['garden']}/{row['lighting']}/cam{int(row['camera'])}/{int(row['frame']):05d}"


def file_columns(row: dict) -> list[str]:
    """The row's filled path columns, in the modality table's order."""
    return [c for c in modalities.PATH_COLUMNS if row.get(c)]


def extension(path: str) -> str:
    return Path(path).suffix.lstrip(".")


def _plain(value: Any) -> Any:
    return value.item() if isinstance(value, np.generic) else value


def metadata(row: dict) -> dict[str, Any]:
    """The manifest row's cells (path cells included, as published) with ``pose`` (left camera-to-world)
    and ``K``: every value JSON's own type, floats kept exactly (JSON writes the shortest repr)."""
    meta = {k: _plain(v) for k, v in row.items()}
    meta["pose"] = row_pose(row).tolist()
    meta["K"] = row_intrinsics(row).tolist()
    return meta


def check_key(key: str) -> None:
    if "." in key.rsplit("/", 1)[-1]:
        raise ValueError(f"shard key {key!r}: its last part may not hold a dot (WebDataset splits names there)")


# --------------------------------------------------------------------- WebDataset
def tar_members(key: str, meta: dict, files: dict[str, tuple[str, bytes]]) -> list[tuple[str, bytes]]:
    """A sample's (member name, bytes): metadata first, then files in the modality table's order."""
    check_key(key)
    members = [(f"{key}.{METADATA}", json.dumps(meta, sort_keys=True).encode())]
    members += [(f"{key}.{column}.{ext}", data) for column, (ext, data) in files.items()]
    return members


def _split_name(name: str) -> tuple[str, str]:
    folder, _, base = name.rpartition("/")
    stem, _, rest = base.partition(".")
    return (f"{folder}/{stem}" if folder else stem), rest


def iter_tar(path: str | Path, columns: Container[str] | None = None) -> Iterator[Sample]:
    """The samples of one shard, its members read front to back; with ``columns``, only those files are read
    (the reader seeks past the others: ``tarfile``'s stream mode ``r|`` would read them through, which took
    4 ms a sample, 640x480 with every layer, against 0.9 ms)."""
    key: str | None = None
    meta: dict[str, Any] | None = None
    files: dict[str, tuple[str, bytes]] = {}
    with tarfile.open(path, mode="r:") as tar:
        for info in tar:
            if not info.isfile():
                continue
            name_key, rest = _split_name(info.name)
            if name_key != key:
                if meta is not None:
                    yield meta, files
                key, meta, files = name_key, None, {}
            column, _, ext = rest.partition(".")
            if rest != METADATA and columns is not None and column not in columns:
                continue
            fh = tar.extractfile(info)
            data = fh.read() if fh is not None else b""
            if rest == METADATA:
                meta = json.loads(data)
            else:
                files[column] = (ext, data)
    if meta is not None:
        yield meta, files


# ------------------------------------------------------------------ Hugging Face
def hf_library():
    """The ``datasets`` module, or an ImportError saying which extra brings it."""
    try:
        import datasets
    except ImportError as exc:
        raise ImportError("--format hf needs the datasets library: pip install 'eden-pipe[shards]'") from exc
    return datasets


def hf_path_field(column: str) -> str:
    return column + PATH_SUFFIX


def iter_hf(rows: Iterable[dict]) -> Iterator[Sample]:
    """Samples from ``datasets`` rows read with every file column undecoded (an ``Image`` as its dict of
    ``bytes``, binary as bytes)."""
    for row in rows:
        files: dict[str, tuple[str, bytes]] = {}
        meta: dict[str, Any] = {}
        for name, value in row.items():
            if name in modalities.COLUMNS:
                meta[name] = row.get(hf_path_field(name)) or ""
                if value is not None:
                    data = value["bytes"] if isinstance(value, dict) else value
                    files[name] = (extension(meta[name]), data)
            elif not (name.endswith(PATH_SUFFIX) and name[: -len(PATH_SUFFIX)] in modalities.COLUMNS):
                meta[name] = value
        yield meta, files
