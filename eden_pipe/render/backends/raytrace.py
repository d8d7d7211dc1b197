"""The Embree backend (``render.backend=raytrace``, the default): every modality, ``render.view``."""

from __future__ import annotations

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


class RaytraceBackend(Backend):
    """One Embree scene shared by every frame thread (queries on a committed scene are thread-safe)."""

    name = "raytrace"
    capabilities = frozenset(MODALITIES)
    max_frame_threads = 0
    exposure_effects = True

    def __init__(self, scene, sky, render_cfg, *, modalities: set[str], threads: int = 0):
        from eden_pipe.render.embree import RayTracer
        from eden_pipe.render.visibility.frame_light import FrameLights

        self.scene, self.sky, self.render_cfg = scene, sky, render_cfg
        self.sky_visibility = getattr(scene, "sky_visibility", None)  # the garden's bake, when the stage ran
        self.tracer = RayTracer(scene.mesh, threads, str(render_cfg.tracer))  # builds the BVH
        self.cloud_regions = cloud_map_regions(scene.mesh)
        # Frames under the same sky and sun (any sky whose clouds do not drift) share the bake's
        # per-probe light: each probe's row is made once a job, not once a frame.
        self.frame_lights = FrameLights() if self.sky_visibility is not None else None

    def frame(self, time: float):
        """The shading settings of one frame (``frame_settings``)."""
        return frame_settings(
            self.render_cfg, self.sky, time, self.cloud_regions, self.sky_visibility, self.frame_lights
        )

    def render_view(self, state, intr, pose, *, want, pose_next=None, pose_prev=None, rng=None, rgb_spp=1):
        from eden_pipe.render.view import render_view

        return render_view(
            self.tracer,
            self.scene,
            intr,
            pose,
            self.sky,
            want=want,
            pose_next=pose_next,
            pose_prev=pose_prev,
            settings=state,
            rng=rng,
            rgb_spp=rgb_spp,
        )

    def render_exposed(self, state, intr, pose_samples, sample_offsets, *, rng, rgb_spp=1):
        from eden_pipe.render.exposure import ExposureScene, render_exposed_rgb

        def scene_at(offset_s: float) -> ExposureScene:
            return ExposureScene(self.tracer, self.scene.mesh, state)  # a static scene: the same at any time

        return render_exposed_rgb(scene_at, intr, pose_samples, sample_offsets, self.sky, rng, rgb_spp)

    def close(self) -> None:
        self.tracer.close()
