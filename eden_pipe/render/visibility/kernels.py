"""The bake's compiled loops: numba kernels that do what its numpy code did, bit for bit.

Each kernel replaces numpy code of :mod:`eden_pipe.render.visibility.bake`,
:mod:`~eden_pipe.render.visibility.bounce` (its sums: :mod:`~eden_pipe.render.visibility.bounce_kernels`)
or :mod:`eden_pipe.render.lightmap`
with the same float operations in the same order (``tests/test_bake_kernels.py``
checks each against that numpy): sums that ``np.bincount`` made run over the
same items in the same order, products and quotients keep their grouping, and
numpy's ``maximum``/``where``/``argmax`` keep their NaN and tie rules. What stays
numpy: BLAS products (``@`` fuses multiplies and adds, so its sums differ from a
plain loop's in the last bit) and ``cos``/``sin`` (numpy's own loops may differ
from the C library's on other CPUs). Kernels release the GIL and take index
ranges, so the tracer's thread pool (``RayTracer.map_chunks``) runs them on
every core; none allocates a table per face, which is where the bake's memory
went (``docs/realism.md``, the bake).
"""

from __future__ import annotations

import numba as nb
import numpy as np

# error_model="numpy": a zero divisor gives inf/nan as in numpy, not an exception.
kernel = nb.njit(nogil=True, cache=True, error_model="numpy")


@kernel
def np_maximum(a: float, b: float) -> float:
    """``np.maximum(a, b)`` for scalars: a NaN wins, and of two zeros ``a``."""
    return a if (a >= b or a != a) else b


@kernel
def _argmax_abs(x: float, y: float, z: float) -> int:
    """``np.argmax(np.abs((x, y, z)))``: the first of equal values, the first NaN if any."""
    best, axis = np.abs(x), 0
    if best != best:
        return 0
    for k, v in ((1, np.abs(y)), (2, np.abs(z))):
        if v != v:
            return k
        if v > best:
            best, axis = v, k
    return axis


# ------------------------------------------------------------------ faces and probes
@kernel
def face_geometry(vertices, faces, f):
    """Face ``f``'s (unit normal along the winding (3), twice its area, centroid (3)), float64, as
    numpy's cross product and norm of the float64 edges made them (``bake.face_frames``)."""
    a0, a1, a2 = (
        np.float64(vertices[faces[f, 0], 0]),
        np.float64(vertices[faces[f, 0], 1]),
        np.float64(vertices[faces[f, 0], 2]),
    )
    b0, b1, b2 = (
        np.float64(vertices[faces[f, 1], 0]),
        np.float64(vertices[faces[f, 1], 1]),
        np.float64(vertices[faces[f, 1], 2]),
    )
    c0, c1, c2 = (
        np.float64(vertices[faces[f, 2], 0]),
        np.float64(vertices[faces[f, 2], 1]),
        np.float64(vertices[faces[f, 2], 2]),
    )
    u0, u1, u2 = b0 - a0, b1 - a1, b2 - a2
    w0, w1, w2 = c0 - a0, c1 - a1, c2 - a2
    x = u1 * w2 - u2 * w1  # np.cross's order
    y = u2 * w0 - u0 * w2
    z = u0 * w1 - u1 * w0
    area2 = np.sqrt(x * x + y * y + z * z)
    scale = np_maximum(area2, 1e-30)
    return x / scale, y / scale, z / scale, area2, (a0 + b0 + c0) / 3.0, (a1 + b1 + c1) / 3.0, (a2 + b2 + c2) / 3.0


@kernel
def face_normal(vertices, faces, f):
    """Face ``f``'s unit normal (:func:`face_geometry`): the bake makes it where it needs it rather
    than hold a float64 table of every face's (141 MB for the default garden)."""
    x, y, z, _, _, _, _ = face_geometry(vertices, faces, f)
    return x, y, z


