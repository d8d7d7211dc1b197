"""Test scenes of the sky-visibility and mirror tests: a uniform sky, grids and a roofed floor.

The scene: a floor under a square roof, lit by a uniform sky of unit radiance
(the furnace test's environment). At a floor point below the roof's centre,
the cosine-weighted fraction of the sky the roof hides is the view factor of
a parallel square (Hottel's corner formula, four corners), so with a black
roof the diffuse shading there is exactly ``1 - F``.
"""

from __future__ import annotations

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import Mesh
from eden_pipe.render.shading import EnvironmentMap, ShadingSettings

ROOF_HALF, ROOF_HEIGHT = 0.5, 0.6


class UniformSky:
    """Unit radiance from every direction, no sun, no clouds, no scenery."""

    sun_direction = np.array([0.0, 0.0, 1.0])
    sun_irradiance = np.zeros(3)
    sun_angular_radius = 0.0

    def radiance(self, directions, time=0.0):
        return np.ones((len(directions), 3), np.float32)

    def ambient_irradiance(self, normals):
        return np.full((len(normals), 3), np.pi, np.float32)

    def scenery(self, directions):
        return np.zeros(len(directions), bool), np.zeros((len(directions), 3))

    def cloud_transmittance(self, points, time=0.0):
        return np.ones(len(points))


def grid(x0, x1, y0, y1, z, cells, *, albedo, semantic=labels.GROUND, flip=False) -> Mesh:
    xs, ys = np.linspace(x0, x1, cells + 1), np.linspace(y0, y1, cells + 1)
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    vertices = np.stack([X.ravel(), Y.ravel(), np.full(X.size, z)], axis=1)
    i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
    a = (i * (cells + 1) + j).ravel()
    b, c, d = a + (cells + 1), a + 1, a + cells + 2
    faces = np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])
    if flip:
        faces = faces[:, ::-1]
    return Mesh.from_arrays(vertices, faces, semantic=semantic, material="dirt", albedo=albedo)


def roofed_floor(roof_albedo=0.0) -> Mesh:
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 40, albedo=0.5)
    roof = grid(-ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT, 4, albedo=roof_albedo, flip=True)
    return Mesh.concatenate([floor, roof])


def parallel_rectangle_factor(point, x1, x2, y1, y2, height):
    """View factor from floor points ``point`` (x, y; scalars or arrays) to the parallel rectangle
    [x1, x2] x [y1, y2] ``height`` above (Hottel's corner formula, four signed corners)."""

    def corner(x, y):
        a, b = x / height, y / height
        return (
            a / np.sqrt(1 + a * a) * np.arctan(b / np.sqrt(1 + a * a))
            + b / np.sqrt(1 + b * b) * np.arctan(a / np.sqrt(1 + b * b))
        ) / (2 * np.pi)

    x1, x2, y1, y2 = x1 - point[0], x2 - point[0], y1 - point[1], y2 - point[1]
    return corner(x2, y2) - corner(x1, y2) - corner(x2, y1) + corner(x1, y1)


def hidden_fraction(half: float, height: float) -> float:
    """View factor from a point to a parallel square centred above it."""
    return float(parallel_rectangle_factor((0.0, 0.0), -half, half, -half, half, height))


def uniform_settings(**kw) -> ShadingSettings:
    sky = UniformSky()
    return ShadingSettings(environment=EnvironmentMap(sky, 0.0), **kw)


def rays_down_at(points: np.ndarray):
    origins = points + np.array([0.0, 0.0, 0.3])
    return origins.astype(np.float32), np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (len(points), 1))


def closed_box(lo, hi, albedo=0.0) -> Mesh:
    """A black box with no gaps between its six sides (nothing sees into it)."""
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    faces = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])
    return Mesh.from_arrays(corners, faces, semantic=labels.OBSTACLE, material="generic", albedo=albedo)
