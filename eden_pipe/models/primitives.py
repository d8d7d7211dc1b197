"""Small, generic, vectorised geometry primitives returning (vertices, faces).

Every builder returns ``(V, F)`` numpy arrays (float64 vertices, int64 faces,
counter-clockwise seen from outside, so closed shapes have positive signed
volume) and batches many instances per call without Python loops per
instance. Wrap them with :meth:`eden_pipe.models.mesh.Mesh.from_arrays` or
:func:`to_mesh` (per-face attributes).

- :func:`box_batch`: N oriented boxes (8 vertices, 12 triangles each)
- :func:`beam_batch`: boxes spanning point pairs (rails, legs, struts)
- :func:`prism_batch`: N convex polygons extruded along a local axis (pickets)
- :func:`lathe`: surface of revolution of an (r, z) profile, optional caps
  (pots, bowls, columns; few segments give prisms and pyramids)
- :func:`icosphere`: subdivided unit icosahedron
- :func:`convex_hull`: 3-D convex hull (incremental, numpy only, for small sets)
- :func:`merge`: concatenate (V, F) pairs
"""

from __future__ import annotations

import numpy as np

from eden_pipe.models.mesh import MATERIALS, Mesh

# Box corners: index = x + 2y + 4z over the unit cube [-0.5, 0.5]^3.
_BOX_CORNERS = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], np.float64) - 0.5
_BOX_FACES = np.array(
    [
        [0, 2, 3],
        [0, 3, 1],  # -z
        [4, 5, 7],
        [4, 7, 6],  # +z
        [0, 1, 5],
        [0, 5, 4],  # -y
        [2, 6, 7],
        [2, 7, 3],  # +y
        [0, 4, 6],
        [0, 6, 2],  # -x
        [1, 3, 7],
        [1, 7, 5],
    ],  # +x
    np.int64,
)


def _batch_faces(template: np.ndarray, n: int, nv: int) -> np.ndarray:
    return (template[None, :, :] + (np.arange(n) * nv)[:, None, None]).reshape(-1, 3)


def rotation_z(angle) -> np.ndarray:
    """(N, 3, 3) rotations about +z (or (3, 3) for a scalar)."""
    a = np.asarray(angle, np.float64)
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(a), np.ones_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def box_batch(centers, sizes, rotations=None) -> tuple[np.ndarray, np.ndarray]:
    """N boxes: ``sizes`` (N, 3) full extents along the box's local axes,
    ``rotations`` (N, 3, 3) local-to-world (identity if None)."""
    centers = np.atleast_2d(np.asarray(centers, np.float64))
    sizes = np.broadcast_to(np.asarray(sizes, np.float64), centers.shape)
    local = _BOX_CORNERS[None, :, :] * sizes[:, None, :]
    if rotations is not None:
        local = np.einsum("nij,nkj->nki", np.broadcast_to(rotations, (len(centers), 3, 3)), local)
    v = (local + centers[:, None, :]).reshape(-1, 3)
    return v, _batch_faces(_BOX_FACES, len(centers), 8)


