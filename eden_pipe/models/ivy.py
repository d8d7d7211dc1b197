"""Ivy growth on analytic skeletons (after Thomas Luft's Ivy Generator).

Hedges and topiaries are grown, as in EDEN, by letting ivy climb a hidden
skeleton shape: a (rounded) box trellis for hedges, a sphere, cone, stacked
spheres or a helix tube for topiaries. The skeleton is never rendered; it only
answers nearest-surface queries (:meth:`Skeleton.query`, an SDF-like
closest point, outward normal and signed distance, vectorised over points).

Growth (:func:`grow_ivy`) follows Luft's rules with the Blender IvyGen
defaults (REFERENCE.md): every live root takes one step per iteration,

    grow    = ivy_size * (wp * primary + wr * random + wa * adhesion)
    gravity = ivy_size * wg * (0, 0, -1) * (floating / max_float) ** 0.7

where random = normalize(U(-.5, .5)^3 + (0, 0, .2)) and adhesion points to the
nearest skeleton point, scaled by 1 - d / max_adhesion (zero beyond). A step
that enters the skeleton is reflected off its surface (the mirror image of
the penetrating part) and marks the node climbing, which resets the floating
length; roots die when they float too long, reach the maximum length, or
(the gardener's shears, an addition for clipped shapes) leave the trim shell
``trim_distance`` outside the skeleton. Live roots branch with a probability
peaking at half the maximum length, for at most ``max_generations``
generations. All live roots advance together (no per-root Python loop).

:func:`ivy_leaves` distributes leaves along the grown segments, with an
acceptance weight growing with relative length along the root and blades
oriented from the smoothed adhesion vector; :func:`tube_mesh` sweeps thin
tubes along all polylines at once (stems, branches, trunks).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eden_pipe.models.leaves import _any_perpendicular as _perpendicular, _unit

UP = np.array([0.0, 0.0, 1.0])


def _uniform_sphere(n: int, rng: np.random.Generator) -> np.ndarray:
    z = rng.uniform(-1.0, 1.0, n)
    phi = rng.uniform(0.0, 2 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], 1)


# =========================================================================== skeletons
class Skeleton:
    """A solid shape answering nearest-surface queries (all methods vectorised)."""

    kind = "skeleton"

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(closest surface point (N,3), outward unit normal there (N,3), signed distance (N,)),
        negative inside."""
        raise NotImplementedError

    def closest_point(self, points: np.ndarray) -> np.ndarray:
        return self.query(points)[0]

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        return self.query(points)[2]

    def sample_surface(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """About area-uniform surface points and their normals (faces resting on the ground excluded)."""
        raise NotImplementedError

    def bounds(self) -> np.ndarray:
        raise NotImplementedError

    def area(self) -> float:
        raise NotImplementedError

    def core_points(self) -> np.ndarray:
        """Inner points from which woody branches reach the surface (K,3)."""
        b = self.bounds()
        return ((b[0] + b[1]) / 2)[None]


@dataclass
class BoxSkeleton(Skeleton):
    """Axis-aligned box (optionally with rounded edges of radius ``rounding``)."""

    center: np.ndarray
    half: np.ndarray
    rounding: float = 0.0
    kind = "box"

    def __post_init__(self):
        self.center = np.asarray(self.center, np.float64)
        self.half = np.asarray(self.half, np.float64)
        self.rounding = float(min(self.rounding, 0.99 * self.half.min()))

    def query(self, points):
        p = np.asarray(points, np.float64).reshape(-1, 3)
        q = p - self.center
        inner = self.half - self.rounding
        qc = np.clip(q, -inner, inner)
        diff = q - qc
        dout = np.linalg.norm(diff, axis=1)
        outside = dout > 1e-12
        normal = np.zeros_like(q)
        normal[outside] = diff[outside] / dout[outside, None]
        # Inside the inner box: the nearest face.
        over = np.abs(q) - inner
        k = np.argmax(over, axis=1)
        rows = np.arange(len(q))
        sgn = np.where(q[rows, k] >= 0, 1.0, -1.0)
        inn = ~outside
        normal[inn] = 0.0
        normal[rows[inn], k[inn]] = sgn[inn]
        sd = np.where(outside, dout, over[rows, k]) - self.rounding
        closest = p - sd[:, None] * normal
        return closest, normal, sd

    def area(self):
        lx, ly, lz = 2 * self.half
        ground = self.center[2] - self.half[2] <= 1e-6
        return 2 * lx * lz + 2 * ly * lz + lx * ly * (1 if ground else 2)

    def sample_surface(self, n, rng):
        lx, ly, lz = 2 * self.half
        ground = self.center[2] - self.half[2] <= 1e-6
        # faces: +x, -x, +y, -y, +z, -z
        areas = np.array([ly * lz, ly * lz, lx * lz, lx * lz, lx * ly, 0.0 if ground else lx * ly])
        face = rng.choice(6, size=n, p=areas / areas.sum())
        u = rng.uniform(-1.0, 1.0, (n, 3)) * self.half
        axis = face // 2
        sign = np.where(face % 2 == 0, 1.0, -1.0)
        u[np.arange(n), axis] = sign * self.half[axis]
        pts, nrm, _ = self.query(self.center + u)
        return pts, nrm

    def bounds(self):
        return np.stack([self.center - self.half, self.center + self.half])

    def core_points(self):
        # a row of points along the box's long axis, at 40% height
        axis = int(np.argmax(self.half[:2]))
        t = np.linspace(-0.8, 0.8, 7)
        pts = np.repeat(self.center[None], len(t), 0)
        pts[:, axis] += t * self.half[axis]
        pts[:, 2] = self.center[2] - 0.2 * self.half[2]
        return pts


@dataclass
class SphereSkeleton(Skeleton):
    center: np.ndarray
    radius: float
    kind = "sphere"

    def __post_init__(self):
        self.center = np.asarray(self.center, np.float64)
        self.radius = float(self.radius)

    def query(self, points):
        p = np.asarray(points, np.float64).reshape(-1, 3)
        d = p - self.center
        r = np.linalg.norm(d, axis=1)
        normal = np.where(r[:, None] > 1e-12, d / np.maximum(r, 1e-12)[:, None], UP)
        return self.center + self.radius * normal, normal, r - self.radius

    def area(self):
        return 4 * np.pi * self.radius**2

    def sample_surface(self, n, rng):
        nrm = _uniform_sphere(n, rng)
        return self.center + self.radius * nrm, nrm

    def bounds(self):
        return np.stack([self.center - self.radius, self.center + self.radius])

    def core_points(self):
        return (self.center - [0, 0, 0.3 * self.radius])[None]


@dataclass
class ConeSkeleton(Skeleton):
    """Solid cone, apex up: base disk of ``radius`` at height ``z0``, apex at ``z0 + height``."""

    z0: float
    radius: float
    height: float
    kind = "cone"

    def query(self, points):
        p = np.asarray(points, np.float64).reshape(-1, 3)
        rho = np.hypot(p[:, 0], p[:, 1])
        az = np.where(rho[:, None] > 1e-12, p[:, :2] / np.maximum(rho, 1e-12)[:, None], [[1.0, 0.0]])
        h = p[:, 2] - self.z0
        R, H = self.radius, self.height
        # base segment (0,0)-(R,0)
        cb = np.stack([np.clip(rho, 0.0, R), np.zeros_like(rho)], 1)
        # slant segment (R,0)-(0,H)
        a = np.array([R, 0.0])
        ab = np.array([-R, H])
        t = np.clip(((np.stack([rho, h], 1) - a) @ ab) / (ab @ ab), 0.0, 1.0)
        cs = a + t[:, None] * ab
        q = np.stack([rho, h], 1)
        db = np.linalg.norm(q - cb, axis=1)
        ds = np.linalg.norm(q - cs, axis=1)
        use_s = ds <= db
        c2 = np.where(use_s[:, None], cs, cb)
        dist = np.minimum(ds, db)
        inside = (h >= 0) & (h <= H) & (rho <= R * (1.0 - h / H))
        seg_n = np.where(use_s[:, None], np.array([H, R]) / np.hypot(H, R), np.array([0.0, -1.0]))
        n2 = np.where((~inside & (dist > 1e-9))[:, None], (q - c2) / np.maximum(dist, 1e-12)[:, None], seg_n)
        sd = np.where(inside, -dist, dist)
        closest = np.concatenate([c2[:, :1] * az, (c2[:, 1:] + self.z0)], 1)
        normal = np.concatenate([n2[:, :1] * az, n2[:, 1:]], 1)
        return closest, normal, sd

    def area(self):
        lat = np.pi * self.radius * np.hypot(self.radius, self.height)
        return lat + (np.pi * self.radius**2 if self.z0 > 1e-6 else 0.0)

    def sample_surface(self, n, rng):
        R, H = self.radius, self.height
        lat = np.pi * R * np.hypot(R, H)
        base = np.pi * R**2 if self.z0 > 1e-6 else 0.0
        on_base = rng.uniform(0, 1, n) < base / (lat + base)
        s = 1.0 - np.sqrt(rng.uniform(0, 1, n))  # height fraction, density ~ radius
        phi = rng.uniform(0, 2 * np.pi, n)
        rb = R * np.sqrt(rng.uniform(0, 1, n))
        rho = np.where(on_base, rb, R * (1 - s))
        z = np.where(on_base, self.z0, self.z0 + H * s)
        pts = np.stack([rho * np.cos(phi), rho * np.sin(phi), z], 1)
        _, nrm, _ = self.query(pts)
        return pts, nrm

    def bounds(self):
        return np.array([[-self.radius, -self.radius, self.z0], [self.radius, self.radius, self.z0 + self.height]])

    def core_points(self):
        return np.array([[0.0, 0.0, self.z0 + f * self.height] for f in (0.1, 0.3, 0.5)])


@dataclass
class StackedSpheresSkeleton(Skeleton):
    """Union of spheres (tiers of a ball topiary)."""

    centers: np.ndarray
    radii: np.ndarray
    kind = "stacked_spheres"

    def __post_init__(self):
        self.centers = np.asarray(self.centers, np.float64).reshape(-1, 3)
        self.radii = np.asarray(self.radii, np.float64).reshape(-1)

    def _all(self, p):
        d = p[:, None, :] - self.centers[None]
        r = np.linalg.norm(d, axis=2)
        return d, r, r - self.radii[None]

    def query(self, points):
        p = np.asarray(points, np.float64).reshape(-1, 3)
        d, r, sd_all = self._all(p)
        k = np.argmin(sd_all, axis=1)
        rows = np.arange(len(p))
        dk, rk = d[rows, k], r[rows, k]
        normal = np.where(rk[:, None] > 1e-12, dk / np.maximum(rk, 1e-12)[:, None], UP)
        return self.centers[k] + self.radii[k, None] * normal, normal, sd_all[rows, k]

    def area(self):
        return float(np.sum(4 * np.pi * self.radii**2))

    def sample_surface(self, n, rng):
        w = self.radii**2 / np.sum(self.radii**2)
        got_p, got_n, have = [], [], 0
        while have < n:
            m = 2 * (n - have) + 16
            k = rng.choice(len(self.radii), size=m, p=w)
            nrm = _uniform_sphere(m, rng)
            pts = self.centers[k] + self.radii[k, None] * nrm
            _, _, sd_all = self._all(pts)
            sd_all[np.arange(m), k] = np.inf
            keep = sd_all.min(1) > -1e-9
            got_p.append(pts[keep])
            got_n.append(nrm[keep])
            have += int(keep.sum())
        return np.concatenate(got_p)[:n], np.concatenate(got_n)[:n]

    def bounds(self):
        return np.stack([(self.centers - self.radii[:, None]).min(0), (self.centers + self.radii[:, None]).max(0)])

    def core_points(self):
        return self.centers - np.stack([np.zeros_like(self.radii)] * 2 + [0.3 * self.radii], 1)


@dataclass
class HelixTubeSkeleton(Skeleton):
    """A tube around a helix winding about the z axis (a spiral topiary).

    The helix rises from ``z0`` to ``z1`` over ``turns`` turns; its coil radius
    goes linearly from ``coil0`` to ``coil1`` and the tube radius from ``tube0``
    to ``tube1`` (ends are rounded)."""

    z0: float
    z1: float
    turns: float
    coil0: float
    coil1: float
    tube0: float
    tube1: float
    phase: float = 0.0
    kind = "spiral"

    @property
    def theta_max(self) -> float:
        return 2 * np.pi * self.turns

    def curve(self, th):
        f = th / self.theta_max
        a = self.coil0 + (self.coil1 - self.coil0) * f
        ang = th + self.phase
        return np.stack([a * np.cos(ang), a * np.sin(ang), self.z0 + (self.z1 - self.z0) * f], -1)

    def _derivs(self, th):
        f = th / self.theta_max
        da = (self.coil1 - self.coil0) / self.theta_max
        a = self.coil0 + (self.coil1 - self.coil0) * f
        ang = th + self.phase
        c, s = np.cos(ang), np.sin(ang)
        dz = (self.z1 - self.z0) / self.theta_max
        d1 = np.stack([da * c - a * s, da * s + a * c, np.full_like(th, dz)], -1)
        d2 = np.stack([-2 * da * s - a * c, 2 * da * c - a * s, np.zeros_like(th)], -1)
        return d1, d2

    def tube_radius(self, th):
        return self.tube0 + (self.tube1 - self.tube0) * th / self.theta_max

    def closest_param(self, points):
        p = np.asarray(points, np.float64).reshape(-1, 3)
        phi = np.mod(np.arctan2(p[:, 1], p[:, 0]) - self.phase, 2 * np.pi)
        zf = (p[:, 2] - self.z0) / (self.z1 - self.z0) * self.turns
        k0 = np.clip(np.round(zf - phi / (2 * np.pi)), 0.0, np.floor(self.turns))  # nearest turns, also beyond the ends
        cand = phi[:, None] + 2 * np.pi * (k0[:, None] + np.array([-1.0, 0.0, 1.0])[None])
        cand = np.concatenate([np.clip(cand, 0, self.theta_max), np.zeros((len(p), 1)),
                               np.full((len(p), 1), self.theta_max)], 1)
        pp = p[:, None, :]
        for _ in range(4):  # Newton on |C(th) - p|^2
            d1, d2 = self._derivs(cand)
            diff = self.curve(cand) - pp
            g = np.sum(d1 * diff, -1)
            hss = np.sum(d1 * d1, -1) + np.sum(d2 * diff, -1)
            step = np.where(hss > 1e-9, g / np.where(hss > 1e-9, hss, 1.0), 0.0)
            cand = np.clip(cand - np.clip(step, -0.5, 0.5), 0.0, self.theta_max)
        dist = np.linalg.norm(self.curve(cand) - pp, axis=-1) - self.tube_radius(cand)
        best = np.argmin(dist, axis=1)
        return cand[np.arange(len(p)), best]

    def query(self, points):
        p = np.asarray(points, np.float64).reshape(-1, 3)
        th = self.closest_param(p)
        c = self.curve(th)
        d = p - c
        r = np.linalg.norm(d, axis=1)
        radial = np.stack([np.cos(th + self.phase), np.sin(th + self.phase), np.zeros_like(th)], 1)
        normal = np.where(r[:, None] > 1e-9, d / np.maximum(r, 1e-12)[:, None], radial)
        rt = self.tube_radius(th)
        return c + rt[:, None] * normal, normal, r - rt

    def _arc_weights(self, m=512):
        th = np.linspace(0, self.theta_max, m)
        d1, _ = self._derivs(th)
        w = np.linalg.norm(d1, axis=1) * self.tube_radius(th)
        return th, w

    def area(self):
        th, w = self._arc_weights()
        return float(2 * np.pi * np.sum(0.5 * (w[1:] + w[:-1]) * np.diff(th)))

    def sample_surface(self, n, rng):
        th_grid, w = self._arc_weights()
        cdf = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * np.diff(th_grid))])
        th = np.interp(rng.uniform(0, cdf[-1], n), cdf, th_grid)
        psi = rng.uniform(0, 2 * np.pi, n)
        d1, _ = self._derivs(th)
        t = _unit(d1)
        radial = np.stack([np.cos(th + self.phase), np.sin(th + self.phase), np.zeros_like(th)], 1)
        e1 = _unit(radial - np.sum(radial * t, 1, keepdims=True) * t)
        e2 = np.cross(t, e1)
        nrm = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2
        return self.curve(th) + self.tube_radius(th)[:, None] * nrm, nrm

    def bounds(self):
        r = max(self.coil0, self.coil1) + max(self.tube0, self.tube1)
        return np.array([[-r, -r, self.z0 - self.tube0], [r, r, self.z1 + self.tube1]])

    def core_points(self):
        th = np.linspace(0.05, 0.95, 12) * self.theta_max
        return self.curve(th)


