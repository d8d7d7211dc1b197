"""The bake's compiled kernels (``render/visibility/kernels.py``) equal, bit for bit, the numpy
code they replaced, which is kept here as the reference: on random meshes and rays with the
awkward cases (zero-area faces, ties between normal components, normals near the tangent
frame's switch, signed zeros), cut into uneven blocks as the tracer's thread pool cuts them."""

from __future__ import annotations

import itertools
from functools import partial
from types import SimpleNamespace

import numpy as np
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from eden_pipe.models.mesh import Mesh
from eden_pipe.render import sh, vec
from eden_pipe.render.embree import Hits
from eden_pipe.render.pathtrace import cosine_directions, stratified_uniforms
from eden_pipe.render.visibility import bake, bounce, kernels, ray_kernels
from eden_pipe.render.visibility.store import exposure_of

EPS = 1e-3


def uneven_blocks(fn, n: int):
    """A stand-in for ``RayTracer.map_chunks``: blocks of uneven sizes, in a shuffled order."""
    cuts = sorted({0, n, *np.random.default_rng(n).integers(0, n + 1, 5).tolist()})
    spans = list(itertools.pairwise(cuts))
    return [fn(a, b) for a, b in reversed(spans)]


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal dtype, shape and bits (NaNs and signed zeros included)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.fixture(scope="module")
def mesh() -> Mesh:
    rng = np.random.default_rng(1)
    vertices = rng.normal(size=(3000, 3)).astype(np.float32) * np.float32(2.0)
    faces = rng.integers(0, len(vertices), (4000, 3))
    faces[:50, 2] = faces[:50, 1]  # zero-area faces
    # faces whose normals tie between two axes (|n_x| == |n_y|) or lie on one
    vertices[:6] = [[0, 0, 0], [1, 1, 0], [0, 0, 1], [0, 0, 0], [1, 0, 0], [0, 1, 0]]
    faces[50:60] = [0, 1, 2]
    faces[60:70] = [3, 4, 5]
    albedo = rng.random((len(faces), 3)).astype(np.float32)
    translucency = np.where(rng.random(len(faces)) < 0.5, rng.random(len(faces)), 0.0).astype(np.float32)
    semantic = rng.integers(0, 3, len(faces))
    return Mesh(vertices, faces, semantic, np.zeros(len(faces)), albedo, translucency)


def numpy_face_frames(mesh):
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cross = np.cross(b - a, c - a)
    area2 = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(area2, 1e-30)[:, None]
    return normals, 0.5 * area2, (a + b + c) / 3.0


def numpy_assign_probes(normals, centroids, opaque, cell_m, cell_height_m):
    n_faces = len(normals)
    cell = np.floor(centroids / np.array([cell_m, cell_m, cell_height_m])).astype(np.int64)
    cell -= cell.min(axis=0)
    span = cell.max(axis=0) + 1
    keys = []
    for side, sign in enumerate((1.0, -1.0)):
        sn = sign * normals
        axis = np.argmax(np.abs(sn), axis=1)
        positive = sn[np.arange(n_faces), axis] > 0
        inside = opaque & (side == 1)
        bin_ = (axis * 2 + positive) * 2 + inside
        keys.append(((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]) * 12 + bin_)
    unique, inverse = np.unique(np.stack(keys, axis=1).ravel(), return_inverse=True)
    return inverse.reshape(n_faces, 2).astype(np.int32), len(unique)


@pytest.fixture(scope="module")
def frames(mesh):
    normals, areas, centroids = numpy_face_frames(mesh)
    face_probe, n_probes = numpy_assign_probes(normals, centroids, mesh.translucency <= 0, 0.5, 0.2)
    return normals, areas, centroids, face_probe, n_probes


def test_face_frames_and_probes_match_numpy(mesh, frames):
    normals, areas, centroids, face_probe, n_probes = frames
    got = bake.face_frames(mesh, uneven_blocks)
    assert all(same(g, e) for g, e in zip(got, (normals, areas, centroids), strict=True))
    which = np.random.default_rng(0).permutation(len(normals))[:500]
    assert same(kernels.face_normals(mesh.vertices, mesh.faces, which), normals[which])
    block = np.empty((300, 3))
    kernels.face_normals_range(mesh.vertices, mesh.faces, block, 40, 340)
    assert same(block, normals[40:340])
    probes, count = bake.assign_probes(normals, centroids, mesh.translucency <= 0, 0.5, 0.2, uneven_blocks)
    assert count == n_probes and same(probes, face_probe)


