"""Glossy mirrors over the bake: what a mirror ray sees where geometry hides the sky.

The ``glossy_mirror`` modes (``predicted``, ``any_hit``, ``traced``) on floors
under a black roof or beside a black wall (:mod:`tests.sky_scenes`), against
the closed answers: none of the black occluder's light, the unit sky elsewhere.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.shading import largest_share, shade
from eden_pipe.render.visibility.bake import bake
from eden_pipe.render.visibility.store import MIN_BLOCKED, SkyVisibility
from tests.sky_scenes import ROOF_HALF, ROOF_HEIGHT, UniformSky, grid, uniform_settings


@pytest.mark.parametrize("glossy_mirror", ["predicted", "any_hit", "traced"])
def test_mirror_rays_see_what_hides_the_sky(glossy_mirror):
    """A glossy floor under a black roof, seen from straight above: its mirror ray meets the roof
    (nothing to reflect), while beside the roof it reflects the unit sky times the Fresnel weight.
    ``any_hit`` sees the mean light of what hides the sky where the ray is blocked (the black roof's:
    none), ``traced`` lights what the ray hits, ``predicted`` decides which from the bake (or a ray);
    the sky dimmed by the visible fraction would see part of the sky."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 40, albedo=0.5)
    floor.specular[:] = 0.04
    roof = grid(-ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT, 4, albedo=0.0, flip=True)
    mesh = Mesh.concatenate([floor, roof])
    sky = UniformSky()
    points = np.array([[0.01, 0.02, 0.0], [1.7, -1.8, 0.0]])
    with RayTracer(mesh, 1) as tracer:
        vis = bake(
            mesh,
            tracer,
            np.random.default_rng(0),
            directions=16,
            spacing_m=0.05,
            rays=4,
            cell_m=0.1,
            cell_height_m=0.03,
            ground_rays=0,
        )
        o, d = points + np.array([0.0, 0.0, 0.2]), np.tile([[0.0, 0.0, -1.0]], (2, 1))
        o, d = o.astype(np.float32), d.astype(np.float32)
        hits = tracer.intersect(o, d)
        out = shade(
            tracer,
            mesh,
            hits,
            o,
            d,
            sky,
            uniform_settings(sky_visibility=vis, glossy_mirror=glossy_mirror),
            np.random.default_rng(0),
        )
    # Seen head-on the Fresnel weight is 1: glossy = specular * radiance along the mirror.
    assert np.allclose(out["glossy"][0], 0.0, atol=1e-6), out["glossy"]
    assert np.allclose(out["glossy"][1], 0.04, rtol=1e-3), out["glossy"]


