"""Procedural terrain materials evaluated at hit points in world space.

Pebbles, gravel, paving tiles with joints, dirt and the soil under the lawn get
their pattern here, per hit point, from world x, y, so the pattern is fixed to
the ground (it never swims with the camera) and costs nothing in triangles.
Each returns a new albedo (the Dcol pass, so the albedo layer shows the
texture) and a shading normal with small bumps. The geometric normal stays
untouched for the normal ground truth.

The patterns are compiled (``kernels.terrain_textures``, one pass per hit; the
kernel lives beside the others: numba's cache follows a kernel's own file only):
the arithmetic is numpy's, operation for operation, in the precision numpy gave
each step (float32 where a step read float32 coordinates, float64 for the noise),
so they are bit-identical to the numpy version, which
``tests/test_terrain_textures.py`` keeps as the oracle.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.models.mesh import MATERIALS
from eden_pipe.render.kernels import terrain_textures

# (cell size m, palette (linear RGB), salt, gap darkness, dome, roundness): pebbles are round and loose
# on soil, gravel packed edge to edge (``kernels._stone``).
PEBBLES = (
    0.045,
    np.array([(0.34, 0.32, 0.29), (0.42, 0.38, 0.32), (0.24, 0.23, 0.22), (0.40, 0.30, 0.22), (0.50, 0.48, 0.45)]),
    11,
    0.25,
    0.9,
    0.48,
)
GRAVEL = (
    0.014,
    np.array([(0.45, 0.44, 0.42), (0.36, 0.35, 0.33), (0.52, 0.49, 0.45), (0.30, 0.29, 0.28)]),
    23,
    0.5,
    0.4,
    0.0,
)
SOILS = ((MATERIALS["dirt"], 0.08, 0.35), (MATERIALS["grass_soil"], 0.05, 0.3))  # (material, noise scale m, amplitude)


def apply_terrain_textures(material: np.ndarray, points: np.ndarray, albedo: np.ndarray, normal: np.ndarray):
    """(albedo, shading normal) (N, 3) float32 for hit points (float32); only terrain materials change,
    and every albedo is clipped to [0, 1]."""
    albedo = np.array(albedo, np.float32)
    normal = np.array(normal, np.float32)
    codes = np.array([MATERIALS["pebbles"], MATERIALS["gravel"], MATERIALS["pavement"]], np.int64)
    terrain_textures(material, np.asarray(points, np.float32), albedo, normal, codes, PEBBLES, GRAVEL, SOILS)
    return albedo, normal
