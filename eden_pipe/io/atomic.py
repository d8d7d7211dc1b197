"""Atomic file replacement for writers that need a path (not a file handle).

Like ``eden_pipe.io.formats``: the data goes to a hidden temporary file in the
destination folder, then ``os.replace`` puts it under its final name, so an
interrupted job never leaves a truncated file under the final name. The
temporary file is removed if the writer fails.

Fault injection (tests only, off unless the variable is set): with
``EDEN_PIPE_FAULT_ENOSPC_AFTER_BYTES=N`` in the environment, the first write that
takes this process past N bytes written through :func:`atomic_path` fails with
``ENOSPC`` as a full disk would (its temporary file removed), and so does every
later one: tests/test_faults.py uses it to fill the disk mid-render.
"""

from __future__ import annotations

import contextlib
import errno
import os
import shutil
import threading
import uuid
from pathlib import Path

FAULT_ENV = "EDEN_PIPE_FAULT_ENOSPC_AFTER_BYTES"
_fault_lock = threading.Lock()
_fault_written = [0]  # bytes charged so far (a list: updated in place under the lock)


def _charge(tmp: Path, path: Path) -> None:
    """The fault-injection hook (see the module doc); does nothing unless FAULT_ENV is set."""
    limit = os.environ.get(FAULT_ENV)
    if limit is None:
        return
    with _fault_lock:
        _fault_written[0] += tmp.stat().st_size
        if _fault_written[0] > int(limit):
            raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)} (injected by {FAULT_ENV})", str(path))


@contextlib.contextmanager
def atomic_path(path, suffix: str = ".tmp"):
    """Yield a temporary path beside ``path``; on success rename it to ``path``.

    ``suffix`` ends the temporary name (some libraries choose the codec by extension).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}{suffix}")
    try:
        try:
            yield tmp
        except Exception as err:
            failure = _filesystem_failure(err, tmp, path)
            if failure is None:
                raise
            raise failure from err
        _charge(tmp, path)
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def write_bytes_atomic(path, data) -> None:
    """Write ``data`` (bytes-like, or a function that writes to a binary file handle) atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            data(fh) if callable(data) else fh.write(data)


#: Errors a full or read-only filesystem gives; libraries that hide them (OpenEXR's RuntimeError,
#: numpy's short write without an errno) are turned back into an OSError naming the file.
FILESYSTEM_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES)


def _filesystem_failure(err: Exception, tmp: Path, path) -> OSError | None:
    """The OSError behind a writer's failure, or None when the filesystem is not the cause."""
    if isinstance(err, OSError) and err.errno is not None:
        return None if err.filename else OSError(err.errno, err.strerror, str(path))
    text = str(err)
    for code in FILESYSTEM_ERRNOS:
        if os.strerror(code) in text:
            return OSError(code, os.strerror(code), str(path))
    if isinstance(err, OSError):  # numpy's "N requested and M written": ask the filesystem with one more byte
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_APPEND | os.O_CREAT)
            try:
                os.write(fd, b"\0")
            finally:
                os.close(fd)
        except OSError as probe:
            return OSError(probe.errno, probe.strerror, str(path))
        return OSError(errno.EIO, f"short write ({text})", str(path))
    return None


def write_if_changed(path, data: bytes) -> bool:
    """Atomically write ``data`` unless the file already holds exactly it; True if written.

    Publishing goes through this, so an identical rerun rewrites (and re-times) nothing."""
    path = Path(path)
    if path.is_file() and path.read_bytes() == data:
        return False
    write_bytes_atomic(path, data)
    return True


def link_or_copy(src, dst) -> bool:
    """Make ``dst`` the same file as ``src`` (a hard link, a copy where links are refused), atomically;
    True if anything was written. Publishing places the stage cache's files under the dataset root so."""
    src, dst = Path(src), Path(dst)
    if dst.exists() and (os.path.samefile(src, dst) or _same_bytes(src, dst)):
        return False
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = dst.with_name(f".{dst.name}.{uuid.uuid4().hex[:6]}.tmp")
    try:
        os.link(src, tmp)
    except OSError:
        shutil.copy2(src, tmp)
    os.replace(tmp, dst)
    return True


def _same_bytes(a: Path, b: Path) -> bool:
    return a.stat().st_size == b.stat().st_size and a.read_bytes() == b.read_bytes()
