"""Sky-visibility stage: the garden's sky visibility and bounce transfer, baked once per garden.

Between scene and render. It depends on the geometry (scene key, bake
settings ``render.sky_visibility``, code) and where the rig stands and looks
(``camera.height_m``, its elevations), never on the lighting, so the five
lightings and every frame of a garden share one artifact:
``stages/sky_visibility/<key>/sky_visibility.npz`` (:class:`eden_pipe.render.visibility.store.SkyVisibility`).
Only the default render needs it (Embree backend, ``render.mode=standard``,
``render.indirect_samples=0``); the pipeline skips the stage otherwise.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

from eden_pipe.config import to_plain
from eden_pipe.rng import rng_for
from eden_pipe.scene.description import read_scene
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash
from eden_pipe.stages.scene import load_scene

FILE = "sky_visibility.npz"


def needs_sky_visibility(render_cfg) -> bool:
    """Whether the render uses the bake: the default light model of the Embree backend."""
    return (
        render_cfg.backend == "raytrace"
        and render_cfg.mode == "standard"
        and int(render_cfg.indirect_samples) == 0
        and bool(render_cfg.sky_visibility.enabled)
    )


def bake_settings(render_cfg, camera_cfg) -> dict:
    """The bake's keyword arguments: ``render.sky_visibility`` and where the rig's cameras stand and
    look (its height over the terrain, the elevations its image spans: ``camera_gain``)."""
    settings = to_plain(render_cfg.sky_visibility)
    settings.pop("enabled")
    half_fov = math.degrees(math.atan2(float(camera_cfg.cy), float(camera_cfg.fy)))
    pitch = float(camera_cfg.pitch_deg)
    settings.update(
        camera_height_m=float(camera_cfg.height_m), camera_elevation_deg=(pitch - half_fov, pitch + half_fov)
    )
    return settings


def run_sky_visibility_stage(render_cfg, camera_cfg, scene_art: Artifact, cache: StageCache) -> Artifact:
    settings = bake_settings(render_cfg, camera_cfg)
    key = config_hash(scene_art.key, settings, code_fingerprint(__name__))

    def builder(folder: Path) -> dict:
        from eden_pipe.render.embree import RayTracer
        from eden_pipe.render.visibility.bake import bake

        _, arrays = load_scene(scene_art)
        seed = read_scene(scene_art).seed
        start = time.perf_counter()
        with RayTracer(arrays.mesh, int(render_cfg.threads), str(render_cfg.tracer)) as tracer:
            bvh = time.perf_counter() - start
            vis = bake(arrays.mesh, tracer, rng_for(seed, "sky_visibility"), **settings)
        vis.save(folder / FILE)
        return {
            "faces": int(arrays.mesh.n_faces),
            "probes": int(vis.n_probes),
            "bvh_seconds": round(bvh, 3),
            "bake_seconds": round(time.perf_counter() - start - bvh, 3),
            "bytes": (folder / FILE).stat().st_size,
        }

    return cache.build("sky_visibility", key, builder)


def load_sky_visibility(art: Artifact):
    from eden_pipe.render.visibility.store import SkyVisibility

    return SkyVisibility.load(art.path / FILE)
