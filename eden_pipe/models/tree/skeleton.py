"""The stem hierarchy of one tree: the trunk, then each level's children placed along their
parents and grown, with radii and the number of leaves each last-level stem carries."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eden_pipe.geometry import local_axis_matrices
from eden_pipe.models.tree.foliage import LeafSet
from eden_pipe.models.tree.parameters import DEG, MAX_CHILDREN, MIN_RADIUS, TreeParams, shape_ratio, tree_params
from eden_pipe.models.tree.stems import (
    StemLevel,
    Uniforms,
    carry_round,
    grow_level,
    interp_spine,
    radius_at,
)
from eden_pipe.rng import rng_for


@dataclass
class Skeleton:
    species: str
    seed: int
    params: TreeParams
    scale: float  # sampled Scale +- ScaleV (metres, before garden scaling)
    levels: list[StemLevel]
    leaf_counts: np.ndarray  # (N_last,) full-detail leaves per last-level stem
    leaves: LeafSet = field(default_factory=LeafSet.empty)
    leaf_aggregation: float = 1.0  # leaves merged into one (>= 1)

    @property
    def n_leaves_full(self) -> int:
        return int(self.leaf_counts.sum())

    def children_per_stem(self, level: int) -> np.ndarray:
        """Number of level-``level`` stems (clones excluded) whose parent is each row of level-1."""
        child = self.levels[level]
        orig = ~child.is_clone
        return np.bincount(child.parent[orig], minlength=self.levels[level - 1].n)


def place_children(p: TreeParams, parent: StemLevel, d_child: int, scale: float, rnd: Uniforms):
    """Positions, frames, lengths and bookkeeping for all level-``d_child`` stems."""
    lv = p.lv
    R = parent.res
    base_frac = float(p["BaseSize"]) if parent.level == 0 else float(lv["nBaseSize"][parent.level])
    a = np.maximum(base_frac, parent.start / R)
    coverage = np.clip((1.0 - a) / max(1.0 - base_frac, 1e-6), 0.0, 1.0)
    nbr = float(lv["nBranches"][d_child])
    if parent.level == 0:
        total = np.full(parent.n, nbr)
    elif parent.level == 1:
        rel = parent.length / np.maximum(parent.parent_length, 1e-9)
        total = nbr * (0.2 + 0.8 * rel / np.maximum(parent.lmax, 1e-6))
    else:
        total = nbr * (1.0 - 0.5 * parent.offset / np.maximum(parent.parent_length, 1e-9))
    expected = np.maximum(total, 0.0) * coverage
    thin = max(1.0, float(expected.sum()) / MAX_CHILDREN)
    counts, _ = carry_round(expected / thin)
    n = int(counts.sum())
    if n == 0:
        return None
    rows = np.repeat(np.arange(parent.n), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    k = np.arange(n) - first
    cnt = counts[rows].astype(np.float64)
    whorl = int(lv["nWhorl"][d_child])
    rot_deg, rot_v = float(lv["nRotate"][d_child]), float(lv["nRotateV"][d_child])
    phase = rnd.u(parent.n)[rows] * 360.0
    if whorl > 1:
        n_whorls = np.ceil(cnt / whorl)
        wi = k // whorl
        per = np.minimum(whorl, cnt - wi * whorl)
        t = a[rows] + (1.0 - a[rows]) * (wi + 0.5 + rnd.sym(n, 0.1)) / n_whorls
        rot = phase + wi * rot_deg + 360.0 * (k % whorl) / per + rnd.sym(n, 10.0 + rot_v)
    else:
        t = a[rows] + (1.0 - a[rows]) * (k + 0.5 + rnd.sym(n, 0.3)) / cnt
        if rot_deg >= 0:
            rot = phase + k * rot_deg + rnd.sym(n, rot_v)
        else:
            sign = np.where(k % 2 == 0, 1.0, -1.0)
            rot = sign * (180.0 + rot_deg + rnd.sym(n, rot_v))
    t = np.clip(t, a[rows] + 1e-3, 0.999)
    L_par = parent.length[rows]
    off = t * L_par
    L_base = base_frac * L_par
    pos_ratio = (L_par - off) / np.maximum(L_par - L_base, 1e-9)
    # length
    lmax = float(lv["nLength"][d_child]) + rnd.sym(n, float(lv["nLengthV"][d_child]))
    lmax = np.maximum(lmax, 0.0)
    if d_child == 1:
        length = L_par * lmax * shape_ratio(int(p["Shape"]), pos_ratio, p)
    else:
        length = lmax * (L_par - 0.6 * off)
    # down angle
    da, dav = float(lv["nDownAngle"][d_child]), float(lv["nDownAngleV"][d_child])
    if dav >= 0:
        down = da + rnd.sym(n, dav)
    else:
        down = da + dav * (1.0 - 2.0 * shape_ratio(0, pos_ratio))
    position, j = interp_spine(parent.points, parent.frames, rows, t)
    Fseg = parent.frames[rows, j]
    F = Fseg @ local_axis_matrices(2, rot * DEG) @ local_axis_matrices(0, down * DEG)
    cap = radius_at(p, parent, rows, t)
    keep = length > 2e-3 * scale  # zero shape ratio (e.g. flame crowns at the base): no stem
    if not keep.any():
        return None
    meta = dict(parent=rows[keep], offset=off[keep], parent_length=L_par[keep], lmax=lmax[keep], radius_cap=cap[keep])
    return position[keep], F[keep], length[keep], meta, thin


def set_radii(p: TreeParams, lvl: StemLevel, parent: StemLevel, scale: float) -> None:
    """Child radius r_parent * (L / L_parent)^RatioPower, below the parent's radius there."""
    min_r = MIN_RADIUS * scale
    rp = parent.radius[lvl.parent]
    r = rp * (lvl.length / np.maximum(lvl.parent_length, 1e-9)) ** float(p["RatioPower"])
    r = np.minimum(r, 0.95 * lvl.radius_cap)
    lvl.radius = np.maximum(r, min_r)


