"""The bake: a garden's :class:`SkyVisibility` from outside-in ray bundles, probes and their bounce.

Once per garden (stage ``sky_visibility``), lighting-free; see
:mod:`eden_pipe.render.visibility` for the method.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from functools import partial

import numpy as np
from threadpoolctl import threadpool_limits

from eden_pipe.heap import release_free_memory
from eden_pipe.render import sh, vec
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.lightmap import bake_lightmaps
from eden_pipe.render.visibility import EPS, RAYS_PER_WAVE, kernels, ray_kernels
from eden_pipe.render.visibility.bounce import SeenRays, bounce_transfer, camera_bounce
from eden_pipe.render.visibility.face_sky import FACE_SKY_POINTS, face_sky_table
from eden_pipe.render.visibility.ground_map import GroundGrid, ground_map
from eden_pipe.render.visibility.shadow_maps import ShadowMaps, strata
from eden_pipe.render.visibility.store import SkyVisibility

MAX_BLOCKED_ALBEDO = 0.8  # caps the multi-bounce factor 1/(1 - a)
MIN_SEEN_V = 0.05  # the least mean visible fraction camera_gain's pseudo-rays assume (no gain from nothing)
MAX_SEEN_GAIN = 3.0  # camera_gain's cap


def face_frames(mesh, map_chunks=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit normals (F, 3) along the winding, areas (F,), centroids (F, 3)), float64, as numpy's
    cross product and norm of the float64 edges make them (:func:`kernels.face_frames_range`);
    ``map_chunks``: ``RayTracer.map_chunks``, to use every core."""
    n_faces = mesh.n_faces
    normals, areas, centroids = np.empty((n_faces, 3)), np.empty(n_faces), np.empty((n_faces, 3))
    kernels.blocks(map_chunks)(
        partial(kernels.face_frames_range, mesh.vertices, mesh.faces, normals, areas, centroids), n_faces
    )
    return normals, areas, centroids


def assign_probes(
    normals: np.ndarray,
    centroids: np.ndarray,
    opaque: np.ndarray,
    cell_m: float,
    cell_height_m: float,
    map_chunks=None,
) -> tuple[np.ndarray, int]:
    """(face_probe (F, 2) int32, probe count): probe = (cell, major axis of the side normal, and
    for opaque faces which side: the inside of a closed solid never shares a probe with an outside)."""
    n_faces = len(normals)
    size = np.array([cell_m, cell_m, cell_height_m])
    lo, hi = kernels.cell_bounds(centroids, size) if n_faces else (np.zeros(3, np.int64), np.zeros(3, np.int64))
    span = hi - lo + 1
    keys = np.empty((n_faces, 2), np.int64)
    kernels.blocks(map_chunks)(
        partial(kernels.probe_keys_range, normals, centroids, size, lo, span, opaque, keys), n_faces
    )
    inverse, count = kernels.unique_inverse(keys.ravel())
    return inverse.reshape(n_faces, 2), int(count)


