"""The stage cache under contention (scale-out): 4 processes racing for one artifact, whole and
resumable, and force applying once per artifact (the garden's nested models included)."""

from __future__ import annotations

import json
import multiprocessing as mp
import time
from pathlib import Path

from eden_pipe.stages.cache import MARKER, StageCache


def _build(root: str, key: str, log: str, start_at: float, resumable: bool) -> tuple[str, bool]:
    while time.time() < start_at:  # every process reaches the lock at about the same moment
        time.sleep(0.001)
    cache = StageCache(root)

    def builder(folder: Path) -> dict:
        with open(log, "a") as fh:  # one line per builder call, whichever process makes it
            fh.write(f"{mp.current_process().pid}\n")
        time.sleep(0.3)  # hold the lock long enough for the others to queue on it
        (folder / "data.txt").write_text("payload")
        return {"by": mp.current_process().pid}

    art = cache.build("model", key, builder, resumable=resumable)
    return str(art.path), art.cached


def test_processes_racing_for_one_artifact_build_it_once(tmp_path):
    ctx = mp.get_context("fork")
    for resumable in (False, True):
        key, log = f"k-{resumable}", tmp_path / f"calls-{resumable}.log"
        start_at = time.time() + 0.5
        with ctx.Pool(4) as pool:
            results = pool.starmap(_build, [(str(tmp_path / "stages"), key, str(log), start_at, resumable)] * 4)
        assert len(log.read_text().split()) == 1  # exactly one builder call
        assert sorted(cached for _, cached in results) == [False, True, True, True]
        assert len({path for path, _ in results}) == 1
        folder = Path(results[0][0])
        assert (folder / "data.txt").read_text() == "payload" and (folder / MARKER).is_file()
    assert not [p for p in (tmp_path / "stages" / "model").iterdir() if p.name.startswith((".tmp-", ".trash-"))]


def test_force_rebuilds_every_artifact_of_the_stage_once(tmp_path):
    calls: list[str] = []

    def builder(name):
        def build(folder: Path) -> dict:
            calls.append(name)
            return {}

        return build

    StageCache(tmp_path).build("model", "garden", builder("garden"))
    StageCache(tmp_path).build("model", "tree", builder("tree"))
    cache = StageCache(tmp_path, {"model"})
    # A forced stage rebuilds each of its artifacts once (the garden's nested models too), then reuses them.
    for name in ("garden", "tree", "garden", "tree"):
        cache.build("model", name, builder(name))
    assert calls == ["garden", "tree", "garden", "tree"]
    assert json.loads((tmp_path / "model" / "tree" / MARKER).read_text())["key"] == "tree"
    cache.build("scene", "s", builder("scene"))
    assert calls[-1] == "scene"
    everything = StageCache(tmp_path, {"all"})
    everything.build("scene", "s", builder("scene"))
    everything.build("scene", "s", builder("scene"))
    assert calls.count("scene") == 2