@pytest.mark.parametrize("top", [0, 1, 70_000, 2**40])
def test_unique_inverse_matches_numpy(top):
    keys = np.random.default_rng(top).integers(0, top + 1, 50_000).astype(np.int64)
    inverse, count = kernels.unique_inverse(keys)
    unique, expected = np.unique(keys, return_inverse=True)
    assert count == len(unique) and same(inverse, expected.astype(np.int32))
    assert kernels.unique_inverse(np.zeros(0, np.int64))[1] == 0


def test_probe_sums_box_and_exposures_match_numpy(mesh, frames):
    normals, areas, _, face_probe, n_probes = frames
    rng = np.random.default_rng(2)
    lo, hi = np.array([-2.0, -2.5, -1.0]), np.array([2.0, 2.5, 1.5])
    v = mesh.vertices[mesh.faces]
    covered = np.all((v >= lo) & (v <= hi), axis=(1, 2))
    assert same(kernels.faces_inside(mesh.vertices, mesh.faces, lo, hi), covered) and covered.any()
    garden = mesh.semantic != 0
    used = mesh.vertices[mesh.faces[garden].ravel()]
    got_lo, got_hi = kernels.garden_bounds(mesh.vertices, mesh.faces, garden)
    assert same(got_lo, used.min(axis=0)) and same(got_hi, used.max(axis=0))

    hits = rng.integers(0, 40, (len(normals), 2)).astype(np.int32)
    open_hits = rng.random((len(normals), 2)) * 30
    hits[~covered], open_hits[~covered] = 0, 0.0
    side_area = np.repeat(areas, 2)
    sign = np.array([1.0, -1.0])
    mean_normal = np.zeros((n_probes, 3))
    for k in range(3):
        weights = side_area * np.outer(normals[:, k], sign).ravel()
        mean_normal[:, k] = np.bincount(face_probe.ravel(), weights=weights, minlength=n_probes)
    expected = (
        mean_normal,
        np.bincount(face_probe.ravel(), weights=np.repeat(covered, 2) * side_area, minlength=n_probes),
        np.bincount(face_probe.ravel(), weights=hits.astype(np.float64).ravel(), minlength=n_probes),
        np.bincount(face_probe.ravel(), weights=open_hits.ravel(), minlength=n_probes),
    )
    got = (
        *kernels.probe_frames(face_probe, areas, normals, covered, n_probes),
        *kernels.probe_hit_sums(face_probe, hits, open_hits, n_probes),
    )
    assert all(same(g, e) for g, e in zip(got, expected, strict=True))

    visible, gain = rng.random(n_probes), rng.random(n_probes) * 3
    probe_visible = np.where(rng.random(n_probes) < 0.1, 0.0, rng.random(n_probes) * 2)
    v_probe = visible[face_probe]
    open_factor = open_hits * (0.014**2 * 2.0 / 128) / np.maximum(areas, 1e-12)[:, None]
    v_face = (hits.astype(np.float64) + 4.0 * v_probe) / (open_hits + 4.0) * open_factor
    exposure = exposure_of(v_face, probe_visible[face_probe])
    exposure[~covered] = 1.0
    got_v = kernels.visible_sky(hits, open_hits, areas, face_probe, visible, 0.014**2 * 2.0 / 128, 4.0)
    got_exposure = kernels.side_exposure(got_v, face_probe, probe_visible, covered)
    assert same(got_v, v_face) and same(got_exposure, exposure)
    limit = 1.0 / np.maximum(probe_visible[face_probe], 1e-6)
    seen = np.where(covered[:, None], np.minimum(exposure * gain[face_probe], limit), 1.0).astype(np.float32)
    assert same(kernels.seen_exposure(exposure, gain, face_probe, probe_visible, covered), seen)


