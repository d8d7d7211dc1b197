"""The stage cache: markers written last, atomic builds, locks across processes."""

from __future__ import annotations

import json
import multiprocessing as mp
import time

import pytest

from eden_pipe.stages.cache import MARKER, NotBuilt, StageCache, config_hash


def test_build_then_cached(tmp_path):
    cache = StageCache(tmp_path)
    calls = []

    def builder(folder):
        calls.append(folder)
        (folder / "x.txt").write_text("hi")
        return {"n": 1}

    a = cache.build("model", "k1", builder)
    b = cache.build("model", "k1", builder)
    assert not a.cached and b.cached and len(calls) == 1
    assert (a.path / "x.txt").read_text() == "hi" and a.marker()["n"] == 1


def test_failed_build_leaves_nothing(tmp_path):
    cache = StageCache(tmp_path)

    def broken(folder):
        (folder / "half.txt").write_text("x")
        raise RuntimeError("boom")

    with pytest.raises(RuntimeError):
        cache.build("scene", "k", broken)
    assert not cache.path("scene", "k").exists()
    assert [p for p in (tmp_path / "scene").iterdir() if not p.name.endswith(".lock")] == []


def test_force_rebuilds_once(tmp_path):
    n = []
    StageCache(tmp_path).build("render", "k", lambda f: n.append(1))
    forced = StageCache(tmp_path, force={"render"})
    assert not forced.build("render", "k", lambda f: n.append(1)).cached
    assert forced.build("render", "k", lambda f: n.append(1)).cached  # force applies once per run
    assert len(n) == 2


def test_resumable_marker_written_last(tmp_path):
    cache = StageCache(tmp_path)

    def builder(folder):
        assert not (folder / MARKER).exists()
        (folder / "unit1").write_text("1")

    art = cache.build("render", "r", builder, resumable=True)
    assert (art.path / MARKER).is_file() and (art.path / "unit1").is_file()


def test_config_hash_is_order_independent():
    assert config_hash({"a": 1, "b": [1, 2]}) == config_hash({"b": [1, 2], "a": 1})
    assert config_hash({"a": 1}) != config_hash({"a": 2})


def _slow_build(root, log):
    cache = StageCache(root)

    def builder(folder):
        with open(log, "a") as fh:
            fh.write("built\n")
        time.sleep(0.5)

    cache.build("model", "shared", builder)


def test_concurrent_jobs_build_once(tmp_path):
    log = tmp_path / "log.txt"
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_slow_build, args=(tmp_path / "c", log)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(30)
    assert all(p.exitcode == 0 for p in procs)
    assert log.read_text() == "built\n"


def test_code_fingerprint_follows_imported_sources_only(tmp_path, monkeypatch):
    from eden_pipe.stages.cache import code_fingerprint

    pkg = tmp_path / "fpdemo"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "stage.py").write_text(
        "def build():\n    from fpdemo.builder import make  # lazy import\n    return make()\n"
    )
    (pkg / "builder.py").write_text("def make():\n    return 1\n")
    (pkg / "unrelated.py").write_text("X = 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))

    def fingerprint():
        code_fingerprint.cache_clear()
        return code_fingerprint("fpdemo.stage", package="fpdemo")

    first = fingerprint()
    (pkg / "unrelated.py").write_text("X = 2\n")
    assert fingerprint() == first, "a module the stage never imports does not change its key"
    (pkg / "builder.py").write_text("def make():\n    return 2\n")
    assert fingerprint() != first, "editing an imported builder changes the key"
    code_fingerprint.cache_clear()


def test_sky_visibility_and_render_keys_cover_every_visibility_module():
    """The bake and the render read the modules of ``render/visibility/``: an edit to any of them
    must change the keys of both stages (their fingerprints hold every one of them)."""
    import pkgutil

    from eden_pipe.render import backends, visibility
    from eden_pipe.stages.cache import code_sources

    prefix = visibility.__name__ + "."
    package = {visibility.__name__} | {m.name for m in pkgutil.iter_modules(visibility.__path__, prefix)}
    assert len(package) >= 6
    bake_stage = set(code_sources("eden_pipe.stages.sky_visibility"))
    render_stage = set(code_sources("eden_pipe.stages.render")) | set(code_sources(backends.module_of("raytrace")))
    assert package <= bake_stage, package - bake_stage
    assert package <= render_stage, package - render_stage


def test_geometry_stage_keys_leave_the_renderer_out():
    """Plants, the garden and the trajectory do not depend on how they are lit: an edit to the
    shading or the ray tracer must not rebuild them (their fingerprints hold no renderer module
    beyond the backend registry, which names the backends)."""
    from eden_pipe.stages.cache import code_sources

    for stage in ("model", "scene", "trajectory"):
        sources = set(code_sources(f"eden_pipe.stages.{stage}"))
        renderer = {s for s in sources if s.startswith("eden_pipe.render.")} - {"eden_pipe.render.backends"}
        assert not renderer, (stage, sorted(renderer))
    assert "eden_pipe.render.embree" in code_sources("eden_pipe.stages.sky_visibility")


def test_package_imports_are_absolute():
    """The code fingerprint follows absolute imports only: a relative one would hide its module."""
    import ast
    from pathlib import Path

    import eden_pipe

    relative = [
        f"{path}:{node.lineno}"
        for path in Path(eden_pipe.__file__).parent.rglob("*.py")
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.ImportFrom) and node.level
    ]
    assert not relative


