"""Freed heap memory handed back between a job's phases (``eden_pipe.heap``)."""

from __future__ import annotations

import sys
import threading

import numpy as np
import pytest

from eden_pipe import heap


def resident_mib() -> float:
    fields = dict(line.split(":", 1) for line in open("/proc/self/status"))
    return int(fields["VmRSS"].split()[0]) / 1024


def free_below_a_pinned_block(kept: list) -> None:
    """240 MB of 8 KB arrays (malloc'd on the heap, not mapped) freed under one that stays: the
    heap's top cannot shrink past the kept block, so glibc keeps the freed pages."""
    blocks = [np.ones(1000) for _ in range(30_000)]
    kept.append(np.ones(1000))
    del blocks


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim: Linux only")
@pytest.mark.parametrize("where", ["main thread", "worker thread"])
def test_freed_pages_go_back_to_the_system(where):
    if heap._malloc_trim() is None:
        pytest.skip("this C library has no malloc_trim (not glibc)")
    kept: list = []
    if where == "main thread":
        free_below_a_pinned_block(kept)
    else:  # a thread's own arena, as the tracer's workers allocate from
        worker = threading.Thread(target=free_below_a_pinned_block, args=(kept,))
        worker.start()
        worker.join()
    before = resident_mib()
    assert heap.release_free_memory() is True
    after = resident_mib()
    assert before - after > 150, f"RSS {before:.0f} -> {after:.0f} MiB"
    assert kept[0].sum() == 1000  # what is still held is untouched


def test_without_malloc_trim_nothing_is_done(monkeypatch):
    monkeypatch.setattr(heap, "_malloc_trim", lambda: None)
    assert heap.release_free_memory() is False