def label_propagation_parts(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Each face's part as the smallest vertex it reaches through shared vertices: every face
    takes the smallest label of its corners, every vertex the smallest of its faces', until
    nothing changes (an independent oracle for ``kernels.mesh_parts``)."""
    label = np.arange(n_vertices)
    while True:
        face_label = label[faces].min(axis=1)
        new = label.copy()
        np.minimum.at(new, faces.ravel(), np.repeat(face_label, 3))
        if np.array_equal(new, label):
            return face_label
        label = new


def test_mesh_parts_join_faces_that_share_vertices():
    """Strips of triangles drawn from small vertex windows make many parts, some joined by a
    chain of shared vertices, some a lone face; a face that repeats a vertex is its own part."""
    rng = np.random.default_rng(4)
    starts = np.sort(rng.integers(0, 5000, 1500))
    faces = starts[:, None] + rng.integers(0, 6, (1500, 3))
    faces[:5] = [[7000, 7001, 7002], [7003, 7003, 7004], [7002, 7005, 7006], [7010, 7011, 7012], [7011, 7012, 7010]]
    parts = kernels.mesh_parts(faces, 7013)
    assert same(parts, label_propagation_parts(faces, 7013))
    assert parts[:5].tolist() == [7000, 7003, 7000, 7010, 7010]
    assert 50 < len(np.unique(parts)) < 1500  # the strips make many parts of several faces
    assert same(kernels.mesh_parts(faces[::-1].copy(), 7013), parts[::-1])  # the order faces come in


def test_pooled_visible_sky_matches_numpy(frames):
    """Each side's hit fraction shrunk toward its part's within its probe, and the part's toward
    the probe's, as numpy's grouped sums give them; a huge part prior leaves each side its part's
    fraction (times its own open factor)."""
    normals, areas, _, face_probe, n_probes = frames
    rng = np.random.default_rng(5)
    n = len(normals)
    hits = rng.integers(0, 40, (n, 2)).astype(np.int32)
    open_hits = rng.random((n, 2)) * 30 + 1.0
    visible = rng.random(n_probes)
    part = rng.integers(0, n // 4, n).astype(np.int64)
    keys = kernels.part_probe_keys(part, face_probe, n_probes)
    assert same(keys, (part[:, None] * n_probes + face_probe).ravel())
    group, n_groups = kernels.unique_inverse(keys)
    scale = 0.014**2 * 2.0 / 128
    group_hits = np.bincount(group, weights=hits.ravel().astype(np.float64), minlength=n_groups)
    group_open = np.bincount(group, weights=open_hits.ravel(), minlength=n_groups)
    v_probe = visible[face_probe].ravel()
    fraction = (group_hits[group] + 8.0 * v_probe) / (group_open[group] + 8.0)
    open_factor = open_hits * scale / np.maximum(areas, 1e-12)[:, None]
    shrunk = hits.astype(np.float64).ravel() + 16.0 * fraction
    expected = (shrunk / (open_hits.ravel() + 16.0)).reshape(-1, 2) * open_factor
    pooled = partial(kernels.pooled_visible_sky, hits, open_hits, areas, face_probe, visible, group, n_groups, scale)
    assert same(pooled(8.0, 16.0), expected)
    only_part = pooled(8.0, 1e15)
    assert np.allclose(only_part, fraction.reshape(-1, 2) * open_factor, rtol=1e-9, atol=0)


def test_bundle_rays_and_their_counts_match_numpy(frames):
    normals, _, _, face_probe, n_probes = frames
    rng = np.random.default_rng(3)
    w = vec.normalize(rng.normal(size=(1, 3)))[0]
    base, e1, e2 = rng.normal(size=3), vec.normalize(rng.normal(size=(1, 3)))[0], rng.normal(size=3)
    gu, gv = np.arange(-1.0, 1.0, 0.07) + 0.01, np.arange(-2.0, 2.0, 0.07) + 0.02
    V, U = np.meshgrid(gv, gu, indexing="ij")
    origins = np.empty((U.size, 3), np.float32)
    kernels.bundle_origins(base, e1, e2, gu, gv, origins)
    assert same(origins, (base + U.reshape(-1, 1) * e1 + V.reshape(-1, 1) * e2).astype(np.float32))

    n_faces = len(normals)
    hits, sh_sums = np.zeros(2 * n_faces), np.zeros((n_probes, sh.COUNT))
    side_hits, got_sums = np.zeros(2 * n_faces, np.int32), np.zeros((n_probes, sh.COUNT))
    wave_count, touched = np.zeros(n_probes, np.int32), np.empty(n_probes, np.int32)
    for _ in range(3):  # waves
        n = 20_000
        res = Hits(
            np.ones(n, np.float32),
            np.where(rng.random(n) < 0.2, -1, rng.integers(0, n_faces, n)),
            vec.normalize(rng.normal(size=(n, 3))).astype(np.float32),
        )
        y = sh.basis(w[None])[0].astype(np.float64)
        prim = res.prim[res.hit]
        side = (res.normal[res.hit] @ w.astype(np.float32) < 0).astype(np.int64)
        counts = np.bincount(prim * 2 + side, minlength=2 * n_faces)
        hits += counts
        touched_sides = np.nonzero(counts)[0]
        probe_of_side = face_probe.ravel()
        per_probe = np.bincount(probe_of_side[touched_sides], weights=counts[touched_sides], minlength=n_probes)
        sh_sums += per_probe[:, None] * y
        kernels.count_bundle_hits(
            res.prim, res.normal, w.astype(np.float32), side_hits, probe_of_side, wave_count, touched, got_sums, y
        )
    assert same(side_hits.astype(np.float64), hits) and same(got_sums, sh_sums) and not wave_count.any()

    open_hits, got_open = np.zeros((n_faces, 2)), np.zeros((n_faces, 2))
    for w in np.vstack([vec.normalize(rng.normal(size=(4, 3))), [[0.0, 0.0, 1.0]]]):
        cos = normals @ w
        open_hits[:, 0] += np.maximum(cos, 0.0)
        open_hits[:, 1] += np.maximum(-cos, 0.0)
        uneven_blocks(lambda a, b, w=w: kernels.add_open_hits(normals[a:b] @ w, got_open, a), n_faces)
    assert same(got_open, open_hits)


def test_cosine_rays_match_pathtrace():
    rng = np.random.default_rng(4)
    n = vec.normalize(rng.normal(size=(20_000, 3)))
    n[:100, 0] = np.repeat([0.9, -0.9, 0.8999999999, 1.0], 25)  # around the tangent frame's switch
    n = vec.normalize(n)
    n[100:110] = [0.0, 0.0, 1.0]
    u1, u2 = rng.random(len(n)), rng.random(len(n))
    expected = cosine_directions(n, u1, u2)
    assert same(ray_kernels.cosine_directions(n, u1, u2, uneven_blocks), expected)
    n32 = n.astype(np.float32)
    assert same(ray_kernels.cosine_directions(n32, u1, u2), cosine_directions(n32, u1, u2))


@pytest.mark.parametrize("rays", [8, 10, 128])
def test_stratified_disc_draws_what_stratified_uniforms_drew(rays):
    rng, expected_rng = np.random.default_rng(5), np.random.default_rng(5)
    u1, rc, rs = ray_kernels.stratified_disc(300, rays, rng, uneven_blocks)
    e1, e2 = stratified_uniforms(300, 0, rays, rays, expected_rng)
    r, phi = np.sqrt(e1.ravel()), 2.0 * np.pi * e2.ravel()
    assert same(u1, e1.ravel()) and same(rc, r * np.cos(phi)) and same(rs, r * np.sin(phi))
    assert rng.random() == expected_rng.random()


def test_node_rays_match_the_lightmaps_tiled_rays():
    rng = np.random.default_rng(6)
    points, normals = rng.normal(size=(700, 3)), vec.normalize(rng.normal(size=(700, 3)))
    w0, m, rays = 100, 500, 16
    for sign in (1.0, -1.0):
        u1, u2 = stratified_uniforms(m, 0, rays, rays, rng)
        side_normal = normals * sign
        n = np.tile(side_normal[w0 : w0 + m], (rays, 1))
        start = np.tile(points[w0 : w0 + m] + side_normal[w0 : w0 + m] * EPS, (rays, 1)).astype(np.float32)
        dirs = cosine_directions(n, u1.ravel(), u2.ravel())
        by_node = np.arange(m * rays).reshape(rays, m).T.ravel()
        r, phi = np.sqrt(u1.ravel()), 2.0 * np.pi * u2.ravel()
        origins, directions = np.empty((m * rays, 3), np.float32), np.empty((m * rays, 3), np.float32)
        uneven_blocks(
            partial(
                ray_kernels.node_rays, points, normals, sign, w0, m, rays, r * np.cos(phi), r * np.sin(phi), u1.ravel(),
                EPS, origins, directions,
            ),
            m,
        )  # fmt: skip
        assert same(origins, start[by_node]) and same(directions, dirs[by_node])
        occluded = rng.random(m * rays) < 0.4
        visible = np.zeros((800, 2))
        ray_kernels.escaped_fraction(occluded[by_node], m, rays, visible, 1, w0)
        assert same(visible[w0 : w0 + m, 1], (~occluded).reshape(rays, m).mean(axis=0))


def test_probe_bounce_rays_match_numpy(mesh, frames):
    normals, areas, _, face_probe, n_probes = frames
    rng = np.random.default_rng(7)
    side_area = np.repeat(areas, 2)
    sides = np.argsort(face_probe.ravel(), kind="stable")
    side_probe = face_probe.ravel()[sides]
    cum_area = np.cumsum(np.maximum(side_area[sides], 1e-12))
    first = np.searchsorted(side_probe, np.arange(n_probes))
    last = np.append(first[1:], len(sides)) - 1
    area_before = np.where(first > 0, cum_area[np.maximum(first - 1, 0)], 0.0)
    span = cum_area[last] - area_before
    order, got_first = kernels.sides_by_probe(face_probe, n_probes)
    assert same(order, sides.astype(np.int32)) and same(got_first, first)
    assert same(kernels.cumulative_side_area(order, areas, 0.0), cum_area)
    assert same(kernels.cumulative_side_area(order[777:], areas, cum_area[776]), cum_area[777:])  # a wave's

    rays, probes = 8, np.arange(10, n_probes - 5)
    n = len(probes)
    tiled = np.tile(probes, rays)
    pick = rng.random(len(tiled))
    pick[:20] = [0.0, 1.0] * 10  # the ends of a probe's area
    target = area_before[tiled] + pick * span[tiled]
    member = np.clip(np.searchsorted(cum_area, target), first[tiled], last[tiled])
    face, back = sides[member] // 2, sides[member] % 2 == 1
    side_normal = normals[face] * np.where(back, -1.0, 1.0)[:, None]
    r1, r2 = rng.random(len(face)), rng.random(len(face))
    s1 = np.sqrt(r1)
    tri, vtx = mesh.faces[face], mesh.vertices
    point = (
        (1 - s1)[:, None] * vtx[tri[:, 0]]
        + (s1 * (1 - r2))[:, None] * vtx[tri[:, 1]]
        + (s1 * r2)[:, None] * vtx[tri[:, 2]]
    )
    u1, u2 = stratified_uniforms(n, 0, rays, rays, rng)
    dirs = cosine_directions(side_normal, u1.ravel(), u2.ravel())
    by_probe = np.arange(n * rays).reshape(rays, n).T.ravel()
    r, phi = np.sqrt(u1.ravel()), 2.0 * np.pi * u2.ravel()
    origins, directions = np.empty((n * rays, 3), np.float32), np.empty((n * rays, 3), np.float32)
    uneven_blocks(
        partial(
            ray_kernels.probe_rays, probes, rays, pick, area_before, span, cum_area, first, last, order, mesh.faces,
            mesh.vertices, r1, r2, r * np.cos(phi), r * np.sin(phi), u1.ravel(), EPS, origins, directions,
        ),
        n * rays,
    )  # fmt: skip
    assert same(origins, (point + side_normal * EPS).astype(np.float32)[by_probe])
    assert same(directions, dirs[by_probe])

    prim = np.where(rng.random(len(tiled)) < 0.3, -1, rng.integers(0, len(normals), len(tiled)))
    hit = prim >= 0
    alb = mesh.albedo[np.where(hit, prim, 0)] * hit[:, None]
    expected = np.zeros((n_probes, 3))
    for k in range(3):
        expected[probes, k] += np.bincount(tiled - probes[0], weights=alb[:, k], minlength=n)
    got = np.zeros((n_probes, 3))
    ray_kernels.blocked_albedo_sum(prim[by_probe], mesh.albedo, n, rays, got, probes[0])
    assert same(got, expected)


def numpy_bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure, per_wave):
    n_recv, rays = hit_face.shape
    out, tint = np.zeros((n_recv, sh.COUNT)), np.zeros((n_recv, 3))
    for p0 in range(0, n_recv, per_wave):
        p1 = min(n_recv, p0 + per_wave)
        f = hit_face[p0:p1].ravel()
        rows = np.repeat(np.arange(p1 - p0), rays)
        blocked = f >= 0
        f, b, rows = f[blocked], hit_back[p0:p1].ravel()[blocked].astype(np.int64), rows[blocked]
        near, far = face_probe[f, b], face_probe[f, 1 - b]
        weight_rgb = mesh.albedo[f] * multi[near]
        light = (
            transfer[near] * exposure[f, b][:, None]
            + (mesh.translucency[f] * exposure[f, 1 - b])[:, None] * transfer[far]
        )
        weight = weight_rgb @ bounce.LUMA_F32
        for k in range(sh.COUNT):
            out[p0:p1, k] = np.bincount(rows, weights=weight * light[:, k], minlength=p1 - p0)
        for k in range(3):
            tint[p0:p1, k] = np.bincount(rows, weights=weight_rgb[:, k], minlength=p1 - p0)
    out /= rays
    tint_luma = tint @ bounce.LUMA_F32
    tint = np.where(tint_luma[:, None] > 1e-9, tint / np.maximum(tint_luma, 1e-9)[:, None], 1.0)
    return out, tint


def test_bounce_transfer_matches_numpy(mesh, frames):
    _, _, _, face_probe, n_probes = frames
    rng = np.random.default_rng(8)
    hit_face = np.where(rng.random((5000, 8)) < 0.4, -1, rng.integers(0, len(face_probe), (5000, 8))).astype(np.int32)
    hit_face[:10] = -1  # receivers that see only sky
    hit_back = rng.random(hit_face.shape) < 0.5
    multi = 1.0 / (1.0 - np.minimum(rng.random((n_probes, 3)), 0.8))
    transfer, exposure = rng.normal(size=(n_probes, sh.COUNT)), rng.random((len(face_probe), 2)) * 2
    expected = numpy_bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure, 1234)
    single = numpy_bounce_transfer(mesh, hit_face, hit_back, np.ones_like(multi), face_probe, transfer, exposure, 1234)
    got = bounce.bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure, uneven_blocks)
    # The bounces as the bake casts them: the sun's without the multi-bounce factor, both with its tint.
    assert same(got[0], expected[0].astype(np.float32)) and same(got[2], expected[1])
    assert same(got[1], single[0].astype(np.float32))
    both = bounce.bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure, sun_multi=True)
    assert same(both[0], got[0]) and both[1] is both[0] and same(both[2], got[2])


def test_camera_sky_rays_and_counts_match_numpy(mesh, frames):
    normals, _, _, face_probe, n_probes = frames
    rng = np.random.default_rng(9)
    eyes, rays, first = rng.normal(size=(40, 3)), 64, 10
    origin = np.repeat(eyes[first:], rays, axis=0)
    d = vec.normalize(rng.normal(size=(len(origin), 3))).astype(np.float32)
    t = (rng.random(len(origin)) * 5).astype(np.float32)
    prim = np.where(rng.random(len(origin)) < 0.3, -1, rng.integers(0, len(normals), len(origin)))
    normal = vec.normalize(rng.normal(size=(len(origin), 3))).astype(np.float32)
    h = np.flatnonzero(prim >= 0)
    dh = d[h]
    back = vec.dot(normal[h], dh) > 0
    side_normal = normals[prim[h]] * np.where(back, -1.0, 1.0)[:, None]
    points = origin[h] + dh * t[h, None]
    u1, u2 = rng.random(len(h)), rng.random(len(h))
    sky = cosine_directions(side_normal, u1, u2)
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    origins, dirs = np.empty((len(h), 3), np.float32), np.empty((len(h), 3), np.float32)
    uneven_blocks(
        partial(
            ray_kernels.camera_sky_rays, h, prim, back, t, d, eyes, first, rays, mesh.vertices, mesh.faces,
            r * np.cos(phi), r * np.sin(phi), u1, EPS, origins, dirs,
        ),
        len(h),
    )  # fmt: skip
    assert same(origins, (points + side_normal * EPS).astype(np.float32)) and same(dirs, sky)

    free = rng.random(len(h)) < 0.5
    side = prim[h] * 2 + back
    n_sides = 2 * len(normals)
    count, escapes = np.bincount(side, minlength=n_sides), np.bincount(side, weights=free, minlength=n_sides)
    got_count, got_escapes = np.zeros(n_sides, np.int32), np.zeros(n_sides, np.int32)
    kernels.count_sides(side, free, got_count, got_escapes)
    assert same(got_count, count.astype(np.int32)) and same(got_escapes.astype(np.float64), escapes)
    v_face = rng.random((len(normals), 2))
    probe = face_probe.ravel()
    expected = (
        np.bincount(probe, weights=escapes, minlength=n_probes),
        np.bincount(probe, weights=count * v_face.ravel(), minlength=n_probes),
        np.bincount(probe, weights=count.astype(np.float64), minlength=n_probes),
    )
    got = kernels.camera_sums(face_probe, got_count, got_escapes, v_face, n_probes)
    assert all(same(g, e) for g, e in zip(got, expected, strict=True))


def test_ground_node_transfer_matches_numpy():
    rng = np.random.default_rng(10)
    m, rays, n = 300, 128, 500
    dirs = vec.normalize(rng.normal(size=(rays * m, 3))).astype(np.float32)  # ray by ray
    hit = rng.random(rays * m) < 0.5
    hit[: 3 * m] = True  # nodes whose first rays are all blocked
    hit.reshape(rays, m)[:, :7] = True  # nodes with every ray blocked: sums of signed zeros
    nodes = rng.permutation(n)[:m]
    expected = np.zeros((n, sh.COUNT))
    open_ = (~hit).astype(np.float64)
    expected[nodes] = (sh.basis(dirs).astype(np.float64) * open_[:, None]).reshape(rays, m, sh.COUNT).mean(axis=0)
    by_node = np.arange(m * rays).reshape(rays, m).T.ravel()
    got = np.zeros((n, sh.COUNT))
    ray_kernels.node_transfer(sh.basis(dirs[by_node]), hit[by_node], m, rays, got, nodes)
    assert same(got, expected)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_blas_products_do_not_depend_on_blas_threads(dtype):
    """The bake runs BLAS on one thread (``bake.bake``): its (N, 3) products (the open hits'
    cosines, the bundles' facing, the bounce's luma) give the values they gave on every BLAS
    thread, in blocks of any size."""
    rng = np.random.default_rng(11)
    rows = rng.normal(size=(300_001, 3)).astype(dtype)
    rows[:1000] = -0.0  # signed zeros
    w = rng.normal(size=3)
    w = (w / np.linalg.norm(w)).astype(dtype)
    with threadpool_limits(limits=8, user_api="blas"):
        many = rows @ w
        luma = rows.astype(np.float32) @ bounce.LUMA_F32
    with threadpool_limits(limits=1, user_api="blas"):
        one = rows @ w
        one_luma = rows.astype(np.float32) @ bounce.LUMA_F32
        blocked = np.concatenate([rows[a:b] @ w for a, b in ((0, 7), (7, 100_000), (100_000, len(rows)))])
    assert same(many, one) and same(luma, one_luma) and same(blocked, one)


def test_bounce_transfer_does_not_depend_on_blas_threads(mesh, frames):
    _, _, _, face_probe, n_probes = frames
    rng = np.random.default_rng(12)
    hit_face = np.where(rng.random((40_000, 8)) < 0.4, -1, rng.integers(0, len(face_probe), (40_000, 8)))
    hit_face = hit_face.astype(np.int32)
    hit_back = rng.random(hit_face.shape) < 0.5
    multi = 1.0 / (1.0 - np.minimum(rng.random((n_probes, 3)), 0.8))
    transfer, exposure = rng.normal(size=(n_probes, sh.COUNT)), rng.random((len(face_probe), 2)) * 2
    args = (mesh, hit_face, hit_back, multi, face_probe, transfer, exposure)
    with threadpool_limits(limits=8, user_api="blas"):
        many = bounce.bounce_transfer(*args)
    with threadpool_limits(limits=1, user_api="blas"):
        one = bounce.bounce_transfer(*args, uneven_blocks)
    assert all(same(a, b) for a, b in zip(many, one, strict=True))


def test_the_bake_runs_blas_on_one_thread_and_gives_it_back(monkeypatch):
    """Inside ``bake`` BLAS has one thread (the tracer's pool is the bake's parallelism); after it,
    the limit it found."""
    seen = []

    class Enough(Exception):
        """The bake's first step ran: no need for the rest."""

    def spy(*args, **kwargs):
        seen.extend(info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas")
        raise Enough

    monkeypatch.setattr(bake, "face_frames", spy)
    before = [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"]
    if not before:
        pytest.skip("no BLAS library that threadpoolctl can see")
    tracer = SimpleNamespace(map_chunks=None)
    with pytest.raises(Enough):
        bake.bake(None, tracer, None, directions=1, spacing_m=1.0, rays=1, cell_m=1.0, cell_height_m=1.0)
    assert seen and all(n == 1 for n in seen)
    assert [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"] == before
