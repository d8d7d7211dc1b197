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


class RaytraceBackend(Backend):
    """One Embree scene shared by every frame thread (queries on a committed scene are thread-safe)."""

    name = "raytrace"
    capabilities = frozenset(MODALITIES)
    max_frame_threads = 0

    def __init__(self, scene, sky, render_cfg, *, modalities: set[str], threads: int = 0):
        from eden_pipe.render.raytrace import RayTracer

        self.scene, self.sky = scene, sky
        self.indirect_samples = int(render_cfg.indirect_samples)
        self.soft_shadow_samples = int(render_cfg.soft_shadow_samples)
        self.mode = str(render_cfg.mode)
        self.reference_samples, self.reference_bounces = int(render_cfg.reference_samples), int(render_cfg.reference_bounces)
        self.sky_visibility = getattr(scene, "sky_visibility", None)  # the garden's bake, when the stage ran
        self.mirror_rays = bool(render_cfg.mirror_rays)
        self.tracer = RayTracer(scene.mesh, threads)  # builds the BVH
        self.cloud_regions = cloud_map_regions(scene.mesh)

    def frame(self, time: float):
        """The shading settings of one frame: the sky and cloud shadows tabulated at ``time``."""
        from eden_pipe.render.shading import EnvironmentMap, ShadingSettings
        from eden_pipe.render.sky import CloudShadowMap

        environment = EnvironmentMap(self.sky, time)
        clouds = CloudShadowMap(self.sky, time, self.cloud_regions)
        return ShadingSettings(indirect_samples=self.indirect_samples, soft_shadow_samples=self.soft_shadow_samples,
                               time=time, environment=environment, clouds=clouds, mode=self.mode,
                               reference_samples=self.reference_samples, reference_bounces=self.reference_bounces,
                               sky_visibility=self.sky_visibility, mirror_rays=self.mirror_rays)

    def render_view(self, state, intr, pose, *, want, pose_next=None, pose_prev=None, rng=None, rgb_spp=1):
        from eden_pipe.render.view import render_view

        return render_view(self.tracer, self.scene, intr, pose, self.sky, want=want, pose_next=pose_next,
                           pose_prev=pose_prev, settings=state, rng=rng, rgb_spp=rgb_spp)

    def close(self) -> None:
        self.tracer.close()
