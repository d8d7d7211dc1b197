"""The display RGB of a view over its exposure: rolling shutter and motion blur (docs/design.md,
Camera effects).

Each row of the view is traced from its own pose (``camera.shutter.exposure_poses``), and the RGB is
the mean over the exposure's sub-frame samples. The scene at a sub-frame time comes from a callback,
``scene_at(offset_s) -> ExposureScene``: the static scene today, moved geometry once the scene
moves within a frame (its BVH refitted by whoever supplies it), with no change here. Only the
display RGB is made this way; the labels, depth, flow and linear layers stay the sharp
global-shutter render of ``render.view.render_view``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from eden_pipe.camera.rig import Intrinsics
from eden_pipe.render.pathtrace import reference_shade
from eden_pipe.render.shading import ShadingSettings, shade


@dataclass(frozen=True)
class ExposureScene:
    """What a sub-frame sample is traced against: the tracer (its BVH), the mesh it holds and the
    frame's shading settings."""

    tracer: Any
    mesh: Any
    settings: ShadingSettings


def primary_rays_per_row(intr: Intrinsics, row_poses: np.ndarray, offset=(0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """As ``render.view.primary_rays``, with row v of the image cast from ``row_poses[v]`` (H, 4, 4)."""
    u, v = intr.pixel_grid(offset)
    dirs_cam = intr.camera_rays(u, v)  # (H, W, 3), camera z = 1
    rotations = row_poses[:, :3, :3]
    dirs = np.einsum("hwj,hij->hwi", dirs_cam, rotations).reshape(-1, 3)
    origins = np.repeat(row_poses[:, :3, 3], intr.width, axis=0)
    return np.ascontiguousarray(origins), np.ascontiguousarray(dirs)


def render_exposed_rgb(
    scene_at: Callable[[float], ExposureScene],
    intr: Intrinsics,
    pose_samples: np.ndarray,
    sample_offsets: np.ndarray,
    sky,
    rng: np.random.Generator,
    rgb_spp: int = 1,
) -> np.ndarray:
    """(H, W, 3) float32 linear RGB: the mean over the sub-frame samples (``pose_samples`` (S, H, 4, 4)
    at ``sample_offsets`` (S,) seconds from the frame time) of each sample's RGB, itself the mean of
    ``rgb_spp`` sub-pixel samples (the pixel centre, then jittered ones) as the sharp render's."""
    h, w = intr.height, intr.width
    acc = np.zeros((h * w, 3), np.float64)
    for row_poses, offset_s in zip(pose_samples, sample_offsets, strict=True):
        scene = scene_at(float(offset_s))
        shade_fn = reference_shade if scene.settings.mode == "reference" else shade
        for s in range(rgb_spp):
            jitter = (0.0, 0.0) if s == 0 else rng.uniform(-0.5, 0.5, size=(h, w, 2))
            origins, dirs = primary_rays_per_row(intr, row_poses, jitter)
            hits = scene.tracer.intersect(origins, dirs, image=(h, w))
            layers = shade_fn(
                scene.tracer, scene.mesh, hits, origins, dirs, sky, scene.settings, rng, layers=(), image_width=w
            )
            acc += layers["linear"]
    return (acc / (len(pose_samples) * rgb_spp)).astype(np.float32).reshape(h, w, 3)
