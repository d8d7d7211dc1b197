"""The bake's ray makers: numba kernels that draw its cosine rays as its numpy code drew them.

The rays of the lightmaps' and the ground map's nodes, of the probes' bounce and
of the camera gain's sky tests, from the uniforms the bake draws with numpy (in
the same order as before, so every ray is bit-identical; see
:mod:`eden_pipe.render.visibility.kernels` for the rules the kernels keep). A
node's or a probe's rays are written side by side: rays that leave one point
are a coherent batch for the tracer (twice as fast per ray in Embree as the
rays of many points interleaved, ``docs/realism.md``).
"""

from __future__ import annotations

import numpy as np

from eden_pipe.render.visibility.kernels import blocks, face_normal, kernel, np_maximum


# ------------------------------------------------------------------ cosine rays
@kernel
def tangent_frame(n0, n1, n2):
    """``vec.orthonormal_basis`` of one unit normal: (t, b) as numpy's cross and norm make them."""
    h0, h1 = (1.0, 0.0) if np.abs(n0) < 0.9 else (0.0, 1.0)
    h2 = 0.0
    t0 = n1 * h2 - n2 * h1
    t1 = n2 * h0 - n0 * h2
    t2 = n0 * h1 - n1 * h0
    length = np.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    t0, t1, t2 = t0 / length, t1 / length, t2 / length
    return t0, t1, t2, n1 * t2 - n2 * t1, n2 * t0 - n0 * t2, n0 * t1 - n1 * t0


@kernel
def cosine_ray(n0, n1, n2, rc, rs, lift, out, j):
    """``pathtrace.cosine_directions`` of one ray into ``out[j]`` (float32): ``rc``, ``rs`` the
    disc point ``sqrt(u1) (cos, sin)(2 pi u2)``, ``lift`` its height ``sqrt(max(0, 1 - u1))``."""
    t0, t1, t2, b0, b1, b2 = tangent_frame(n0, n1, n2)
    out[j, 0] = np.float32(t0 * rc + b0 * rs + n0 * lift)
    out[j, 1] = np.float32(t1 * rc + b1 * rs + n1 * lift)
    out[j, 2] = np.float32(t2 * rc + b2 * rs + n2 * lift)


@kernel
def cosine_rows(normals, rc, rs, u1, out, start, stop):
    """``pathtrace.cosine_directions`` of rows ``start:stop`` into ``out`` (float32)."""
    for j in range(start, stop):
        cosine_ray(
            normals[j, 0], normals[j, 1], normals[j, 2], rc[j], rs[j], np.sqrt(np_maximum(0.0, 1.0 - u1[j])), out, j
        )