def sky_directions(count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) directions over the upper hemisphere, stratified in (cos theta, phi): equal solid angles."""
    rows, cols = strata(count)  # strata of equal solid angle
    k = np.arange(count)
    z = (k // cols + rng.random(count)) / rows
    phi = 2.0 * np.pi * (k % cols + rng.random(count)) / cols
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def sky_hits(
    mesh,
    tracer: RayTracer,
    areas: np.ndarray,
    face_probe: np.ndarray,
    n_probes: int,
    box: tuple[np.ndarray, np.ndarray],
    rng: np.random.Generator,
    *,
    directions: int,
    spacing_m: float,
    shadow_maps: bool = False,
):
    """Outside-in visibility: for each sky direction, a grid of parallel rays (``spacing_m`` apart)
    enters ``box`` from that direction; a face side is hit by about ``V area cos / spacing^2`` of
    them. Returns (hits (F, 2) int32, expected hits if nothing occluded (F, 2) float64, per-probe SH
    sums (P, 16), the rays' first-hit depth maps if ``shadow_maps``, else none: ``ShadowMaps``).
    Each wave of a bundle is one row-major grid of parallel rays (a coherent batch)."""
    lo, hi = box
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2) + 1.0
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    n_faces = len(areas)
    sky = sky_directions(directions, rng)
    open_hits = np.zeros((n_faces, 2))

    def open_block(a: int, b: int) -> None:
        # Direction by direction over a block of faces (the block stays in cache): the same BLAS
        # product per face as over all faces at once, summed in the same order.
        normals = np.empty((b - a, 3))
        kernels.face_normals_range(mesh.vertices, mesh.faces, normals, a, b)
        for w in sky:
            kernels.add_open_hits(normals @ w, open_hits, a)
        open_hits[a:b] *= (areas[a:b] / spacing_m**2)[:, None]

    tracer.map_chunks(open_block, n_faces)
    side_hits = np.zeros(2 * n_faces, np.int32)
    sh_sums = np.zeros((n_probes, sh.COUNT))
    probe_of_side = face_probe.ravel()
    wave_count, touched = np.zeros(n_probes, np.int32), np.empty(n_probes, np.int32)

    def count(res, w32: np.ndarray, y: np.ndarray, direction: int, first_row: int) -> None:
        if maps.present:
            maps.store(direction, first_row, res.t)
        kernels.count_bundle_hits(res.prim, res.normal, w32, side_hits, probe_of_side, wave_count, touched, sh_sums, y)

    grids = [bundle_grid(w, corners - centre, spacing_m, rng) for w in sky]
    if shadow_maps:
        maps = ShadowMaps.allocate(
            centre,
            radius,
            spacing_m,
            [np.concatenate([w, e1, e2]) for w, (e1, e2, _, _) in zip(sky, grids, strict=True)],
            [(gu[0], gv[0], len(gu), len(gv)) for _, _, gu, gv in grids],
        )
    else:
        maps = ShadowMaps.none()
    # A wave's hits are counted on a thread of their own while the next wave is traced (one at a
    # time, in wave order: the SH sums add up in the order they always did).
    with ThreadPoolExecutor(1) as counter:
        counted = counter.submit(lambda: None)
        for k, (w, (e1, e2, gu, gv)) in enumerate(zip(sky, grids, strict=True)):
            base, w32 = centre + radius * w, w.astype(np.float32)
            y = sh.basis(w[None])[0].astype(np.float64)
            rows = max(1, RAYS_PER_WAVE // len(gu))  # bounded memory per call
            along = np.tile((-w).astype(np.float32), (min(rows, len(gv)) * len(gu), 1))
            for v0 in range(0, len(gv), rows):
                grid = gv[v0 : v0 + rows]
                origins = np.empty((len(grid) * len(gu), 3), np.float32)
                kernels.bundle_origins(base, e1, e2, gu, grid, origins)
                # A row-major grid of parallel rays: an image to the tracer (coherent packets). Counts,
                # not labels: where two faces tie at the closest distance, the packet's pick counts
                # (docs/scale-out.md, the bake: a few rays in a million; settling them cost 0.3 of the rays).
                res = tracer.intersect(origins, along[: len(origins)], image=(len(grid), len(gu)), settle_ties=False)
                counted.result()
                counted = counter.submit(count, res, w32, y, k, v0)
        counted.result()
    return side_hits.reshape(n_faces, 2), open_hits, sh_sums, maps


def bundle_grid(w: np.ndarray, corners: np.ndarray, spacing_m: float, rng: np.random.Generator):
    """(e1, e2, gu, gv): the axes across sky direction ``w`` and the coordinates along them of its
    bundle's rays, ``spacing_m`` apart over the box's ``corners`` (about its centre), at a random offset."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(w, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w, e1)
    u, v = corners @ e1, corners @ e2
    offset = rng.random(2) * spacing_m
    gu = np.arange(u.min() - spacing_m, u.max() + spacing_m, spacing_m) + offset[0]
    gv = np.arange(v.min() - spacing_m, v.max() + spacing_m, spacing_m) + offset[1]
    return e1, e2, gu, gv


def camera_gain(
    mesh,
    tracer: RayTracer,
    rng: np.random.Generator,
    face_probe: np.ndarray,
    n_probes: int,
    v_face: np.ndarray,
    box,
    *,
    views: int,
    rays: int,
    height_m: float,
    elevation_deg: tuple[float, float],
    prior_rays: float,
    keep_hits: bool = False,
) -> tuple[np.ndarray, SeenRays | None]:
    """(P,) per probe: the sky seen by the points of its faces that cameras see, over those face
    sides' own visible fraction (``v_face`` (F, 2)). A camera sees the parts of a leaf or a fence
    that open toward it, and they see more sky than the face's average (hedges: 0.253 at the
    pixels against 0.199 over their faces), which one value per face cannot hold. ``views``
    cameras stand ``height_m`` over random walkable points of the garden (grass, ground or
    pavement with nothing above) and trace ``rays`` rays each at random headings within the rig's
    elevations; from each point hit, one cosine ray tests the sky. Each probe's escapes over its
    sampled sides' visible fractions, shrunk toward 1 by ``prior_rays`` pseudo-rays (at least
    ``MIN_SEEN_V`` visible) and capped at ``MAX_SEEN_GAIN``; 1 where no camera ray lands. With
    ``keep_hits``, the sky rays are closest-hit rays, and what the blocked ones met is returned for
    :func:`bounce.camera_bounce` (else None)."""
    from eden_pipe import labels

    lo, hi = box
    n_sides = 2 * len(face_probe)
    top = np.column_stack([lo[:2] + rng.random((views, 2)) * (hi[:2] - lo[:2]), np.full(views, hi[2] + 1.0)])
    down = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (views, 1))
    floor = tracer.intersect(top.astype(np.float32), down)
    walkable = floor.hit & np.isin(
        np.take(mesh.semantic, np.maximum(floor.prim, 0)), [labels.GRASS, labels.GROUND, labels.PAVEMENT]
    )
    eyes = top[walkable] - np.column_stack([np.zeros((walkable.sum(), 2)), floor.t[walkable] - height_m])
    count, escapes = np.zeros(n_sides, np.int32), np.zeros(n_sides, np.int32)
    kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    for first in range(0, len(eyes), per_wave):
        n = len(eyes[first : first + per_wave]) * rays
        yaw = rng.random(n) * 2.0 * np.pi
        pitch = rng.random(n)
        d = np.empty((n, 3), np.float32)
        tracer.map_chunks(partial(headings, yaw, pitch, elevation_deg, d), n)
        res = tracer.intersect(np.repeat(eyes[first : first + per_wave].astype(np.float32), rays, axis=0), d)
        h = np.flatnonzero(res.hit)
        back = vec.dot(res.normal[h], d[h]) > 0  # the ray meets side 1
        u1 = rng.random(len(h))
        r, phi = np.sqrt(u1), 2.0 * np.pi * rng.random(len(h))
        rc, rs = r * np.cos(phi), r * np.sin(phi)
        origins, sky = np.empty((len(h), 3), np.float32), np.empty((len(h), 3), np.float32)
        tracer.map_chunks(
            partial(
                ray_kernels.camera_sky_rays, h, res.prim, back, res.t, d, eyes, first, rays,
                mesh.vertices, mesh.faces, rc, rs, u1, EPS, origins, sky,
            ),
            len(h),
        )  # fmt: skip
        sides = res.prim[h] * 2 + back
        if keep_hits:
            met = tracer.intersect(origins, sky)
            free = ~met.hit
            b = np.flatnonzero(met.hit)
            start = np.take(sides, b)
            kept.append(
                (
                    np.take(face_probe.reshape(-1), start).astype(np.int32),
                    np.take(met.prim, b).astype(np.int32),
                    vec.dot(vec.gather(met.normal, b), vec.gather(sky, b)) > 0,
                )
            )
        else:
            free = ~tracer.occluded(origins, sky)
        kernels.count_sides(sides, free, count, escapes)
    seen, expected, samples = kernels.camera_sums(face_probe, count, escapes, v_face, n_probes)
    prior = prior_rays * np.maximum(expected / np.maximum(samples, 1e-12), MIN_SEEN_V)
    gain = np.minimum((seen + prior) / (expected + prior), MAX_SEEN_GAIN)
    if not keep_hits:
        return gain, None
    if not kept:
        return gain, SeenRays(np.zeros(0, np.int32), np.zeros(0, np.int32), np.zeros(0, bool), samples)
    probe, face, side = (np.concatenate(column) for column in zip(*kept, strict=True))
    return gain, SeenRays(probe, face, side, samples)


