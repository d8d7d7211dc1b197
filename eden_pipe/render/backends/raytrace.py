"""The Embree backend (``render.backend=raytrace``, the default): every modality, ``render.view``."""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Any

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
    return [(*_bounds(garden), 0.2), (*_bounds(v), 0.5)]


def _bounds(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (3,) lowest and highest coordinates of ``points`` (N, 3), one column at a time: numpy's
    reduction over the rows of an (N, 3) array walks three values a step, 20x slower (0.24 s for
    the default garden's vertices)."""
    return (
        np.array([points[:, k].min() for k in range(3)], points.dtype),
        np.array([points[:, k].max() for k in range(3)], points.dtype),
    )


def frame_settings(render_cfg, sky, time: float, cloud_regions: list, sky_visibility=None, frame_lights=None):
    """The shading settings of one frame (``render.*`` light-model keys): the sky and its cloud
    shadows tabulated at ``time``, and the garden's bake where the light model uses it
    (``frame_lights``: the job's ``visibility.frame_light.FrameLights``, shared by its frames)."""
    from eden_pipe.render.shading import EnvironmentMap, ShadingSettings
    from eden_pipe.render.sky import CloudShadowMap

    return ShadingSettings(
        indirect_samples=int(render_cfg.indirect_samples),
        soft_shadow_samples=int(render_cfg.soft_shadow_samples),
        soft_shadow_radius=int(render_cfg.soft_shadow_radius),
        time=time,
        environment=EnvironmentMap(sky, time),
        clouds=CloudShadowMap(sky, time, cloud_regions),
        mode=str(render_cfg.mode),
        reference_samples=int(render_cfg.reference_samples),
        reference_bounces=int(render_cfg.reference_bounces),
        sky_visibility=sky_visibility,
        glossy_mirror=str(render_cfg.glossy_mirror),
        mirror_rays=float(render_cfg.mirror_rays),
        pixel_sky_rays=int(render_cfg.pixel_sky_rays),
        pixel_sky_radius=int(render_cfg.pixel_sky_radius),
        frame_lights=frame_lights,
    )


@dataclass
class MovingFrame:
    """A frame's state when the mesh moves: its shading settings and the tracers holding the mesh at
    this frame's time and at its neighbours' (None past the trajectory's ends)."""

    settings: Any  # render.shading.ShadingSettings
    now: Any  # RayTracer
    next: object | None
    prev: object | None
    time: float = 0.0  # the frame's, seconds


class MovingScenes:
    """Each frame thread's ring of movable Embree scenes (wind, docs/design.md "Wind").

    A frame needs the mesh at its own time and at both neighbours' (flow and occlusion follow the
    moved surface). A thread renders consecutive frames, so each new frame moves one scene of its
    ring to the next time and refits its BVH; the other two are reused. Three scenes a thread, and
    with motion blur a fourth, moved to each sub-frame time of the exposure (:meth:`exposure_at`)."""

    SCENES_PER_THREAD = 3

    def __init__(self, mesh, field, threads: int, tracer: str, frame_threads: int = 1, blur: bool = False):
        from eden_pipe.render.embree import RayTracer

        self.mesh, self.field = mesh, field
        self._local = threading.local()
        self._lock = threading.Lock()
        # Every thread's scenes are built now, with the job's setup (a BVH build each), not in its first frame.
        per_thread = self.SCENES_PER_THREAD + int(blur)
        self._made = [RayTracer(mesh, threads, tracer, movable=True) for _ in range(per_thread * frame_threads)]
        self._free = list(self._made)

    def exposure_at(self, time: float):
        """This thread's exposure scene holding the mesh at ``time`` (a sub-frame time of motion blur)."""
        held = getattr(self._local, "exposure", None)
        if held is None:
            with self._lock:
                held = (None, self._free.pop())
        if held[0] != time:
            self.field.move(time, held[1].vertices)
            held[1].refit()
            held = (time, held[1])
        self._local.exposure = held
        return held[1]

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
        self,
        scene,
        sky,
        render_cfg,
        *,
        modalities: set[str],
        threads: int = 0,
        wind=None,
        frame_threads: int = 1,
        blur: bool = False,
    ):
        """``wind``: the mesh's motion (``render.wind.WindField``), rendered by ``frame_threads`` threads,
        with motion blur (``blur``: a scene a thread for the exposure's sub-frame times)."""
        from eden_pipe.render.embree import RayTracer
        from eden_pipe.render.visibility.frame_light import FrameLights

        self.scene, self.sky, self.render_cfg = scene, sky, render_cfg
        self.sky_visibility = getattr(scene, "sky_visibility", None)  # the garden's bake, when the stage ran
        self.cloud_regions = cloud_map_regions(scene.mesh)
        # Frames under the same sky and sun (any sky whose clouds do not drift) share the bake's
        # per-probe light: each probe's row is made once a job, not once a frame.
        self.frame_lights = FrameLights() if self.sky_visibility is not None else None
        self.moving = None
        if wind is not None:
            self.moving = MovingScenes(scene.mesh, wind, threads, str(render_cfg.tracer), frame_threads, blur)
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
            time,
        )

    def render_view(
        self, state, intr, pose, *, want, pose_next=None, pose_prev=None, rng=None, rgb_spp=1, partner=None
    ):
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
            partner=partner,
        )

    def render_exposed(self, state, intr, pose_samples, sample_offsets, *, rng, rgb_spp=1):
        return self.render_exposed_views(state, intr, [(pose_samples, rng)], sample_offsets, rgb_spp=rgb_spp)[0]

    def render_exposed_views(self, state, intr, views, sample_offsets, *, rgb_spp=1):
        from eden_pipe.render.exposure import ExposureScene, render_exposed_views

        def scene_at(offset_s: float) -> ExposureScene:
            if not isinstance(state, MovingFrame):
                return ExposureScene(self.tracer, self.scene.mesh, state)  # a static scene: the same at any time
            # Wind: the mesh moved to the sample's time (motion blur of the foliage too), once per sample for
            # every view of the frame; the frame's own scene at its time.
            assert self.moving is not None  # a MovingFrame comes from the moving scenes
            moved = state.now if offset_s == 0 else self.moving.exposure_at(state.time + offset_s)
            return ExposureScene(moved, self.scene.mesh, state.settings)

        return render_exposed_views(scene_at, intr, views, sample_offsets, self.sky, rgb_spp)

    def close(self) -> None:
        if self.tracer is not None:
            self.tracer.close()
        if self.moving is not None:
            self.moving.close()
