"""Leaf sites along grown ivy: how many leaves each segment carries (Luft's weighting by
relative length, optional evening-out by light competition) and how each blade faces."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe.geometry import UP, normalize, uniform_sphere
from eden_pipe.models.ivy.growth import IvyGrowth


def _smooth_per_root(growth: IvyGrowth, values: np.ndarray, half_window: int) -> np.ndarray:
    """Moving average of per-node values within each root (window clipped at root ends)."""
    cs = np.concatenate([np.zeros((1,) + values.shape[1:]), np.cumsum(values, axis=0)])
    i = np.arange(growth.n_nodes)
    s = growth.root_start[growth.root]
    e = s + growth.root_count[growth.root] - 1
    lo = np.maximum(i - half_window, s)
    hi = np.minimum(i + half_window, e)
    return (cs[hi + 1] - cs[lo]) / (hi - lo + 1).reshape((-1,) + (1,) * (values.ndim - 1))


@dataclass
class LeafSites:
    positions: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    weights: np.ndarray  # relative length along the root, in [0, 1]


def ivy_leaves(
    growth: IvyGrowth,
    rng: np.random.Generator,
    *,
    per_node: float = 1.0,
    probability: float = 0.35,
    weight_floor: float = 0.0,
    normal_jitter: float = 0.4,
    up_bias: float = 0.2,
    offset: tuple[float, float] = (0.0, 0.0),
    smooth: int = 3,
    expected_count: float | None = None,
    spread: float = 0.0,
    even_cell: float = 0.0,
    oversample: float = 2.5,
) -> LeafSites:
    """Leaf sites along the ivy segments.

    Each segment carries ``per_node`` candidate leaves (fractions drawn
    stochastically), each kept with probability ``probability * w`` where
    ``w = floor + (1 - floor) * (length / root_length) ** 0.7`` grows with the
    relative length along the root (Luft). With ``expected_count`` the
    candidates per node are chosen so that about that many leaves result;
    with ``even_cell`` too, ``oversample`` times as many candidates are drawn
    and thinned by capping the count per ``even_cell``-sized voxel (competition
    for light), which evens out the foliage density.
    Blades face away from the surface (the smoothed adhesion vector,
    reversed), tilted by random jitter and a phototropic ``up_bias``;
    ``offset`` pushes the leaf base outwards and ``spread`` scatters it sideways (metres)."""
    g = growth
    local = g.local_index()
    seg_end = np.flatnonzero(local >= 1)
    if len(seg_end) == 0:
        z = np.zeros((0, 3))
        return LeafSites(z, z, z, np.zeros(0))
    total = np.maximum(g.root_length()[g.root[seg_end]], 1e-9)
    rel = np.clip(g.length[seg_end] / total, 0.0, 1.0)
    w = weight_floor + (1.0 - weight_floor) * rel**0.7
    if expected_count is not None:
        over = oversample if even_cell > 0 else 1.0
        per_node = over * float(expected_count) / max(probability * float(w.sum()), 1e-9)
    base_n = np.floor(per_node)
    count = (base_n + (rng.uniform(0, 1, len(seg_end)) < per_node - base_n)).astype(np.int64)
    cand = np.repeat(seg_end, count)
    wc = np.repeat(w, count)
    relc = np.repeat(rel, count)
    keep = rng.uniform(0, 1, len(cand)) < probability * wc
    cand, relc = cand[keep], relc[keep]
    k = len(cand)
    u = rng.uniform(0, 1, k)[:, None]
    a, b = g.pos[cand - 1], g.pos[cand]
    pos = a + u * (b - a)
    if even_cell > 0 and expected_count is not None and k > expected_count:
        # Competition for light: cap the leaves per cell so the foliage is evenly dense.
        _, cell = np.unique(np.floor(pos / even_cell).astype(np.int64), axis=0, return_inverse=True)
        cell = cell.reshape(-1)
        counts = np.bincount(cell).astype(np.float64)
        lo_q, hi_q = 0.0, counts.max()
        for _ in range(40):
            q = 0.5 * (lo_q + hi_q)
            if np.minimum(counts, q).sum() < expected_count:
                lo_q = q
            else:
                hi_q = q
        keep = rng.uniform(0, 1, k) < np.minimum(1.0, hi_q / counts[cell])
        cand, relc, pos = cand[keep], relc[keep], pos[keep]
        a, b = a[keep], b[keep]
        k = len(cand)
    adh = _smooth_per_root(g, g.adhesion, smooth)[cand]
    alen = np.linalg.norm(adh, axis=1)
    outward = np.where(alen[:, None] > 1e-6, -adh / np.maximum(alen, 1e-12)[:, None], UP)
    normal = normalize(outward + normal_jitter * uniform_sphere(k, rng) + up_bias * UP)
    seg_dir = normalize(b - a)
    tangent = normalize(seg_dir + 0.9 * uniform_sphere(k, rng) + 0.3 * outward)
    pos = pos + outward * rng.uniform(offset[0], offset[1], k)[:, None]
    if spread > 0:  # scatter sideways (in the surface plane) to even out clumping along stems
        lat = uniform_sphere(k, rng)
        lat -= np.sum(lat * outward, 1, keepdims=True) * outward
        pos = pos + spread * rng.uniform(0, 1, k)[:, None] * lat
    return LeafSites(pos, normal, tangent, relc)
