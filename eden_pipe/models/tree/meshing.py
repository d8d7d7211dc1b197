"""From skeleton to mesh: stem tubes with a level of detail chosen to fit the triangle budget,
leaf cards, colours, and the final scaling to the garden height."""

from __future__ import annotations

import numpy as np

from eden_pipe import labels
from eden_pipe.colour import jitter_hsv_rows
from eden_pipe.geometry import normalize
from eden_pipe.models.leaves import card_leaf
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.models.presets import draw_float
from eden_pipe.models.tree.foliage import place_leaves
from eden_pipe.models.tree.parameters import MAX_LEAF_AREA_GROWTH, MIN_RADIUS, RING_EPS, TreeParams, tree_params
from eden_pipe.models.tree.skeleton import Skeleton, grow_skeleton
from eden_pipe.models.tree.stems import StemLevel, taper_radius
from eden_pipe.models.tubes import ring_faces, ring_vertices
from eden_pipe.rng import rng_for


def _level_sides(p: TreeParams) -> list[int]:
    lobes = int(p["Lobes"]) if float(p["LobeDepth"]) > 0 else 0
    trunk = 8 if lobes == 0 else int(min(16, max(8, 2 * lobes + 2)))
    return [trunk, 6, 4, 3]


def _ring_z(p: TreeParams, lvl: StemLevel, step: int) -> np.ndarray:
    R = lvl.res
    zs = set(np.round(np.arange(0, R + 1, max(step, 1)) / R, 9).tolist())
    zs.add(1.0)
    if lvl.level == 0:
        if float(p["Flare"]) > 0:
            zs.update([0.02, 0.05, 0.09])
        if float(p.lv["nTaper"][0]) >= 2:
            r0 = float(lvl.radius[0])
            L = float(lvl.length[0])
            n_extra = int(min(160, max(8, 4 * L / max(2 * r0, 1e-6))))
            zs.update(np.round(np.linspace(0, 1, n_extra + 1), 9).tolist())
    z = np.array(sorted(zs))
    keep = np.concatenate([[True], np.diff(z) > 2e-3])
    keep[-1] = True
    z = z[keep]
    if len(z) >= 2 and z[-1] - z[-2] <= 2e-3:
        z = np.delete(z, -2)
    return z


def _tube_tris(lvl: StemLevel, z: np.ndarray, sides: int) -> int:
    nq = sides if sides >= 3 else 1
    zs = lvl.start / lvl.res
    valid = (z[None, :-1] >= zs[:, None] - RING_EPS).sum(axis=1)
    return int(valid.sum()) * nq * 2


def _stem_tubes(p: TreeParams, lvl: StemLevel, z: np.ndarray, sides: int, min_radius: float):
    """Vertices (V,3), faces (F,3) and the stem row of each face for one level's tubes."""
    N, R = lvl.n, lvl.res
    M = len(z)
    x = z * R
    j = np.minimum(np.floor(x + 1e-9).astype(np.int64), R - 1)
    u = x - j
    P = lvl.points
    centers = P[:, j] + (P[:, j + 1] - P[:, j]) * u[None, :, None]  # (N, M, 3)
    seg_dir = lvl.frames[:, :, :, 2]  # (N, R, 3)
    dirs = seg_dir[:, j]
    joint = (np.abs(u) < 1e-6) & (j > 0)
    if np.any(joint):
        jj = j[joint]
        dirs[:, joint] = normalize(seg_dir[:, jj - 1] + seg_dir[:, jj])
    # ring frames by parallel transport of the first segment's x axis
    U = np.empty((N, M, 3))
    V = np.empty((N, M, 3))
    prev = lvl.frames[:, 0, :, 0]
    for m in range(M):
        dm = dirs[:, m]
        um = prev - dm * np.sum(prev * dm, axis=1, keepdims=True)
        um = normalize(um)
        U[:, m] = um
        V[:, m] = np.cross(dm, um)
        prev = um
    Zb = np.broadcast_to(z[None, :], (N, M))
    radius = taper_radius(p, lvl.level, lvl.radius[:, None], lvl.length[:, None], Zb) * lvl.rfac[:, j]
    radius = np.maximum(radius, min_radius)
    if sides >= 3:
        phi = np.arange(sides) * (2 * np.pi / sides)
    else:
        phi = np.array([0.0, np.pi])
    rr = np.broadcast_to(radius[:, :, None], (N, M, len(phi)))
    if lvl.level == 0 and float(p["LobeDepth"]) > 0 and int(p["Lobes"]) > 0:
        rr = rr * (1.0 + float(p["LobeDepth"]) * np.sin(int(p["Lobes"]) * phi))[None, None, :]
    verts = ring_vertices(centers, rr, U, V, phi)
    ns = len(phi)
    nq = ns if ns >= 3 else 1  # a two-point "ring" is a flat ribbon: one quad per ring pair
    tmpl = ring_faces(np.arange(M - 1), ns, nq).reshape(-1, 3)  # (Q*2, 3)
    m_idx = np.repeat(np.arange(M - 1), nq)
    ring_of_face = np.repeat(m_idx, 2)
    zs = lvl.start / R
    valid = z[ring_of_face][None, :] >= zs[:, None] - RING_EPS  # (N, Q*2)
    faces = tmpl[None] + (np.arange(N) * (M * ns))[:, None, None]
    stem_of_face = np.broadcast_to(np.arange(N)[:, None], valid.shape)
    return verts.reshape(-1, 3), faces[valid], stem_of_face[valid]


