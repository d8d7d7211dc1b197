"""Shared fixtures: configs composed through Hydra exactly as the CLI does (``config.make_cfg``)."""

from __future__ import annotations

from pathlib import Path

import pytest

from eden_pipe.config import make_cfg

REPO = Path(__file__).resolve().parents[1]

# A tiny but complete job: small garden, low resolution, 4 frames.
TINY = [
    "garden=small",
    "camera.width=96",
    "camera.height=72",
    "camera.fx=96",
    "camera.fy=96",
    "camera.cx=48",
    "camera.cy=36",
    "camera.trajectory.frames=[4,4]",
    "garden.lawn.triangles_per_m2=1500",
    "progress=false",
    # A coarse sky-visibility bake (the default's 14 mm bundles cost ~0.5M rays per direction, its
    # camera gain 16M rays, the lightmaps of this lawn's soil 49M: 39 s of a 7 s bake).
    "render.sky_visibility.directions=8",
    "render.sky_visibility.spacing_m=0.04",
    "render.sky_visibility.rays=2",
    "render.sky_visibility.camera_views=200",
    "render.sky_visibility.camera_rays=256",
    "render.sky_visibility.lightmap_rays=8",
]


@pytest.fixture
def cfg_factory(tmp_path):
    def factory(overrides=(), root: Path | None = None):
        return make_cfg(root or tmp_path, list(overrides))

    return factory
