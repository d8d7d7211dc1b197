"""The bounce of the points cameras see (``render.sky_visibility.seen_bounce``, docs/realism.md, Bounce).

A probe's own bounce rays leave every part of its faces, the hidden ones too; the camera gain's sky
rays leave the points cameras see. ``bounce.camera_bounce`` replaces each probe's bounce by those
rays' (closest-hit) light, shrunk toward the probe's own by pseudo-rays.
"""

from __future__ import annotations

import copy

import numpy as np

from eden_pipe import labels
from eden_pipe.colour import LUMA
from eden_pipe.models.mesh import Mesh
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.pathtrace import reference_shade
from eden_pipe.render.shading import shade
from eden_pipe.render.visibility.bake import bake
from eden_pipe.render.visibility.bounce import SeenRays, camera_bounce
from tests.sky_scenes import UniformSky, closed_box, grid, uniform_settings


def test_camera_bounce_sums_the_seen_rays_light_and_shrinks_toward_the_probe():
    """Exact values on hand-made tables: each kept ray adds its hit face's albedo (luma) times the
    hit probe's factor times the hit side's light (its probe's transfer times its exposure, plus
    translucency times the other side's); a probe's rows become (sums + prior * own) / (samples +
    prior), in place, also where every ray escaped (probe 1: shrunk toward zero); a probe no camera
    saw keeps its own rows bit for bit; the sun's table leaves the factor out, and one shared table
    (``sun_multi_bounce``) is blended once, with the factor."""
    rng = np.random.default_rng(0)
    n_faces, n_probes = 4, 5
    mesh = Mesh.from_arrays(
        rng.random((6, 3)), np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5]]), semantic=labels.HEDGE,
        material="leaf", albedo=rng.random((n_faces, 3)) * 0.8, translucency=rng.random(n_faces) * 0.5,
    )  # fmt: skip
    face_probe = np.array([[0, 1], [2, 3], [2, 4], [3, 1]], np.int32)
    transfer, exposure = rng.random((n_probes, 16)), rng.random((n_faces, 2)) * 2
    multi = 1.0 + rng.random((n_probes, 3))
    own, own_sun = rng.random((n_probes, 16)).astype(np.float32), rng.random((n_probes, 16)).astype(np.float32)
    seen = SeenRays(
        probe=np.array([0, 0, 2, 3, 0], np.int32),
        hit_face=np.array([1, 3, 0, 2, 1], np.int32),
        hit_back=np.array([False, True, True, False, True]),
        samples=np.array([9.0, 2.0, 3.0, 1.0, 0.0]),
    )
    prior = 8.0
    bounce, sun_bounce = own.copy(), own_sun.copy()
    camera_bounce(mesh, seen, multi, face_probe, transfer, exposure, bounce, sun_bounce, prior)

    def expected(factor, rows):
        sums = np.zeros((n_probes, 16))
        for p, f, b in zip(seen.probe, seen.hit_face, seen.hit_back.astype(int), strict=True):
            near, far = face_probe[f, b], face_probe[f, 1 - b]
            weight = (mesh.albedo[f] * factor[near]) @ LUMA
            light = transfer[near] * exposure[f, b] + mesh.translucency[f] * exposure[f, 1 - b] * transfer[far]
            sums[p] += weight * light
        return ((sums + prior * rows) / (seen.samples + prior)[:, None]).astype(np.float32)

    assert np.allclose(bounce, expected(multi, own), rtol=1e-6, atol=1e-7)
    assert np.allclose(sun_bounce, expected(np.ones_like(multi), own_sun), rtol=1e-6, atol=1e-7)
    unseen = seen.samples == 0
    assert np.array_equal(bounce[unseen], own[unseen]) and np.array_equal(sun_bounce[unseen], own_sun[unseen])
    shared = own.copy()
    camera_bounce(mesh, seen, multi, face_probe, transfer, exposure, shared, shared, prior)
    assert np.allclose(shared, expected(multi, own), rtol=1e-6, atol=1e-7)

    # The colour: each probe the rays light takes that of the albedo they meet (times the factor),
    # weighted by the hit side's band-0 light, shrunk toward its own (luma 1) by the prior's rays
    # at those rays' mean light; probes without a lit hit keep theirs, bit for bit.
    own_tint = rng.random((n_probes, 3)) + 0.1
    own_tint /= (own_tint @ LUMA)[:, None]
    tint = own_tint.copy()
    bounce = own.copy()
    camera_bounce(mesh, seen, multi, face_probe, transfer, exposure, bounce, own_sun.copy(), prior, tint)
    assert np.allclose(bounce, expected(multi, own), rtol=1e-6, atol=1e-7)  # the rows as without a tint
    colour, lit = np.zeros((n_probes, 3)), np.zeros(n_probes)
    for p, f, b in zip(seen.probe, seen.hit_face, seen.hit_back.astype(int), strict=True):
        near, far = face_probe[f, b], face_probe[f, 1 - b]
        light = transfer[near, 0] * exposure[f, b] + mesh.translucency[f] * exposure[f, 1 - b] * transfer[far, 0]
        colour[p] += mesh.albedo[f] * multi[near] * light
        lit[p] += (mesh.albedo[f] * multi[near]) @ LUMA * light
    met = lit > 0
    pseudo = prior * lit[met] / seen.samples[met]
    want = own_tint.copy()
    want[met] = (colour[met] + pseudo[:, None] * own_tint[met]) / (lit[met] + pseudo)[:, None]
    assert met.tolist() == [True, False, True, True, False]
    assert np.allclose(tint, want, rtol=1e-9)
    assert np.allclose(tint @ LUMA, 1.0)
    assert np.array_equal(tint[~met], own_tint[~met])

    # Probes in blocks (the tracer's map_chunks): every table the same, bit for bit, however cut.
    def one_probe_a_block(fn, n):
        return [fn(k, k + 1) for k in range(n)]

    cut = own.copy(), own_sun.copy(), own_tint.copy()
    camera_bounce(mesh, seen, multi, face_probe, transfer, exposure, *cut[:2], prior, cut[2], one_probe_a_block)
    whole = own.copy(), own_sun.copy(), own_tint.copy()
    camera_bounce(mesh, seen, multi, face_probe, transfer, exposure, *whole[:2], prior, whole[2])
    assert all(np.array_equal(a, b) for a, b in zip(cut, whole, strict=True))


