"""Each face side's own visible sky at three points of the face, read once in the bake from the
bundles' depth maps (:mod:`eden_pipe.render.visibility.shadow_maps`), and blended by a render at
each hit (``render.sky_visibility.face_sky``; docs/realism.md, "Each face side's sky at three
points"); with ``face_sky_moments``, also the directions each side sees the sky in, to order 2
("The sky by the directions a face side sees it in")."""

from __future__ import annotations

import numpy as np
from numba import njit

from eden_pipe.render.prefetch import prefetch
from eden_pipe.render.visibility.shadow_maps import MOMENTS, ShadowMaps

# The points V_k / 2 + (V_0 + V_1 + V_2) / 6, at barycentric
# coordinates (2/3, 1/6, 1/6) and its turns, where a pixel blends them linearly
# (docs/realism.md, "Each face side's sky at three points").
FACE_SKY_POINTS = 3
FACE_SKY_STEPS = 65535  # the table's visible fractions in steps of 1/65535 (uint16)
MOMENT_STEPS = 127  # the moments' means in steps of 1/127 (int8; each polynomial is within [-1, 1])
# With the moments, a side's record is 8 uint16 (16 bytes, never across a cache line): its three
# fractions, then its MOMENTS int8 means in bytes MOMENT_BYTE.., then a spare: a hit reads both at once.
SIDE_COLUMNS = 8
MOMENT_BYTE = 2 * FACE_SKY_POINTS
PREFETCH_HITS = 32  # face_sky_exposure asks for a face's rows this many hits ahead (16: slower, 64: no faster)


@njit(nogil=True, cache=True)
def _face_sky_points(vertices, faces, first, stop, points, normals):
    """Rows 3 (i - first) + k, for the faces i in first..stop-1: point k of face i (float32) and the
    unit normal of its winding (float32; zero for a degenerate face)."""
    for i in range(first, stop):
        a, b, c = faces[i, 0], faces[i, 1], faces[i, 2]
        ax, ay, az = np.float64(vertices[a, 0]), np.float64(vertices[a, 1]), np.float64(vertices[a, 2])
        bx, by, bz = np.float64(vertices[b, 0]), np.float64(vertices[b, 1]), np.float64(vertices[b, 2])
        cx, cy, cz = np.float64(vertices[c, 0]), np.float64(vertices[c, 1]), np.float64(vertices[c, 2])
        e1x, e1y, e1z = bx - ax, by - ay, bz - az
        e2x, e2y, e2z = cx - ax, cy - ay, cz - az
        nx = e1y * e2z - e1z * e2y
        ny = e1z * e2x - e1x * e2z
        nz = e1x * e2y - e1y * e2x
        length = np.sqrt(nx * nx + ny * ny + nz * nz)
        inv = 1.0 / length if length > 0.0 else 0.0
        sx, sy, sz = (ax + bx + cx) / 6.0, (ay + by + cy) / 6.0, (az + bz + cz) / 6.0
        row = 3 * (i - first)
        points[row, 0], points[row, 1], points[row, 2] = 0.5 * ax + sx, 0.5 * ay + sy, 0.5 * az + sz
        points[row + 1, 0], points[row + 1, 1], points[row + 1, 2] = 0.5 * bx + sx, 0.5 * by + sy, 0.5 * bz + sz
        points[row + 2, 0], points[row + 2, 1], points[row + 2, 2] = 0.5 * cx + sx, 0.5 * cy + sy, 0.5 * cz + sz
        for k in range(3):
            normals[row + k, 0] = np.float32(nx * inv)
            normals[row + k, 1] = np.float32(ny * inv)
            normals[row + k, 2] = np.float32(nz * inv)


@njit(nogil=True, cache=True, inline="always")
def _face_frame(vertices, faces, f):
    """What :func:`_blend` needs of face ``f`` alone, made once for the hits in a row on it: its
    first vertex, its edges from it (float32) and their dot products (float64)."""
    a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
    ax, ay, az = vertices[a, 0], vertices[a, 1], vertices[a, 2]
    e0x, e0y, e0z = vertices[b, 0] - ax, vertices[b, 1] - ay, vertices[b, 2] - az
    e1x, e1y, e1z = vertices[c, 0] - ax, vertices[c, 1] - ay, vertices[c, 2] - az
    d00 = np.float64(e0x) * e0x + np.float64(e0y) * e0y + np.float64(e0z) * e0z
    d01 = np.float64(e0x) * e1x + np.float64(e0y) * e1y + np.float64(e0z) * e1z
    d11 = np.float64(e1x) * e1x + np.float64(e1y) * e1y + np.float64(e1z) * e1z
    return ax, ay, az, e0x, e0y, e0z, e1x, e1y, e1z, d00, d01, d11, d00 * d11 - d01 * d01