def make_skeleton(spec: dict) -> Skeleton:
    """A skeleton from resolved (already drawn) parameters: ``{"type": ..., ...}``."""
    kind = spec["type"]
    if kind == "box":
        L, D, H = spec["length"], spec["depth"], spec["height"]
        lift = spec.get("lift", 0.0)
        return BoxSkeleton(center=[0.0, 0.0, lift + H / 2], half=[L / 2, D / 2, H / 2], rounding=spec.get("rounding", 0.0))
    if kind == "sphere":
        r = spec["radius"]
        return SphereSkeleton(center=[0.0, 0.0, spec.get("lift", 0.0) + r], radius=r)
    if kind == "cone":
        return ConeSkeleton(z0=spec.get("lift", 0.0), radius=spec["radius"], height=spec["height"])
    if kind == "stacked_spheres":
        return StackedSpheresSkeleton(centers=spec["centers"], radii=spec["radii"])
    if kind == "spiral":
        return HelixTubeSkeleton(z0=spec["z0"], z1=spec["z1"], turns=spec["turns"], coil0=spec["coil0"],
                                 coil1=spec["coil1"], tube0=spec["tube0"], tube1=spec["tube1"],
                                 phase=spec.get("phase", 0.0))
    raise KeyError(f"unknown skeleton type {kind!r}; allowed: box, sphere, cone, stacked_spheres, spiral")