def grow_skeleton(species: str, seed: int, params: TreeParams | None = None) -> Skeleton:
    """The stem hierarchy of one tree (full detail) plus per-stem leaf counts.

    Deterministic in (species, seed). Leaves themselves are placed later by
    :func:`place_leaves` so that the triangle budget can merge them first.
    """
    p = params or tree_params(species)
    rnd_g = Uniforms(rng_for(seed, "tree", species, "global"))
    scale = float(p["Scale"]) + float(rnd_g.sym(1, float(p["ScaleV"]))[0])
    scale = max(scale, 0.25 * float(p["Scale"]), 0.5)
    trunk_len = max((float(p.lv["nLength"][0]) + float(rnd_g.sym(1, float(p.lv["nLengthV"][0]))[0])) * scale, 0.1)
    scale0 = float(p["0Scale"]) + float(rnd_g.sym(1, float(p["0ScaleV"]))[0])

    levels: list[StemLevel] = []
    frames0 = np.eye(3)[None].copy()
    # a small random heading so that the trunk's curvature plane varies with the seed
    frames0 = local_axis_matrices(2, rnd_g.u(1) * 2 * np.pi) @ frames0
    meta0 = dict(
        parent=np.array([-1]),
        offset=np.zeros(1),
        parent_length=np.array([trunk_len]),
        lmax=np.array([1.0]),
        radius_cap=np.array([np.inf]),
    )
    trunk = grow_level(
        p,
        0,
        scale,
        np.zeros((1, 3)),
        frames0,
        np.array([trunk_len]),
        meta0,
        Uniforms(rng_for(seed, "tree", species, "level", 0)),
    )
    trunk.radius = np.full(trunk.n, max(trunk_len * float(p["Ratio"]) * max(scale0, 0.05), MIN_RADIUS * scale))
    levels.append(trunk)
    for d in range(1, p.levels):
        placed = place_children(p, levels[-1], d, scale, Uniforms(rng_for(seed, "tree", species, "children", d)))
        if placed is None:
            break
        origins, F, lengths, meta, thin = placed
        lvl = grow_level(p, d, scale, origins, F, lengths, meta, Uniforms(rng_for(seed, "tree", species, "level", d)))
        lvl.weight = levels[-1].weight * thin
        set_radii(p, lvl, levels[-1], scale)
        levels.append(lvl)

    last = levels[-1]
    leaf_counts = leaf_counts_per_stem(p, last)
    return Skeleton(species=species, seed=seed, params=p, scale=scale, levels=levels, leaf_counts=leaf_counts)


def leaf_counts_per_stem(p: TreeParams, last: StemLevel) -> np.ndarray:
    n_leaves = float(p["Leaves"])
    if n_leaves == 0:
        return np.zeros(last.n, dtype=np.int64)
    if n_leaves < 0:  # a fan at every stem tip (clones included)
        return np.full(last.n, int(round(-n_leaves * last.weight)), dtype=np.int64)
    R = last.res
    a0 = float(p["LeafStart"])
    a = np.maximum(a0, last.start / R)
    coverage = np.clip((1.0 - a) / max(1.0 - a0, 1e-6), 0.0, 1.0)
    if last.level == 0:
        ratio = np.ones(last.n)
    else:
        ratio = last.offset / np.maximum(last.parent_length, 1e-9)
    dens = n_leaves * shape_ratio(int(p["LeafDistrib"]), ratio, p) * float(p["LeafQuality"])
    counts, _ = carry_round(dens * coverage * last.weight)
    return counts