@njit(nogil=True, cache=True, inline="always")
def _blend(frame, v0, v1, v2, x, y, z):
    """A face side's visible sky at the point (x, y, z) on the face (``frame``: :func:`_face_frame`):
    its values ``v0``, ``v1``, ``v2`` at its three points blended by the point's barycentric
    coordinates b (weights 2 b - 1/3: exact at the three points, linear across the face), kept
    within the three values' range (no extrapolation toward the corners), as float64."""
    ax, ay, az, e0x, e0y, e0z, e1x, e1y, e1z, d00, d01, d11, den = frame
    qx, qy, qz = x - ax, y - ay, z - az
    d20 = np.float64(qx) * e0x + np.float64(qy) * e0y + np.float64(qz) * e0z
    d21 = np.float64(qx) * e1x + np.float64(qy) * e1y + np.float64(qz) * e1z
    if den > 0.0:
        b1 = min(max((d11 * d20 - d01 * d21) / den, 0.0), 1.0)
        b2 = min(max((d00 * d21 - d01 * d20) / den, 0.0), 1.0 - b1)
        b0 = 1.0 - b1 - b2
        value = (2.0 * b0 - 1.0 / 3.0) * v0 + (2.0 * b1 - 1.0 / 3.0) * v1 + (2.0 * b2 - 1.0 / 3.0) * v2
    else:
        value = (v0 + v1 + v2) / 3.0
    return min(max(value, min(v0, v1, v2)), max(v0, v1, v2))


