"""Ivy growth after Luft's Ivy Generator: every live root steps at once per iteration
(primary direction, randomness, adhesion to the skeleton, gravity), climbs by reflecting off
the skeleton, dies when floating or trimmed, and branches (see the package docstring)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eden_pipe.errors import ConfigError
from eden_pipe.geometry import UP, any_perpendicular, normalize, uniform_sphere
from eden_pipe.models.ivy.skeletons import Skeleton


@dataclass
class IvyParams:
    """Luft/IvyGen parameters (the Blender IvyGen defaults) plus the clipping extensions."""

    max_length: float = 1.0
    primary_weight: float = 0.5
    random_weight: float = 0.2
    gravity_weight: float = 1.0
    adhesion_weight: float = 0.1
    branching_probability: float = 0.05
    leaf_probability: float = 0.35
    ivy_size: float = 0.02
    leaf_size: float = 0.02
    branch_size: float = 0.001
    max_float_length: float = 0.5
    max_adhesion_distance: float = 1.0
    max_generations: int = 3
    trim_distance: float | None = None  # roots die beyond this distance outside the skeleton
    branch_dir: str = "spread"  # "up" (Luft: new roots start upwards) or "spread" (along the surface)
    ground_z: float = 0.0
    max_roots: int = 20000
    max_steps: int = 400

    @classmethod
    def from_dict(cls, d: dict | None, ignore: tuple[str, ...] = ()) -> IvyParams:
        """Parameters from a preset mapping; unknown keys (other than ``ignore``) are an error."""
        d = {k: v for k, v in dict(d or {}).items() if k not in ignore}
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ConfigError(f"unknown ivy parameter(s) {unknown}; allowed: {sorted(cls.__dataclass_fields__)}")
        return cls(**d)


@dataclass
class IvyGrowth:
    """Grown ivy: nodes sorted by root, chronologically within each root."""

    pos: np.ndarray  # (M,3)
    root: np.ndarray  # (M,) root id
    adhesion: np.ndarray  # (M,3) adhesion vector at the node
    length: np.ndarray  # (M,) length along the root from its start
    climbing: np.ndarray  # (M,) bool
    root_generation: np.ndarray  # (R,)
    root_start: np.ndarray  # (R,) first node index
    root_count: np.ndarray  # (R,) nodes per root
    extra: dict = field(default_factory=dict)

    @property
    def n_roots(self) -> int:
        return len(self.root_start)

    @property
    def n_nodes(self) -> int:
        return len(self.pos)

    def local_index(self) -> np.ndarray:
        return np.arange(self.n_nodes) - self.root_start[self.root]

    def root_length(self) -> np.ndarray:
        """Final length of each root (R,)."""
        last = self.root_start + self.root_count - 1
        return self.length[last]


def surface_directions(normals: np.ndarray, rng: np.random.Generator, up_bias: float) -> np.ndarray:
    """Random directions in the tangent planes, biased towards 'up along the surface'."""
    n = len(normals)
    r = uniform_sphere(n, rng) + up_bias * UP
    r = r - np.sum(r * normals, 1, keepdims=True) * normals
    bad = np.linalg.norm(r, axis=1) < 1e-6
    r[bad] = any_perpendicular(normals[bad])
    return normalize(r)


def grow_ivy(
    skeleton: Skeleton, seeds: np.ndarray, seed_dirs: np.ndarray, params: IvyParams, rng: np.random.Generator
) -> IvyGrowth:
    """Grow ivy from ``seeds`` (S,3) with initial primary directions ``seed_dirs`` (S,3)."""
    P = params
    seeds = np.asarray(seeds, np.float64).reshape(-1, 3)
    cap = max(P.max_roots, len(seeds))
    pos = np.zeros((cap, 3))
    primary = np.zeros((cap, 3))
    length = np.zeros(cap)
    floating = np.zeros(cap)
    gen = np.zeros(cap, np.int64)
    alive = np.zeros(cap, bool)
    n_roots = len(seeds)
    pos[:n_roots] = seeds
    primary[:n_roots] = normalize(np.asarray(seed_dirs, np.float64).reshape(-1, 3))
    alive[:n_roots] = True

    _, n0, _ = skeleton.query(seeds)
    # node chunks: (root ids, positions, adhesion, length, climbing)
    chunks = [(np.arange(n_roots), seeds.copy(), -n0 * 0.0, np.zeros(n_roots), np.ones(n_roots, bool))]
    up_rand = np.array([0.0, 0.0, 0.2])
    for _step in range(P.max_steps):
        idx = np.flatnonzero(alive[:n_roots])
        if len(idx) == 0:
            break
        m = len(idx)
        p = pos[idx]
        rnd = normalize(rng.uniform(-0.5, 0.5, (m, 3)) + up_rand)
        _, nrm, sd = skeleton.query(p)
        d = np.maximum(sd, 0.0)
        adh = -nrm * np.clip(1.0 - d / P.max_adhesion_distance, 0.0, 1.0)[:, None]
        grow = P.ivy_size * (P.primary_weight * primary[idx] + P.random_weight * rnd + P.adhesion_weight * adh)
        grav = P.ivy_size * P.gravity_weight * np.power(np.clip(floating[idx] / P.max_float_length, 0, None), 0.7)
        new = p + grow
        new[:, 2] -= grav
        # collision: reflect the penetrating part off the skeleton surface, and off the ground
        _, n2, sd2 = skeleton.query(new)
        hit = sd2 < 0.0
        new[hit] -= 2.0 * sd2[hit, None] * n2[hit]
        low = new[:, 2] < P.ground_z
        new[low, 2] = 2 * P.ground_z - new[low, 2]
        climbing = hit | low
        if P.trim_distance is not None:
            sd_new = skeleton.signed_distance(new)
            inside_shell = sd_new <= P.trim_distance
        else:
            inside_shell = np.ones(m, bool)
        step = new - p
        seg = np.linalg.norm(step, axis=1)
        gdir = step.copy()
        gdir[:, 2] += grav
        gdir = normalize(gdir)
        primary[idx] = normalize(primary[idx] + 0.5 * (gdir - primary[idx]))
        length[idx] += seg
        floating[idx] = np.where(climbing, 0.0, floating[idx] + seg)
        pos[idx] = new
        keep = inside_shell
        chunks.append((idx[keep], new[keep], adh[keep], length[idx][keep], climbing[keep]))
        alive[idx] = keep & (length[idx] < P.max_length) & (floating[idx] < P.max_float_length)

        # branching: probability peaks at half the maximum length
        live = idx[alive[idx]]
        live = live[gen[live] < P.max_generations - 1]
        if len(live) and n_roots < cap:
            weight = 1.0 - (np.cos(length[live] / P.max_length * 2 * np.pi) * 0.5 + 0.5)
            born = live[rng.uniform(0, 1, len(live)) < P.branching_probability * weight]
            born = born[: cap - n_roots]
            k = len(born)
            if k:
                new_ids = np.arange(n_roots, n_roots + k)
                pos[new_ids] = pos[born]
                if P.branch_dir == "up":
                    primary[new_ids] = UP
                else:
                    _, nb, _ = skeleton.query(pos[born])
                    dirs = surface_directions(nb, rng, 0.3)
                    primary[new_ids] = normalize(dirs + 0.3 * primary[born])
                length[new_ids] = 0.0
                floating[new_ids] = floating[born]
                gen[new_ids] = gen[born] + 1
                alive[new_ids] = True
                chunks.append((new_ids, pos[born].copy(), np.zeros((k, 3)), np.zeros(k), np.ones(k, bool)))
                n_roots += k

    root = np.concatenate([c[0] for c in chunks])
    order = np.argsort(root, kind="stable")
    root = root[order]
    node_pos = np.concatenate([c[1] for c in chunks])[order]
    node_adh = np.concatenate([c[2] for c in chunks])[order]
    node_len = np.concatenate([c[3] for c in chunks])[order]
    node_climb = np.concatenate([c[4] for c in chunks])[order]
    counts = np.bincount(root, minlength=n_roots)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    # the seed/branch node of a root takes the adhesion of its first grown node
    first = starts[counts > 1]
    node_adh[first] = node_adh[first + 1]
    return IvyGrowth(
        pos=node_pos,
        root=root,
        adhesion=node_adh,
        length=node_len,
        climbing=node_climb,
        root_generation=gen[:n_roots].copy(),
        root_start=starts,
        root_count=counts,
    )
