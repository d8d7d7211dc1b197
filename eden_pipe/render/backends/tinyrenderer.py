"""The pybullet TinyRenderer backend (``render.backend=tinyrenderer``): a preview and test oracle."""

from __future__ import annotations

from eden_pipe.render.backends import Backend


class TinyRendererBackend(Backend):
    """One private pybullet client: not safe to share between threads, so one frame at a time."""

    name = "tinyrenderer"
    capabilities = frozenset({"rgb", "semantic", "instance", "depth"})
    max_frame_threads = 1

    def __init__(self, scene, sky, render_cfg, *, modalities: set[str], threads: int = 0):
        from eden_pipe.render.rasterizer import TinyRenderer, light_direction_for

        self.scene, self.sky = scene, sky
        self.renderer = TinyRenderer(scene, light_direction=light_direction_for(sky), shade="rgb" in modalities)

    def render_view(
        self, state, intr, pose, *, want, pose_next=None, pose_prev=None, rng=None, rgb_spp=1, partner=None
    ):
        from eden_pipe.render.rasterizer import render_view_tinyrenderer

        return render_view_tinyrenderer(self.renderer, self.scene, intr, pose, self.sky, want=want)

    def close(self) -> None:
        self.renderer.close()
