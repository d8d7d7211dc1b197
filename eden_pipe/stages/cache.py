"""The stage cache: ``stages/<stage>/<key>/`` folders with a completion marker.

A key hashes the stage's resolved config slice, its upstream keys and the
stage's code fingerprint (the source of the stage module and of every
eden_pipe module it imports), so an artifact is only ever reused by the code
that made it: editing a builder rebuilds what it built, with no version number
to remember. An artifact is finished when its ``DONE.json`` marker
exists; the marker is always written last:

- whole artifacts are built in a temporary sibling folder which is renamed into
  place (atomic on one filesystem), so a crash never leaves a half artifact
  that looks finished;
- resumable artifacts (the render stage) are built in place, unit by unit (one
  frame at a time, each with its own marker), and get ``DONE.json`` when every
  unit is there; a rerun skips the finished units.

Concurrent jobs on one cache serialise on a per-artifact ``fcntl`` lock, so two
jobs needing the same artifact build it once; the second finds it cached.

The marker records the artifact's content (file count, total bytes and a digest of
every file's relative path and size). Reusing an artifact re-lists its folder (one
``stat`` per file, no reads: milliseconds for a render of thousands of files) and a
damaged artifact (a truncated or missing file) is logged in one line and rebuilt
instead of crashing a later stage. Contents are not hashed: that would read every
byte on every reuse.

``StageCache(root, lookup_only=True)`` never builds or writes: ``build`` returns a
finished artifact or raises :class:`NotBuilt`. The pre-flight checks use it to run
the stage functions for their keys alone (what is already done, before any work).
"""

from __future__ import annotations

import ast
import contextlib
import fcntl
import functools
import hashlib
import importlib.util
import json
import logging
import os
import shutil
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

MARKER = "DONE.json"
log = logging.getLogger("eden_pipe")


class NotBuilt(Exception):
    """``stage/key`` is not finished (raised by a lookup-only cache instead of building it)."""

    def __init__(self, stage: str, key: str, path: Path):
        super().__init__(f"{stage}/{key} is not built")
        self.stage, self.key, self.path = stage, key, path


def config_hash(*parts: Any, length: int = 16) -> str:
    """Stable hex digest of JSON-serialisable parts (dict keys sorted)."""
    text = json.dumps(parts, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:length]


@functools.cache
def code_fingerprint(module_name: str, package: str = "eden_pipe") -> str:
    """Hash of the source of ``module_name`` and of every ``package`` module it imports,
    transitively (:func:`code_sources`)."""
    sources = code_sources(module_name, package)
    digest = hashlib.sha256()
    for name in sorted(sources):
        digest.update(name.encode() + b"\0" + sources[name])
    return digest.hexdigest()[:16]