@kernel
def stratify(jitter1, jitter2, n_points, g, u1, u2, start, stop):
    """``pathtrace.stratified_uniforms``'s (u1, u2) at flat places ``start:stop`` of its (rays,
    n_points) layout, from its jitters: sample ``r`` of a point in cell ``(r // g, r % g)`` of a
    g x g grid, uniform past ``g * g``."""
    for q in range(start, stop):
        r = q // n_points
        if r < g * g:
            u1[q] = (np.float64(r // g) + jitter1[q]) / np.float64(g)
            u2[q] = (np.float64(r % g) + jitter2[q]) / np.float64(g)
        else:
            u1[q], u2[q] = jitter1[q], jitter2[q]


def stratified_disc(
    n_points: int, rays: int, rng: np.random.Generator, map_chunks=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(u1, rc, rs), each (rays * n_points,) ray by ray: ``pathtrace.stratified_uniforms(n_points,
    0, rays, rays, rng)``'s u1 (the same draws) and the disc point ``sqrt(u1) (cos, sin)(2 pi u2)``
    of ``pathtrace.cosine_directions`` (numpy's own ``cos`` and ``sin``), in blocks on every core."""
    g = max(1, int(np.sqrt(rays)))
    jitter1, jitter2 = rng.random((rays, n_points)).ravel(), rng.random((rays, n_points)).ravel()
    u1, u2 = np.empty(len(jitter1)), np.empty(len(jitter1))
    rc, rs = np.empty(len(jitter1)), np.empty(len(jitter1))

    def block(a: int, b: int) -> None:
        stratify(jitter1, jitter2, n_points, g, u1, u2, a, b)
        r, phi = np.sqrt(u1[a:b]), 2.0 * np.pi * u2[a:b]
        np.multiply(r, np.cos(phi), out=rc[a:b])
        np.multiply(r, np.sin(phi), out=rs[a:b])

    blocks(map_chunks)(block, len(u1))
    return u1, rc, rs


def cosine_directions(normals: np.ndarray, u1: np.ndarray, u2: np.ndarray, map_chunks=None) -> np.ndarray:
    """``pathtrace.cosine_directions`` (float32, the same bits) without its (N, 3) float64
    temporaries; ``map_chunks``: ``RayTracer.map_chunks``, to use every core."""
    normals = np.ascontiguousarray(normals, np.float64)
    u1 = np.ascontiguousarray(u1, np.float64)
    out = np.empty((len(normals), 3), np.float32)

    def block(a: int, b: int) -> None:
        r, phi = np.sqrt(u1[a:b]), 2.0 * np.pi * u2[a:b]
        cosine_rows(normals[a:b], r * np.cos(phi), r * np.sin(phi), u1[a:b], out[a:b], 0, b - a)

    blocks(map_chunks)(block, len(normals))
    return out


# ------------------------------------------------------------------ nodes: lightmaps and the ground map
@kernel
def node_rays(points, normals, sign, first, count, rays, rc, rs, u1, eps, origins, directions, start, stop):
    """The cosine rays of nodes ``first + start .. first + stop`` of a wave of ``count`` nodes
    (``points``, unit ``normals`` (N, 3) times the side's ``sign``): ray ``r`` of node ``i`` reads
    ``r * count + i`` of ``rc``, ``rs``, ``u1`` (``lightmap.bake_lightmaps``'s tiled layout,
    :func:`cosine_ray`) and goes to ``i * rays + r``: a node's rays, which leave one point, are a
    coherent batch for the tracer. Origins are the points lifted by ``eps`` along the side
    normal, float32 as numpy casts them."""
    for i in range(start, stop):
        node = first + i
        n0, n1, n2 = normals[node, 0] * sign, normals[node, 1] * sign, normals[node, 2] * sign
        o0 = np.float32(points[node, 0] + n0 * eps)
        o1 = np.float32(points[node, 1] + n1 * eps)
        o2 = np.float32(points[node, 2] + n2 * eps)
        t0, t1, t2, b0, b1, b2 = tangent_frame(n0, n1, n2)
        for r in range(rays):
            src, j = r * count + i, i * rays + r
            origins[j, 0], origins[j, 1], origins[j, 2] = o0, o1, o2
            lift = np.sqrt(np_maximum(0.0, 1.0 - u1[src]))
            directions[j, 0] = np.float32(t0 * rc[src] + b0 * rs[src] + n0 * lift)
            directions[j, 1] = np.float32(t1 * rc[src] + b1 * rs[src] + n1 * lift)
            directions[j, 2] = np.float32(t2 * rc[src] + b2 * rs[src] + n2 * lift)


@kernel
def escaped_fraction(occluded, count, rays, out, column, first):
    """``out[first + i, column]``: the share of node ``i``'s ``rays`` (node by node) that escaped."""
    for i in range(count):
        free = 0
        for r in range(rays):
            if not occluded[i * rays + r]:
                free += 1
        out[first + i, column] = free / rays


@kernel
def node_transfer(basis, blocked, count, rays, out, nodes):
    """``out[nodes[i]]``: the mean over node ``i``'s ``rays`` (node by node) of ``basis`` (N, 16)
    float32 where the ray escaped, in float64: the ground map's ``(basis * open).mean`` over its
    rays, summed in ray order from zero as numpy sums them."""
    for i in range(count):
        for k in range(basis.shape[1]):
            total = 0.0
            for r in range(rays):
                j = i * rays + r
                total += np.float64(basis[j, k]) * (0.0 if blocked[j] else 1.0)
            out[nodes[i], k] = total / rays


# ------------------------------------------------------------------ probes' bounce rays
@kernel
def probe_rays(
    probes, rays, pick, area_before, span, cum_area, first, last, order,
    faces, vertices, r1, r2, rc, rs, u1, eps, origins, dirs, start, stop,
):  # fmt: skip
    """Rays ``start:stop`` of the bounce rays of ``probes``, probe by probe (ray ``r`` of probe ``i``
    at ``i * rays + r``: a probe's rays leave a few nearby faces, a coherent batch for the tracer),
    into ``origins``, ``dirs`` (float32), as the bake's numpy drew them from its uniforms, which
    are laid out ray by ray (``r * len(probes) + i``, as ``np.tile``): the face side holding the
    area ``area_before + pick * span`` of the probe (``np.searchsorted`` on ``cum_area``, clipped
    to the probe's sides ``first..last`` of ``order``), a point on it from ``r1``, ``r2``, lifted
    by ``eps``, and a cosine direction about the side normal from ``rc``, ``rs``, ``u1``
    (:func:`cosine_ray`)."""
    n = len(probes)
    for q in range(start, stop):
        i, r = q // rays, q % rays
        j = r * n + i
        p = probes[i]
        lo, hi = first[p], last[p]
        goal = area_before[p] + pick[j] * span[p]
        while lo < hi:  # the first place in first..last whose cumulative area reaches the goal
            mid = (lo + hi) // 2
            if cum_area[mid] < goal:
                lo = mid + 1
            else:
                hi = mid
        s = order[lo]
        face, sign = s // 2, -1.0 if s % 2 == 1 else 1.0
        x, y, z = face_normal(vertices, faces, face)
        n0, n1, n2 = x * sign, y * sign, z * sign
        s1 = np.sqrt(r1[j])
        wa, wb, wc = 1 - s1, s1 * (1 - r2[j]), s1 * r2[j]
        for k in range(3):
            point = (
                wa * np.float64(vertices[faces[face, 0], k])
                + wb * np.float64(vertices[faces[face, 1], k])
                + wc * np.float64(vertices[faces[face, 2], k])
            )
            nk = n0 if k == 0 else (n1 if k == 1 else n2)
            origins[q, k] = np.float32(point + nk * eps)
        cosine_ray(n0, n1, n2, rc[j], rs[j], np.sqrt(np_maximum(0.0, 1.0 - u1[j])), dirs, q)


@kernel
def blocked_albedo_sum(prim, albedo, n, rays, out, first):
    """``out[first + i]``: the albedo summed over receiver ``i``'s rays (ray ``r`` at ``i * rays + r``)
    that hit, in ray order, float64 (``np.bincount``'s sums of float32 weights)."""
    for i in range(n):
        for k in range(3):
            total = 0.0
            for r in range(rays):
                f = prim[i * rays + r]
                total += np.float64(albedo[max(f, 0), k] * np.float32(1.0 if f >= 0 else 0.0))
            out[first + i, k] = total


# ------------------------------------------------------------------ camera gain
@kernel
def camera_sky_rays(
    hits, prim, back, t, d, eyes, first, rays, vertices, faces, rc, rs, u1, eps, origins, dirs, start, stop
):
    """``camera_gain``'s sky rays of the camera rays ``hits`` (of eye ``first + ray // rays``,
    directions ``d`` float32, hit at ``t`` on faces ``prim``, ``back``: on side 1), rows
    ``start:stop``: from the point hit, lifted by ``eps`` along the side's normal, a cosine direction
    about it (``rc``, ``rs``, ``u1``: :func:`cosine_ray`); float32 as numpy made them."""
    for m in range(start, stop):
        j = hits[m]
        sign = -1.0 if back[m] else 1.0
        face, eye = prim[j], first + j // rays
        x, y, z = face_normal(vertices, faces, face)
        n0, n1, n2 = x * sign, y * sign, z * sign
        for k in range(3):
            point = eyes[eye, k] + np.float64(d[j, k] * t[j])  # float32 product, as numpy's
            nk = n0 if k == 0 else (n1 if k == 1 else n2)
            origins[m, k] = np.float32(point + nk * eps)
        cosine_ray(n0, n1, n2, rc[m], rs[m], np.sqrt(np_maximum(0.0, 1.0 - u1[m])), dirs, m)