# =========================================================================== growth
@dataclass
class IvyParams:
    """Luft/IvyGen parameters (REFERENCE.md defaults) plus the clipping extensions."""

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
    def from_dict(cls, d: dict | None, ignore: tuple[str, ...] = ()) -> "IvyParams":
        """Parameters from a preset mapping; unknown keys (other than ``ignore``) are an error."""
        d = {k: v for k, v in dict(d or {}).items() if k not in ignore}
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise KeyError(f"unknown ivy parameter(s) {unknown}; allowed: {sorted(cls.__dataclass_fields__)}")
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
    r = _uniform_sphere(n, rng) + up_bias * UP
    r = r - np.sum(r * normals, 1, keepdims=True) * normals
    bad = np.linalg.norm(r, axis=1) < 1e-6
    r[bad] = _perpendicular(normals[bad])
    return _unit(r)


def grow_ivy(skeleton: Skeleton, seeds: np.ndarray, seed_dirs: np.ndarray, params: IvyParams,
             rng: np.random.Generator) -> IvyGrowth:
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
    primary[:n_roots] = _unit(np.asarray(seed_dirs, np.float64).reshape(-1, 3))
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
        rnd = _unit(rng.uniform(-0.5, 0.5, (m, 3)) + up_rand)
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
        gdir = _unit(gdir)
        primary[idx] = _unit(primary[idx] + 0.5 * (gdir - primary[idx]))
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
                    primary[new_ids] = _unit(dirs + 0.3 * primary[born])
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
    return IvyGrowth(pos=node_pos, root=root, adhesion=node_adh, length=node_len, climbing=node_climb,
                     root_generation=gen[:n_roots].copy(), root_start=starts, root_count=counts)


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


