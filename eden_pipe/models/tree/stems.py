"""Growing the stems of one level: all stems of a level grow together, segment by segment
(curvature, splits into clones, attraction up, pruning), plus the radius profile along a stem."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe.geometry import UP, axis_angle_matrices, local_axis_matrices
from eden_pipe.models.tree.parameters import (
    DEG,
    MAX_FAMILY,
    MAX_STEMS_PER_LEVEL,
    MAX_TRUNK_STEMS,
    TreeParams,
    envelope_inside,
)


@dataclass
class StemLevel:
    """All stems of one level (clones included) as arrays."""

    level: int
    points: np.ndarray  # (N, R+1, 3) spine points
    frames: np.ndarray  # (N, R, 3, 3) segment frames, columns = x, y, z (z along the stem)
    length: np.ndarray  # (N,) stem length (clones: the whole stem's length)
    radius: np.ndarray  # (N,) base radius before split factors
    rfac: np.ndarray  # (N, R) per-segment radius factor from splits
    start: np.ndarray  # (N,) first segment owned by this row (clones > 0)
    parent: np.ndarray  # (N,) row in the previous level (-1 for the trunk)
    offset: np.ndarray  # (N,) distance along the parent to the attachment point
    parent_length: np.ndarray  # (N,)
    lmax: np.ndarray  # (N,) sampled nLength (+- nLengthV)
    family: np.ndarray  # (N,) index of the original stem (clones share it)
    radius_cap: np.ndarray  # (N,) parent radius at the attachment point
    weight: float = 1.0  # stems each row stands for (> 1 when a huge level was thinned)

    @property
    def n(self) -> int:
        return len(self.length)

    @property
    def res(self) -> int:
        return self.frames.shape[1]

    @property
    def is_clone(self) -> np.ndarray:
        return self.start > 0


def turn_toward_up(F: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Turn frames (N,3,3) so their z axis moves toward +Z by ``angle`` (negative: away)."""
    z = F[:, :, 2]
    axis = np.cross(z, UP)
    n = np.linalg.norm(axis, axis=1)
    ok = (n > 1e-9) & (np.abs(angle) > 1e-12)
    if not np.any(ok):
        return F
    out = F.copy()
    rot = axis_angle_matrices(axis[ok] / n[ok, None], angle[ok])
    out[ok] = rot @ F[ok]
    return out


def carry_round(x: np.ndarray, carry: float = 0.0) -> tuple[np.ndarray, float]:
    """Round fractional counts in order with the Weber-Penn carried error.

    ``n_i = int(x_i + err + 0.5); err -= n_i - x_i`` is the same as rounding the
    running sum, which vectorises. Returns the counts and the new error.
    """
    x = np.maximum(np.asarray(x, dtype=np.float64), 0.0)
    if len(x) == 0:
        return np.zeros(0, dtype=np.int64), carry
    total = carry + np.cumsum(x)
    rounded = np.floor(total + 0.5)
    counts = np.diff(np.concatenate([[0.0], rounded])).astype(np.int64)
    return np.maximum(counts, 0), float(total[-1] - rounded[-1])


def interp_spine(points: np.ndarray, frames: np.ndarray, rows: np.ndarray, t: np.ndarray):
    """Position, segment index and fraction at stem fractions ``t`` on ``rows``."""
    R = frames.shape[1]
    x = np.clip(t, 0.0, 1.0) * R
    j = np.minimum(np.floor(x).astype(np.int64), R - 1)
    u = x - j
    p0 = points[rows, j]
    p1 = points[rows, j + 1]
    return p0 + (p1 - p0) * u[:, None], j


def taper_radius(p: TreeParams, level: int, r0: np.ndarray, L: np.ndarray, Z: np.ndarray) -> np.ndarray:
    """Weber-Penn stem radius at fractions Z (broadcast with r0 and L)."""
    taper = float(p.lv["nTaper"][level])
    if taper < 1:
        unit = taper
    elif taper < 2:
        unit = 2.0 - taper
    else:
        unit = 0.0
    taper_z = r0 * (1.0 - unit * Z)
    if taper < 1:
        radius = taper_z
    else:
        z2 = (1.0 - Z) * L
        tz = np.maximum(taper_z, 1e-9)
        if taper < 2:
            z3 = z2
            depth = np.ones_like(z2)
        else:
            z3 = np.abs(z2 - 2.0 * tz * np.floor(z2 / (2.0 * tz) + 0.5))
            depth = np.where(z2 < tz, 1.0, taper - 2.0)
        rounded = (1.0 - depth) * tz + depth * np.sqrt(np.clip(tz * tz - (z3 - tz) ** 2, 0.0, None))
        radius = np.where((taper < 2) & (z3 >= tz), taper_z, rounded)
    if level == 0:
        flare = float(p["Flare"])
        y = np.maximum(0.0, 1.0 - 8.0 * Z)
        radius = radius * (1.0 + flare * (100.0**y - 1.0) / 100.0)
    return radius


