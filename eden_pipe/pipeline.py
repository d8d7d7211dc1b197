"""One job: model -> scene -> trajectory -> render -> manifest, each stage cached.

``run_job(cfg)`` is what ``python -m eden_pipe`` calls for every (garden,
lighting) job; it is also the programmatic entry point used by the tests and
benchmarks. It converts the config once (``config.to_config``: DictConfig ->
typed ``EdenConfig``), checks it and the world it will write to before any
stage (``preflight.check_job``), and hands each stage its typed slice:

==============  =========================================================
model           ``GardenConfig``
scene           ``GardenConfig``, ``CameraConfig`` (rig height: proxy clip)
trajectory      ``CameraConfig`` (rig + ``TrajectoryConfig``), the lighting's name
                (a walk per lighting unless ``share_across_lightings``)
sky_visibility  ``RenderConfig`` (its ``sky_visibility`` bake settings), ``CameraConfig`` (where the rig
                stands and looks); skipped unless the render uses it
render          the whole ``EdenConfig`` (render, lighting, camera)
manifest        ``SplitConfig``, ``CameraConfig``, the lighting's name
==============  =========================================================
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

from omegaconf import DictConfig

from eden_pipe.config import EdenConfig
from eden_pipe.heap import release_free_memory
from eden_pipe.preflight import check_job
from eden_pipe.stages.cache import Artifact, StageCache
from eden_pipe.stages.describe import publish_metadata
from eden_pipe.stages.manifest import publish, run_manifest_stage
from eden_pipe.stages.model import run_model_stage
from eden_pipe.stages.render import run_render_stage
from eden_pipe.stages.scene import run_scene_stage
from eden_pipe.stages.sky_visibility import needs_sky_visibility, run_sky_visibility_stage
from eden_pipe.stages.trajectory import run_trajectory_stage

log = logging.getLogger("eden_pipe")


@dataclass
class JobResult:
    artifacts: dict[str, Artifact] = field(default_factory=dict)
    dataset: Path | None = None
    published: dict = field(default_factory=dict)


def _call(name: str, fn, *args, **kwargs) -> Artifact:
    return fn(*args, **kwargs)


CHAIN = ("model", "scene", "trajectory", "sky_visibility", "render")


def run_stages(cfg: EdenConfig, cache: StageCache, step=_call, through: str = "render") -> dict[str, Artifact]:
    """The stage chain up to render (or up to ``through``, for benchmarks that time one stage), in order,
    each called through ``step(name, fn, *args, **kwargs)``.

    The one place the chain is written: ``run_job`` runs it; the pre-flight disk estimate walks it
    on a lookup-only cache, which raises ``NotBuilt`` at the first stage not cached yet.
    """
    reached = CHAIN[: CHAIN.index(through) + 1]
    arts = {"model": step("model", run_model_stage, cfg.garden, cache)}
    if "scene" in reached:
        arts["scene"] = step("scene", run_scene_stage, cfg.garden, cfg.camera, arts["model"], cache)
    if "trajectory" in reached:
        arts["trajectory"] = step(
            "trajectory", run_trajectory_stage, cfg.camera, arts["scene"], arts["model"], cache, cfg.lighting.name
        )
    if "sky_visibility" in reached:
        arts["sky_visibility"] = (
            step("sky_visibility", run_sky_visibility_stage, cfg.render, cfg.camera, arts["scene"], cache)
            if needs_sky_visibility(cfg.render)
            else None
        )
    if "render" in reached:
        arts["render"] = step(
            "render",
            run_render_stage,
            cfg,
            arts["scene"],
            arts["trajectory"],
            cache,
            progress=bool(cfg.progress),
            sky_visibility=arts["sky_visibility"],
        )
    return arts


def run_job(cfg: DictConfig | EdenConfig, *, echo=print) -> JobResult:
    """Run (or reuse) every stage for one garden under one lighting."""
    cfg = check_job(cfg)  # every check before any stage: config, presets, folders, free space
    cache = StageCache(cfg.paths.stages, set(cfg.force))
    result = JobResult()

    def step(name: str, fn, *args, **kwargs) -> Artifact:
        start = time.perf_counter()
        art = fn(*args, **kwargs)
        art.seconds = time.perf_counter() - start
        release_free_memory()  # what the stage freed goes back before the next one (eden_pipe.heap)
        result.artifacts[name] = art
        echo(f"[eden-pipe] {name:<10} {'cached' if art.cached else 'built':<6} {art.seconds:8.2f} s")
        return art

    arts = run_stages(cfg, cache, step)
    scene, traj, render = arts["scene"], arts["trajectory"], arts["render"]
    manifest = step(
        "manifest", run_manifest_stage, cfg.split, cfg.camera, cfg.lighting.name, scene, render, traj, cache
    )
    result.dataset = Path(cfg.paths.dataset)
    # Metadata first (instance table, lighting, rig and poses, configs, dataset.json): publishing the
    # images then merges the root manifest once, with dataset.json's test-subsample settings.
    meta_written = publish_metadata(cfg, scene, traj, render, result.dataset)
    result.published = publish(manifest, render, result.dataset)
    result.published["files_written"] += meta_written
    echo(
        f"[eden-pipe] dataset    {result.dataset}/manifest.csv: {result.published['root_rows']} rows, "
        f"{result.published['files_written']} files written"
    )
    return result