def code_sources(module_name: str, package: str = "eden_pipe") -> dict[str, bytes]:
    """The source of ``module_name`` and of every ``package`` module it imports, transitively, by
    module name (imports inside functions included: the AST is walked, not executed). Only absolute
    imports are followed: a relative import would leave its module out of the fingerprint."""
    sources: dict[str, bytes] = {}
    todo = [module_name]
    while todo:
        name = todo.pop()
        if name in sources:
            continue
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):  # ``from pkg.module import function``: not a module
            continue
        if spec is None or not spec.origin or not spec.origin.endswith(".py"):
            continue
        source = Path(spec.origin).read_bytes()
        sources[name] = source
        for node in ast.walk(ast.parse(source)):
            if isinstance(node, ast.Import):
                todo += [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                todo += [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
        todo = [n for n in todo if n == package or n.startswith(package + ".")]
    return sources


@contextlib.contextmanager
def file_lock(path: Path):
    """Exclusive advisory lock held for the duration of the block."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a+") as fh:
        fcntl.flock(fh.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh.fileno(), fcntl.LOCK_UN)


@dataclass
class Artifact:
    stage: str
    key: str
    path: Path
    cached: bool
    seconds: float

    def marker(self) -> dict:
        return json.loads((self.path / MARKER).read_text())


class StageCache:
    """Builds or reuses stage artifacts under ``root``."""

    def __init__(self, root: str | os.PathLike, force: set[str] | None = None, *, lookup_only: bool = False):
        self.root = Path(root)
        self.force = set(force or ())
        self.lookup_only = lookup_only
        self._rebuilt: set[tuple[str, str]] = set()  # forced artifacts this cache has already rebuilt

    def path(self, stage: str, key: str) -> Path:
        return self.root / stage / key

    def _forced(self, stage: str, key: str) -> bool:
        """Force applies once per artifact and cache: every artifact of a forced stage (the garden's
        models too, built inside the model stage) is rebuilt once; later calls reuse the fresh build."""
        return (stage in self.force or "all" in self.force) and (stage, key) not in self._rebuilt

    def build(
        self, stage: str, key: str, builder: Callable[[Path], dict | None], *, resumable: bool = False
    ) -> Artifact:
        """Return the finished artifact ``stage/key``, building it if needed.

        ``builder(folder)`` writes the artifact's files into ``folder`` and may
        return a dict of facts that goes into the marker. With ``resumable``
        the folder is the final one and the builder must skip units that are
        already finished.
        """
        final = self.path(stage, key)
        start = time.perf_counter()
        if self.lookup_only:
            if (final / MARKER).is_file() and damage(final) is None:
                return Artifact(stage, key, final, True, 0.0)
            raise NotBuilt(stage, key, final)
        with file_lock(self.root / stage / f".{key}.lock"):
            forced = self._forced(stage, key)
            if forced:
                self._rebuilt.add((stage, key))
            if (final / MARKER).is_file() and not forced:
                problem = damage(final)
                if problem is None:
                    return Artifact(stage, key, final, True, time.perf_counter() - start)
                log.warning(f"[eden-pipe] stage cache {stage}/{key} is damaged ({problem}): rebuilding it")
                forced = True
            if forced and final.exists():
                _remove_tree(final)
            if resumable:
                final.mkdir(parents=True, exist_ok=True)
                facts = builder(final) or {}
                _write_marker(final, stage, key, facts, time.perf_counter() - start)
            else:
                tmp = final.parent / f".tmp-{key}-{uuid.uuid4().hex[:8]}"
                tmp.mkdir(parents=True)
                try:
                    facts = builder(tmp) or {}
                    _write_marker(tmp, stage, key, facts, time.perf_counter() - start)
                    if final.exists():  # an unfinished leftover without marker
                        _remove_tree(final)
                    os.rename(tmp, final)
                except BaseException:
                    shutil.rmtree(tmp, ignore_errors=True)
                    raise
        return Artifact(stage, key, final, False, time.perf_counter() - start)


def content_summary(folder: Path) -> dict:
    """Count, total size and a digest of (relative path, size) of every file under ``folder``
    except the marker and hidden files (locks, temporaries): what a finished artifact must still hold."""
    digest = hashlib.sha256()
    count = total = 0
    entries = []
    for dirpath, dirnames, filenames in os.walk(folder):
        dirnames[:] = [d for d in dirnames if not d.startswith(".")]
        for name in filenames:
            if name.startswith(".") or (name == MARKER and dirpath == str(folder)):
                continue
            path = os.path.join(dirpath, name)
            entries.append((os.path.relpath(path, folder), os.stat(path).st_size))
    for rel, size in sorted(entries):
        digest.update(f"{rel}\t{size}\n".encode())
        count, total = count + 1, total + size
    return {"files": count, "bytes": total, "digest": digest.hexdigest()[:16]}


def damage(folder: Path) -> str | None:
    """None if the finished artifact in ``folder`` holds what its marker recorded, else what differs."""
    try:
        recorded = json.loads((folder / MARKER).read_text()).get("content")
    except (OSError, ValueError) as err:
        return f"unreadable {MARKER}: {err}"
    if recorded is None:  # a marker from before content was recorded: nothing to compare
        return None
    found = content_summary(folder)
    if found == recorded:
        return None
    return (
        f"{found['files']} files / {found['bytes']} bytes found, {recorded['files']} files / "
        f"{recorded['bytes']} bytes recorded"
        + ("" if found["files"] != recorded["files"] or found["bytes"] != recorded["bytes"] else ", sizes differ")
    )


def _write_marker(folder: Path, stage: str, key: str, facts: dict, seconds: float) -> None:
    data = {"stage": stage, "key": key, "seconds": round(seconds, 3), **facts, "content": content_summary(folder)}
    tmp = folder / f".{MARKER}.tmp"
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True))
    os.replace(tmp, folder / MARKER)


def _remove_tree(path: Path) -> None:
    """Move aside then delete, so a crash mid-delete never leaves a marker with missing files."""
    trash = path.parent / f".trash-{path.name}-{uuid.uuid4().hex[:8]}"
    os.rename(path, trash)
    shutil.rmtree(trash, ignore_errors=True)