def wall_beside_floor_views(mirrors, wall_albedo=0.0, **settings):
    """A glossy floor point 0.3 m from a wall 2 m tall (black unless ``wall_albedo``), seen from two
    sides under a unit sky: the mirror direction toward the wall (31 degrees up) meets it, the one
    away from it (67 degrees up) sees open sky. Returns ({mirror: (2,) light along the mirror per
    unit Fresnel weight and specular colour}, the point's shading (its cosine-weighted visible
    sky), any-hit rays traced per mirror)."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 40, albedo=0.5)
    floor.specular[:] = 0.04
    floor.material[:] = MATERIALS["generic"]  # no bump map: the mirror direction is exact
    wall = Mesh.from_arrays(
        np.array([[0.3, -2.0, 0.0], [0.3, 2.0, 0.0], [0.3, 2.0, 2.0], [0.3, -2.0, 2.0]]),
        np.array([[0, 1, 2], [0, 2, 3]]),
        semantic=labels.OBSTACLE,
        material="generic",
        albedo=wall_albedo,
    )
    mesh = Mesh.concatenate([floor, wall])
    sky = UniformSky()
    point = np.array([-0.05, 0.02, 0.0])
    cameras = np.array([[-1.05, 0.02, 0.6], [0.2, 0.02, 0.6]])  # mirror toward the wall; away from it
    o = cameras.astype(np.float32)
    d = (point - cameras).astype(np.float32)
    with RayTracer(mesh, 1) as tracer:
        vis = bake(
            mesh,
            tracer,
            np.random.default_rng(0),
            directions=64,
            spacing_m=0.02,
            rays=16,
            cell_m=0.1,
            cell_height_m=0.03,
            ground_rays=0,
        )
        hits = tracer.intersect(o, d)
        assert np.all(hits.hit) and np.all(np.take(mesh.semantic, hits.prim) == labels.GROUND)
        per_unit, rays = {}, {}  # glossy per unit Fresnel weight and specular colour: the light along the mirror
        traced = []
        occluded = tracer.occluded
        tracer.occluded = lambda origins, *a, **k: traced.append(len(origins)) or occluded(origins, *a, **k)
        for mirror in mirrors:
            traced.clear()
            out = shade(
                tracer,
                mesh,
                hits,
                o,
                d,
                sky,
                uniform_settings(sky_visibility=vis, glossy_mirror=mirror, **settings),
                np.random.default_rng(0),
                layers=("glossy", "shading"),
            )
            unit = d / np.linalg.norm(d, axis=1, keepdims=True)
            weight = np.minimum((0.04 + 0.96 * (1.0 - np.abs(unit[:, 2])) ** 5) / 0.04, 2.0)
            per_unit[mirror] = out["glossy"][:, 1] / (0.04 * weight)
            rays[mirror] = sum(traced)
    return per_unit, out["shading"][0, 1], rays


def test_predicted_mirror_decides_by_the_sky_along_its_own_direction():
    """The floor point beside the wall (:func:`wall_beside_floor_views`): its cosine-weighted visible
    fraction is one number (about 0.6), which would say "sky" both ways, but ``predicted`` takes the
    probe's transfer along each mirror direction (no ray with ``mirror_rays`` 0): toward the wall
    the sky is unlikely, so it sees the black wall's light (none), away from it the whole sky, as
    traced mirror rays do."""
    per_unit, visible, rays = wall_beside_floor_views(("predicted", "traced"), mirror_rays=0.0)
    assert 0.5 < visible < 0.75, visible  # a black wall: no bounce
    assert rays["predicted"] == 0
    assert np.allclose(per_unit["traced"], [0.0, 1.0], atol=1e-3), per_unit["traced"]
    assert np.allclose(per_unit["predicted"], [0.0, 1.0], atol=1e-3), per_unit["predicted"]


def test_a_blocked_mirror_reads_the_mean_light_of_what_hides_the_sky():
    """Beside a grey wall, the mirror toward it meets the wall: ``predicted`` (no ray) reads its
    probe's bounce over the probe's blocked fraction, the mean light of what hides its sky, which
    is the wall's light the traced mirror finds within 10 % (the wall is lit alike along its
    height; 0.95 of it), and the open sky away from it."""
    per_unit, _, _ = wall_beside_floor_views(("predicted", "traced"), wall_albedo=0.6, mirror_rays=0.0)
    toward = per_unit["predicted"][0] / per_unit["traced"][0]
    assert per_unit["traced"][0] > 0.2 and 0.9 < toward < 1.1, per_unit
    assert np.isclose(per_unit["predicted"][1], 1.0, atol=1e-3)  # away from the wall: the open sky


def test_blocked_radiance_divides_by_the_probes_blocked_fraction():
    """The mean light of what hides a side's sky: its probe's bounce over the probe's blocked
    fraction (1 - v, v clipped to 0..1), never below ``MIN_BLOCKED``: exact values."""
    bounce = np.array([[0.2, 0.1, 0.05], [0.2, 0.1, 0.05], [0.3, 0.3, 0.3], [0.1, 0.2, 0.3]], np.float32)
    visible = np.array([0.5, 0.75, 1.2, -0.1], np.float32)
    got = SkyVisibility.blocked_radiance(bounce, visible)
    want = bounce / np.array([[0.5], [0.25], [MIN_BLOCKED], [1.0]], np.float32)
    assert np.allclose(got, want, rtol=1e-6) and got.dtype == np.float32


def test_predicted_mirror_rays_test_the_guesses_it_is_unsure_of():
    """With ``mirror_rays`` 1, ``predicted`` tests every upward mirror whose baked fraction is neither
    0 nor 1 with one any-hit ray: the view away from the wall (about 0.8) traces it; the one toward
    the wall, whose fraction the bake puts at exactly 0, keeps its guess without a ray."""
    per_unit, _, rays = wall_beside_floor_views(("predicted", "traced"), mirror_rays=1.0)
    assert np.allclose(per_unit["predicted"], per_unit["traced"], atol=1e-3), per_unit
    assert np.allclose(per_unit["traced"], [0.0, 1.0], atol=1e-3) and rays["predicted"] == 1


def test_predicted_mirror_ray_overrules_a_wrong_guess():
    """A glossy floor point straight under a small black square 1 m up, seen from above: its mirror
    meets the square, but the square hides a few per cent of the sky, which the bake's band-limited
    fraction along the zenith smooths to a likely "sky". Without rays ``predicted`` reflects the
    unit sky; with them the one uncertain mirror is tested and sees the square's light (none)."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 40, albedo=0.5)
    floor.specular[:] = 0.04
    floor.material[:] = MATERIALS["generic"]  # no bump map: the mirror direction is exact
    square = grid(-0.15, 0.15, -0.15, 0.15, 1.0, 2, albedo=0.0, flip=True)
    mesh = Mesh.concatenate([floor, square])
    sky = UniformSky()
    o = np.array([[0.01, 0.02, 0.5]], np.float32)
    d = np.array([[0.0, 0.0, -1.0]], np.float32)
    glossy = {}
    with RayTracer(mesh, 1) as tracer:
        vis = bake(
            mesh,
            tracer,
            np.random.default_rng(0),
            directions=64,
            spacing_m=0.02,
            rays=16,
            cell_m=0.1,
            cell_height_m=0.03,
            ground_rays=0,
        )
        hits = tracer.intersect(o, d)
        for share in (0.0, 1.0):
            glossy[share] = shade(
                tracer,
                mesh,
                hits,
                o,
                d,
                sky,
                uniform_settings(sky_visibility=vis, glossy_mirror="predicted", mirror_rays=share),
                np.random.default_rng(0),
                layers=("glossy",),
            )["glossy"][0, 1]
    assert np.isclose(glossy[0.0], 0.04, rtol=1e-3), glossy  # head-on: Fresnel weight 1, the unit sky
    assert np.isclose(glossy[1.0], 0.0, atol=1e-6), glossy


