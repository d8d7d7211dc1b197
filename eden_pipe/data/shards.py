"""Stream a dataset's shards as torch items: ``EdenShards``, an ``IterableDataset`` over the folder that
``python -m eden_pipe.tools.export --format webdataset`` or ``--format hf`` wrote (docs/exports.md, Shards).

An item is what :class:`eden_pipe.data.EdenDataset` gives for the same manifest row, tensor for tensor: a
sample's files are the dataset's own bytes, and they are decoded by the modality table's readers and turned
into tensors by the same code (:class:`eden_pipe.data.dataset.FrameTensors`). The table's readers read files
(OpenCV, OpenEXR), so each file of a sample is written to a private scratch folder first, in memory
(``/dev/shm``) where the system has one, and read from there.

Differences from the folder's dataset: one split per stream, in the export's order (drawn from its seed);
``index`` counts the items this iterator (or DataLoader worker) has given; ``pairs`` is not offered (a sample
holds one frame, its t+1 frame sits elsewhere in a shuffled stream). Under a ``DataLoader`` with several
workers, worker w of n reads shards w, w + n, ... (WebDataset) or the w-th contiguous n-th of the rows
(Hugging Face), so every sample is read once per epoch.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

from torch.utils.data import IterableDataset, get_worker_info

from eden_pipe import modalities as modality_table
from eden_pipe.data import shard_layout as layout
from eden_pipe.data.dataset import DEFAULT_IGNORE_INDEX, FrameTensors, loader_columns, resolve_modalities

MEMORY_SCRATCH = Path("/dev/shm")


def scratch_folder() -> str | None:
    """Where a sample's files are decoded from: ``/dev/shm`` when writable, else the system's temp folder."""
    return str(MEMORY_SCRATCH) if MEMORY_SCRATCH.is_dir() and os.access(MEMORY_SCRATCH, os.W_OK) else None


def shard_format(source: Path) -> str:
    """``webdataset`` or ``hf``, by the index file an export writes; ValueError naming the folder otherwise."""
    if (source / layout.INDEX).is_file():
        return "webdataset"
    if (source / layout.HF_INDEX).is_file():
        return "hf"
    raise ValueError(
        f"{source}: not a shard export (no {layout.INDEX} of --format webdataset, no {layout.HF_INDEX} of --format hf)"
    )


class EdenShards(FrameTensors, IterableDataset):
    """One split of a shard export as a stream of items (see the module docstring).

    Args:
        source: the export's folder (``--out`` of ``--format webdataset`` or ``--format hf``).
        modalities, stereo, ignore_index, transform: as :class:`eden_pipe.data.EdenDataset`.
        split: which split's shards to read.
    """

    def __init__(
        self,
        source: str | os.PathLike,
        modalities: Iterable[str] = ("rgb",),
        *,
        split: str,
        stereo: bool = False,
        ignore_index: int = DEFAULT_IGNORE_INDEX,
        transform: Callable[[dict], dict] | None = None,
    ):
        self.source = Path(source)
        self.format = shard_format(self.source)
        if self.format == "hf":
            layout.hf_library()  # fail here, not in a DataLoader worker
        self.columns = loader_columns()
        self.modalities = resolve_modalities(modalities)
        self.stereo, self.ignore_index, self.transform = bool(stereo), int(ignore_index), transform
        splits = self._splits()
        if split not in splits:
            raise ValueError(f"split {split!r}: {self.source} holds the splits {', '.join(sorted(splits))}")
        self.split = split
        self.shards = [self.source / name for name in splits[split]]
        # The files an item reads: the requested columns and the occlusion masks of requested flows.
        self.needed = self.needed_columns()
        masks = [modality_table.COLUMNS[c].mask for c in self.needed]
        self.wanted = set(self.needed) | {m for m in masks if m}

    def _splits(self) -> dict[str, list[str]]:
        if self.format == "webdataset":
            index = json.loads((self.source / layout.INDEX).read_text())
            return {name: part["shards"] for name, part in index["splits"].items()}
        return {name: [name] for name in json.loads((self.source / layout.HF_INDEX).read_text())["splits"]}

    def _samples(self) -> Iterator[layout.Sample]:
        info = get_worker_info()
        worker, workers = (info.id, info.num_workers) if info is not None else (0, 1)
        if self.format == "webdataset":
            for shard in self.shards[worker::workers]:
                yield from layout.iter_tar(shard, self.wanted)
            return
        datasets = layout.hf_library()
        part = datasets.load_from_disk(str(self.shards[0]))
        files = [c for c in part.column_names if c in modality_table.COLUMNS]
        # Only the files an item reads, each left undecoded (its stored bytes).
        part = part.remove_columns([c for c in files if c not in self.wanted])
        for column in self.wanted & set(files):
            if isinstance(part.features[column], datasets.Image):
                part = part.cast_column(column, datasets.Image(decode=False))
        yield from layout.iter_hf(part.shard(num_shards=workers, index=worker, contiguous=True))

    def __iter__(self) -> Iterator[dict]:
        with tempfile.TemporaryDirectory(prefix="eden-shards-", dir=scratch_folder()) as scratch:
            root = Path(scratch)
            count = 0
            for meta, files in self._samples():
                if not all(c in files for c in self.needed):
                    continue  # as the folder's dataset: rows lacking a requested file are left out
                rec = dict(meta)
                for column in modality_table.PATH_COLUMNS:
                    if column in self.wanted and column in files:
                        ext, data = files[column]
                        rec[column] = f"{column}.{ext}"
                        (root / rec[column]).write_bytes(data)
                    elif column not in files:
                        rec[column] = ""
                yield self.item(root, rec, count)
                count += 1

    def __repr__(self) -> str:
        return (
            f"EdenShards({str(self.source)!r}, {self.format}, split={self.split!r}, {len(self.shards)} shard(s), "
            f"modalities={list(self.modalities)}, stereo={self.stereo})"
        )
