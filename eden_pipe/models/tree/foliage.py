"""Leaves of a tree: where they sit on the last stem level, how they face, and how many
full-detail leaves merge into one when the triangle budget is tight."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from eden_pipe.geometry import UP, local_axis_matrices, rotate_vectors
from eden_pipe.models.leaves import card_leaf
from eden_pipe.models.tree.parameters import DEG, MAX_LEAF_AREA_GROWTH, shape_ratio
from eden_pipe.models.tree.stems import Uniforms, carry_round, interp_spine
from eden_pipe.rng import rng_for

if TYPE_CHECKING:
    from eden_pipe.models.tree.skeleton import Skeleton


@dataclass
class LeafSet:
    position: np.ndarray  # (K, 3) leaf base
    x: np.ndarray  # (K, 3) width axis
    y: np.ndarray  # (K, 3) normal
    z: np.ndarray  # (K, 3) length axis
    length: np.ndarray  # (K,)
    width: np.ndarray  # (K,)
    stem: np.ndarray  # (K,) row of the last stem level
    alt: np.ndarray  # (K,) bool: uses the alternative leaf colour

    @property
    def n(self) -> int:
        return len(self.length)

    @classmethod
    def empty(cls) -> LeafSet:
        z3 = np.zeros((0, 3))
        z1 = np.zeros(0)
        return cls(z3, z3, z3, z3, z1, z1, np.zeros(0, np.int64), np.zeros(0, bool))


def place_leaves(skel: Skeleton, max_leaves: int | None = None, max_area_growth: float | None = None) -> LeafSet:
    """Place the skeleton's leaves, merging groups of them into larger ones if over ``max_leaves``.

    A merged leaf grows to keep the foliage area, but by at most
    ``max_area_growth`` (default ``MAX_LEAF_AREA_GROWTH``) times a preset leaf.
    """
    p = skel.params
    last = skel.levels[-1]
    full = skel.leaf_counts.astype(np.float64)
    total = float(full.sum())
    if total <= 0 or (max_leaves is not None and max_leaves <= 0):
        skel.leaves, skel.leaf_aggregation = LeafSet.empty(), 1.0
        return skel.leaves
    agg = 1.0
    if max_leaves is not None and total > max_leaves:
        agg = total / max_leaves
    counts, _ = carry_round(full / agg)
    if max_leaves is not None and counts.sum() > max_leaves:  # rounding overshoot
        excess = int(counts.sum() - max_leaves)
        nz = np.nonzero(counts)[0][::-1][:excess]
        counts[nz] -= 1
    n = int(counts.sum())
    if n == 0:
        skel.leaves, skel.leaf_aggregation = LeafSet.empty(), agg
        return skel.leaves
    agg = total / n
    rnd = Uniforms(rng_for(skel.seed, "tree", skel.species, "leaves"))
    rows = np.repeat(np.arange(last.n), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    k = (np.arange(n) - first).astype(np.float64)
    cnt = counts[rows].astype(np.float64)
    li = min(p.levels, 3)
    lv = p.lv
    R = last.res
    fan = float(p["Leaves"]) < 0
    if fan:
        t = np.ones(n)
        position = last.points[rows, R]
        Fseg = last.frames[rows, R - 1]
        spread = float(p["FanAngle"]) * DEG
        alpha = -0.5 * spread + spread * (k + 0.5) / cnt + rnd.sym(n, 0.1 * spread / np.maximum(cnt, 1))
        tilt = (float(p["FanTilt"]) + rnd.sym(n, 8.0)) * DEG
        F = Fseg @ local_axis_matrices(0, tilt) @ local_axis_matrices(1, alpha)
        bend = 0.0
    else:
        a0 = float(p["LeafStart"])
        a = np.maximum(a0, last.start / R)[rows]
        t = a + (1.0 - a) * (k + 0.5 + rnd.sym(n, 0.35)) / cnt
        t = np.clip(t, 0.0, 1.0)
        position, j = interp_spine(last.points, last.frames, rows, t)
        Fseg = last.frames[rows, j]
        rot_deg, rot_v = float(lv["nRotate"][li]), float(lv["nRotateV"][li])
        if rot_deg >= 0:
            rot = rnd.u(last.n)[rows] * 360.0 + k * rot_deg + rnd.sym(n, rot_v)
        else:
            sign = np.where(k % 2 == 0, 1.0, -1.0)
            rot = sign * (180.0 + rot_deg + rnd.sym(n, rot_v))
        da, dav = float(lv["nDownAngle"][li]), float(lv["nDownAngleV"][li])
        if dav >= 0:
            down = da + rnd.sym(n, dav)
        else:
            down = da + dav * (1.0 - 2.0 * shape_ratio(0, 1.0 - t))
        F = Fseg @ local_axis_matrices(2, rot * DEG) @ local_axis_matrices(0, down * DEG)
        bend = float(p["LeafBend"])
    X, Y, Z = F[:, :, 0].copy(), F[:, :, 1].copy(), F[:, :, 2].copy()
    # the leaf's upper side faces the sky (leaves are two-sided; keep the frame right-handed)
    flip = Y[:, 2] < 0
    X[flip] *= -1
    Y[flip] *= -1
    if bend > 0:
        th_pos = np.arctan2(position[:, 1], position[:, 0])
        th_n = np.arctan2(Y[:, 1], Y[:, 0])
        dth = (th_pos - th_n + np.pi) % (2 * np.pi) - np.pi
        upz = np.tile(UP, (n, 1))
        ang = bend * dth
        X, Y, Z = (rotate_vectors(v, upz, ang) for v in (X, Y, Z))
        axis = np.cross(Y, UP)
        norm = np.linalg.norm(axis, axis=1)
        ok = norm > 1e-9
        axis = np.where(ok[:, None], axis / np.maximum(norm, 1e-12)[:, None], np.array([1.0, 0, 0]))
        phi = np.arccos(np.clip(Y[:, 2], -1, 1)) * bend * ok
        X, Y, Z = (rotate_vectors(v, axis, phi) for v in (X, Y, Z))
    shape = card_leaf(p["leaf_shape"])
    size = float(p["LeafScale"]) / np.sqrt(max(float(p["LeafQuality"]), 1e-3))
    length = size * (1.0 + rnd.sym(n, 0.12))
    width = length * float(p["LeafScaleX"])
    # merged leaves keep the foliage area up to a point; beyond it the crown just gets sparser
    a_len = shape["agg_len"]
    grow = min(agg, MAX_LEAF_AREA_GROWTH if max_area_growth is None else max_area_growth)
    length = length * grow**a_len
    width = width * grow ** (1.0 - a_len)
    position = position + Z * (float(p["LeafStemLen"]) * length)[:, None]
    alt = np.zeros(n, dtype=bool)
    frac = float(p["leaf_alt_fraction"] or 0.0)
    if p["leaf_color_alt"] is not None and frac > 0:
        stem_alt = rnd.u(last.n) < min(1.0, 2.0 * frac)
        alt = stem_alt[rows] & (t > 0.5)
    skel.leaves = LeafSet(position, X, Y, Z, length, width, rows, alt)
    skel.leaf_aggregation = agg
    return skel.leaves