@kernel
def face_frames_range(vertices, faces, normals, areas, centroids, start, stop):
    """``bake.face_frames`` for faces ``start:stop``: unit normals, areas and centroids."""
    for i in range(start, stop):
        x, y, z, area2, c0, c1, c2 = face_geometry(vertices, faces, i)
        normals[i, 0], normals[i, 1], normals[i, 2] = x, y, z
        areas[i] = 0.5 * area2
        centroids[i, 0], centroids[i, 1], centroids[i, 2] = c0, c1, c2


@kernel
def face_normals_range(vertices, faces, out, start, stop):
    """``out[i - start]``: the unit normal of face ``i`` for ``i`` in ``start:stop``."""
    for i in range(start, stop):
        out[i - start, 0], out[i - start, 1], out[i - start, 2] = face_normal(vertices, faces, i)


@kernel
def face_normals(vertices, faces, which):
    """(K, 3) the unit normals of faces ``which`` (:func:`face_geometry`)."""
    out = np.empty((len(which), 3))
    for j in range(len(which)):
        out[j, 0], out[j, 1], out[j, 2] = face_normal(vertices, faces, which[j])
    return out


@kernel
def _cell(centroids, size, i, k) -> np.int64:
    """``np.floor(centroids / size).astype(np.int64)`` of one face and axis."""
    return np.int64(np.floor(centroids[i, k] / size[k]))


@kernel
def cell_bounds(centroids, size):
    """((3,) least, (3,) greatest) probe cell of the faces' ``centroids`` (F >= 1)."""
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for k in range(3):
        lo[k] = hi[k] = _cell(centroids, size, 0, k)
    for i in range(1, centroids.shape[0]):
        for k in range(3):
            c = _cell(centroids, size, i, k)
            lo[k] = min(lo[k], c)
            hi[k] = max(hi[k], c)
    return lo, hi


@kernel
def probe_keys_range(normals, centroids, size, lo, span, opaque, keys, start, stop):
    """``bake.assign_probes``'s keys of faces ``start:stop``, both sides: (cell, major axis of the
    side normal, its sign, and for opaque faces which side); cells counted from ``lo``."""
    for i in range(start, stop):
        axis = _argmax_abs(normals[i, 0], normals[i, 1], normals[i, 2])
        c0 = _cell(centroids, size, i, 0) - lo[0]
        c1 = _cell(centroids, size, i, 1) - lo[1]
        c2 = _cell(centroids, size, i, 2) - lo[2]
        cell_key = ((c0 * span[1] + c1) * span[2] + c2) * 12
        along = normals[i, axis]
        front = (axis * 2 + (1 if along > 0 else 0)) * 2
        back = (axis * 2 + (1 if -along > 0 else 0)) * 2 + (1 if opaque[i] else 0)
        keys[i, 0] = cell_key + front
        keys[i, 1] = cell_key + back


@kernel
def unique_inverse(keys):
    """``np.unique(keys, return_inverse=True)``'s inverse (int32) and count for non-negative int64
    ``keys``: each key's rank among the distinct keys, by a radix sort (16 bits a pass, as many
    passes as the largest key needs; a fifth of the time of numpy's argsort of 12 million keys)."""
    n = len(keys)
    inverse = np.empty(n, np.int32)
    if n == 0:
        return inverse, 0
    top = keys.max()
    order = np.arange(n).astype(np.int32)
    spare = np.empty(n, np.int32)
    shift = 0
    while shift == 0 or (top >> shift) > 0:
        count = np.zeros(65537, np.int64)
        for j in range(n):
            count[((keys[order[j]] >> shift) & 0xFFFF) + 1] += 1
        for b in range(65536):
            count[b + 1] += count[b]
        for j in range(n):  # stable: equal digits keep the order of the pass before
            digit = (keys[order[j]] >> shift) & 0xFFFF
            spare[count[digit]] = order[j]
            count[digit] += 1
        order, spare = spare, order
        shift += 16
    rank = 0
    inverse[order[0]] = 0
    for j in range(1, n):
        if keys[order[j]] != keys[order[j - 1]]:
            rank += 1
        inverse[order[j]] = rank
    return inverse, rank + 1