def _frames(p0: np.ndarray, p1: np.ndarray, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (N,3,3) whose local x runs p0->p1 (local z as close to ``up``
    as possible), and the segment lengths."""
    d = p1 - p0
    length = np.linalg.norm(d, axis=1)
    x = d / np.maximum(length, 1e-12)[:, None]
    up = np.broadcast_to(np.asarray(up, np.float64), x.shape)
    # Fall back to +y where the segment is parallel to up.
    alt = np.broadcast_to(np.array([0.0, 1.0, 0.0]), x.shape)
    par = np.abs(np.sum(x * up, 1)) > 0.999
    up = np.where(par[:, None], alt, up)
    y = np.cross(up, x)
    y /= np.linalg.norm(y, axis=1, keepdims=True)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-1), length


def beam_batch(p0, p1, width, height, up=(0.0, 0.0, 1.0)) -> tuple[np.ndarray, np.ndarray]:
    """Boxes from ``p0`` to ``p1`` (N, 3) with cross-section ``width`` (across,
    horizontal where possible) x ``height`` (towards ``up``)."""
    p0 = np.atleast_2d(np.asarray(p0, np.float64))
    p1 = np.atleast_2d(np.asarray(p1, np.float64))
    rot, length = _frames(p0, p1, up)
    n = len(p0)
    sizes = np.column_stack([length, np.broadcast_to(width, n), np.broadcast_to(height, n)])
    return box_batch(0.5 * (p0 + p1), sizes, rot)


def prism_batch(polygons, depth, origins, rotations=None) -> tuple[np.ndarray, np.ndarray]:
    """N convex polygons (N, P, 2) given counter-clockwise in the local (x, z)
    plane, extruded over local y in [-depth/2, depth/2]; then rotated and moved
    to ``origins`` (N, 3)."""
    poly = np.asarray(polygons, np.float64)
    if poly.ndim == 2:
        poly = np.broadcast_to(poly, (len(np.atleast_2d(origins)),) + poly.shape)
    n, p = poly.shape[:2]
    depth = np.broadcast_to(np.asarray(depth, np.float64), (n,))
    front = np.stack([poly[..., 0], np.broadcast_to(-0.5 * depth[:, None], (n, p)), poly[..., 1]], -1)
    back = front.copy()
    back[..., 1] = 0.5 * depth[:, None]
    local = np.concatenate([front, back], axis=1)  # (N, 2P, 3)
    if rotations is not None:
        local = np.einsum("nij,nkj->nki", np.broadcast_to(rotations, (n, 3, 3)), local)
    v = (local + np.atleast_2d(np.asarray(origins, np.float64))[:, None, :]).reshape(-1, 3)
    # A polygon counter-clockwise in (x, z) seen from -y faces -y: the front cap.
    fan = np.array([[0, i, i + 1] for i in range(1, p - 1)], np.int64)
    sides = []
    for i in range(p):
        j = (i + 1) % p
        sides += [[i, p + i, p + j], [i, p + j, j]]
    template = np.concatenate([fan, fan[:, [0, 2, 1]] + p, np.array(sides, np.int64)])
    return v, _batch_faces(template, n, 2 * p)


def lathe(
    radii, heights, segments: int = 24, cap_bottom: bool = False, cap_top: bool = False, phase: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Revolve the profile (r_i, z_i) about +z. A profile running upwards on
    the outside (or downwards on the inside) faces outwards. ``cap_bottom``
    closes the first point's ring with a fan facing -z, ``cap_top`` the last
    one's facing +z. Radii must be > 0 (a cap supplies the axis point)."""
    r = np.asarray(radii, np.float64)
    z = np.asarray(heights, np.float64)
    m, s = len(r), int(segments)
    ang = phase + 2.0 * np.pi * np.arange(s) / s
    ring = np.stack([np.cos(ang), np.sin(ang)], -1)
    v = np.concatenate([r[:, None, None] * ring[None, :, :], np.broadcast_to(z[:, None, None], (m, s, 1))], -1).reshape(
        -1, 3
    )
    i = np.arange(m - 1)[:, None]
    j = np.arange(s)[None, :]
    j1 = (j + 1) % s
    a, b, c, d = i * s + j, i * s + j1, (i + 1) * s + j, (i + 1) * s + j1
    faces = [np.stack([a, b, d], -1).reshape(-1, 3), np.stack([a, d, c], -1).reshape(-1, 3)]
    extra: list[list[float]] = []
    if cap_bottom:
        centre = len(v) + len(extra)
        extra.append([0.0, 0.0, z[0]])
        faces.append(np.column_stack([np.full(s, centre), (np.arange(s) + 1) % s, np.arange(s)]))
    if cap_top:
        centre = len(v) + len(extra)
        extra.append([0.0, 0.0, z[-1]])
        top = (m - 1) * s
        faces.append(np.column_stack([np.full(s, centre), top + np.arange(s), top + (np.arange(s) + 1) % s]))
    if extra:
        v = np.concatenate([v, np.array(extra)])
    return v, np.concatenate(faces).astype(np.int64)


def icosphere(subdivisions: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Unit sphere from a subdivided icosahedron (20 * 4**n faces)."""
    t = (1.0 + 5**0.5) / 2.0
    v = np.array(
        [
            [-1, t, 0],
            [1, t, 0],
            [-1, -t, 0],
            [1, -t, 0],
            [0, -1, t],
            [0, 1, t],
            [0, -1, -t],
            [0, 1, -t],
            [t, 0, -1],
            [t, 0, 1],
            [-t, 0, -1],
            [-t, 0, 1],
        ],
        np.float64,
    )
    f = np.array(
        [
            [0, 11, 5],
            [0, 5, 1],
            [0, 1, 7],
            [0, 7, 10],
            [0, 10, 11],
            [1, 5, 9],
            [5, 11, 4],
            [11, 10, 2],
            [10, 7, 6],
            [7, 1, 8],
            [3, 9, 4],
            [3, 4, 2],
            [3, 2, 6],
            [3, 6, 8],
            [3, 8, 9],
            [4, 9, 5],
            [2, 4, 11],
            [6, 2, 10],
            [8, 6, 7],
            [9, 8, 1],
        ],
        np.int64,
    )
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    for _ in range(int(subdivisions)):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        inv = inv.reshape(-1)
        mid = v[uniq[:, 0]] + v[uniq[:, 1]]
        mid /= np.linalg.norm(mid, axis=1, keepdims=True)
        nf = len(f)
        m01, m12, m20 = (inv[:nf] + len(v), inv[nf : 2 * nf] + len(v), inv[2 * nf :] + len(v))
        v = np.concatenate([v, mid])
        f = np.concatenate(
            [
                np.column_stack([f[:, 0], m01, m20]),
                np.column_stack([f[:, 1], m12, m01]),
                np.column_stack([f[:, 2], m20, m12]),
                np.column_stack([m01, m12, m20]),
            ]
        )
    return v, f


def convex_hull(points, eps: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Convex hull of a small point set (incremental; O(n^2), fine for n < ~500).
    Returns (hull vertices, faces) with only the points on the hull kept."""
    p = np.asarray(points, np.float64)
    n = len(p)
    if n < 4:
        raise ValueError("convex hull needs at least 4 points")
    scale = float(np.ptp(p, axis=0).max()) or 1.0
    tol = eps * scale
    i0 = int(np.argmin(p[:, 0]))
    i1 = int(np.argmax(np.linalg.norm(p - p[i0], axis=1)))
    line = p[i1] - p[i0]
    i2 = int(np.argmax(np.linalg.norm(np.cross(p - p[i0], line), axis=1)))
    nrm = np.cross(p[i1] - p[i0], p[i2] - p[i0])
    dist = (p - p[i0]) @ nrm
    i3 = int(np.argmax(np.abs(dist)))
    if abs(dist[i3]) <= tol * np.linalg.norm(nrm):
        raise ValueError("convex hull of coplanar points")
    faces = [(i0, i1, i2), (i0, i3, i1), (i1, i3, i2), (i2, i3, i0)]
    if dist[i3] > 0:  # make the first face point away from i3
        faces = [(a, c, b) for a, b, c in faces]

    def planes(fs):
        f = np.array(fs)
        nn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        nn /= np.linalg.norm(nn, axis=1, keepdims=True)
        return nn, np.sum(nn * p[f[:, 0]], 1)

    nn, off = planes(faces)
    for q in range(n):
        if q in (i0, i1, i2, i3):
            continue
        visible = nn @ p[q] - off > tol
        if not visible.any():
            continue
        vis = [faces[k] for k in np.flatnonzero(visible)]
        edges = {(a, b) for a, b, c in vis} | {(b, c) for a, b, c in vis} | {(c, a) for a, b, c in vis}
        horizon = [(a, b) for a, b in edges if (b, a) not in edges]
        keep = [faces[k] for k in np.flatnonzero(~visible)]
        new = [(a, b, q) for a, b in horizon]
        faces = keep + new
        nn2, off2 = planes(new)
        nn = np.concatenate([nn[~visible], nn2])
        off = np.concatenate([off[~visible], off2])
    f = np.array(faces, np.int64)
    used, inv = np.unique(f, return_inverse=True)
    return p[used], inv.reshape(-1, 3)


def merge(parts: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    vs, fs, off = [], [], 0
    for v, f in parts:
        vs.append(v)
        fs.append(f + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(fs)


def signed_volume(v: np.ndarray, f: np.ndarray) -> float:
    """Divergence-theorem volume; positive for closed, outward-facing shells."""
    t = np.asarray(v, np.float64)[f]
    return float(np.sum(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2]))) / 6.0)


def to_mesh(v, f, *, semantic: int, material: str, albedo, translucency=0.0, specular=0.0) -> Mesh:
    """Mesh with per-face (or scalar) attributes; ``material`` is a name."""
    n = len(f)
    alb = np.broadcast_to(np.asarray(albedo, np.float32), (n, 3))
    return Mesh(
        v,
        f,
        np.full(n, semantic),
        np.full(n, MATERIALS[material]),
        alb,
        np.broadcast_to(np.asarray(translucency, np.float32), (n,)),
        np.broadcast_to(np.asarray(specular, np.float32), (n,)),
    )