def ivy_leaves(growth: IvyGrowth, rng: np.random.Generator, *, per_node: float = 1.0, probability: float = 0.35,
               weight_floor: float = 0.0, normal_jitter: float = 0.4, up_bias: float = 0.2,
               offset: tuple[float, float] = (0.0, 0.0), smooth: int = 3,
               expected_count: float | None = None, spread: float = 0.0, even_cell: float = 0.0,
               oversample: float = 2.5) -> LeafSites:
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
    normal = _unit(outward + normal_jitter * _uniform_sphere(k, rng) + up_bias * UP)
    seg_dir = _unit(b - a)
    tangent = _unit(seg_dir + 0.9 * _uniform_sphere(k, rng) + 0.3 * outward)
    pos = pos + outward * rng.uniform(offset[0], offset[1], k)[:, None]
    if spread > 0:  # scatter sideways (in the surface plane) to even out clumping along stems
        lat = _uniform_sphere(k, rng)
        lat -= np.sum(lat * outward, 1, keepdims=True) * outward
        pos = pos + spread * rng.uniform(0, 1, k)[:, None] * lat
    return LeafSites(pos, normal, tangent, relc)


# =========================================================================== tubes
def tube_mesh(points: np.ndarray, radii: np.ndarray, path_id: np.ndarray, sides: int = 3,
              ref: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
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
    tan = _unit(p[nxt] - p[prv])
    # parallel transport along each path
    starts = np.flatnonzero(~same_prev)
    lengths = np.diff(np.concatenate([starts, [P]]))
    normal = np.zeros_like(p)
    t0 = tan[starts]
    if ref is None:
        n0 = _perpendicular(t0)
    else:
        n0 = _unit(np.cross(t0, np.cross(np.broadcast_to(ref, t0.shape), t0)))
        bad = np.linalg.norm(np.cross(t0, np.broadcast_to(ref, t0.shape)), axis=1) < 1e-6
        n0[bad] = _perpendicular(t0[bad])
    normal[starts] = n0
    for j in range(1, int(lengths.max())):
        sel = lengths > j
        i = starts[sel] + j
        prev_n = normal[i - 1]
        t = tan[i]
        nn = prev_n - np.sum(prev_n * t, 1, keepdims=True) * t
        bad = np.linalg.norm(nn, axis=1) < 1e-9
        if np.any(bad):
            nn[bad] = _perpendicular(t[bad])
        normal[i] = _unit(nn)
    binormal = np.cross(tan, normal)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(ang)[None, :, None] * normal[:, None, :] + np.sin(ang)[None, :, None] * binormal[:, None, :]
    verts = p[:, None, :] + r[:, None, None] * ring
    a = np.flatnonzero(same_next)
    k = np.arange(sides)
    k1 = (k + 1) % sides
    v00 = a[:, None] * sides + k[None]
    v01 = a[:, None] * sides + k1[None]
    v10 = (a[:, None] + 1) * sides + k[None]
    v11 = (a[:, None] + 1) * sides + k1[None]
    faces = np.concatenate([np.stack([v00, v01, v11], -1), np.stack([v00, v11, v10], -1)], 1)
    return verts.reshape(-1, 3).astype(np.float32), faces.reshape(-1, 3).astype(np.int32)


def ivy_stems(growth: IvyGrowth, *, radius: float = 0.0015, every: int = 3, sides: int = 3,
              generation_scale: float = 0.75, min_radius: float = 0.0004,
              ground_z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
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


def branch_paths(starts: np.ndarray, ends: np.ndarray, rng: np.random.Generator, *, segments: int = 4,
                 wobble: float = 0.15, sag: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
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
