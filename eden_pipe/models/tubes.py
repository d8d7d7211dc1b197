"""The one tube mesher: rings of vertices around a centreline, joined by quads.

Every tube in the models is built from the same two pieces: :func:`ring_vertices`
(a ring of ``sides`` points around each centre, in the plane of two frame
vectors) and :func:`ring_faces` (two triangles per quad between a ring and the
next, counter-clockwise seen from outside). :func:`tube_mesh` sweeps open
tubes along many polylines at once (ivy stems, branches, trunks, flower
stalks); tree stems use the same rings with their own taper, lobes and level of
detail (:mod:`eden_pipe.models.tree.meshing`).
"""

from __future__ import annotations

import numpy as np

from eden_pipe.geometry import any_perpendicular, normalize


def ring_vertices(
    centres: np.ndarray, radii: np.ndarray, u: np.ndarray, v: np.ndarray, angles: np.ndarray
) -> np.ndarray:
    """Points ``centre + radius * (cos(a) u + sin(a) v)`` for each centre (..., 3) and angle (S,).

    ``radii`` broadcasts against (..., S) (one radius per ring, or per ring point for lobed
    trunks); returns (..., S, 3)."""
    ring = np.cos(angles)[..., :, None] * u[..., None, :] + np.sin(angles)[..., :, None] * v[..., None, :]
    return centres[..., None, :] + radii[..., None] * ring


def ring_faces(rings: np.ndarray, sides: int, quads: int | None = None) -> np.ndarray:
    """(R, Q, 2, 3) vertex indices joining ring ``i`` to ring ``i + 1`` for each ``i`` in ``rings``.

    Rings hold ``sides`` consecutive vertices each; quad ``k`` joins points ``k`` and
    ``k + 1`` (wrapping), ``quads`` of them (default ``sides``; 1 for a flat ribbon)."""
    rings = np.asarray(rings)[:, None]
    k = np.arange(sides if quads is None else quads)[None]
    k1 = (k + 1) % sides
    a = rings * sides + k
    b = rings * sides + k1
    c = (rings + 1) * sides + k1
    d = (rings + 1) * sides + k
    return np.stack([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=2)


def tube_mesh(
    points: np.ndarray, radii: np.ndarray, path_id: np.ndarray, sides: int = 3, ref: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Open tubes swept along polylines, all at once.

    ``points`` (P,3) with ``path_id`` (P,) non-decreasing (consecutive points of
    one path adjacent); ``radii`` (P,). Rings use parallel-transported frames
    (vectorised across paths). Returns float32 (P*sides,3) vertices and int32
    faces, counter-clockwise seen from outside. Paths of one point give no faces."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    r = np.broadcast_to(np.asarray(radii, np.float64), (len(p),))
    pid = np.asarray(path_id).reshape(-1)
    P = len(p)
    if P == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    same_next = np.zeros(P, bool)
    same_next[:-1] = pid[1:] == pid[:-1]
    same_prev = np.zeros(P, bool)
    same_prev[1:] = same_next[:-1]
    nxt = np.where(same_next, np.arange(P) + 1, np.arange(P))
    prv = np.where(same_prev, np.arange(P) - 1, np.arange(P))
    tan = normalize(p[nxt] - p[prv])
    # parallel transport along each path
    starts = np.flatnonzero(~same_prev)
    lengths = np.diff(np.concatenate([starts, [P]]))
    normal = np.zeros_like(p)
    t0 = tan[starts]
    if ref is None:
        n0 = any_perpendicular(t0)
    else:
        n0 = normalize(np.cross(t0, np.cross(np.broadcast_to(ref, t0.shape), t0)))
        bad = np.linalg.norm(np.cross(t0, np.broadcast_to(ref, t0.shape)), axis=1) < 1e-6
        n0[bad] = any_perpendicular(t0[bad])
    normal[starts] = n0
    for j in range(1, int(lengths.max())):
        sel = lengths > j
        i = starts[sel] + j
        prev_n = normal[i - 1]
        t = tan[i]
        nn = prev_n - np.sum(prev_n * t, 1, keepdims=True) * t
        bad = np.linalg.norm(nn, axis=1) < 1e-9
        if np.any(bad):
            nn[bad] = any_perpendicular(t[bad])
        normal[i] = normalize(nn)
    binormal = np.cross(tan, normal)
    ang = 2 * np.pi * np.arange(sides) / sides
    verts = ring_vertices(p, r[:, None], normal, binormal, ang)
    # per segment: every ring quad's first triangle, then every second one
    faces = ring_faces(np.flatnonzero(same_next), sides).transpose(0, 2, 1, 3)
    return verts.reshape(-1, 3).astype(np.float32), faces.reshape(-1, 3).astype(np.int32)