_DETAIL = [  # (sides per level 1..3 as offsets from the defaults, ring step per level)
    ((6, 4, 3), (1, 1, 1, 1)),
    ((5, 4, 3), (1, 1, 1, 1)),
    ((5, 3, 3), (1, 1, 1, 1)),
    ((4, 3, 2), (1, 1, 1, 1)),
    ((4, 3, 2), (1, 1, 2, 2)),
    ((3, 2, 2), (1, 2, 2, 2)),
    ((3, 2, 2), (1, 2, 3, 3)),
    ((2, 2, 2), (1, 3, 4, 4)),
]


def _choose_detail(p: TreeParams, skel: Skeleton, stem_budget: int):
    """Pick sides/ring steps per level (and levels to drop) so stem triangles fit."""
    base = _level_sides(p)
    n_levels = len(skel.levels)
    for drop in range(n_levels):
        keep_levels = n_levels - drop
        for deep, steps in _DETAIL:
            sides = [base[0]] + list(deep)
            zsets = [_ring_z(p, lvl, steps[lvl.level]) for lvl in skel.levels[:keep_levels]]
            tris = sum(
                _tube_tris(lvl, z, sides[lvl.level]) for lvl, z in zip(skel.levels[:keep_levels], zsets, strict=True)
            )
            if tris <= stem_budget:
                return sides, zsets, keep_levels, tris
    # trunk only, as a triangular prism with as many rings as still fit
    trunk = skel.levels[0]
    k = int(np.clip(stem_budget // 6 + 1, 2, 2 * trunk.res + 1))
    while True:
        z = np.linspace(0.0, 1.0, k)
        tri = _tube_tris(trunk, z, 3)
        if tri <= stem_budget or k == 2:
            return [3, 2, 2, 2], [z], 1, tri
        k -= 1


def build_tree(
    species: str, seed: int, height_range: tuple[float, float] | None = None, triangle_budget: int = 150_000
) -> Mesh:
    """A Weber-Penn tree of ``species`` as a :class:`Mesh` (Z up, trunk base at the origin).

    The height (top of the highest vertex) is drawn uniformly from
    ``height_range`` (metres; the preset's ``height_m`` if None) and the tree is
    scaled uniformly to it. Same (species, seed, budget) gives identical arrays.
    The mesh never has more than ``triangle_budget`` triangles: over budget,
    stems lose sides and rings and leaves are merged into fewer, larger ones.
    """
    p = tree_params(species)
    skel = grow_skeleton(species, seed, p)
    budget = int(triangle_budget)
    if budget < 16:
        raise ValueError(f"triangle_budget too small: {budget}")
    shape = card_leaf(p["leaf_shape"])
    tpl = len(shape["faces"])
    leaf_full = skel.n_leaves_full * tpl
    leaf_reserve = min(leaf_full, int(0.6 * budget))
    sides, zsets, keep_levels, stem_tris = _choose_detail(p, skel, budget - leaf_reserve)
    max_leaves = max(0, (budget - stem_tris) // tpl) if leaf_full > 0 else 0
    # tight budgets may grow merged leaves further so the crown keeps its mass
    leaves = place_leaves(skel, max_leaves, MAX_LEAF_AREA_GROWTH * max(1.0, 150_000 / budget))

    rng_c = rng_for(seed, "tree", species, "color")
    verts, faces, mats, albedo, transl, spec = [], [], [], [], [], []
    n_v = 0
    # ---- bark
    bark = jitter_hsv_rows(
        np.asarray(p["bark_color"], np.float64),
        rng_c.uniform(-0.02, 0.02),
        rng_c.uniform(0.85, 1.15),
        rng_c.uniform(0.8, 1.2),
    )[0]
    for lvl, z in zip(skel.levels[:keep_levels], zsets, strict=True):
        v, f, stem = _stem_tubes(p, lvl, z, sides[lvl.level], 0.4 * MIN_RADIUS * skel.scale)
        stem_shade = 1.0 + (rng_c.random(lvl.n) * 2 - 1) * 0.06
        col = np.clip(bark[None, :] * stem_shade[stem][:, None] * (1.0 + 0.04 * lvl.level), 0, 1)
        verts.append(v)
        faces.append(f + n_v)
        n_v += len(v)
        mats.append(np.full(len(f), MATERIALS["bark"], np.uint8))
        albedo.append(col)
        transl.append(np.zeros(len(f)))
        spec.append(np.full(len(f), 0.01))
    # ---- leaves
    if leaves.n:
        tv, tf = shape["verts"], shape["faces"]
        W = leaves.width[:, None, None]
        Lg = leaves.length[:, None, None]
        lv_verts = (
            leaves.position[:, None, :]
            + tv[None, :, 0:1] * W * leaves.x[:, None, :]
            + tv[None, :, 1:2] * Lg * leaves.z[:, None, :]
            + tv[None, :, 2:3] * W * leaves.y[:, None, :]
        )  # (K, m, 3)
        above = lv_verts[:, :, 2].min(axis=1) > 0.0
        lv_verts = lv_verts[above]
        alt = leaves.alt[above]
        K = len(lv_verts)
        m = tv.shape[0]
        lf = tf[None] + (np.arange(K) * m)[:, None, None] + n_v
        verts.append(lv_verts.reshape(-1, 3))
        faces.append(lf.reshape(-1, 3))
        n_v += K * m
        base_leaf = jitter_hsv_rows(
            np.asarray(p["leaf_color"], np.float64),
            rng_c.uniform(-0.025, 0.025),
            rng_c.uniform(0.85, 1.15),
            rng_c.uniform(0.8, 1.2),
        )[0]
        cols = np.tile(base_leaf, (K, 1))
        if p["leaf_color_alt"] is not None and alt.any():
            cols[alt] = np.asarray(p["leaf_color_alt"], np.float64)
        cols = jitter_hsv_rows(
            cols, rng_c.uniform(-0.012, 0.012, K), rng_c.uniform(0.92, 1.08, K), rng_c.uniform(0.88, 1.12, K)
        )
        tri_per = len(tf)
        mats.append(np.full(K * tri_per, MATERIALS["leaf"], np.uint8))
        albedo.append(np.repeat(cols, tri_per, axis=0))
        transl.append(np.full(K * tri_per, float(p["leaf_translucency"])))
        spec.append(np.full(K * tri_per, float(p["leaf_specular"])))

    V = np.concatenate(verts)
    Fc = np.concatenate(faces).astype(np.int64)
    # drop vertices no face uses (clone rows' shared rings)
    used = np.zeros(len(V), bool)
    used[Fc.ravel()] = True
    remap = np.cumsum(used) - 1
    V = V[used]
    Fc = remap[Fc]
    # ---- garden height
    lo, hi = height_range if height_range is not None else tuple(p["height_m"])
    h_rng = rng_for(seed, "tree", species, "height")
    target = draw_float([float(lo), float(hi)], h_rng)
    top = float(V[:, 2].max())
    V = V * (target / max(top, 1e-9))
    n_f = len(Fc)
    return Mesh(
        V,
        Fc,
        np.full(n_f, labels.TREE, np.uint8),
        np.concatenate(mats),
        np.concatenate(albedo),
        np.concatenate(transl),
        np.concatenate(spec),
    )
