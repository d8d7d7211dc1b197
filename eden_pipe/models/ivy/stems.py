"""Woody parts of ivy plants: stem tubes along the grown roots, and gently curved branch
polylines (inner branches, topiary trunks) for :func:`eden_pipe.models.tubes.tube_mesh`."""

from __future__ import annotations

import numpy as np

from eden_pipe.models.ivy.growth import IvyGrowth
from eden_pipe.models.tubes import tube_mesh


def ivy_stems(
    growth: IvyGrowth,
    *,
    radius: float = 0.0015,
    every: int = 3,
    sides: int = 3,
    generation_scale: float = 0.75,
    min_radius: float = 0.0004,
    ground_z: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Thin stem tubes along every root, keeping every ``every``-th node (and each root's last);
    thicker towards the root's start, thinner for later generations."""
    g = growth
    local = g.local_index()
    last = local == g.root_count[g.root] - 1
    keep = ((local % every) == 0) | last
    keep &= g.root_count[g.root] >= 2
    idx = np.flatnonzero(keep)
    total = np.maximum(g.root_length()[g.root[idx]], 1e-9)
    frac = 1.0 - g.length[idx] / total
    rad = radius * (0.45 + 0.55 * frac) * generation_scale ** g.root_generation[g.root[idx]]
    rad = np.maximum(rad, min_radius)
    pts = g.pos[idx].copy()
    pts[:, 2] = np.maximum(pts[:, 2], ground_z + rad)  # keep the tube above the ground
    return tube_mesh(pts, rad, g.root[idx], sides=sides)


def branch_paths(
    starts: np.ndarray,
    ends: np.ndarray,
    rng: np.random.Generator,
    *,
    segments: int = 4,
    wobble: float = 0.15,
    sag: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Gently curved polylines from ``starts`` (B,3) to ``ends`` (B,3): ((B*(segments+1),3) points, path ids)."""
    s = np.asarray(starts, np.float64).reshape(-1, 3)
    e = np.asarray(ends, np.float64).reshape(-1, 3)
    B = len(s)
    t = np.linspace(0, 1, segments + 1)
    d = e - s
    L = np.linalg.norm(d, axis=1)
    off = rng.normal(0, 1, (B, 3)) * (wobble * L)[:, None]
    bend = np.sin(np.pi * t)[None, :, None] * off[:, None, :]
    pts = s[:, None] + t[None, :, None] * d[:, None] + bend
    pts[:, :, 2] -= sag * (np.sin(np.pi * t)[None] * L[:, None])
    ids = np.repeat(np.arange(B), segments + 1)
    return pts.reshape(-1, 3), ids
