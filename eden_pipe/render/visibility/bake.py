"""The bake: a garden's :class:`SkyVisibility` from outside-in ray bundles, probes and their bounce.

Once per garden (stage ``sky_visibility``), lighting-free; see
:mod:`eden_pipe.render.visibility` for the method.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.render import sh, vec
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.lightmap import bake_lightmaps
from eden_pipe.render.visibility import EPS, RAYS_PER_WAVE
from eden_pipe.render.visibility.bounce import bounce_transfer
from eden_pipe.render.visibility.ground_map import GroundGrid, ground_map
from eden_pipe.render.visibility.store import SkyVisibility, exposure_of

MAX_BLOCKED_ALBEDO = 0.8  # caps the multi-bounce factor 1/(1 - a)
MIN_SEEN_V = 0.05  # the least mean visible fraction camera_gain's pseudo-rays assume (no gain from nothing)
MAX_SEEN_GAIN = 3.0  # camera_gain's cap


def face_frames(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit normals (F, 3) along the winding, areas (F,), centroids (F, 3)), float64."""
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cross = np.cross(b - a, c - a)
    area2 = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(area2, 1e-30)[:, None]
    return normals, 0.5 * area2, (a + b + c) / 3.0


def assign_probes(
    normals: np.ndarray, centroids: np.ndarray, opaque: np.ndarray, cell_m: float, cell_height_m: float
) -> tuple[np.ndarray, int]:
    """(face_probe (F, 2) int32, probe count): probe = (cell, major axis of the side normal, and
    for opaque faces which side: the inside of a closed solid never shares a probe with an outside)."""
    n_faces = len(normals)
    cell = np.floor(centroids / np.array([cell_m, cell_m, cell_height_m])).astype(np.int64)
    if n_faces:
        cell -= cell.min(axis=0)
    span = cell.max(axis=0) + 1 if n_faces else np.ones(3, np.int64)
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


