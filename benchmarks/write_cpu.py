"""CPU time of each manifest column's writer (quantising, encoding, writing the file), per row.

Reads a rendered dataset's files back as the arrays a render hands the writers (every format is
lossless up to its quantisation, so the writers do the same work) and writes each with the
column's writer (``modalities.COLUMNS[column].write``, the render's options) into a scratch
folder (tmpfs where there is one), keeping each file's least CPU time (``time.process_time``)
over ``--repeats`` interleaved rounds. Another revision's writers: put its tree first on
PYTHONPATH (as ``benchmarks/pair_profile.py``), and alternate the two runs.

    python benchmarks/write_cpu.py --dataset /work/cache/bench/dataset [--frames 2] [--cameras 2,3,4] [--repeats 5]
    PYTHONPATH=/path/to/REV-worktree python benchmarks/write_cpu.py ...
"""

from __future__ import annotations

import argparse
import csv
import os
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path[:0] = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]  # another tree first

from eden_pipe.modalities import COLUMNS, WriteOptions  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--dataset", type=Path, default=Path("/work/cache/bench/dataset"))
    parser.add_argument("--frames", default="", help="comma-separated frames to time (default: all)")
    parser.add_argument("--cameras", default="", help="comma-separated cameras to time (default: all)")
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    import cv2

    cv2.setNumThreads(1)  # as in the render stage (threadpoolctl there)
    frames = {int(f) for f in args.frames.split(",") if f}
    cameras = {int(c) for c in args.cameras.split(",") if c}
    with open(args.dataset / "manifest.csv") as fh:
        rows = [
            r
            for r in csv.DictReader(fh)
            if (not frames or int(r["frame"]) in frames) and (not cameras or int(r["camera"]) in cameras)
        ]
    files = [
        (i, column, COLUMNS[column].read(args.dataset / row[column]))
        for i, row in enumerate(rows)
        for column in COLUMNS
        if row.get(column)
    ]
    options = WriteOptions()  # the render's defaults: png16 depth, compact storage, png_compression 1
    best: dict[tuple[int, str], float] = {}
    size: dict[tuple[int, str], int] = {}
    scratch_dir = "/dev/shm" if os.path.isdir("/dev/shm") else None
    with tempfile.TemporaryDirectory(dir=scratch_dir) as tmp:
        for _ in range(args.repeats):
            for i, column, array in files:
                path = Path(tmp) / f"{column}.{COLUMNS[column].file_format(options).ext}"
                start = time.process_time()
                COLUMNS[column].write(path, array, options)
                best[(i, column)] = min(best.get((i, column), float("inf")), time.process_time() - start)
                size[(i, column)] = path.stat().st_size
    per_column: dict[str, list[float]] = {}
    for (i, column), seconds in best.items():
        entry = per_column.setdefault(column, [0.0, 0.0])
        entry[0] += seconds * 1e3 / len(rows)
        entry[1] += size[(i, column)] / 1e3 / len(rows)
    print(f"{len(rows)} rows; writer CPU ms and file kB per row (mean):")
    for column, (ms, kb) in per_column.items():
        print(f"  {column:14s} {ms:6.2f} ms {kb:8.1f} kB")
    ms, kb = (sum(v[k] for v in per_column.values()) for k in (0, 1))
    print(f"  total          {ms:6.2f} ms {kb:8.1f} kB")


if __name__ == "__main__":
    main()
