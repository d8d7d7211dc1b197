"""How the reference path tracer counts ``render.reference_bounces``: as Cycles counts
``render.cycles.max_bounces``, the light of the primary hit and of that many vertices after it, each
vertex's continuation ray gathering the sky (docs/realism.md, Cycles)."""

from __future__ import annotations

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import Mesh
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.pathtrace import radiance_along
from eden_pipe.render.shading import ShadingSettings
from tests.sky_scenes import UniformSky, grid


def board(x0, x1, y0, y1, z, *, albedo, flip=False) -> Mesh:
    """A square of untextured wood (the terrain's textures would change a ground's albedo)."""
    g = grid(x0, x1, y0, y1, z, 4, albedo=albedo, flip=flip)
    return Mesh.from_arrays(g.vertices, g.faces, semantic=labels.OBSTACLE, material="wood", albedo=albedo)


def test_the_last_vertex_gathers_the_sky_along_its_continuation():
    """Rays down at an open floor of albedo 0.4 under a sky of unit radiance: every ray from the floor
    escapes, so with any limit of one bounce or more the radiance arriving is exactly the floor's
    0.4 (it was 0 with one bounce, when the last vertex gathered only the sun); a ray that escapes at
    once brings the sky's 1."""
    floor = board(-5.0, 5.0, -5.0, 5.0, 0.0, albedo=0.4)
    origins = np.array([[0.1, 0.2, 1.0], [-1.3, 0.7, 2.0], [0.0, 0.0, 1.0]], np.float32)
    dirs = np.array([[0.0, 0.0, -1.0], [0.3, -0.2, -1.0], [0.0, 0.0, 1.0]], np.float32)
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    with RayTracer(floor, 1) as tracer:
        for bounces in (1, 2, 6):
            got = radiance_along(
                tracer, floor, UniformSky(), ShadingSettings(), np.random.default_rng(bounces), origins, dirs, bounces
            )
            assert np.allclose(got[:2], 0.4, rtol=1e-6), (bounces, got)
            assert np.allclose(got[2], 1.0), (bounces, got)


def test_a_bounce_more_adds_the_light_of_one_vertex_more():
    """A floor of albedo 0.5 under a roof of albedo 0.5 (its top black), a ray up at the roof's
    underside: odd vertices lie on the roof, which sees only the floor (and the sky past the floor's
    edge, 40 times as far as the roof is high), even ones on the floor, which sees the sky around the
    roof. With the same random numbers, one bounce gathers about nothing, two the floor's sky, three
    nothing more (the roof's vertex), four the floor's sky again, less than the first time."""
    floor = board(-20.0, 20.0, -20.0, 20.0, 0.0, albedo=0.5)
    roof = board(-1.0, 1.0, -1.0, 1.0, 0.5, albedo=0.5, flip=True)
    mesh = Mesh.concatenate([floor, roof])
    origins = np.tile(np.array([[0.0, 0.0, 0.2]], np.float32), (4096, 1))
    dirs = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (4096, 1))
    means = []
    with RayTracer(mesh, 1) as tracer:
        for bounces in (1, 2, 3, 4):
            got = radiance_along(
                tracer, mesh, UniformSky(), ShadingSettings(), np.random.default_rng(7), origins, dirs, bounces
            )
            means.append(float(got[:, 1].mean()))
    assert means[0] < 1e-3 and means[1] > 0.05, means
    assert abs(means[2] - means[1]) < 1e-3, means
    assert 0.005 < means[3] - means[2] < means[1] - means[0], means