def test_largest_share_picks_the_top_scores_above_zero():
    rng = np.random.default_rng(5)
    score = rng.random(100_000).astype(np.float32)
    score[rng.random(len(score)) < 0.3] = 0.0  # downward mirrors and sure guesses: never picked
    for share in (0.05, 0.25, 0.6):
        pick = largest_share(score, share)
        left = np.setdiff1d(np.arange(len(score)), pick)
        assert np.all(np.diff(pick) > 0) and np.all(score[pick] > 0)
        assert score[pick].min() > score[left].max()
        assert abs(len(pick) - share * len(score)) < 0.02 * len(score), (share, len(pick))
    assert len(largest_share(score, 0.0)) == 0
    assert np.array_equal(largest_share(score, 1.0), np.flatnonzero(score > 0))


@pytest.mark.parametrize("tilt_deg", [0.0, 20.0])
def test_image_blocks_share_any_hit_rays_only_where_mirror_directions_agree(tilt_deg):
    """An image (rays straight down, one per pixel of a 32 x 32 grid) of a glossy floor under a black
    roof. On the flat floor every mirror direction is the same: each 2 x 2 pixel block traces one
    ray, and a pixel differs from its own ray's answer only in a block the roof's edge crosses. On a
    floor of faces tilted +-20 degrees in a checkerboard (one face per pixel, so neighbours'
    mirrors differ) every pixel keeps its own ray and the image equals the unshared one exactly."""
    cells = width = 32
    floor = grid(-1.0, 1.0, -1.0, 1.0, 0.0, cells, albedo=0.5)
    step = 2.0 / cells
    ridge = np.where(np.arange(cells + 1) % 2 == 1, np.tan(np.radians(tilt_deg)) * step, 0.0)
    floor.vertices[:, 2] = (ridge[:, None] + ridge[None, :]).ravel()  # vertex (i, j): x = x_i, y = y_j
    floor.specular[:] = 0.04
    floor.material[:] = MATERIALS["generic"]  # no bump map: the shading normal is the face's
    roof = grid(-ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT, 4, albedo=0.0, flip=True)
    mesh = Mesh.concatenate([floor, roof])
    if tilt_deg:
        u = -1.0 + (np.arange(width) + 0.5) * step  # one pixel per face
    else:
        u = (np.arange(width) + 0.5) / width * 1.9 - 0.95 + 0.013  # the roof's edge splits blocks
    Y, X = np.meshgrid(u, u, indexing="ij")  # row-major image: rows along y
    o = np.stack([X.ravel(), Y.ravel(), np.full(X.size, 0.3)], axis=1).astype(np.float32)
    d = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (len(o), 1))
    sky = UniformSky()
    with RayTracer(mesh, 1) as tracer:
        vis = bake(
            mesh,
            tracer,
            np.random.default_rng(0),
            directions=16,
            spacing_m=0.05,
            rays=4,
            cell_m=0.1,
            cell_height_m=0.03,
            ground_rays=0,
        )
        hits = tracer.intersect(o, d)
        traced = []
        occluded = tracer.occluded
        tracer.occluded = lambda origins, *a, **k: traced.append(len(origins)) or occluded(origins, *a, **k)
        settings = uniform_settings(sky_visibility=vis, glossy_mirror="any_hit")
        own = shade(tracer, mesh, hits, o, d, sky, settings, np.random.default_rng(0))["glossy"]
        own_rays = sum(traced)
        traced.clear()
        shared = shade(tracer, mesh, hits, o, d, sky, settings, np.random.default_rng(0), image_width=width)["glossy"]
        shared_rays = sum(traced)
    assert own_rays == width * width
    if tilt_deg:
        assert shared_rays == width * width and np.array_equal(shared, own)
    else:
        assert shared_rays == width * width // 4
        differ = np.any(np.abs(shared - own) > 1e-6, axis=1).reshape(width, width)
        under = (np.abs(X) < ROOF_HALF) & (np.abs(Y) < ROOF_HALF)  # the mirror ray meets the roof
        blocks = under.reshape(width // 2, 2, width // 2, 2)
        split = np.repeat(np.repeat(blocks.any(axis=(1, 3)) & ~blocks.all(axis=(1, 3)), 2, 0), 2, 1)
        assert differ.any() and not np.any(differ & ~split)


def test_a_view_shades_the_same_on_one_ray_thread_or_two(monkeypatch):
    """A tracer of two threads traces a view's mirror rays in chunks on its pool: every layer of a
    translucent, glossy floor's image under a roof (the default ``predicted`` mirrors, their rays
    shared in 2 x 2 blocks; the floor's back-side lookups) equals the one of a single-threaded
    tracer, bit for bit."""
    import eden_pipe.render.embree as embree

    monkeypatch.setattr(embree, "MIN_SPLIT", 16)  # the view's few hundred mirror rays in several chunks
    width = 48
    floor = grid(-1.0, 1.0, -1.0, 1.0, 0.0, 24, albedo=0.5, semantic=labels.GRASS)
    floor.specular[:] = 0.04
    floor.translucency[:] = 0.3
    roof = grid(-ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT, 4, albedo=0.6, flip=True)
    mesh = Mesh.concatenate([floor, roof])
    u = (np.arange(width) + 0.5) / width * 1.9 - 0.95
    Y, X = np.meshgrid(u, u, indexing="ij")
    o = np.stack([X.ravel() * 0.5, Y.ravel() * 0.5, np.full(X.size, 0.3)], axis=1).astype(np.float32)
    d = np.stack([X.ravel(), Y.ravel(), np.full(X.size, -1.0)], axis=1).astype(np.float32)
    sky = UniformSky()
    layers = {}
    for threads in (1, 2):
        with RayTracer(mesh, threads) as tracer:
            vis = bake(
                mesh,
                tracer,
                np.random.default_rng(0),
                directions=16,
                spacing_m=0.05,
                rays=4,
                cell_m=0.1,
                cell_height_m=0.03,
                ground_rays=0,
            )
            hits = tracer.intersect(o, d)
            layers[threads] = shade(
                tracer,
                mesh,
                hits,
                o,
                d,
                sky,
                uniform_settings(sky_visibility=vis),
                np.random.default_rng(0),
                image_width=width,
            )
    assert np.any(layers[1]["glossy"] > 0) and np.any(layers[1]["glossy"] == 0)  # mirrors that see sky, and roof
    for name, value in layers[1].items():
        assert np.array_equal(value, layers[2][name]), name