@njit(nogil=True, cache=True)
def face_sky_exposure(
    table, vertices, faces, prim, back, points, side_exposure, probe_visible, exposure, least, fit, seen
):  # fmt: skip
    """``exposure`` (H,) float32 of H hits, in place, where their side is lit through a probe
    (``side_exposure`` finite and >= 0): scaled so that their visible fraction (``probe_visible``
    times it, within 1) is their face side's at the hit (:func:`_blend`), where that fraction is
    at least ``least`` (below, it says nothing), and at most the whole sky (1 / ``probe_visible``).
    With the moments (``table`` (F, 2, SIDE_COLUMNS)), ``seen`` (H, 3) float32 receives at the same
    hits the mean radiance of the sky their side sees: its moments' means times the sky's ``fit``
    (1 + MOMENTS, 3) float32 (:func:`hemisphere_fit`); else ``seen`` is (0, 3) and ``fit`` unread."""
    zero, one = np.float32(0.0), np.float32(1.0)
    with_moments = seen.shape[0] > 0
    means = table.view(np.int8)  # (F, 2, 2 SIDE_COLUMNS): a side's moments in bytes MOMENT_BYTE..
    step = np.float32(1.0 / MOMENT_STEPS)
    scale = 1.0 / FACE_SKY_STEPS
    # Neighbouring pixels often lie on the same face side (two in five hits on the default garden's
    # plants): what depends on the side alone is kept from the hit before.
    scaled = np.empty(MOMENTS, np.float32)
    radiance = np.zeros(3, np.float32)
    n = prim.shape[0]
    if n == 0 or faces.shape[0] == 0:
        return exposure
    frame = _face_frame(vertices, faces, 0)  # (made again at the first hit)
    seen_side, framed_face, valued_side = -1, -1, -1
    v0 = v1 = v2 = 0.0
    for i in range(n):
        # The rows of faces a few pixels on are asked for now, their vertices once those rows have
        # come: the rows lie anywhere in tables of hundreds of MB, and each read waited for memory.
        if i + PREFETCH_HITS < n and prim[i + PREFETCH_HITS] >= 0:
            ahead = prim[i + PREFETCH_HITS]
            prefetch(table.ctypes.data + ahead * table.strides[0])
            prefetch(faces.ctypes.data + ahead * faces.strides[0])
        if i + PREFETCH_HITS // 2 < n and prim[i + PREFETCH_HITS // 2] >= 0:
            ahead = prim[i + PREFETCH_HITS // 2]
            for k in range(3):
                prefetch(vertices.ctypes.data + faces[ahead, k] * vertices.strides[0])
        if not (side_exposure[i] >= zero and side_exposure[i] < np.inf):
            continue
        f = prim[i]
        side = 1 if back[i] else 0
        if with_moments:
            if 2 * f + side != seen_side:
                seen_side = 2 * f + side
                for k in range(MOMENTS):
                    scaled[k] = np.float32(means[f, side, MOMENT_BYTE + k]) * step
                for c in range(3):
                    total = fit[0, c]
                    for k in range(MOMENTS):
                        total += scaled[k] * fit[1 + k, c]
                    radiance[c] = total
            for c in range(3):
                seen[i, c] = radiance[c]
        visible = probe_visible[i]
        bake = min(max(visible * exposure[i], zero), one)
        if bake < least:
            continue
        if f != framed_face:
            framed_face = f
            frame = _face_frame(vertices, faces, f)
        if 2 * f + side != valued_side:
            valued_side = 2 * f + side
            v0, v1, v2 = table[f, side, 0] * scale, table[f, side, 1] * scale, table[f, side, 2] * scale
        at = np.float32(_blend(frame, v0, v1, v2, points[i, 0], points[i, 1], points[i, 2]))
        limit = one / max(visible, np.float32(1e-6))
        exposure[i] = min(exposure[i] * (at / bake), limit)
    return exposure


@njit(nogil=True, cache=True)
def sides_sky_light(side_exposure, seen, probe_visible, exposure, bounce, light):
    """``light`` (H, 3) float32 Dind of H hits, in place, where their side is lit through a probe
    (``side_exposure`` finite and >= 0): their visible fraction (``probe_visible`` times
    ``exposure``, within 1) times the mean radiance ``seen`` (H, 3) of the sky their side sees
    (:func:`face_sky_exposure`), plus their ``bounce`` (H, 3)."""
    zero, one = np.float32(0.0), np.float32(1.0)
    for i in range(seen.shape[0]):
        if not (side_exposure[i] >= zero and side_exposure[i] < np.inf):
            continue
        visible = min(max(probe_visible[i] * exposure[i], zero), one)
        for c in range(3):
            light[i, c] = visible * seen[i, c] + bounce[i, c]
    return light


@njit(nogil=True, cache=True)
def _side_records(sums, weighted, records, means):
    """The face sides' records ``records`` (n, 2, SIDE_COLUMNS) uint16 and their moments' bytes
    ``means`` (n, 2, MOMENTS) int8 from :meth:`ShadowMaps.both_sides_moments`' ``sums`` (2, 3 n)
    and ``weighted`` (2, MOMENTS, 3 n) at the n faces' three points: each point's fraction within
    1 in steps of 1/FACE_SKY_STEPS, and the side's moments' means over its three points' open
    directions in steps of 1/MOMENT_STEPS (zero where they see none)."""
    steps, top, tiny = np.float32(FACE_SKY_STEPS), np.float32(MOMENT_STEPS), np.float32(1e-12)
    one = np.float32(1.0)
    for i in range(records.shape[0]):
        row = FACE_SKY_POINTS * i
        for side in range(2):
            a, b, c = sums[side, row], sums[side, row + 1], sums[side, row + 2]
            for k in range(FACE_SKY_POINTS):
                records[i, side, k] = np.uint16(np.rint(min(sums[side, row + k], one) * steps))
            total = max(a + b + c, tiny)
            for k in range(MOMENTS):
                w = weighted[side, k]
                mean = (w[row] + w[row + 1] + w[row + 2]) / total * top
                means[i, side, k] = np.int8(np.rint(min(max(mean, -top), top)))


def face_sky_table(maps: ShadowMaps, vertices: np.ndarray, faces: np.ndarray, run, moments: bool = False) -> np.ndarray:
    """(F, 2, 3) uint16: each face side's visible sky (:meth:`ShadowMaps.visible_fraction`) at its
    three points (side 0 the winding's normal's, side 1 the other), in steps of 1/FACE_SKY_STEPS.
    With ``moments``, (F, 2, SIDE_COLUMNS): each side's record also holds, in its bytes MOMENT_BYTE..
    as int8 in steps of 1/MOMENT_STEPS, its :func:`direction_polynomials`' cosine-weighted means
    over the directions its three points see the sky in (zero where they see none). ``run`` is the
    tracer's ``map_chunks`` (faces in chunks across its threads)."""
    table = np.zeros((len(faces), 2, SIDE_COLUMNS if moments else FACE_SKY_POINTS), np.uint16)
    means = table.view(np.int8)[:, :, MOMENT_BYTE : MOMENT_BYTE + MOMENTS]

    def chunk(first: int, stop: int) -> None:
        n = stop - first
        points = np.empty((FACE_SKY_POINTS * n, 3), np.float32)
        normals = np.empty((FACE_SKY_POINTS * n, 3), np.float32)
        _face_sky_points(vertices, faces, first, stop, points, normals)
        if not moments:
            for side, seen in enumerate(maps.both_sides(points, normals)):
                table[first:stop, side] = np.rint(seen * FACE_SKY_STEPS).astype(np.uint16).reshape(n, FACE_SKY_POINTS)
            return
        _side_records(*maps.both_sides_moments(points, normals), table[first:stop], means[first:stop])

    run(chunk, len(faces))
    return table


def side_moments(table: np.ndarray) -> np.ndarray:
    """(F, 2, MOMENTS) int8 view: the moments' means of a face table made with them."""
    return table.view(np.int8)[:, :, MOMENT_BYTE : MOMENT_BYTE + MOMENTS]