def headings(yaw, pitch, elevation_deg, out, start: int, stop: int) -> None:
    """``camera_gain``'s ray directions ``start:stop`` (float32, into ``out``) from their headings
    ``yaw`` and uniforms ``pitch`` over the rig's elevations (degrees)."""
    up = np.radians(elevation_deg[0] + (elevation_deg[1] - elevation_deg[0]) * pitch[start:stop])
    out[start:stop, 0] = np.cos(up) * np.cos(yaw[start:stop])
    out[start:stop, 1] = np.cos(up) * np.sin(yaw[start:stop])
    out[start:stop, 2] = np.sin(up)


def bounce_rays(mesh, tracer: RayTracer, rng, areas, face_probe, n_probes: int, rays: int):
    """The probes' bounce rays: ``rays`` cosine rays each from area-sampled points of its face sides
    (all rays of a wave in one tracer call). Returns (the face each ray hit (P, rays) int32, -1 where
    it escaped; the hit side facing the probe (P, rays), 1 where the ray runs along the hit face's
    winding normal; the mean albedo the rays hit (P, 3))."""
    order, first = kernels.sides_by_probe(face_probe, n_probes)  # the face sides probe by probe
    last = np.append(first[1:], len(order)) - 1
    blocked_albedo = np.zeros((n_probes, 3))
    hit_face = np.full((n_probes, rays), -1, np.int32)
    hit_back = np.zeros((n_probes, rays), bool)
    probes_per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    area_so_far = 0.0  # the side areas summed over the probes before the wave's (one cumulative sum)
    for p0 in range(0, n_probes if rays else 0, probes_per_wave):
        p1 = min(n_probes, p0 + probes_per_wave)
        n = p1 - p0
        # The wave's probes' sides and their cumulative area, from the sum so far: the values a
        # cumulative sum over every side holds there, without that (2F,) table.
        sides = order[first[p0] : last[p1 - 1] + 1]
        cum_area = kernels.cumulative_side_area(sides, areas, area_so_far)
        wave_first, wave_last = first[p0:p1] - first[p0], last[p0:p1] - first[p0]
        area_before = np.where(first[p0:p1] > 0, np.concatenate([[area_so_far], cum_area])[wave_first], 0.0)
        span = cum_area[wave_last] - area_before
        area_so_far = cum_area[-1]
        pick = rng.random(n * rays)
        r1, r2 = rng.random(n * rays), rng.random(n * rays)
        u1, rc, rs = ray_kernels.stratified_disc(n, rays, rng, tracer.map_chunks)
        origins, dirs = np.empty((n * rays, 3), np.float32), np.empty((n * rays, 3), np.float32)
        tracer.map_chunks(
            partial(
                ray_kernels.probe_rays, np.arange(n), rays, pick, area_before, span, cum_area, wave_first, wave_last,
                sides, mesh.faces, mesh.vertices, r1, r2, rc, rs, u1, EPS, origins, dirs,
            ),
            n * rays,
        )  # fmt: skip
        res = tracer.intersect(origins, dirs)
        ray_kernels.blocked_albedo_sum(res.prim, mesh.albedo, n, rays, blocked_albedo, p0)
        hit_face[p0:p1] = np.where(res.hit, res.prim, -1).reshape(n, rays)
        # The hit face's side that faces the ray's origin: 1 when the ray travels along its winding normal.
        hit_back[p0:p1] = (vec.dot(res.normal, dirs) > 0).reshape(n, rays)
    blocked_albedo /= max(rays, 1)
    return hit_face, hit_back, blocked_albedo