def sky_directions(count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) directions over the upper hemisphere, stratified in (cos theta, phi): equal solid angles."""
    # rows x cols strata of equal solid angle, exactly ``count`` of them (a partial row would bias the estimate)
    rows = min((r for r in range(1, count + 1) if count % r == 0), key=lambda r: abs(r - np.sqrt(count / 2)))
    cols = count // rows
    k = np.arange(count)
    z = (k // cols + rng.random(count)) / rows
    phi = 2.0 * np.pi * (k % cols + rng.random(count)) / cols
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def sky_hits(
    mesh,
    tracer: RayTracer,
    normals: np.ndarray,
    areas: np.ndarray,
    face_probe: np.ndarray,
    n_probes: int,
    box: tuple[np.ndarray, np.ndarray],
    rng: np.random.Generator,
    *,
    directions: int,
    spacing_m: float,
):
    """Outside-in visibility: for each sky direction, a grid of parallel rays (``spacing_m`` apart)
    enters ``box`` from that direction; a face side is hit by about ``V area cos / spacing^2`` of
    them. Returns (hits (F, 2), expected hits if nothing occluded (F, 2), per-probe SH sums (P, 16))."""
    lo, hi = box
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2) + 1.0
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    n_faces = len(normals)
    hits = np.zeros(2 * n_faces)
    open_hits = np.zeros((n_faces, 2))
    sh_sums = np.zeros((n_probes, sh.COUNT))
    probe_of_side = face_probe.ravel()
    for w in sky_directions(directions, rng):
        helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(w, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(w, e1)
        u, v = (corners - centre) @ e1, (corners - centre) @ e2
        offset = rng.random(2) * spacing_m
        gu = np.arange(u.min() - spacing_m, u.max() + spacing_m, spacing_m) + offset[0]
        gv = np.arange(v.min() - spacing_m, v.max() + spacing_m, spacing_m) + offset[1]
        cos = normals @ w
        open_hits[:, 0] += np.maximum(cos, 0.0)
        open_hits[:, 1] += np.maximum(-cos, 0.0)
        for v0 in range(0, len(gv), max(1, RAYS_PER_WAVE // len(gu))):  # bounded memory per call
            V, U = np.meshgrid(gv[v0 : v0 + max(1, RAYS_PER_WAVE // len(gu))], gu, indexing="ij")
            origins = (centre + radius * w + U.reshape(-1, 1) * e1 + V.reshape(-1, 1) * e2).astype(np.float32)
            # A row-major grid of parallel rays: an image to the tracer (coherent packets, same hits).
            res = tracer.intersect(origins, (-w).astype(np.float32)[None].repeat(len(origins), 0), image=V.shape)
            prim = res.prim[res.hit]
            side = (res.normal[res.hit] @ w.astype(np.float32) < 0).astype(np.int64)  # 1: hit from behind the winding
            key = prim * 2 + side
            counts = np.bincount(key, minlength=2 * n_faces)
            hits += counts
            touched = np.nonzero(counts)[0]
            y = sh.basis(w[None])[0].astype(np.float64)
            sh_sums += np.bincount(probe_of_side[touched], weights=counts[touched], minlength=n_probes)[:, None] * y
    open_hits *= (areas / spacing_m**2)[:, None]
    return hits.reshape(n_faces, 2), open_hits, sh_sums


def camera_gain(
    mesh,
    tracer: RayTracer,
    rng: np.random.Generator,
    normals: np.ndarray,
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
) -> np.ndarray:
    """(P,) per probe: the sky seen by the points of its faces that cameras see, over those face
    sides' own visible fraction (``v_face`` (F, 2)). A camera sees the parts of a leaf or a fence
    that open toward it, and they see more sky than the face's average (hedges: 0.253 at the
    pixels against 0.199 over their faces), which one value per face cannot hold. ``views``
    cameras stand ``height_m`` over random walkable points of the garden (grass, ground or
    pavement with nothing above) and trace ``rays`` rays each at random headings within the rig's
    elevations; from each point hit, one cosine ray tests the sky. Each probe's escapes over its
    sampled sides' visible fractions, shrunk toward 1 by ``prior_rays`` pseudo-rays (at least
    ``MIN_SEEN_V`` visible) and capped at ``MAX_SEEN_GAIN``; 1 where no camera ray lands."""
    from eden_pipe import labels
    from eden_pipe.render.pathtrace import cosine_directions

    lo, hi = box
    n_sides = 2 * len(normals)
    top = np.column_stack([lo[:2] + rng.random((views, 2)) * (hi[:2] - lo[:2]), np.full(views, hi[2] + 1.0)])
    down = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (views, 1))
    floor = tracer.intersect(top.astype(np.float32), down)
    walkable = floor.hit & np.isin(
        np.take(mesh.semantic, np.maximum(floor.prim, 0)), [labels.GRASS, labels.GROUND, labels.PAVEMENT]
    )
    eyes = top[walkable] - np.column_stack([np.zeros((walkable.sum(), 2)), floor.t[walkable] - height_m])
    count, escapes = np.zeros(n_sides), np.zeros(n_sides)
    per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    for first in range(0, len(eyes), per_wave):
        origin = np.repeat(eyes[first : first + per_wave], rays, axis=0)
        yaw = rng.random(len(origin)) * 2.0 * np.pi
        up = np.radians(elevation_deg[0] + (elevation_deg[1] - elevation_deg[0]) * rng.random(len(origin)))
        d = np.column_stack([np.cos(up) * np.cos(yaw), np.cos(up) * np.sin(yaw), np.sin(up)]).astype(np.float32)
        res = tracer.intersect(origin.astype(np.float32), d)
        h = np.flatnonzero(res.hit)
        dh = d[h]
        back = vec.dot(res.normal[h], dh) > 0  # the ray meets side 1
        side_normal = normals[res.prim[h]] * np.where(back, -1.0, 1.0)[:, None]
        points = origin[h] + dh * res.t[h, None]
        sky = cosine_directions(side_normal, rng.random(len(h)), rng.random(len(h)))
        free = ~tracer.occluded((points + side_normal * EPS).astype(np.float32), sky)
        side = res.prim[h] * 2 + back
        count += np.bincount(side, minlength=n_sides)
        escapes += np.bincount(side, weights=free, minlength=n_sides)
    probe = face_probe.ravel()
    seen = np.bincount(probe, weights=escapes, minlength=n_probes)
    expected = np.bincount(probe, weights=count * v_face.ravel(), minlength=n_probes)
    samples = np.bincount(probe, weights=count, minlength=n_probes)
    prior = prior_rays * np.maximum(expected / np.maximum(samples, 1e-12), MIN_SEEN_V)
    return np.minimum((seen + prior) / (expected + prior), MAX_SEEN_GAIN)


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
    prior_hits: float = 4.0,
    prior_rays: float = 8.0,
) -> SkyVisibility:
    """The bake (see the module doc): the sky transfer from outside-in ray bundles, the bounce from
    ``rays`` cosine rays per probe (all rays of a wave in one Embree call); with ``camera_views``,
    each face side's exposure is scaled to the sky of the points of it that cameras see
    (:func:`camera_gain`); with ``lightmap_cell_m``, faces wider than a cell get a lightmap
    (:mod:`eden_pipe.render.lightmap`)."""
    from eden_pipe import labels

    normals, areas, centroids = face_frames(mesh)
    n_faces = len(normals)
    opaque = mesh.translucency <= 0
    face_probe, n_probes = assign_probes(normals, centroids, opaque, cell_m, cell_height_m)
    side_area = np.repeat(areas, 2)
    sign = np.array([1.0, -1.0])
    mean_normal = np.zeros((n_probes, 3))
    for k in range(3):
        mean_normal[:, k] = np.bincount(
            face_probe.ravel(), weights=side_area * np.outer(normals[:, k], sign).ravel(), minlength=n_probes
        )
    mean_normal = vec.normalize(mean_normal, 1e-12)

    # Sky transfer, outside-in, over the garden's box; faces outside it (the skirt of distant ground)
    # get a ground map (``ground_map``) where they are flat, else the open sky.
    garden = mesh.semantic != labels.BACKGROUND
    pad = 0.01
    if np.any(garden):
        used = mesh.vertices[mesh.faces[garden].ravel()]
        box = (used.min(axis=0).astype(np.float64) - pad, used.max(axis=0).astype(np.float64) + pad)
        v = mesh.vertices[mesh.faces]
        covered = np.all((v >= box[0]) & (v <= box[1]), axis=(1, 2))
    else:
        box, covered = None, np.zeros(n_faces, bool)
    hits = np.zeros((n_faces, 2))
    open_hits = np.zeros((n_faces, 2))
    sh_sums = np.zeros((n_probes, sh.COUNT))
    if box is not None:
        hits, open_hits, sh_sums = sky_hits(
            mesh, tracer, normals, areas, face_probe, n_probes, box, rng, directions=directions, spacing_m=spacing_m
        )
    hits[~covered], open_hits[~covered] = 0.0, 0.0
    probe_hits = np.bincount(face_probe.ravel(), weights=hits.ravel(), minlength=n_probes)
    probe_open = np.bincount(face_probe.ravel(), weights=open_hits.ravel(), minlength=n_probes)
    probe_covered = np.bincount(face_probe.ravel(), weights=np.repeat(covered, 2) * side_area, minlength=n_probes)
    # T_p = area-weighted mean transfer of the probe's covered sides: hits * spacing^2 / area * 2/J
    transfer = sh_sums * (spacing_m**2 * 2.0 / max(directions, 1)) / np.maximum(probe_covered, 1e-12)[:, None]
    uncovered = probe_covered <= 0
    transfer[uncovered] = sh.open_transfer(mean_normal[uncovered].astype(np.float32))
    visible = np.where(probe_open > 0, probe_hits / np.maximum(probe_open, 1e-12), 1.0)
    # Each side's own cosine-weighted visible sky (its hit fraction, shrunk toward its probe's by
    # ``prior_hits`` pseudo-hits where few rays reach a tiny face, times its own open-sky factor
    # 2/J sum cos+), as a ratio to its probe's transfer: the probe gives the shape, the face the amount.
    v_probe = visible[face_probe]
    open_factor = open_hits * (spacing_m**2 * 2.0 / max(directions, 1)) / np.maximum(areas, 1e-12)[:, None]
    v_face = (hits + prior_hits * v_probe) / (open_hits + prior_hits) * open_factor
    probe_visible = transfer[:, 0] / sh.basis(np.zeros((1, 3)))[0, 0]
    exposure = exposure_of(v_face, probe_visible[face_probe])
    exposure[~covered] = 1.0
    # What the render reads: the camera's share of each side. The bounce below keeps the plain
    # exposure (the points random bounce rays meet are not drawn by a camera).
    seen_exposure = exposure
    if camera_views > 0 and box is not None:
        gain = camera_gain(
            mesh,
            tracer,
            rng.spawn(1)[0],
            normals,
            face_probe,
            n_probes,
            v_face,
            box,
            views=camera_views,
            rays=camera_rays,
            height_m=camera_height_m,
            elevation_deg=camera_elevation_deg,
            prior_rays=prior_rays,
        )
        limit = 1.0 / np.maximum(probe_visible[face_probe], 1e-6)  # a side sees at most all of its sky
        seen_exposure = np.where(covered[:, None], np.minimum(exposure * gain[face_probe], limit), 1.0)
    # Its own generator (after camera_gain's): the bounce and ground map below draw what they drew without it.
    lightmaps = bake_lightmaps(
        mesh, tracer, rng.spawn(1)[0], normals, areas, covered, cell_m=lightmap_cell_m, rays=lightmap_rays
    )

    # Bounce: cosine rays from each probe; what the blocked ones hit, lit as that face side is lit.
    blocked_albedo = np.zeros((n_probes, 3))
    sides = np.argsort(face_probe.ravel(), kind="stable")
    side_probe = face_probe.ravel()[sides]
    cum_area = np.cumsum(np.maximum(side_area[sides], 1e-12))
    first = np.searchsorted(side_probe, np.arange(n_probes))
    last = np.append(first[1:], len(sides)) - 1
    area_before = np.where(first > 0, cum_area[np.maximum(first - 1, 0)], 0.0)
    span = cum_area[last] - area_before
    hit_face = np.full((n_probes, rays), -1, np.int32)
    hit_back = np.zeros((n_probes, rays), bool)
    probes_per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    from eden_pipe.render.pathtrace import cosine_directions, stratified_uniforms

    for p0 in range(0, n_probes if rays else 0, probes_per_wave):
        probes = np.arange(p0, min(n_probes, p0 + probes_per_wave))
        n = len(probes)
        tiled = np.tile(probes, rays)
        target = area_before[tiled] + rng.random(len(tiled)) * span[tiled]
        member = np.clip(np.searchsorted(cum_area, target), first[tiled], last[tiled])
        face, back = sides[member] // 2, sides[member] % 2 == 1
        side_normal = normals[face] * np.where(back, -1.0, 1.0)[:, None]
        r1, r2 = rng.random(len(face)), rng.random(len(face))
        s1 = np.sqrt(r1)
        tri = mesh.faces[face]
        vtx = mesh.vertices
        point = (
            (1 - s1)[:, None] * vtx[tri[:, 0]]
            + (s1 * (1 - r2))[:, None] * vtx[tri[:, 1]]
            + (s1 * r2)[:, None] * vtx[tri[:, 2]]
        )
        u1, u2 = stratified_uniforms(n, 0, rays, rays, rng)
        dirs = cosine_directions(side_normal, u1.ravel(), u2.ravel())
        res = tracer.intersect((point + side_normal * EPS).astype(np.float32), dirs)
        alb = mesh.albedo[np.where(res.hit, res.prim, 0)] * res.hit[:, None]
        for k in range(3):
            blocked_albedo[probes, k] += np.bincount(tiled - p0, weights=alb[:, k], minlength=n)
        hit_face[probes] = np.where(res.hit, res.prim, -1).reshape(rays, n).T
        # The hit face's side that faces the ray's origin: 1 when the ray travels along its winding normal.
        hit_back[probes] = (vec.dot(res.normal, dirs) > 0).reshape(rays, n).T
    blocked_albedo /= max(rays, 1)
    multi = 1.0 / (1.0 - np.minimum(blocked_albedo, MAX_BLOCKED_ALBEDO))
    bounce, tint = bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure)
    ground = ground_map(
        mesh,
        tracer,
        rng,
        normals,
        covered,
        box,
        face_probe,
        transfer,
        exposure,
        multi,
        rays=ground_rays,
        cell_m=ground_cell_m,
        reach_m=ground_reach_m,
    )
    if ground is not None:
        transfer, mean_normal = (
            np.concatenate([transfer, ground.transfer]),
            np.concatenate([mean_normal, ground.normal]),
        )
        bounce, tint = np.concatenate([bounce, ground.bounce]), np.concatenate([tint, ground.tint])
    return SkyVisibility(
        face_probe,
        seen_exposure.astype(np.float32),
        transfer.astype(np.float32),
        mean_normal.astype(np.float32),
        bounce.astype(np.float32),
        tint.astype(np.float32),
        *(ground.grid_fields(n_probes) if ground is not None else GroundGrid.none()),
        lightmaps,
    )
