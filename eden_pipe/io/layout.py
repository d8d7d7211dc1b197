"""File layout of a render artifact, and writing a finished frame into it.

Files go to ``<folder>/cam<k>/<column>/<frame>.<ext>`` where ``column`` is the
manifest column (docs/design.md, Dataset layout) and ``ext`` its format's extension
(:mod:`eden_pipe.modalities`). A frame is finished when ``frames/<frame>.json``
exists (written last, by rename, after all its files), so an interrupted render
resumes at the first unfinished frame.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from eden_pipe.modalities import COLUMNS, WriteOptions, columns_for

MARKERS = "frames"


def frame_files(
    k: int, frame: int, modalities, options: WriteOptions, has_next: bool, has_prev: bool
) -> dict[str, str]:
    """Manifest column -> relative file path for camera pair ``k`` of one frame (table order)."""
    return {
        c.name: f"cam{k}/{c.name}/{frame:05d}.{c.file_format(options).ext}"
        for c in columns_for(modalities, has_next, has_prev)
    }


def marker_path(folder: Path, frame: int) -> Path:
    return Path(folder) / MARKERS / f"{frame:05d}.json"


def unfinished(folder: Path, n_frames: int) -> list[int]:
    """Frames below ``n_frames`` without a completion marker (creates the marker folder)."""
    (Path(folder) / MARKERS).mkdir(exist_ok=True)
    return [f for f in range(n_frames) if not marker_path(folder, f).is_file()]


def write_files(folder: Path, files: dict[str, str], data: dict[str, np.ndarray], options: WriteOptions) -> None:
    """Write each column's array to its file (``files`` from :func:`frame_files`)."""
    for column, rel in files.items():
        COLUMNS[column].write(Path(folder) / rel, data[column], options)


def write_marker(folder: Path, frame: int, time: float, files: dict[str, dict[str, str]]) -> None:
    """Mark ``frame`` finished: its time and every camera pair's files (atomic rename)."""
    target = marker_path(folder, frame)
    tmp = target.with_name(f".{frame:05d}.json.tmp")
    tmp.write_text(json.dumps({"frame": frame, "time": time, "files": files}))
    tmp.replace(target)
