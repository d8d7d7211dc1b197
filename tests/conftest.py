"""Shared fixtures: configs composed through Hydra exactly as the CLI does (``config.make_cfg``)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from eden_pipe.config import make_cfg

REPO = Path(__file__).resolve().parents[1]
# The reliability scripts' job helpers, imported by path so that a bare ``pytest`` finds them too.
sys.path.insert(0, str(REPO / "scripts"))
from reliability_jobs import COARSE_BAKE  # noqa: E402

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
    *COARSE_BAKE,
]


@pytest.fixture
def cfg_factory(tmp_path):
    def factory(overrides=(), root: Path | None = None):
        return make_cfg(root or tmp_path, list(overrides))

    return factory