def radius_at(p: TreeParams, lvl: StemLevel, rows: np.ndarray, t: np.ndarray) -> np.ndarray:
    R = lvl.res
    j = np.minimum(np.floor(np.clip(t, 0, 1) * R).astype(np.int64), R - 1)
    r = taper_radius(p, lvl.level, lvl.radius[rows], lvl.length[rows], np.clip(t, 0, 1))
    return r * lvl.rfac[rows, j]


class Uniforms:
    """Uniform helpers on one generator."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def sym(self, n, scale=1.0):
        """U(-scale, scale), shape n."""
        return (self.rng.random(n) * 2.0 - 1.0) * scale

    def u(self, n):
        return self.rng.random(n)


def grow_level(p: TreeParams, d: int, scale: float, origins, frames0, lengths, meta: dict, rnd: Uniforms) -> StemLevel:
    """Grow all stems of level ``d`` (segments, curvature, splits, attraction, pruning)."""
    lv = p.lv
    R = int(lv["nCurveRes"][d])
    N = len(lengths)
    pos = np.zeros((N, R + 1, 3))
    pos[:, 0] = origins
    frames = np.zeros((N, R, 3, 3))
    F = frames0.copy()
    L = lengths.astype(np.float64).copy()
    rfac = np.ones((N, R))
    start = np.zeros(N, dtype=np.int64)
    family = np.arange(N)
    upcorr = np.zeros(N)
    meta = {k: np.asarray(v).copy() for k, v in meta.items()}

    curve, back, curve_v = float(lv["nCurve"][d]), float(lv["nCurveBack"][d]), abs(float(lv["nCurveV"][d]))
    seg_splits = float(lv["nSegSplits"][d])
    split_angle, split_angle_v = float(lv["nSplitAngle"][d]), float(lv["nSplitAngleV"][d])
    att = float(p.attraction[d])
    base_splits = int(p["0BaseSplits"]) if d == 0 else 0
    split_height = p["SplitHeight"]
    if split_height is None:
        split_height = float(p["BaseSize"])
    s_base = max(1, int(float(split_height) * R + 0.5)) if R > 1 else 0
    cap = MAX_TRUNK_STEMS if d == 0 else MAX_STEMS_PER_LEVEL
    carry = 0.0

    for s in range(R):
        n_now = len(L)
        # ---- splits at the start of segment s (clones own segments s..R-1)
        if s >= 1 and (seg_splits > 0 or (d == 0 and s == s_base and base_splits > 0)):
            if d == 0 and s == s_base and base_splits > 0:
                counts = np.full(n_now, base_splits, dtype=np.int64)
            else:
                counts, carry = carry_round(np.full(n_now, seg_splits), carry)
            counts = limit_family(counts, family, MAX_TRUNK_STEMS if d == 0 else MAX_FAMILY)
            room = cap - n_now
            if counts.sum() > room:
                counts = np.where(np.cumsum(counts) <= max(room, 0), counts, 0)
            if counts.sum() > 0:
                src = np.nonzero(counts)[0]
                nsrc = counts[src]
                clone_src = np.repeat(src, nsrc)
                branch_idx = np.arange(len(clone_src)) - np.repeat(np.cumsum(nsrc) - nsrc, nsrc) + 1
                # append clone rows (copies of their source)
                pos = np.concatenate([pos, pos[clone_src]])
                frames = np.concatenate([frames, frames[clone_src]])
                F = np.concatenate([F, F[clone_src]])
                L = np.concatenate([L, L[clone_src]])
                rfac = np.concatenate([rfac, rfac[clone_src]])
                start = np.concatenate([start, np.full(len(clone_src), s)])
                family = np.concatenate([family, family[clone_src]])
                upcorr = np.concatenate([upcorr, upcorr[clone_src]])
                meta = {k: np.concatenate([v, v[clone_src]]) for k, v in meta.items()}
                rows = np.concatenate([src, np.arange(n_now, n_now + len(clone_src))])
                b = np.concatenate([np.zeros(len(src), np.int64), branch_idx])
                nb = np.concatenate([nsrc, np.repeat(nsrc, nsrc)]) + 1
                # one split angle and azimuth phase per split event
                ev_angle_src = split_angle + rnd.sym(len(src), split_angle_v)
                ev_phase_src = rnd.u(len(src)) * 2 * np.pi
                ev_of_row = np.concatenate([np.arange(len(src)), np.repeat(np.arange(len(src)), nsrc)])
                z = F[rows, :, 2]
                decl = np.degrees(np.arccos(np.clip(z[:, 2], -1, 1)))
                tilt = np.maximum(0.0, ev_angle_src[ev_of_row] - decl) * DEG
                phi = ev_phase_src[ev_of_row] + 2 * np.pi * b / nb
                axis_local = np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], axis=1)
                axis = np.einsum("nij,nj->ni", F[rows], axis_local)
                Fr = axis_angle_matrices(axis, tilt) @ F[rows]
                if d >= 1:
                    psi = (20.0 + 0.75 * (30.0 + np.abs(decl - 90.0)) * rnd.u(len(rows)) ** 2) * DEG
                    sign = np.where(b % 2 == 1, 1.0, -1.0)
                    psi = np.where(b == 0, 0.0, psi * sign)
                    Fr = axis_angle_matrices(np.tile(UP, (len(rows), 1)), psi) @ Fr
                F[rows] = Fr
                rfac[rows, s:] *= (1.0 / np.sqrt(nb))[:, None]
                if d == 0:
                    upcorr[rows] = 0.5 * tilt / max(R - s, 1)
        n_now = len(L)
        # ---- curvature
        if not (d == 0 and s == 0):
            if back == 0.0:
                base_angle = curve / R
            else:
                base_angle = (2.0 * curve / R) if s < R / 2.0 else (2.0 * back / R)
            ax = (base_angle + rnd.sym(n_now, curve_v / R)) * DEG
            ay = rnd.sym(n_now, 0.5 * curve_v / R) * DEG
            F = F @ local_axis_matrices(0, ax) @ local_axis_matrices(1, ay)
        if d == 0 and np.any(upcorr > 0):
            decl = np.arccos(np.clip(F[:, 2, 2], -1, 1))
            F = turn_toward_up(F, np.minimum(upcorr, decl))
        if att != 0.0:
            decl = np.arccos(np.clip(F[:, 2, 2], -1, 1))
            ang = att * decl / R
            ang = np.where(ang > 0, np.minimum(ang, decl), np.maximum(ang, -(np.pi - decl)))
            F = turn_toward_up(F, ang)
        frames[:, s] = F
        pos[:, s + 1] = pos[:, s] + F[:, :, 2] * (L / R)[:, None]

    # ---- pruning (envelope, then ground): scale whole stem families about their origin
    if d >= 1:
        prune_ratio = float(p["PruneRatio"])
        if prune_ratio > 0:
            f = prune_factor(pos, start, family, lambda q: ~envelope_inside(q, p, scale))
            f = prune_ratio * f + (1.0 - prune_ratio)
            pos, L = apply_prune(pos, L, f)
        ground = 0.01 * scale
        f = prune_factor(pos, start, family, lambda q: q[..., 2] < ground)
        pos, L = apply_prune(pos, L, f)

    return StemLevel(
        level=d,
        points=pos,
        frames=frames,
        length=L,
        radius=np.zeros(len(L)),
        rfac=rfac,
        start=start,
        parent=meta["parent"].astype(np.int64),
        offset=meta["offset"],
        parent_length=meta["parent_length"],
        lmax=meta["lmax"],
        family=family,
        radius_cap=meta["radius_cap"],
    )


def limit_family(counts: np.ndarray, family: np.ndarray, cap: int) -> np.ndarray:
    """Clip clone counts so no stem family (a stem and its clones) exceeds ``cap`` rows."""
    src = np.nonzero(counts)[0]
    if len(src) == 0:
        return counts
    size = np.bincount(family, minlength=family.max() + 1)
    fam = family[src]
    order = np.argsort(fam, kind="stable")
    fs, c = fam[order], counts[src][order]
    cs = np.cumsum(c)
    first = np.concatenate([[True], fs[1:] != fs[:-1]])
    group_base = np.maximum.accumulate(np.where(first, cs - c, 0))
    within = cs - group_base
    allowed = np.maximum(cap - size[fs], 0)
    c_new = np.clip(c - np.maximum(within - allowed, 0), 0, c)
    out = counts.copy()
    out[src[order]] = c_new
    return out


def prune_factor(pos, start, family, outside_fn, iterations: int = 6) -> np.ndarray:
    """Length factor per row so that no owned spine point is outside (family minimum)."""
    N, M = pos.shape[:2]
    R = M - 1
    origin = pos[:, :1]
    f = np.ones(N)
    k_idx = np.arange(M)[None, :]
    owned = k_idx >= np.maximum(start, 1)[:, None]
    for _ in range(iterations):
        q = origin + (pos - origin) * f[:, None, None]
        out = outside_fn(q) & owned
        bad = out.any(axis=1)
        if not bad.any():
            break
        first = np.argmax(out, axis=1)
        # keep the part before the first outside point
        frac = np.clip((first - 0.5) / R, 0.02, 1.0)
        new_f = np.where(bad, f * np.minimum(frac, 0.9), f)
        fam = np.ones(family.max() + 1)
        np.minimum.at(fam, family, new_f)
        f = fam[family]
    return f


def apply_prune(pos, L, f):
    origin = pos[:, :1]
    return origin + (pos - origin) * f[:, None, None], L * f
