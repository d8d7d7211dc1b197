"""The pybullet TinyRenderer backend (``render.backend=tinyrenderer``): a preview and test oracle."""

from __future__ import annotations

import numpy as np

from eden_pipe.render.backends import Backend

NEAR = 0.01  # metres: the near plane of its projection; the rig keeps far more clearance than this
# Its depth is OpenGL's non-linear depth d in [0, 1), a float32 interpolated by the rasteriser, whose
# z-depth far*near / (far - (far - near) d) moves by about z^2 / near per unit of d: a few float32
# steps of d near 1 (2^-24 each) are millimetres at 10 m. Four steps: measured on the small garden's
# 640 x 480 views, one step already put every sampled pixel on its instance's faces.
DEPTH_STEPS = 4
DEPTH_STEP = 2.0**-24


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

    @classmethod
    def depth_error(cls, z: np.ndarray) -> np.ndarray:
        z = np.asarray(z, np.float64)
        return DEPTH_STEPS * DEPTH_STEP / NEAR * z * z