@kernel
def probe_frames(face_probe, areas, normals, covered, n_probes):
    """Per probe, summed over its face sides in side order as ``np.bincount`` sums: the
    area-weighted side normal (P, 3) and the covered area (P,)."""
    mean_normal = np.zeros((n_probes, 3))
    probe_covered = np.zeros(n_probes)
    for i in range(face_probe.shape[0]):
        for s in range(2):
            p = face_probe[i, s]
            sign = 1.0 if s == 0 else -1.0
            for k in range(3):
                mean_normal[p, k] += areas[i] * (normals[i, k] * sign)
            probe_covered[p] += (1.0 if covered[i] else 0.0) * areas[i]
    return mean_normal, probe_covered


@kernel
def probe_hit_sums(face_probe, hits, open_hits, n_probes):
    """Per probe, summed over its face sides in side order: bundle hits and open hits (P each)."""
    probe_hits = np.zeros(n_probes)
    probe_open = np.zeros(n_probes)
    for i in range(face_probe.shape[0]):
        for s in range(2):
            p = face_probe[i, s]
            probe_hits[p] += hits[i, s]
            probe_open[p] += open_hits[i, s]
    return probe_hits, probe_open


# ------------------------------------------------------------------ outside-in bundles
@kernel
def bundle_origins(base, e1, e2, gu, gv, out):
    """The origins of a bundle's grid rows ``gv`` (row-major, columns ``gu``), float32:
    ``base + U e1 + V e2`` as numpy sums it (``base``: the bundle's centre out along its direction)."""
    n_u = len(gu)
    for r in range(len(gv)):
        v = gv[r]
        for c in range(n_u):
            u = gu[c]
            j = r * n_u + c
            for k in range(3):
                out[j, k] = np.float32(base[k] + u * e1[k] + v * e2[k])


@kernel
def count_bundle_hits(prim, normal, toward, side_hits, probe_of_side, wave_count, touched, sh_sums, basis):
    """One wave of a bundle, its rays' hit faces ``prim`` (N,) (-1: none) and unit ``normal`` (N, 3)
    float32: each hit counts on its face side (the side behind the winding where the normal points
    away from ``toward`` (3,) float32, the sky direction) in ``side_hits`` (2F,) int32, and the
    wave's hits per probe, times the direction's SH ``basis`` (16,), add to ``sh_sums`` (P, 16) as
    ``sky_hits`` adds them (one sum per probe and wave; ``wave_count``: zeros, left zero)."""
    n_touched = 0
    wx, wy, wz = toward[0], toward[1], toward[2]
    for j in range(len(prim)):
        f = prim[j]
        if f < 0:
            continue
        side = 2 * f + (1 if normal[j, 0] * wx + normal[j, 1] * wy + normal[j, 2] * wz < 0 else 0)
        side_hits[side] += 1
        p = probe_of_side[side]
        if wave_count[p] == 0:
            touched[n_touched] = p
            n_touched += 1
        wave_count[p] += 1
    for t in range(n_touched):
        p = touched[t]
        count = np.float64(wave_count[p])
        for k in range(sh_sums.shape[1]):
            sh_sums[p, k] += count * basis[k]
        wave_count[p] = 0


@kernel
def add_open_hits(cos, open_hits, start):
    """``open_hits[start + i] += (max(cos, 0), max(-cos, 0))`` with numpy's ``maximum``."""
    for i in range(len(cos)):
        c = cos[i]
        open_hits[start + i, 0] += np_maximum(c, 0.0)
        open_hits[start + i, 1] += np_maximum(-c, 0.0)


# ------------------------------------------------------------------ probes' face sides
@kernel
def sides_by_probe(face_probe, n_probes):
    """``np.argsort(face_probe.ravel(), kind="stable")`` as int32 (a counting sort: the same
    order) and each probe's first place in it."""
    flat = face_probe.ravel()
    first = np.zeros(n_probes + 1, np.int64)
    for s in range(len(flat)):
        first[flat[s] + 1] += 1
    for p in range(n_probes):
        first[p + 1] += first[p]
    fill = first[:-1].copy()
    order = np.empty(len(flat), np.int32)
    for s in range(len(flat)):
        p = flat[s]
        order[fill[p]] = s
        fill[p] += 1
    return order, first[:-1]


