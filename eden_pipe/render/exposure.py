"""The display RGB of a view over its exposure: rolling shutter and motion blur (docs/design.md,
Camera effects).

Each row of the view is traced from its own pose (``camera.shutter.exposure_poses``), and the RGB is
the mean over the exposure's sub-frame samples. The scene at a sub-frame time comes from a callback,
``scene_at(offset_s) -> ExposureScene``: the static scene, or with wind the mesh moved to that time
(its BVH refitted by the backend), asked once per sample for every view of a frame
(:func:`render_exposed_views`). Only the
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
    return render_exposed_views(scene_at, intr, [(pose_samples, rng)], sample_offsets, sky, rgb_spp)[0]


def render_exposed_views(
    scene_at: Callable[[float], ExposureScene],
    intr: Intrinsics,
    views: list[tuple[np.ndarray, np.random.Generator]],
    sample_offsets: np.ndarray,
    sky,
    rgb_spp: int = 1,
) -> list[np.ndarray]:
    """:func:`render_exposed_rgb` of several views (each its (S, H, 4, 4) poses and generator) over the
    same sub-frame times, sample by sample: ``scene_at`` is asked once per sample for all of them (a
    moving mesh is moved once per sample, not once per sample and view). Each view's result is the one
    :func:`render_exposed_rgb` gives it alone (its generator draws in the same order)."""
    h, w = intr.height, intr.width
    acc = [np.zeros((h * w, 3), np.float64) for _ in views]
    for j, offset_s in enumerate(sample_offsets):
        scene = scene_at(float(offset_s))
        shade_fn = reference_shade if scene.settings.mode == "reference" else shade
        for (pose_samples, rng), total in zip(views, acc, strict=True):
            for s in range(rgb_spp):
                jitter = (0.0, 0.0) if s == 0 else rng.uniform(-0.5, 0.5, size=(h, w, 2))
                origins, dirs = primary_rays_per_row(intr, pose_samples[j], jitter)
                hits = scene.tracer.intersect(origins, dirs, image=(h, w))
                layers = shade_fn(
                    scene.tracer, scene.mesh, hits, origins, dirs, sky, scene.settings, rng, layers=(), image_width=w
                )
                total += layers["linear"]
    return [(total / (len(sample_offsets) * rgb_spp)).astype(np.float32).reshape(h, w, 3) for total in acc]