def test_a_board_half_in_a_black_box_gets_the_bounce_of_the_half_cameras_see():
    """A grey board stands on a bright floor, its left half inside a closed black box. Its two
    faces span both halves (a quarter of one and three quarters of the other lie inside): their
    probes' own bounce rays leave the hidden parts too, where nothing is lit. Cameras see the open
    half only: with ``seen_bounce`` the board's shading there matches the path-traced reference's
    mean within 4 % (1-3 % over four bake seeds), with more bounce on both faces; without it, it is
    over 6 % too dark (7-10 %). The bake's other tables are the same either way (the camera gain's
    sky rays meet the same surfaces, closest-hit or not)."""
    floor = grid(-4.0, 4.0, -4.0, 4.0, 0.0, 1, albedo=0.8)
    board = Mesh.from_arrays(
        np.array([[-2.0, 0.0, 0.0], [2.0, 0.0, 0.0], [2.0, 0.0, 1.5], [-2.0, 0.0, 1.5]]),
        np.array([[0, 1, 2], [0, 2, 3]]),
        semantic=labels.OBSTACLE,
        material="generic",
        albedo=0.5,
    )
    mesh = Mesh.concatenate([floor, board, closed_box([-2.2, -0.5, -0.1], [0.0, 0.5, 1.6])])
    sky = UniformSky()
    settings = dict(directions=32, spacing_m=0.05, rays=64, cell_m=0.1, cell_height_m=0.03, ground_rays=0)
    rng = np.random.default_rng(3)
    points = np.column_stack([0.05 + 1.9 * rng.random(300), np.zeros(300), 0.05 + 1.4 * rng.random(300)])
    o = (points + [0.0, -1.0, 0.0]).astype(np.float32)
    d = np.tile(np.array([[0.0, 1.0, 0.0]], np.float32), (len(points), 1))
    with RayTracer(mesh, 1) as tracer:
        vis = {
            kept: bake(
                mesh, tracer, np.random.default_rng(0), camera_views=400, camera_rays=256, seen_bounce=kept, **settings
            )
            for kept in (False, True)
        }
        hits = tracer.intersect(o, d)
        assert np.all(np.isin(hits.prim, [2, 3]))  # the board's two faces

        def shading(v):
            return shade(tracer, mesh, hits, o, d, sky, uniform_settings(sky_visibility=v), np.random.default_rng(0))[
                "shading"
            ][:, 1]

        reference = reference_shade(
            tracer, mesh, hits, o, d, sky, uniform_settings(mode="reference", reference_samples=256),
            np.random.default_rng(4), layers=("shading",),
        )["shading"][:, 1]  # fmt: skip
        got = {kept: shading(v).mean() / reference.mean() - 1.0 for kept, v in vis.items()}
        no_bounce = copy.copy(vis[True])
        no_bounce.bounce, no_bounce.sun_bounce = np.zeros_like(no_bounce.bounce), np.zeros_like(no_bounce.sun_bounce)
        bounce = {kept: (shading(v) - shading(no_bounce)).mean() for kept, v in vis.items()}
    assert abs(got[True]) < 0.04 and got[False] < -0.06, got
    assert bounce[True] > 1.1 * bounce[False], bounce
    for key in ("face_probe", "exposure", "transfer", "normal", "tint"):
        assert np.array_equal(getattr(vis[False], key), getattr(vis[True], key)), key
    board_probes = vis[True].face_probe[2:4].ravel()
    assert np.all(vis[True].bounce[board_probes, 0] > vis[False].bounce[board_probes, 0])
