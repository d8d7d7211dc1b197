"""The reference renderer (``render.mode=reference``): converged multi-bounce path tracing.

It writes the same intrinsic passes by the same formula as the default
(:func:`eden_pipe.render.shading.compose`): at each primary hit, shading =
Ddir + Dind is the total irradiance/pi on the side facing the viewer,
translucency = Dcol * t * (irradiance/pi behind the face), glossy = the sun
lobe plus the radiance arriving along the mirror direction. Only the light
differs from the default:

- the sun's disc is sampled (next-event estimation) at every vertex of a path,
  cloud shadows included;
- ``reference_samples`` paths per pixel and side (stratified cosine directions
  at the first bounce), each up to ``reference_bounces`` diffuse or
  translucent bounces (a vertex reflects with probability 1/(1+t) and transmits
  with t/(1+t), weight albedo*(1+t)), Russian roulette after the second;
- rays that leave the scene see the sky's radiance (the same environment the
  default's ambient and visibility transfer integrate; distant scenery is
  background only, as in the default);
- the mirror direction of glossy faces is traced, not assumed open.

Wavefront style: every path of a bounce is in one Embree call. Slow, and
exists to measure the default against (``benchmarks/realism.py``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from eden_pipe.render import vec
from eden_pipe.render.embree import Hits, RayTracer
from eden_pipe.render.offsets import OFFSET_M, leave
from eden_pipe.render.shading import (
    LAYERS,
    ShadingSettings,
    background_of,
    compose,
    direct_sun,
    glossy_parts,
    primary_surface,
    sun_directions,
)
from eden_pipe.render.textures import apply_terrain_textures

PATHS_PER_WAVE = 1 << 18  # paths traced together (bounds memory; every bounce of a wave is one Embree call)
# Sun-disc samples for the primary hit's direct light: one for every 8 paths, at least 16. Where the disc is
# partly hidden (a penumbra) 16 samples alone leave 10-25 % of noise in a pixel's sun light, which the
# paths' count does not average away (docs/realism.md, The glossy light).
SUN_SAMPLES_PRIMARY = 16
SUN_SAMPLES_PER_PATHS = 8
ROULETTE_AFTER = 2  # bounces before Russian roulette may end a path
# Secondary rays leave surfaces by render.offsets.leave; a ray that still meets the face it leaves is
# traced on from just past that hit (intersect_leaving).


def cosine_directions(n: np.ndarray, u1: np.ndarray, u2: np.ndarray) -> np.ndarray:
    """Cosine-distributed directions about unit normals ``n`` (N, 3) from uniforms u1, u2 (N,)."""
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    t, b = vec.orthonormal_basis(n.astype(np.float64))
    d = (
        t * (r * np.cos(phi))[:, None]
        + b * (r * np.sin(phi))[:, None]
        + n * np.sqrt(np.maximum(0.0, 1.0 - u1))[:, None]
    )
    return d.astype(np.float32)


def intersect_leaving(tracer: RayTracer, o: np.ndarray, d: np.ndarray, own: np.ndarray) -> Hits:
    """Closest hits of rays that leave faces ``own`` (-1: none): a hit on the ray's own face (a
    plane is never met twice) is skipped by tracing on from just past it; ``t`` stays along the
    original ray."""
    hits = tracer.intersect(o, d)
    again = np.nonzero((hits.prim == own) & (own >= 0))[0]
    if len(again):
        skip = hits.t[again] * np.float32(1.0 + 1e-6) + np.float32(OFFSET_M)
        more = tracer.intersect(vec.gather(o, again) + vec.gather(d, again) * skip[:, None], vec.gather(d, again))
        hits.t[again] = np.where(more.hit, more.t + skip, np.float32(np.inf))
        hits.prim[again] = more.prim
        hits.normal[again] = more.normal
    return hits


def sun_visible_leaving(tracer: RayTracer, points, normals, prim, dist):
    """``visible(idx, sign, to_sun) -> (len(idx),) bool`` for :func:`direct_sun`: shadow rays from
    the hits ``idx`` on the side ``sign`` of their geometric normal, with the robust offset, own face skipped."""

    def visible(idx: np.ndarray, sign: np.ndarray, to_sun: np.ndarray) -> np.ndarray:
        n = vec.gather(normals, idx) * sign.astype(np.float32)[:, None]
        o = leave(vec.gather(points, idx), n, np.take(dist, idx))
        d = np.broadcast_to(to_sun.astype(np.float32), o.shape)
        return ~intersect_leaving(tracer, o, np.ascontiguousarray(d), np.take(prim, idx)).hit

    return visible


def stratified_uniforms(n_points: int, first: int, count: int, total: int, rng: np.random.Generator):
    """(u1, u2), each (count, n_points): samples ``first .. first+count`` of ``total`` per point,
    jittered in a g x g grid over the unit square (g = floor(sqrt(total))), the rest uniform."""
    g = max(1, int(np.sqrt(total)))
    j = np.arange(first, first + count)[:, None]
    jitter1, jitter2 = rng.random((count, n_points)), rng.random((count, n_points))
    in_grid = j < g * g
    u1 = np.where(in_grid, (j // g + jitter1) / g, jitter1)
    u2 = np.where(in_grid, (j % g + jitter2) / g, jitter2)
    return u1, u2


def radiance_along(
    tracer: RayTracer,
    mesh,
    sky,
    settings: ShadingSettings,
    rng: np.random.Generator,
    origins: np.ndarray,
    dirs: np.ndarray,
    bounces: int,
    own: np.ndarray | None = None,
) -> np.ndarray:
    """(M, 3) radiance arriving at ``origins`` along ``dirs``: sky where a path escapes, sun by
    next-event estimation at every diffuse or translucent vertex, up to ``bounces`` vertices, each of
    which also gathers the sky along its continuation ray. That is how Cycles counts ``max_bounces``:
    its limit ends a path at the surface after the last bounce, whose own light is not gathered, so
    the light of the primary hit and of ``bounces`` vertices after it is in (docs/realism.md, Cycles)."""
    m = len(origins)
    total = np.zeros((m, 3), np.float32)
    alive = np.arange(m)
    throughput = np.ones((m, 3), np.float32)
    o, d = origins.astype(np.float32), vec.normalize(dirs.astype(np.float32))
    leaving = np.full(m, -1, np.int64) if own is None else np.asarray(own, np.int64)
    sun = np.asarray(sky.sun_irradiance, np.float32)
    has_sun = bool(np.any(sun > 0))
    for depth in range(bounces + 1):
        if not len(alive):
            break
        hits = intersect_leaving(tracer, o, d, leaving)
        hit = hits.hit
        escaped = np.nonzero(~hit)[0]
        if len(escaped):
            total[alive[escaped]] += throughput[escaped] * settings.sky_radiance(sky, vec.gather(d, escaped))
        if depth == bounces:  # the surface after the last vertex: its light is past the limit
            break
        keep = np.nonzero(hit)[0]
        alive, throughput, o, d = alive[keep], throughput[keep], o[keep], d[keep]
        prim = hits.prim[keep]
        dist = hits.t[keep]
        points = o + d * dist[:, None]
        n = vec.facing(vec.gather(hits.normal, keep), d)
        albedo, n_shade = apply_terrain_textures(np.take(mesh.material, prim), points, vec.gather(mesh.albedo, prim), n)
        trans = np.take(mesh.translucency, prim)
        if has_sun:
            to_sun = sun_directions(sky, max(2, len(points)), rng)[: len(points)].astype(np.float32)
            to_sun = np.broadcast_to(to_sun, points.shape) if len(to_sun) == 1 else to_sun  # a point sun: one direction
            cos = vec.dot(n_shade, to_sun)
            lit = np.nonzero((cos > 1e-6) | ((cos < -1e-6) & (trans > 0)))[0]
            if len(lit):
                c = cos[lit]
                side = np.sign(c).astype(np.float32)
                start = leave(vec.gather(points, lit), vec.gather(n, lit) * side[:, None], np.take(dist, lit))
                visible = ~intersect_leaving(tracer, start, vec.gather(to_sun, lit), np.take(prim, lit)).hit
                weight = np.where(c > 0, c, -c * trans[lit]) * visible
                weight = weight * settings.cloud_transmittance(sky, vec.gather(points, lit)) / np.pi
                total[alive[lit]] += (throughput[lit] * vec.gather(albedo, lit)) * (weight[:, None] * sun)
        # Continue: reflect about n with probability 1/(1+t), else transmit about -n.
        transmit = rng.random(len(points)) * (1.0 + trans) > 1.0
        side = np.where(transmit, np.float32(-1.0), np.float32(1.0))
        normal = n * side[:, None]
        d = cosine_directions(normal, rng.random(len(points)), rng.random(len(points)))
        o = leave(points, normal, dist)
        leaving = prim
        throughput = throughput * albedo * (1.0 + trans)[:, None]
        if depth + 1 >= ROULETTE_AFTER:
            survive_p = np.clip(throughput.max(axis=1), 0.1, 1.0)
            survive = np.nonzero(rng.random(len(points)) < survive_p)[0]
            alive, o, d, leaving = alive[survive], o[survive], d[survive], leaving[survive]
            throughput = vec.gather(throughput, survive) / survive_p[survive, None]
    return total


def reference_shade(
    tracer: RayTracer,
    mesh,
    hits: Hits,
    origins: np.ndarray,
    directions: np.ndarray,
    sky,
    settings: ShadingSettings,
    rng: np.random.Generator,
    layers=LAYERS,
    image_width: int | None = None,
) -> dict[str, np.ndarray]:
    """Like :func:`eden_pipe.render.shading.shade` (same keys and formula), lit by path tracing
    (``image_width`` is unused: every pixel traces its own paths)."""
    n_rays = len(origins)
    samples, bounces = int(settings.reference_samples), int(settings.reference_bounces)
    background = background_of(sky, directions, hits.hit, settings.time)
    s = primary_surface(mesh, hits, origins, directions)
    n_hit = len(s.idx)
    t_idx = np.nonzero(s.trans > 0)[0]
    g_idx = np.nonzero(s.spec > 0)[0]
    dist = hits.t[s.idx]
    front, back = direct_sun(
        tracer,
        s.points,
        s.n_shade,
        sky,
        replace(settings, soft_shadow_samples=max(SUN_SAMPLES_PRIMARY, samples // SUN_SAMPLES_PER_PATHS)),
        rng,
        geometric=s.n,
        back_lit=s.trans > 0,
        visible=sun_visible_leaving(tracer, s.points, s.n, s.prim, dist),
    )
    g_dir, mirror, mirror_weight = glossy_parts(
        vec.gather(s.n_shade, g_idx), vec.gather(s.d, g_idx), vec.gather(front, g_idx), sky
    )
    # Path starts per sample: the front side of every hit, the back of translucent hits, the mirror
    # direction of glossy hits (a fixed first segment, so it needs fewer samples).
    normals = np.concatenate([s.n, -vec.gather(s.n, t_idx)])
    starts = leave(
        np.concatenate([s.points, vec.gather(s.points, t_idx)]), normals, np.concatenate([dist, dist[t_idx]])
    )
    own = np.concatenate([s.prim, s.prim[t_idx]])
    mirror_samples = max(1, samples // 8)
    indirect = np.zeros((len(normals), 3), np.float64)
    mirrored = np.zeros((len(g_idx), 3), np.float64)
    per_wave = max(1, PATHS_PER_WAVE // max(1, len(normals)))
    for first in range(0, samples, per_wave):
        count = min(per_wave, samples - first)
        u1, u2 = stratified_uniforms(len(normals), first, count, samples, rng)
        dirs = cosine_directions(np.tile(normals, (count, 1)), u1.ravel(), u2.ravel())
        o = np.tile(starts, (count, 1))
        leaving = np.tile(own, count)
        m_count = max(0, min(count, mirror_samples - first))
        if m_count and len(g_idx):
            g_start = leave(vec.gather(s.points, g_idx), vec.gather(s.n, g_idx), dist[g_idx])
            o = np.concatenate([o, np.tile(g_start, (m_count, 1))])
            dirs = np.concatenate([dirs, np.tile(mirror, (m_count, 1))])
            leaving = np.concatenate([leaving, np.tile(s.prim[g_idx], m_count)])
        radiance = radiance_along(tracer, mesh, sky, settings, rng, o, dirs, bounces, own=leaving)
        indirect += radiance[: count * len(normals)].reshape(count, len(normals), 3).sum(axis=0)
        if m_count and len(g_idx):
            mirrored += radiance[count * len(normals) :].reshape(m_count, len(g_idx), 3).sum(axis=0)
    indirect /= max(samples, 1)
    mirrored /= mirror_samples
    shading = front + indirect[:n_hit]
    back_total = np.zeros((n_hit, 3), np.float32)
    if len(t_idx):
        back_total = vec.Scatter(t_idx, n_hit).expand((vec.gather(back, t_idx) + indirect[n_hit:]).astype(np.float32))
    gloss = np.zeros((n_hit, 3), np.float32)
    if len(g_idx):
        gloss = vec.Scatter(g_idx, n_hit).expand((g_dir + mirrored * mirror_weight[:, None]).astype(np.float32))
    return compose(n_rays, s, background, shading, back_total, gloss, layers)
