"""The Embree backend (``render.backend=raytrace``, the default): every modality, ``render.view``."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import numpy as np

from eden_pipe import labels
from eden_pipe.modalities import MODALITIES
from eden_pipe.render.backends import Backend


def cloud_map_regions(mesh) -> list:
    """Cloud-shadow tables for a scene: 0.2 m over the garden itself, 0.5 m over everything
    (the background skirt reaches 60 m out, seen at grazing angles). Worst-case error against
    the exact sum, where a shadow edge crosses a cell: 0.003 and 0.02 in transmittance."""
    if mesh.n_faces == 0:
        return []
    v = mesh.vertices
    garden_faces = mesh.semantic != labels.BACKGROUND
    used = np.zeros(len(v), bool)
    used[mesh.faces[garden_faces].ravel()] = True
    garden = v[used] if np.any(used) else v
    return [(garden.min(axis=0), garden.max(axis=0), 0.2), (v.min(axis=0), v.max(axis=0), 0.5)]


def frame_settings(render_cfg, sky, time: float, cloud_regions: list, sky_visibility=None, frame_lights=None):
    """The shading settings of one frame (``render.*`` light-model keys): the sky and its cloud
    shadows tabulated at ``time``, and the garden's bake where the light model uses it
    (``frame_lights``: the job's ``visibility.frame_light.FrameLights``, shared by its frames)."""
    from eden_pipe.render.shading import EnvironmentMap, ShadingSettings
    from eden_pipe.render.sky import CloudShadowMap

    return ShadingSettings(
        indirect_samples=int(render_cfg.indirect_samples),
        soft_shadow_samples=int(render_cfg.soft_shadow_samples),
        time=time,
        environment=EnvironmentMap(sky, time),
        clouds=CloudShadowMap(sky, time, cloud_regions),
        mode=str(render_cfg.mode),
        reference_samples=int(render_cfg.reference_samples),
        reference_bounces=int(render_cfg.reference_bounces),
        sky_visibility=sky_visibility,
        glossy_mirror=str(render_cfg.glossy_mirror),
        mirror_rays=float(render_cfg.mirror_rays),
        frame_lights=frame_lights,
    )


@dataclass
class MovingFrame:
    """A frame's state when the mesh moves: its shading settings and the tracers holding the mesh at
    this frame's time and at its neighbours' (None past the trajectory's ends)."""

    settings: object
    now: object  # RayTracer
    next: object | None
    prev: object | None


class MovingScenes:
    """Each frame thread's ring of movable Embree scenes (wind, docs/design.md "Wind").

    A frame needs the mesh at its own time and at both neighbours' (flow and occlusion follow the
    moved surface). A thread renders consecutive frames, so each new frame moves one scene of its
    ring to the next time and refits its BVH; the other two are reused. Three scenes a thread."""

    SCENES_PER_THREAD = 3

    def __init__(self, mesh, field, threads: int, tracer: str, frame_threads: int = 1):
        from eden_pipe.render.embree import RayTracer

        self.mesh, self.field = mesh, field
        self._local = threading.local()
        self._lock = threading.Lock()
        # Every thread's scenes are built now, with the job's setup (a BVH build each), not in its first frame.
        self._made = [
            RayTracer(mesh, threads, tracer, movable=True) for _ in range(self.SCENES_PER_THREAD * frame_threads)
        ]
        self._free = list(self._made)

    def at(self, times: list[float]) -> dict:
        """This thread's tracers holding the mesh at each of ``times`` (at most three)."""
        ring: dict = getattr(self._local, "ring", None) or {}  # time -> the tracer holding the mesh then
        out = {t: ring[t] for t in times if t in ring}
        spare = [(t, tracer) for t, tracer in ring.items() if t not in out]
        for t in times:
            if t in out:
                continue
            if not spare:
                with self._lock:
                    spare.append((None, self._free.pop()))  # a thread never holds more than three
            tracer = spare.pop()[1]
            self.field.move(t, tracer.vertices)
            tracer.refit()
            out[t] = tracer
        self._local.ring = {**out, **dict(spare)}  # unused ones keep their time
        return out

    def close(self) -> None:
        with self._lock:
            for tracer in self._made:
                tracer.close()
            self._made.clear()


class RaytraceBackend(Backend):
    """One Embree scene shared by every frame thread (queries on a committed scene are thread-safe);
    with wind, a ring of movable scenes per frame thread (:class:`MovingScenes`)."""

    name = "raytrace"
    capabilities = frozenset(MODALITIES)
    max_frame_threads = 0
    moves_geometry = True
    exposure_effects = True

    def __init__(
        self, scene, sky, render_cfg, *, modalities: set[str], threads: int = 0, wind=None, frame_threads: int = 1
    ):
        from eden_pipe.render.embree import RayTracer
        from eden_pipe.render.visibility.frame_light import FrameLights

        self.scene, self.sky, self.render_cfg = scene, sky, render_cfg
        self.sky_visibility = getattr(scene, "sky_visibility", None)  # the garden's bake, when the stage ran
        self.cloud_regions = cloud_map_regions(scene.mesh)
        # Frames under the same sky and sun (any sky whose clouds do not drift) share the bake's
        # per-probe light: each probe's row is made once a job, not once a frame.
        self.frame_lights = FrameLights() if self.sky_visibility is not None else None
        self.moving = (
            None if wind is None else MovingScenes(scene.mesh, wind, threads, str(render_cfg.tracer), frame_threads)
        )
        self.tracer = None if wind is not None else RayTracer(scene.mesh, threads, str(render_cfg.tracer))  # BVH

    def frame(self, time: float, prev_time: float | None = None, next_time: float | None = None):
        """The shading settings of one frame (``frame_settings``); with wind, a :class:`MovingFrame`."""
        settings = frame_settings(
            self.render_cfg, self.sky, time, self.cloud_regions, self.sky_visibility, self.frame_lights
        )
        if self.moving is None:
            return settings
        tracers = self.moving.at([t for t in (time, next_time, prev_time) if t is not None])
        return MovingFrame(
            settings,
            tracers[time],
            None if next_time is None else tracers[next_time],
            None if prev_time is None else tracers[prev_time],
        )

    def render_view(self, state, intr, pose, *, want, pose_next=None, pose_prev=None, rng=None, rgb_spp=1):
        from eden_pipe.render.view import Motion, render_view

        tracer, motion, settings = self.tracer, None, state
        if isinstance(state, MovingFrame):
            tracer, settings = state.now, state.settings
            motion = Motion(self.scene.mesh.faces, state.now.vertices, state.next, state.prev)
        return render_view(
            tracer,
            self.scene,
            intr,
            pose,
            self.sky,
            want=want,
            pose_next=pose_next,
            pose_prev=pose_prev,
            settings=settings,
            rng=rng,
            rgb_spp=rgb_spp,
            motion=motion,
        )

    def render_exposed(self, state, intr, pose_samples, sample_offsets, *, rng, rgb_spp=1):
        from eden_pipe.render.exposure import ExposureScene, render_exposed_rgb

        tracer, settings = self.tracer, state
        if isinstance(state, MovingFrame):
            # Wind: the mesh as it stands at the frame's time, mid-exposure, for every sample (the
            # camera's motion blurs, the foliage's does not: docs/design.md, Camera effects).
            tracer, settings = state.now, state.settings

        def scene_at(offset_s: float) -> ExposureScene:
            return ExposureScene(tracer, self.scene.mesh, settings)  # the same at any time of the exposure

        return render_exposed_rgb(scene_at, intr, pose_samples, sample_offsets, self.sky, rng, rgb_spp)

    def close(self) -> None:
        if self.tracer is not None:
            self.tracer.close()
        if self.moving is not None:
            self.moving.close()
