"""The directions each face side sees the sky in (``render.sky_visibility.face_sky_moments``): the
bake's table of the polynomials' cosine-weighted means over each side's visible sky, the frame's
sky fitted by the same polynomials, and the render's sky term from both.

The table against Embree's own rays from the same points, the fit against a sky it can hold
exactly, the file round trip, and the render under a sky brighter at the zenith than at the
horizon: the floor under a roof's edge sees the sky low down, and its shading follows the exact
sky (many traced rays a pixel) more closely with the moments than with the probe's transfer.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.render.embree import RayTracer
from eden_pipe.render.shading import EnvironmentMap, ShadingSettings, shade
from eden_pipe.render.visibility import shadow_maps
from eden_pipe.render.visibility.bake import bake
from eden_pipe.render.visibility.face_sky import MOMENT_STEPS, SIDE_COLUMNS, side_moments
from eden_pipe.render.visibility.shadow_maps import MOMENTS, direction_polynomials, hemisphere_fit
from eden_pipe.render.visibility.store import SkyVisibility
from tests.sky_scenes import UniformSky
from tests.test_pixel_sky import ROOF_EDGE_SIDE, roof_edge_bake, roof_edge_mesh, roof_edge_view

FLOOR_FACES = 160 * 160 * 2  # roof_edge_mesh's floor comes first


@pytest.fixture(scope="module")
def roof_moments():
    """The roof-edge scene baked with the face table alone and with its moments (the same seed; the
    maps kept, for their directions), with the slope that keeps a plane from hiding itself
    (tests/test_shadow_maps.py)."""
    mesh = roof_edge_mesh()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
        with RayTracer(mesh, 1) as tracer:
            table = roof_edge_bake(mesh, tracer, face_sky=True)
        with RayTracer(mesh, 1) as tracer:
            moments = roof_edge_bake(mesh, tracer, face_sky=True, face_sky_moments=True, shadow_maps=True)
    return mesh, table, moments


def cosine_rays(normal: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) float32 cosine-distributed directions about the unit ``normal`` (here +z)."""
    assert np.allclose(normal, [0.0, 0.0, 1.0])
    u1, u2 = rng.random(count), rng.random(count)
    r = np.sqrt(u1)
    return np.stack([r * np.cos(2 * np.pi * u2), r * np.sin(2 * np.pi * u2), np.sqrt(1 - u1)], axis=1).astype(
        np.float32
    )


