"""Freed heap memory handed back to the operating system between a job's phases.

glibc's malloc keeps what a process frees in its arenas, for reuse. What the tracer's worker
threads and numba's compiler free stays in their arenas' free lists. It counts in the process's RSS
until it is trimmed: glibc gives back on its own only free memory at the top of a heap, not pages
below blocks still in use. The next phase's large tables do not always fit those holes, so the
job's peak grows by what lies free. ``malloc_trim(0)`` returns every arena's free pages.

This is done at the bake's phase boundaries and between stages. On the default garden a whole job
peaked at 2,253-2,265 against 2,337-2,347 MiB, and the bake alone at 2,212 against 2,312 MiB
(docs/scale-out.md, Memory). Values are untouched.
Where the C library has no ``malloc_trim`` (musl, macOS, Windows) this does nothing.
"""

from __future__ import annotations

import ctypes
import functools
import sys


@functools.cache
def _malloc_trim():
    """glibc's ``malloc_trim`` from the process's own C library, or None where there is none."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(None)  # the symbols already loaded into the process: its own libc
    except OSError:
        return None
    trim = getattr(libc, "malloc_trim", None)
    if trim is None:  # not glibc
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_memory() -> bool:
    """Return the heap's free pages to the operating system (glibc). True where that was done."""
    trim = _malloc_trim()
    if trim is None:
        return False
    trim(0)
    return True
