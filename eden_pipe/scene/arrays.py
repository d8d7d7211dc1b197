"""The renderer-agnostic scene every backend consumes (docs/design.md, Stages, artifacts and cache keys):
plain arrays, no renderer."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe.models.mesh import Mesh


@dataclass
class SceneArrays:
    """What a renderer needs of a scene: the world mesh and a per-face instance id."""

    mesh: Mesh  # in world coordinates
    instance: np.ndarray  # (F,) uint16, 0 = no instance (terrain, lawn, skirt)
    sky_visibility: object | None = None  # render.visibility.store.SkyVisibility, the garden's bake (when used)
