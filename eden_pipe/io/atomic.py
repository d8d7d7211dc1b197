"""Atomic file replacement for writers that need a path (not a file handle).

Like ``eden_pipe.io.formats``: the data goes to a hidden temporary file in the
destination folder, then ``os.replace`` puts it under its final name, so an
interrupted job never leaves a truncated file under the final name. The
temporary file is removed if the writer fails.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from pathlib import Path


@contextlib.contextmanager
def atomic_path(path, suffix: str = ".tmp"):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    ``suffix`` ends the temporary name (some libraries choose the codec by extension).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}{suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def write_bytes_atomic(path, data) -> None:
    """Write ``data`` (bytes-like, or a function that writes to a binary file handle) atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            data(fh) if callable(data) else fh.write(data)


def write_if_changed(path, data: bytes) -> bool:
    """Atomically write ``data`` unless the file already holds exactly it; True if written.

    Publishing goes through this, so an identical rerun rewrites (and re-times) nothing."""
    path = Path(path)
    if path.is_file() and path.read_bytes() == data:
        return False
    write_bytes_atomic(path, data)
    return True