def test_the_table_holds_each_sides_sky_directions_as_rays_find_them(roof_moments, tmp_path):
    """The moments change no other table, and the face table's fractions are the ones made without
    them bit for bit; each floor face's up side holds the polynomials' means over the sky its three
    points see: against 4,096 traced cosine rays from those points, within 0.02 on average and 0.1
    at worst (the maps have 64 directions); where every direction is open, the means of all the
    maps' directions to the table's step (near the hemisphere's: z 2/3, z^2 1/2, the rest 0); a
    side that sees no sky holds zeros; the table survives the file exactly."""
    mesh, table, moments = roof_moments
    for name in SkyVisibility.FIELDS + SkyVisibility.EXACT:
        assert np.array_equal(getattr(table, name), getattr(moments, name)), name
    assert np.array_equal(moments.face_sky[:, :, :3], table.face_sky)  # the fractions, bit for bit
    assert np.all(moments.face_sky[:, :, SIDE_COLUMNS - 1] == 0)  # the record's spare
    means = side_moments(moments.face_sky)
    assert moments.face_sky.shape == (mesh.n_faces, 2, SIDE_COLUMNS) and moments.has_side_moments
    assert not table.has_side_moments
    rng = np.random.default_rng(5)
    centres = mesh.vertices[mesh.faces[:FLOOR_FACES]].mean(axis=1)
    edge = np.flatnonzero((np.abs(centres[:, 0] - 0.5) < 0.15) & (np.abs(centres[:, 1]) < 0.3))
    faces = rng.choice(edge, 40, replace=False)
    up = np.array([0.0, 0.0, 1.0])
    errors = []
    with RayTracer(mesh, 1) as tracer:
        for f in faces:
            corners = mesh.vertices[mesh.faces[f]].astype(np.float64)
            sums, seen = np.zeros(MOMENTS), 0
            for k in range(3):
                point = corners[k] / 2 + corners.sum(axis=0) / 6 + 1e-4 * up
                d = cosine_rays(up, 4096, rng)
                free = ~tracer.intersect(np.tile(point, (len(d), 1)).astype(np.float32), d).hit
                sums += direction_polynomials(d[free]).sum(axis=0)
                seen += int(free.sum())
            errors.append(means[f, 0].astype(np.float64) / MOMENT_STEPS - sums / max(seen, 1))
    assert np.abs(errors).mean() < 0.02 and np.abs(errors).max() < 0.1, np.abs(errors).mean(axis=0)
    # Far from the roof a side sees every direction of the maps: their own cosine-weighted means.
    w = moments.shadow_maps.frame[:, 0:3]
    cos = np.maximum(w[:, 2], 0.0)
    every = (direction_polynomials(w) * cos[:, None]).sum(axis=0) / cos.sum()
    assert np.allclose(every, [0, 0, 2 / 3, 0, 0, 0, 0, 0.5], atol=0.04)  # the hemisphere's, to 64 directions
    seen = moments.face_sky[:FLOOR_FACES, 0].astype(np.int64).sum(axis=1)
    open_ = np.flatnonzero(seen == seen.max())  # every direction open at all three points
    assert len(open_) > 1000
    assert np.abs(means[open_, 0] / MOMENT_STEPS - every).max() <= 0.5 / MOMENT_STEPS + 1e-6
    assert np.all(means[:FLOOR_FACES, 1] == 0)  # the floor's underside: the ground, no sky
    moments.save(tmp_path / "moments.npz")
    assert np.array_equal(SkyVisibility.load(tmp_path / "moments.npz").face_sky, moments.face_sky)


def test_the_fit_holds_a_sky_of_order_two_exactly():
    """A radiance that is a polynomial of order 2 in the direction (each colour its own) is fitted
    exactly; a side's sky light is then its means times the fit, the constant's weight 1."""
    rng = np.random.default_rng(1)
    coeffs = rng.normal(size=(1 + MOMENTS, 3))

    def radiance(d):
        return np.concatenate([np.ones((len(d), 1)), direction_polynomials(d)], axis=1) @ coeffs

    assert np.allclose(hemisphere_fit(radiance), coeffs, atol=1e-4)


def exact_floor_light(tracer: RayTracer, points: np.ndarray, sky, rng: np.random.Generator) -> np.ndarray:
    """(N,) the sky light (E / pi, the green channel) at floor ``points`` (N, 3), up normals: the
    mean radiance along 2,048 traced cosine rays from each, blocked ones black."""
    up = np.array([0.0, 0.0, 1.0])
    exact = np.zeros(len(points))
    for i, p in enumerate(np.asarray(points, np.float64) + 1e-4 * up):
        rays = cosine_rays(up, 2048, rng)
        free = ~tracer.intersect(np.tile(p, (len(rays), 1)).astype(np.float32), rays).hit
        exact[i] = (sky.radiance(rays)[:, 1] * free).mean()
    return exact


class ZenithSky(UniformSky):
    """A sky bright at the zenith and dim at the horizon (radiance 0.2 + 1.6 z^2 above, none below)."""

    def radiance(self, directions, time=0.0):
        d = np.asarray(directions, np.float64)
        z = np.clip(d[:, 2] / np.linalg.norm(d, axis=1), 0.0, 1.0)
        return np.repeat((0.2 + 1.6 * z * z)[:, None], 3, axis=1).astype(np.float32)

    def ambient_irradiance(self, normals):
        """Exact for an upward normal (the floor, all this test shades): pi (0.2 + 1.6 / 2)."""
        return np.full((len(normals), 3), np.pi * (0.2 + 0.8), np.float32)


