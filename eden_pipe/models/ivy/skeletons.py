"""The hidden shapes ivy climbs to make hedges and topiaries (never rendered).

A skeleton answers nearest-surface queries (:meth:`Skeleton.query`: closest
point, outward normal and signed distance, vectorised over points) and samples
its surface for ivy seeds. Each kind is one class, registered in
:data:`SKELETONS` (preset ``type`` -> class): the class draws its own
parameters from a bush preset's ``skeleton`` section (:meth:`Skeleton.draw_spec`)
and builds itself from them (:meth:`Skeleton.from_spec`), so a new kind is one
class added to the table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe.errors import ConfigError
from eden_pipe.geometry import UP, normalize, uniform_sphere
from eden_pipe.models.presets import draw, draw_int


class Skeleton:
    """A solid shape answering nearest-surface queries (all methods vectorised)."""

    kind = "skeleton"
    #: preset keys of this kind's ``skeleton`` section, besides ``type`` and ``lift``
    preset_keys: frozenset = frozenset()

    @classmethod
    def draw_spec(cls, spec: dict, rng: np.random.Generator, lift: float) -> tuple[dict, float]:
        """This kind's parameters drawn from its preset section, and the trunk top height (0 = no trunk)."""
        raise NotImplementedError

    @classmethod
    def from_spec(cls, spec: dict) -> Skeleton:
        """The skeleton from drawn parameters (what :meth:`draw_spec` returned, plus ``lift``)."""
        raise NotImplementedError

    def query(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(closest surface point (N,3), outward unit normal there (N,3), signed distance (N,)),
        negative inside."""
        raise NotImplementedError

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
    preset_keys = frozenset({"length", "depth", "height", "rounding"})

    @classmethod
    def draw_spec(cls, spec, rng, lift):
        out = {k: float(draw(spec.get(k, 0.0), rng)) for k in ("length", "depth", "height", "rounding")}
        return out, 0.0

    @classmethod
    def from_spec(cls, spec):
        L, D, H = spec["length"], spec["depth"], spec["height"]
        lift = spec.get("lift", 0.0)
        return cls(center=[0.0, 0.0, lift + H / 2], half=[L / 2, D / 2, H / 2], rounding=spec.get("rounding", 0.0))

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
    preset_keys = frozenset({"radius"})

    @classmethod
    def draw_spec(cls, spec, rng, lift):
        radius = float(draw(spec["radius"], rng))
        return {"radius": radius}, lift + 0.3 * radius

    @classmethod
    def from_spec(cls, spec):
        r = spec["radius"]
        return cls(center=[0.0, 0.0, spec.get("lift", 0.0) + r], radius=r)

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
        nrm = uniform_sphere(n, rng)
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
    preset_keys = frozenset({"radius", "height"})

    @classmethod
    def draw_spec(cls, spec, rng, lift):
        out = {"radius": float(draw(spec["radius"], rng))}
        out["height"] = float(draw(spec["height"], rng))
        return out, lift + 0.25 * out["height"]

    @classmethod
    def from_spec(cls, spec):
        return cls(z0=spec.get("lift", 0.0), radius=spec["radius"], height=spec["height"])

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
    preset_keys = frozenset({"tiers", "radius", "shrink", "gap"})

    @classmethod
    def draw_spec(cls, spec, rng, lift):
        tiers = draw_int(spec.get("tiers", 3), rng)
        r = float(draw(spec["radius"], rng))
        shrink = float(draw(spec.get("shrink", 0.75), rng))
        gap = float(draw(spec.get("gap", 0.0), rng))  # fraction of the lower radius; < 0 overlaps
        centers, radii, z = [], [], lift
        for _ in range(tiers):
            centers.append([0.0, 0.0, z + r])
            radii.append(r)
            z = z + 2 * r + gap * r
            r *= shrink
        return {"centers": centers, "radii": radii}, centers[-1][2]

    @classmethod
    def from_spec(cls, spec):
        return cls(centers=spec["centers"], radii=spec["radii"])

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
            nrm = uniform_sphere(m, rng)
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
    preset_keys = frozenset({"height", "turns", "coil_radius", "tube_radius", "taper"})

    @classmethod
    def draw_spec(cls, spec, rng, lift):
        h = float(draw(spec["height"], rng))
        out = {"turns": float(draw(spec.get("turns", 3.0), rng))}
        coil0 = float(draw(spec["coil_radius"], rng))
        tube0 = float(draw(spec["tube_radius"], rng))
        taper = float(draw(spec.get("taper", 0.45), rng))
        out.update(
            z0=lift + tube0,
            z1=lift + h - tube0 * taper,
            coil0=coil0,
            coil1=coil0 * taper,
            tube0=tube0,
            tube1=tube0 * (0.5 + 0.5 * taper),
            phase=float(rng.uniform(0, 2 * np.pi)),
        )
        return out, lift + h

    @classmethod
    def from_spec(cls, spec):
        return cls(
            z0=spec["z0"],
            z1=spec["z1"],
            turns=spec["turns"],
            coil0=spec["coil0"],
            coil1=spec["coil1"],
            tube0=spec["tube0"],
            tube1=spec["tube1"],
            phase=spec.get("phase", 0.0),
        )

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
        cand = np.concatenate(
            [np.clip(cand, 0, self.theta_max), np.zeros((len(p), 1)), np.full((len(p), 1), self.theta_max)], 1
        )
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
        t = normalize(d1)
        radial = np.stack([np.cos(th + self.phase), np.sin(th + self.phase), np.zeros_like(th)], 1)
        e1 = normalize(radial - np.sum(radial * t, 1, keepdims=True) * t)
        e2 = np.cross(t, e1)
        nrm = np.cos(psi)[:, None] * e1 + np.sin(psi)[:, None] * e2
        return self.curve(th) + self.tube_radius(th)[:, None] * nrm, nrm

    def bounds(self):
        r = max(self.coil0, self.coil1) + max(self.tube0, self.tube1)
        return np.array([[-r, -r, self.z0 - self.tube0], [r, r, self.z1 + self.tube1]])

    def core_points(self):
        th = np.linspace(0.05, 0.95, 12) * self.theta_max
        return self.curve(th)


SKELETONS: dict[str, type[Skeleton]] = {
    cls.kind: cls for cls in (BoxSkeleton, SphereSkeleton, ConeSkeleton, StackedSpheresSkeleton, HelixTubeSkeleton)
}


def skeleton_class(kind: str) -> type[Skeleton]:
    try:
        return SKELETONS[kind]
    except KeyError:
        raise ConfigError(f"unknown skeleton type {kind!r}; allowed: {', '.join(SKELETONS)}") from None


def draw_skeleton_spec(spec: dict, rng: np.random.Generator) -> tuple[dict, float]:
    """Drawn skeleton parameters (for :func:`make_skeleton`) and the trunk top height (0 = none)."""
    kind = spec["type"]
    cls = skeleton_class(kind)
    lift = float(draw(spec.get("lift", 0.0), rng))
    out: dict = {"type": kind, "lift": lift}
    params, trunk_top = cls.draw_spec(spec, rng, lift)
    out.update(params)
    return out, trunk_top


def make_skeleton(spec: dict) -> Skeleton:
    """A skeleton from resolved (already drawn) parameters: ``{"type": ..., ...}``."""
    return skeleton_class(spec["type"]).from_spec(spec)


def skeleton_preset_keys() -> set:
    """Every key a ``skeleton`` preset section may use (whatever its type)."""
    return {"type", "lift"}.union(*(cls.preset_keys for cls in SKELETONS.values()))
