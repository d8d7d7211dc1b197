"""Read throughput (samples/s): a dataset folder through EdenDataset vs its shards through EdenShards.

    python benchmarks/shard_throughput.py [--dataset DIR] [--repeats 3] [--shard-size 64]

Without ``--dataset`` it first makes a small dataset in a temporary folder (``python -m eden_pipe garden=small
'camera.trajectory.frames=[6,6]'``: 30 rows at 640x480; 6 minutes on 2 shared cores, 4 of them the sky-visibility
bake). It exports the dataset with ``--format webdataset`` and ``--format hf`` (files, sizes and export times
printed), then reads every row of every split, one process, no DataLoader workers, for two modality sets: ``rgb``
alone and every layer the dataset has (stereo included). Each reader makes ``--repeats`` passes, taking turns; its
best pass counts (the files are in the page cache after the first: this measures the readers' own cost, not a
network filesystem's latency, where shards gain most).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from eden_pipe import modalities as modality_table
from eden_pipe.data import EdenDataset, EdenShards
from eden_pipe.data.dataset import loader_columns
from eden_pipe.data.manifest_reader import load_manifest
from eden_pipe.tools.export import export

SMALL = ["garden=small", "camera.trajectory.frames=[6,6]", "progress=false"]


def make_dataset(tmp: Path) -> Path:
    cmd = [sys.executable, "-m", "eden_pipe", *SMALL]
    cmd += [f"paths.stages={tmp / 'stages'}", f"paths.dataset={tmp / 'dataset'}", f"hydra.run.dir={tmp / 'run'}"]
    subprocess.run(cmd, check=True)
    return tmp / "dataset"


def folder_bytes(path: Path) -> int:
    return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())


def rates(readers: dict, repeats: int) -> dict[str, tuple[float, int]]:
    """name -> (best samples/s over the passes, samples per pass); the readers take turns within each pass, so
    a change in the machine's load falls on all of them alike."""
    best = dict.fromkeys(readers, float("inf"))
    counts = dict.fromkeys(readers, 0)
    for _ in range(repeats):
        for name, make in readers.items():
            start = time.perf_counter()
            counts[name] = sum(1 for _ in make())
            best[name] = min(best[name], time.perf_counter() - start)
    return {name: (counts[name] / best[name], counts[name]) for name in readers}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", help="an existing dataset root (default: make a small one)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--shard-size", default="64", help="--shard-size of both exports (default 64 samples)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="shard-bench-") as tmp_name:
        tmp = Path(tmp_name)
        root = Path(args.dataset) if args.dataset else make_dataset(tmp)
        manifest = load_manifest(root)
        splits = sorted(manifest["split"].astype(str).unique())
        paths = [p for c in modality_table.PATH_COLUMNS if c in manifest.columns for p in manifest[c] if p]
        size = sum((root / p).stat().st_size for p in paths)
        print(f"dataset {root}: {len(manifest)} rows, splits {splits}, {len(paths)} files, {size / 1e6:.1f} MB")
        sources = {}
        for fmt in ("webdataset", "hf"):
            out = tmp / fmt
            start = time.perf_counter()
            export(root, fmt, out, shard_size=args.shard_size, seed=0)
            took = time.perf_counter() - start
            files = sum(1 for p in out.rglob("*") if p.is_file())
            print(f"export {fmt:10s} {took:6.2f} s, {files} files, {folder_bytes(out) / 1e6:6.1f} MB")
            sources[fmt] = out
        columns = loader_columns()
        layers = [key for key, column in columns.items() if column in manifest.columns and manifest[column].any()]
        for name, modalities, stereo in (("rgb", ["rgb"], False), ("every layer", layers, True)):
            print(f"\nmodalities: {name} ({', '.join(modalities)}; stereo={stereo})")

            def folder(modalities=modalities, stereo=stereo):
                for split in splits:
                    ds = EdenDataset(root, modalities, split=split, stereo=stereo)
                    yield from (ds[i] for i in range(len(ds)))

            def stream(fmt, modalities=modalities, stereo=stereo):
                for split in splits:
                    yield from EdenShards(sources[fmt], modalities, split=split, stereo=stereo)

            readers = {"folder (EdenDataset)": folder}
            readers.update({f"{fmt} (EdenShards)": (lambda fmt=fmt: stream(fmt)) for fmt in sources})
            results = rates(readers, args.repeats)
            base = results["folder (EdenDataset)"][0]
            for label, (value, count) in results.items():
                print(f"  {label:32s} {value:8.1f} samples/s  ({count} samples)  {value / base:.2f}x")


if __name__ == "__main__":
    main()