def test_render_weighs_the_sky_by_where_the_floor_sees_it():
    """A camera under the roof looks at the floor across its edge, under a sky five times brighter
    at the zenith than at the horizon: points under the roof see only its low, dim sky. Bakes of
    256 directions with 30 cm probe cells, each cell holding points that see the sky differently.
    Against the exact sky light (2,048 traced cosine rays a pixel), the moments' render is within
    0.03 on average, under 0.7 of the face table's alone (which takes the directions from the
    probe's transfer), and its mean within 3 %; its sky no longer depends on the probes: with
    10 cm cells the image is the same."""
    mesh = roof_edge_mesh()
    side = ROOF_EDGE_SIDE
    o, d, _ = roof_edge_view()
    sky = ZenithSky()
    shaded = {}
    rng = np.random.default_rng(2)
    variants = {"table": (0.3, False), "moments": (0.3, True), "small cells": (0.1, True)}
    with pytest.MonkeyPatch.context() as patch, RayTracer(mesh, 1) as tracer:
        patch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
        hits = tracer.intersect(o, d)
        assert np.all(hits.hit & (hits.prim < FLOOR_FACES))
        for name, (cell, moments) in variants.items():
            vis = bake(
                mesh, tracer, np.random.default_rng(0), directions=256, spacing_m=0.02, rays=16, cell_m=cell,
                cell_height_m=0.03, ground_rays=0, face_sky=True, face_sky_moments=moments,
            )  # fmt: skip
            settings = ShadingSettings(environment=EnvironmentMap(sky, 0.0), sky_visibility=vis)
            out = shade(
                tracer, mesh, hits, o, d, sky, settings, np.random.default_rng(0), layers=("shading",),
                image_width=side,
            )  # fmt: skip
            shaded[name] = out["shading"][:, 1]
        exact = exact_floor_light(tracer, o + d * hits.t[:, None], sky, rng)
    table_error = np.abs(shaded["table"] - exact).mean()
    moments_error = np.abs(shaded["moments"] - exact).mean()
    assert moments_error < min(0.7 * table_error, 0.03), (moments_error, table_error)
    assert abs(shaded["moments"].mean() / exact.mean() - 1) < 0.03
    assert np.allclose(shaded["small cells"], shaded["moments"], atol=1e-6)


def test_with_the_maps_a_pixel_keeps_its_own_fraction_and_takes_its_sides_directions():
    """With the maps kept and the table's moments (``shadow_maps`` and ``face_sky_moments``, the
    accurate preset): under a uniform sky the floor's shading is the maps' alone (each pixel's own
    visible fraction, which the directions do not change); under the zenith-bright sky it is closer
    to the exact sky light than the maps' alone, whose directions come from 30 cm probe cells."""
    mesh = roof_edge_mesh()
    side = ROOF_EDGE_SIDE
    o, d, _ = roof_edge_view()
    rng = np.random.default_rng(3)
    shaded = {}
    with pytest.MonkeyPatch.context() as patch, RayTracer(mesh, 1) as tracer:
        patch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
        hits = tracer.intersect(o, d)
        settings = dict(directions=256, spacing_m=0.02, rays=16, cell_m=0.3, cell_height_m=0.03, ground_rays=0)
        bakes = {
            moments: bake(
                mesh,
                tracer,
                np.random.default_rng(0),
                shadow_maps=True,
                face_sky=moments,
                face_sky_moments=moments,
                **settings,
            )
            for moments in (False, True)
        }
        assert bakes[True].has_side_moments and not bakes[False].has_side_moments
        for sky in (UniformSky(), ZenithSky()):
            for moments, vis in bakes.items():
                shading = ShadingSettings(environment=EnvironmentMap(sky, 0.0), sky_visibility=vis)
                out = shade(
                    tracer, mesh, hits, o, d, sky, shading, np.random.default_rng(0), layers=("shading",),
                    image_width=side,
                )  # fmt: skip
                shaded[type(sky).__name__, moments] = out["shading"][:, 1]
        exact = exact_floor_light(tracer, o + d * hits.t[:, None], ZenithSky(), rng)
    assert np.allclose(shaded["UniformSky", True], shaded["UniformSky", False], atol=1e-3)  # float32 SH sums
    maps_error = np.abs(shaded["ZenithSky", False] - exact).mean()
    moments_error = np.abs(shaded["ZenithSky", True] - exact).mean()
    assert moments_error < min(0.8 * maps_error, 0.03), (moments_error, maps_error)