def test_model_keys_change_when_code_or_a_preset_changes(tmp_path, monkeypatch):
    import shutil

    from eden_pipe.models import species
    from eden_pipe.stages import model

    copy = tmp_path / "species"
    shutil.copytree(species.SPECIES_DIR, copy)
    monkeypatch.setattr(species, "SPECIES_DIR", copy)
    species.presets_fingerprint.cache_clear()
    before = model.model_key("trees", "quaking_aspen", 3, {})
    assert model.model_key("trees", "quaking_aspen", 3, {}) == before
    preset = copy / "trees" / "quaking_aspen.yaml"
    preset.write_text(preset.read_text() + "\n# edited\n")
    species.presets_fingerprint.cache_clear()
    assert model.model_key("trees", "quaking_aspen", 3, {}) != before
    species.presets_fingerprint.cache_clear()


# ------------------------------------------------ damaged artifacts (docs/reliability.md)
def _payload_builder(calls):
    def builder(folder):
        calls.append(1)
        (folder / "sub").mkdir()
        (folder / "sub" / "data.bin").write_bytes(bytes(range(256)) * 8)
        (folder / "small.txt").write_text("kept")
        return {"n": 2}

    return builder


@pytest.mark.parametrize("resumable", [False, True], ids=["whole", "resumable"])
@pytest.mark.parametrize("damage_kind", ["truncated", "missing", "grown"])
def test_damaged_artifact_is_detected_and_rebuilt(tmp_path, caplog, resumable, damage_kind):
    cache, calls = StageCache(tmp_path), []
    art = cache.build("scene", "k", _payload_builder(calls), resumable=resumable)
    assert art.marker()["content"] == {"files": 2, "bytes": 2048 + 4, "digest": art.marker()["content"]["digest"]}
    target = art.path / "sub" / "data.bin"
    if damage_kind == "truncated":
        target.write_bytes(target.read_bytes()[:1000])
    elif damage_kind == "missing":
        target.unlink()
    else:
        target.write_bytes(target.read_bytes() + b"x")
    again = StageCache(tmp_path).build("scene", "k", _payload_builder(calls), resumable=resumable)
    assert not again.cached and len(calls) == 2
    assert target.read_bytes() == bytes(range(256)) * 8
    assert "stage cache scene/k is damaged" in caplog.text
    assert StageCache(tmp_path).build("scene", "k", _payload_builder(calls)).cached and len(calls) == 2


def test_unreadable_marker_counts_as_damage(tmp_path):
    calls = []
    art = StageCache(tmp_path).build("model", "k", _payload_builder(calls))
    (art.path / MARKER).write_text("{not json")
    assert not StageCache(tmp_path).build("model", "k", _payload_builder(calls)).cached and len(calls) == 2
    assert json.loads((art.path / MARKER).read_text())["n"] == 2


def test_hidden_files_and_an_identical_artifact_are_not_damage(tmp_path):
    calls = []
    art = StageCache(tmp_path).build("model", "k", _payload_builder(calls))
    (art.path / ".leftover.tmp").write_text("a temporary of an interrupted writer")
    assert StageCache(tmp_path).build("model", "k", _payload_builder(calls)).cached and len(calls) == 1


def test_lookup_only_cache_finds_finished_artifacts_and_writes_nothing(tmp_path):
    lookup = StageCache(tmp_path / "stages", lookup_only=True)
    with pytest.raises(NotBuilt) as missing:
        lookup.build("render", "r", lambda folder: pytest.fail("a lookup must not build"))
    assert missing.value.stage == "render" and missing.value.path == tmp_path / "stages" / "render" / "r"
    assert not (tmp_path / "stages").exists()
    calls = []
    StageCache(tmp_path / "stages").build("render", "r", _payload_builder(calls), resumable=True)
    assert lookup.build("render", "r", _payload_builder(calls)).cached and len(calls) == 1
    (tmp_path / "stages" / "render" / "r" / "small.txt").unlink()
    with pytest.raises(NotBuilt):  # damaged: not finished for the lookup either
        lookup.build("render", "r", _payload_builder(calls))