def flat_outside(mesh, covered: np.ndarray) -> np.ndarray:
    """(K,) the flat faces (normal within 2.6 degrees of vertical) outside the bundles' box:
    the land the ground map lights."""
    outside = np.flatnonzero(~covered)
    return outside[np.abs(kernels.face_normals(mesh.vertices, mesh.faces, outside)[:, 2]) > 0.999]


def float32_rows(probe_rows: np.ndarray, node_rows: np.ndarray | None) -> np.ndarray:
    """The probes' rows then the ground map's nodes' (None: none) in one float32 table: the values
    of the float64 rows joined and cast whole, without that joined table."""
    nodes = 0 if node_rows is None else len(node_rows)
    table = np.empty((len(probe_rows) + nodes, probe_rows.shape[1]), np.float32)
    table[: len(probe_rows)] = probe_rows
    if node_rows is not None:
        table[len(probe_rows) :] = node_rows
    return table


# The bake's parallelism is the tracer's pool (``RayTracer.map_chunks``) and the bundles' counting
# thread: BLAS workers under them only oversubscribe the cores, spinning after each small (N, 3)
# product (the bounce transfer took 6.1 s of CPU for 1.8 s of work on 2 cores; docs/scale-out.md,
# the bake). A product's values do not depend on BLAS's thread count (tests/test_bake_kernels.py).
@threadpool_limits.wrap(limits=1, user_api="blas")
def bake(
    mesh,
    tracer: RayTracer,
    rng: np.random.Generator,
    *,
    directions: int,
    spacing_m: float,
    rays: int,
    cell_m: float,
    cell_height_m: float,
    ground_cell_m: float = 0.5,
    ground_reach_m: float = 30.0,
    ground_rays: int = 128,
    camera_views: int = 0,
    camera_rays: int = 4096,
    camera_height_m: float = 0.8,
    camera_elevation_deg: tuple[float, float] = (-31.0, 11.0),
    lightmap_cell_m: float = 0.0,
    lightmap_rays: int = 128,
    sun_multi_bounce: bool = False,
    seen_bounce: bool = False,
    fast_rays: bool = False,
    shadow_maps: bool = False,
    face_sky: bool = False,
    face_sky_moments: bool = False,
    prior_hits: float = 32.0,
    part_prior_hits: float = 64.0,
    prior_rays: float = 8.0,
    gain_prior_rays: float = 64.0,
) -> SkyVisibility:
    """The bake (see the module doc): the sky transfer from outside-in ray bundles, the bounce from
    ``rays`` cosine rays per probe (all rays of a wave in one Embree call); with ``camera_views``,
    each face side's exposure is scaled to the sky of the points of it that cameras see
    (:func:`camera_gain`, shrunk toward 1 by ``gain_prior_rays`` pseudo-rays; the seen bounce by
    ``prior_rays``); with ``lightmap_cell_m``, faces wider than a cell get a lightmap
    (:mod:`eden_pipe.render.lightmap`). With ``fast_rays``, the tracer's scene is built again
    without Embree's robust flag after the camera gain (``RayTracer.rebuild``; it is left so): the
    lightmaps', bounce and ground map's rays cost less, while the bundles and the camera gain,
    which thin blades' edges would sway, stay watertight (docs/scale-out.md, the bake). With
    ``shadow_maps``, the bundles' first-hit distances are kept as depth maps for each point's own
    visible sky at render time (:mod:`eden_pipe.render.visibility.shadow_maps`); with ``face_sky``,
    they are read once here at three points of every face side, which a render blends at each hit
    (:func:`eden_pipe.render.visibility.face_sky.face_sky_table`; with ``face_sky_moments`` also
    the directions each side sees the sky in, to order 2), and dropped unless kept."""
    from eden_pipe import labels

    run = tracer.map_chunks
    normals, areas, centroids = face_frames(mesh, run)
    n_faces = len(normals)
    face_probe, n_probes = assign_probes(normals, centroids, mesh.translucency <= 0, cell_m, cell_height_m, run)
    del centroids

    # Sky transfer, outside-in, over the garden's box; faces outside it (the skirt of distant ground)
    # get a ground map (``ground_map``) where they are flat, else the open sky.
    garden = mesh.semantic != labels.BACKGROUND
    pad = 0.01
    if np.any(garden):
        used_lo, used_hi = kernels.garden_bounds(mesh.vertices, mesh.faces, garden)
        box = (used_lo.astype(np.float64) - pad, used_hi.astype(np.float64) + pad)
        covered = kernels.faces_inside(mesh.vertices, mesh.faces, *box)
    else:
        box, covered = None, np.zeros(n_faces, bool)
    del garden
    mean_normal, probe_covered = kernels.probe_frames(face_probe, areas, normals, covered, n_probes)
    mean_normal = vec.normalize(mean_normal, 1e-12)
    # Past here the bake makes a face's normal where it needs it (kernels.face_normal): no table.
    del normals
    hits = np.zeros((n_faces, 2), np.int32)
    open_hits = np.zeros((n_faces, 2))
    sh_sums = np.zeros((n_probes, sh.COUNT))
    maps = ShadowMaps.none()
    if box is not None:
        hits, open_hits, sh_sums, maps = sky_hits(
            mesh, tracer, areas, face_probe, n_probes, box, rng,
            directions=directions, spacing_m=spacing_m, shadow_maps=shadow_maps or face_sky,
        )  # fmt: skip
    sides_sky = np.zeros((0, 2, FACE_SKY_POINTS), np.uint16)
    if face_sky and maps.present:
        sides_sky = face_sky_table(maps, mesh.vertices, mesh.faces, run, face_sky_moments)
    if not shadow_maps:
        maps = ShadowMaps.none()
    hits[~covered], open_hits[~covered] = 0, 0.0
    probe_hits, probe_open = kernels.probe_hit_sums(face_probe, hits, open_hits, n_probes)
    # T_p = area-weighted mean transfer of the probe's covered sides: hits * spacing^2 / area * 2/J
    transfer = sh_sums
    transfer *= spacing_m**2 * 2.0 / max(directions, 1)
    transfer /= np.maximum(probe_covered, 1e-12)[:, None]
    uncovered = probe_covered <= 0
    transfer[uncovered] = sh.open_transfer(mean_normal[uncovered].astype(np.float32))
    visible = np.where(probe_open > 0, probe_hits / np.maximum(probe_open, 1e-12), 1.0)
    # Each side's own cosine-weighted visible sky (its hit fraction, times its own open-sky factor
    # 2/J sum cos+), as a ratio to its probe's transfer: the probe gives the shape, the face the amount.
    # Few rays reach a small face, so its fraction is shrunk toward its part's within the probe (the
    # faces it shares vertices with: a leaf, a blade) by ``part_prior_hits`` pseudo-hits, and the
    # part's toward the probe's by ``prior_hits``; with no part prior, the side's straight toward the
    # probe's (docs/realism.md, the bake).
    probe_visible = transfer[:, 0] / sh.basis(np.zeros((1, 3)))[0, 0]
    open_scale = spacing_m**2 * 2.0 / max(directions, 1)
    if part_prior_hits > 0:
        keys = kernels.part_probe_keys(kernels.mesh_parts(mesh.faces, len(mesh.vertices)), face_probe, n_probes)
        group, n_groups = kernels.unique_inverse(keys)
        del keys
        v_face = kernels.pooled_visible_sky(
            hits, open_hits, areas, face_probe, visible, group, n_groups, open_scale, prior_hits, part_prior_hits
        )
        del group
    else:
        v_face = kernels.visible_sky(hits, open_hits, areas, face_probe, visible, open_scale, prior_hits)
    del hits, open_hits
    release_free_memory()  # between phases: what they freed goes back (eden_pipe.heap)
    # What the render reads: the camera's share of each side. The bounce below keeps the plain
    # exposure (the points random bounce rays meet are not drawn by a camera).
    gain, seen = None, None
    if camera_views > 0 and box is not None:
        gain, seen = camera_gain(
            mesh,
            tracer,
            rng.spawn(1)[0],
            face_probe,
            n_probes,
            v_face,
            box,
            views=camera_views,
            rays=camera_rays,
            height_m=camera_height_m,
            elevation_deg=camera_elevation_deg,
            prior_rays=gain_prior_rays,
            keep_hits=seen_bounce,
        )
    exposure = kernels.side_exposure(v_face, face_probe, probe_visible, covered)
    del v_face
    release_free_memory()
    if gain is None:
        seen_exposure = exposure.astype(np.float32)
    else:
        seen_exposure = kernels.seen_exposure(exposure, gain, face_probe, probe_visible, covered)
    if fast_rays and tracer.robust:
        tracer.rebuild(robust=False)
    # Its own generator (after camera_gain's): the bounce and ground map below draw what they drew without it.
    lightmaps = bake_lightmaps(
        mesh, tracer, rng.spawn(1)[0], areas, covered, cell_m=lightmap_cell_m, rays=lightmap_rays
    )
    release_free_memory()
    hit_face, hit_back, blocked_albedo = bounce_rays(mesh, tracer, rng, areas, face_probe, n_probes, rays)
    release_free_memory()
    multi = 1.0 / (1.0 - np.minimum(blocked_albedo, MAX_BLOCKED_ALBEDO))
    bounce, sun_bounce, tint = bounce_transfer(
        mesh, hit_face, hit_back, multi, face_probe, transfer, exposure, run, sun_multi=sun_multi_bounce
    )
    del hit_face, hit_back
    release_free_memory()
    if seen is not None:  # what lights the points cameras see (the ground map below keeps the probes' own)
        camera_bounce(mesh, seen, multi, face_probe, transfer, exposure, bounce, sun_bounce, prior_rays, tint, run)
        del seen
    ground = ground_map(
        mesh,
        tracer,
        rng,
        flat_outside(mesh, covered) if box is not None else np.zeros(0, np.int64),
        box,
        face_probe,
        transfer,
        exposure,
        multi,
        map_chunks=run,
        sun_multi=sun_multi_bounce,
        rays=ground_rays,
        cell_m=ground_cell_m,
        reach_m=ground_reach_m,
    )
    del areas, exposure, covered, multi
    release_free_memory()
    # Each table cast to float32 on its own, the ground map's nodes after the probes, and let go of.
    rows = {"transfer": transfer, "normal": mean_normal, "bounce": bounce, "sun_bounce": sun_bounce, "tint": tint}
    del transfer, mean_normal, bounce, sun_bounce, tint
    transfer32, normal32, bounce32, sun_bounce32, tint32 = (
        float32_rows(rows.pop(name), getattr(ground, name, None))
        for name in ("transfer", "normal", "bounce", "sun_bounce", "tint")
    )
    return SkyVisibility(
        face_probe,
        seen_exposure,
        transfer32,
        normal32,
        bounce32,
        sun_bounce32,
        tint32,
        *(ground.grid_fields(n_probes) if ground is not None else GroundGrid.none()),
        lightmaps,
        maps,
        sides_sky,
    )