@kernel
def cumulative_side_area(order, areas, total):
    """``np.cumsum(np.maximum(side_area[order], 1e-12))`` with ``side_area`` each face's area twice,
    continuing a sum that had reached ``total`` (0.0: from the start)."""
    out = np.empty(len(order))
    for j in range(len(order)):
        total += np_maximum(areas[order[j] // 2], 1e-12)
        out[j] = total
    return out


# ------------------------------------------------------------------ the bake's box, exposures, camera gain
@kernel
def garden_bounds(vertices, faces, garden):
    """(least, greatest) float32 vertex coordinates of the ``garden`` faces (at least one), as
    ``np.min``/``np.max`` over their vertices make them (a NaN wins)."""
    lo = np.full(3, np.inf, np.float32)
    hi = np.full(3, -np.inf, np.float32)
    for i in range(faces.shape[0]):
        if not garden[i]:
            continue
        for c in range(3):
            for k in range(3):
                v = vertices[faces[i, c], k]
                if lo[k] == lo[k] and (v < lo[k] or v != v):  # a NaN, once in, stays
                    lo[k] = v
                if hi[k] == hi[k] and (v > hi[k] or v != v):
                    hi[k] = v
    return lo, hi


@kernel
def faces_inside(vertices, faces, lo, hi):
    """(F,) bool: every vertex of the face lies in the box ``lo``..``hi`` (float64 bounds)."""
    out = np.empty(faces.shape[0], np.bool_)
    for i in range(faces.shape[0]):
        inside = True
        for c in range(3):
            for k in range(3):
                v = np.float64(vertices[faces[i, c], k])
                inside = inside and v >= lo[k] and v <= hi[k]
        out[i] = inside
    return out


@kernel
def visible_sky(hits, open_hits, areas, face_probe, visible, open_scale, prior_hits):
    """``bake``'s ``v_face`` (F, 2) float64: each face side's cosine-weighted visible sky, its hit
    fraction shrunk toward its probe's ``visible`` by ``prior_hits`` pseudo-hits, times its
    open-sky factor."""
    v_face = np.empty(hits.shape)
    for i in range(hits.shape[0]):
        area = np_maximum(areas[i], 1e-12)
        for s in range(2):
            open_factor = open_hits[i, s] * open_scale / area
            shrunk = np.float64(hits[i, s]) + prior_hits * visible[face_probe[i, s]]
            v_face[i, s] = shrunk / (open_hits[i, s] + prior_hits) * open_factor
    return v_face


# ------------------------------------------------------------------ parts: faces joined by shared vertices
@kernel
def _root(parent, v):
    """Vertex ``v``'s part root in the union-find forest ``parent``, halving the path on the way."""
    while parent[v] != v:
        parent[v] = parent[parent[v]]
        v = parent[v]
    return v


@kernel
def mesh_parts(faces, n_vertices):
    """Each face's connected part (F,) int64: faces that share a vertex, transitively, are one part
    (a leaf, a blade, a hedge's box); a part is named by its smallest vertex, so the labels do not
    depend on the order faces are joined in."""
    parent = np.arange(n_vertices)
    for f in range(faces.shape[0]):
        for k in range(2):
            a, b = _root(parent, faces[f, k]), _root(parent, faces[f, k + 1])
            if a < b:
                parent[b] = a
            elif b < a:
                parent[a] = b
    part = np.empty(faces.shape[0], np.int64)
    for f in range(faces.shape[0]):
        part[f] = _root(parent, faces[f, 0])
    return part


@kernel
def part_probe_keys(part, face_probe, n_probes):
    """(2F,) int64 keys of each face side's part within its probe, for :func:`unique_inverse`."""
    keys = np.empty(2 * face_probe.shape[0], np.int64)
    for i in range(face_probe.shape[0]):
        for s in range(2):
            keys[2 * i + s] = part[i] * n_probes + face_probe[i, s]
    return keys


@kernel
def pooled_visible_sky(
    hits, open_hits, areas, face_probe, visible, group, n_groups, open_scale, prior_hits, part_prior_hits
):
    """:func:`visible_sky` with the bundles' hits pooled over each side's ``group`` (its part within
    its probe, :func:`part_probe_keys`): the group's hit fraction shrunk toward its probe's
    ``visible`` by ``prior_hits`` pseudo-hits, the side's own shrunk toward its group's by
    ``part_prior_hits``, times the side's open-sky factor (docs/realism.md, the bake)."""
    group_hits = np.zeros(n_groups)
    group_open = np.zeros(n_groups)
    for i in range(hits.shape[0]):
        for s in range(2):
            g = group[2 * i + s]
            group_hits[g] += np.float64(hits[i, s])
            group_open[g] += open_hits[i, s]
    v_face = np.empty(hits.shape)
    for i in range(hits.shape[0]):
        area = np_maximum(areas[i], 1e-12)
        for s in range(2):
            g = group[2 * i + s]
            part = (group_hits[g] + prior_hits * visible[face_probe[i, s]]) / (group_open[g] + prior_hits)
            open_factor = open_hits[i, s] * open_scale / area
            shrunk = np.float64(hits[i, s]) + part_prior_hits * part
            v_face[i, s] = shrunk / (open_hits[i, s] + part_prior_hits) * open_factor
    return v_face


@kernel
def side_exposure(v_face, face_probe, probe_visible, covered):
    """(F, 2) float64: each side's visible sky over its probe's (``store.exposure_of``); 1 off the
    bundles' box."""
    exposure = np.empty(v_face.shape)
    for i in range(v_face.shape[0]):
        for s in range(2):
            pv = probe_visible[face_probe[i, s]]
            exposure[i, s] = (v_face[i, s] / np_maximum(pv, 1e-6) if pv > 1e-6 else 0.0) if covered[i] else 1.0
    return exposure


@kernel
def seen_exposure(exposure, gain, face_probe, probe_visible, covered):
    """(F, 2) float32: the exposure scaled by the camera gain of its probe, at most the side's whole
    sky (``1 / probe_visible``); 1 off the bundles' box."""
    out = np.empty(exposure.shape, np.float32)
    for i in range(exposure.shape[0]):
        for s in range(2):
            p = face_probe[i, s]
            limit = 1.0 / np_maximum(probe_visible[p], 1e-6)
            scaled = exposure[i, s] * gain[p]
            out[i, s] = np.float32((scaled if (scaled <= limit or scaled != scaled) else limit) if covered[i] else 1.0)
    return out


@kernel
def count_sides(side, free, count, escapes):
    """Each camera ray's face side counted in ``count``, and in ``escapes`` where its sky ray was free."""
    for j in range(len(side)):
        count[side[j]] += 1
        if free[j]:
            escapes[side[j]] += 1


@kernel
def camera_sums(face_probe, count, escapes, v_face, n_probes):
    """Per probe, over its sides in order (``np.bincount``'s sums): sky rays that escaped, the
    escapes the sides' own visible fractions expect, and camera rays (P each)."""
    seen = np.zeros(n_probes)
    expected = np.zeros(n_probes)
    samples = np.zeros(n_probes)
    for i in range(face_probe.shape[0]):
        for s in range(2):
            p, j = face_probe[i, s], 2 * i + s
            seen[p] += np.float64(escapes[j])
            expected[p] += np.float64(count[j]) * v_face[i, s]
            samples[p] += np.float64(count[j])
    return seen, expected, samples


def blocks(map_chunks):
    """``map_chunks`` (``RayTracer.map_chunks``: ``fn(start, stop)`` over blocks of ``n`` on every
    core), or without it one call ``fn(0, n)``."""
    return (lambda fn, n: fn(0, n)) if map_chunks is None else map_chunks
