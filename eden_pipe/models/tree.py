"""Weber & Penn parametric trees: 19 species as triangle meshes.

The model follows J. Weber and J. Penn, "Creation and Rendering of Realistic
Trees" (SIGGRAPH 1995), in the form popularised by Wolfram Diestel's Arbaro
(Java) and Blender's Sapling add-on; the species presets under
``conf/species/trees/`` take their numbers from the published Weber-Penn
tables, Arbaro's and Sapling's presets (re-entered by hand, adapted where
those tools use their own conventions).

A tree is a hierarchy of *stems*: the trunk (level 0) carries level-1
branches, which carry level-2 branches and so on up to ``Levels - 1``; the
last stem level carries the leaves. Every stem is ``nCurveRes`` straight
segments whose direction turns by ``nCurve`` (or ``nCurve`` then
``nCurveBack`` over the two halves) plus a random ``nCurveV`` part;
``AttractionUp`` turns stems of level >= 2 toward (or, negative, away from)
the sky. Segments may split into clones (``nSegSplits``, ``0BaseSplits``,
fractional counts carried as an error from stem to stem) that diverge by
``nSplitAngle`` less the stem's declination. Children sit along their parent
(the trunk above ``BaseSize``) with spiral ``nRotate`` (negative: alternating
sides) and ``nDownAngle`` (negative variation: a function of the position on
the parent); level-1 lengths follow the crown shape ratio (``Shape`` 0-7 or
the pruning envelope 8), deeper ones ``nLength * (L_parent - 0.6 offset)``;
counts follow ``nBranches`` with the Weber-Penn length/offset factors.
Radii follow ``Ratio``/``RatioPower`` with ``nTaper`` (0-1 conical, 1-2
rounded tip, 2-3 periodic, as in palm trunks), trunk ``Flare`` and ``Lobes``.
With ``PruneRatio`` > 0, stems leaving the envelope (``PruneWidth``,
``PruneWidthPeak``, ``PrunePowerLow/High``) are shortened, and every stem is
shortened where it would go below ground. Leaves are ``Leaves`` per stem of the
last level (scaled by shape ratio ``LeafDistrib`` of the stem's offset;
negative: a fan at the stem tip), sized ``LeafScale`` x ``LeafScaleX`` and
turned outward/upward by ``LeafBend``.

Small extensions (optional preset keys): ``SplitHeight`` (fraction of the
trunk where base splits happen), ``nAttractionUp`` (per-level override, as in
Sapling), ``nBaseSize`` (bare fraction at the base of level >= 1 parents),
``nWhorl`` (children in whorls of this many, as in pines and firs),
``FanAngle`` / ``FanTilt`` (degrees spanned by fan leaves, and the blade's
bend up from the petiole), ``LeafStart`` (bare fraction at
the base of leaf-bearing stems), ``leaf_color_alt`` / ``leaf_alt_fraction``
(a second leaf colour near stem tips, e.g. bottlebrush flowers).

Geometry: stems are open tubes (8+/6/4/3 sides by level, a flat two-sided
ribbon when the triangle budget forces it); leaves are small shaped polygons
(elliptic, ovate, deltoid, lobed, palmate, needle, palm leaflet, sphere, ...)
of 2-8 triangles. Everything is labelled ``labels.TREE``; stems use material
``bark`` and leaves ``leaf``. The whole tree is finally scaled uniformly so
that its height is drawn from the preset's garden height range.

Generation is level-synchronous and vectorised: all stems of one level are
grown together (a Python loop over segment index only), children and leaves
are placed with array operations, and tubes and leaves are emitted as batched
vertex/face arrays.

Limits that keep presets tractable (Weber-Penn splitting is exponential and
some tables ask for millions of leaves): a stem family holds at most
``MAX_FAMILY`` rows (``MAX_TRUNK_STEMS`` for the trunk); a level above
``MAX_CHILDREN`` stems is thinned evenly and each kept stem carries the
leaves of those it stands for; over the triangle budget, stems first lose
sides and rings (then whole deep levels) and leaves are merged into fewer,
larger ones, each at most ``MAX_LEAF_AREA_GROWTH`` times a preset leaf's area
(more under tight budgets), so very leafy presets end up somewhat sparser than
the tables imply. Clones split their radius (area-preserving), and split
trunks are half-corrected back toward the vertical.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.models.species import list_species, load_species
from eden_pipe.rng import rng_for

__all__ = [
    "build_tree",
    "grow_skeleton",
    "tree_params",
    "shape_ratio",
    "list_tree_species",
    "TreeParams",
    "Skeleton",
    "StemLevel",
    "LeafSet",
    "LEAF_SHAPES",
]

DEG = np.pi / 180.0
UP = np.array([0.0, 0.0, 1.0])

LEVEL_KEYS = (
    "nLength", "nLengthV", "nTaper", "nSegSplits", "nSplitAngle", "nSplitAngleV",
    "nCurveRes", "nCurve", "nCurveBack", "nCurveV", "nDownAngle", "nDownAngleV",
    "nRotate", "nRotateV", "nBranches",
)
LEVEL_DEFAULTS = {
    "nLength": 0.5, "nLengthV": 0.0, "nTaper": 1.0, "nSegSplits": 0.0, "nSplitAngle": 0.0,
    "nSplitAngleV": 0.0, "nCurveRes": 3, "nCurve": 0.0, "nCurveBack": 0.0, "nCurveV": 0.0,
    "nDownAngle": 45.0, "nDownAngleV": 0.0, "nRotate": 140.0, "nRotateV": 0.0, "nBranches": 0,
    "nBaseSize": 0.0, "nWhorl": 0,
}
GLOBAL_DEFAULTS = {
    "Shape": 0, "Levels": 3, "Scale": 10.0, "ScaleV": 0.0, "BaseSize": 0.2, "Ratio": 0.015,
    "RatioPower": 1.2, "Flare": 0.5, "Lobes": 0, "LobeDepth": 0.0, "0Scale": 1.0, "0ScaleV": 0.0,
    "0BaseSplits": 0, "Leaves": 0, "LeafScale": 0.2, "LeafScaleX": 1.0, "LeafBend": 0.3,
    "LeafStemLen": 0.0, "LeafQuality": 1.0, "LeafDistrib": 4, "AttractionUp": 0.0,
    "PruneRatio": 0.0, "PruneWidth": 0.5, "PruneWidthPeak": 0.5, "PrunePowerLow": 0.5,
    "PrunePowerHigh": 0.5, "SplitHeight": None, "FanAngle": 180.0, "FanTilt": 0.0, "LeafStart": 0.1,
    "leaf_shape": "elliptic", "leaf_color": [0.06, 0.14, 0.03], "bark_color": [0.12, 0.09, 0.07],
    "leaf_translucency": 0.3, "leaf_specular": 0.05, "height_m": [3.0, 5.0],
    "leaf_color_alt": None, "leaf_alt_fraction": 0.0,
}

MAX_TRUNK_STEMS = 12        # trunk plus its clones
MAX_FAMILY = 8              # a branch plus its clones (Weber-Penn splitting is exponential)
MAX_STEMS_PER_LEVEL = 40000
MAX_CHILDREN = 20000        # stems per level; above it children are thinned and leaves carry the weight
MIN_RADIUS = 1.5e-4         # smallest stem radius, as a fraction of the tree scale
MAX_LEAF_AREA_GROWTH = 16.0 # a merged leaf is at most this many times the area of a preset leaf
RING_EPS = 1e-6


# ----------------------------------------------------------------------------- parameters
@dataclass
class TreeParams:
    """A species preset resolved to plain values; per-level values are 4-lists."""

    name: str
    g: dict
    lv: dict  # key -> np.ndarray (4,)
    attraction: np.ndarray  # (4,) effective AttractionUp per level

    @property
    def levels(self) -> int:
        return int(np.clip(self.g["Levels"], 1, 4))

    def __getitem__(self, key):
        return self.g[key]


def tree_params(species: str | dict) -> TreeParams:
    """Resolve a preset name (or an already loaded dict) into :class:`TreeParams`."""
    data = load_species("trees", species) if isinstance(species, str) else dict(species)
    name = data.get("name", species if isinstance(species, str) else "custom")
    g = dict(GLOBAL_DEFAULTS)
    for key, value in data.items():
        if not (key.startswith("n") and key[1:2].isupper()):
            g[str(key)] = value
    lv = {}
    for key in LEVEL_KEYS + ("nBaseSize", "nWhorl"):
        raw = data.get(key, LEVEL_DEFAULTS[key])
        vals = list(raw) if isinstance(raw, (list, tuple)) else [raw]
        vals = [LEVEL_DEFAULTS[key] if v is None else v for v in vals]
        vals = (vals + [vals[-1]] * 4)[:4]
        lv[key] = np.asarray(vals, dtype=np.float64)
    lv["nCurveRes"] = np.maximum(1, np.round(lv["nCurveRes"])).astype(int)
    att = np.array([0.0, 0.0, float(g["AttractionUp"]), float(g["AttractionUp"])])
    override = data.get("nAttractionUp")
    if override is not None:
        for i, v in enumerate(list(override)[:4]):
            if v is not None:
                att[i] = float(v)
    return TreeParams(name=name, g=g, lv=lv, attraction=att)


def list_tree_species() -> list[str]:
    return list_species("trees")


def shape_ratio(shape: int, r, p: TreeParams | None = None) -> np.ndarray:
    """Weber-Penn shape ratio for crown shape ``shape`` at ratio ``r`` (0 top .. 1 base)."""
    r = np.asarray(r, dtype=np.float64)
    shape = int(shape)
    if shape == 8:
        peak = float(p["PruneWidthPeak"]) if p else 0.5
        lo = float(p["PrunePowerLow"]) if p else 0.5
        hi = float(p["PrunePowerHigh"]) if p else 0.5
        peak = min(max(peak, 1e-3), 1 - 1e-3)
        rc = np.clip(r, 0.0, 1.0)
        upper = (rc / (1.0 - peak)) ** hi
        lower = np.clip((1.0 - rc) / peak, 0.0, None) ** lo
        out = np.where(rc < 1.0 - peak, upper, lower)
        return np.where((r < 0) | (r > 1), 0.0, out)
    r = np.clip(r, 0.0, 1.0)
    if shape == 0:
        return 0.2 + 0.8 * r
    if shape == 1:
        return 0.2 + 0.8 * np.sin(np.pi * r)
    if shape == 2:
        return 0.2 + 0.8 * np.sin(0.5 * np.pi * r)
    if shape == 3:
        return np.ones_like(r)
    if shape == 4:
        return 0.5 + 0.5 * r
    if shape == 5:
        return np.where(r <= 0.7, r / 0.7, (1.0 - r) / 0.3)
    if shape == 6:
        return 1.0 - 0.8 * r
    if shape == 7:
        return np.where(r <= 0.7, 0.5 + 0.5 * r / 0.7, 0.5 + 0.5 * (1.0 - r) / 0.3)
    raise ValueError(f"unknown Weber-Penn shape {shape}")


def _envelope_inside(pts: np.ndarray, p: TreeParams, scale: float) -> np.ndarray:
    """Weber-Penn pruning envelope test for points (..., 3), trunk base at the origin."""
    base = float(p["BaseSize"])
    ratio = (scale - pts[..., 2]) / (scale * max(1.0 - base, 1e-6))
    env = shape_ratio(8, ratio, p)
    rad = np.hypot(pts[..., 0], pts[..., 1]) / scale
    return (rad < float(p["PruneWidth"]) * env) & (ratio >= 0) & (ratio <= 1)


# ----------------------------------------------------------------------------- rotations
def _axis_angle(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(N,3,3) rotation matrices about unit axes (N,3) by angles (N,) (Rodrigues)."""
    axis = np.asarray(axis, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    t = 1.0 - c
    m = np.empty((len(angle), 3, 3))
    m[:, 0, 0] = c + x * x * t
    m[:, 0, 1] = x * y * t - z * s
    m[:, 0, 2] = x * z * t + y * s
    m[:, 1, 0] = y * x * t + z * s
    m[:, 1, 1] = c + y * y * t
    m[:, 1, 2] = y * z * t - x * s
    m[:, 2, 0] = z * x * t - y * s
    m[:, 2, 1] = z * y * t + x * s
    m[:, 2, 2] = c + z * z * t
    return m


def _rot_local(axis_index: int, angle: np.ndarray) -> np.ndarray:
    """(N,3,3) rotations about the local x (0), y (1) or z (2) axis."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros((len(angle), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis_index]
    m[:, axis_index, axis_index] = 1.0
    m[:, i, i] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    m[:, j, j] = c
    return m


def _rotate_vectors(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=1, keepdims=True) * (1.0 - c)


def _normalize(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def _toward_up(F: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Turn frames (N,3,3) so their z axis moves toward +Z by ``angle`` (negative: away)."""
    z = F[:, :, 2]
    axis = np.cross(z, UP)
    n = np.linalg.norm(axis, axis=1)
    ok = (n > 1e-9) & (np.abs(angle) > 1e-12)
    if not np.any(ok):
        return F
    out = F.copy()
    rot = _axis_angle(axis[ok] / n[ok, None], angle[ok])
    out[ok] = rot @ F[ok]
    return out


def _carry_round(x: np.ndarray, carry: float = 0.0) -> tuple[np.ndarray, float]:
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


# ----------------------------------------------------------------------------- skeleton
@dataclass
class StemLevel:
    """All stems of one level (clones included) as arrays."""

    level: int
    points: np.ndarray      # (N, R+1, 3) spine points
    frames: np.ndarray      # (N, R, 3, 3) segment frames, columns = x, y, z (z along the stem)
    length: np.ndarray      # (N,) stem length (clones: the whole stem's length)
    radius: np.ndarray      # (N,) base radius before split factors
    rfac: np.ndarray        # (N, R) per-segment radius factor from splits
    start: np.ndarray       # (N,) first segment owned by this row (clones > 0)
    parent: np.ndarray      # (N,) row in the previous level (-1 for the trunk)
    offset: np.ndarray      # (N,) distance along the parent to the attachment point
    parent_length: np.ndarray  # (N,)
    lmax: np.ndarray        # (N,) sampled nLength (+- nLengthV)
    family: np.ndarray      # (N,) index of the original stem (clones share it)
    radius_cap: np.ndarray  # (N,) parent radius at the attachment point
    weight: float = 1.0     # stems each row stands for (> 1 when a huge level was thinned)

    @property
    def n(self) -> int:
        return len(self.length)

    @property
    def res(self) -> int:
        return self.frames.shape[1]

    @property
    def is_clone(self) -> np.ndarray:
        return self.start > 0


@dataclass
class LeafSet:
    position: np.ndarray  # (K, 3) leaf base
    x: np.ndarray         # (K, 3) width axis
    y: np.ndarray         # (K, 3) normal
    z: np.ndarray         # (K, 3) length axis
    length: np.ndarray    # (K,)
    width: np.ndarray     # (K,)
    stem: np.ndarray      # (K,) row of the last stem level
    alt: np.ndarray       # (K,) bool: uses the alternative leaf colour

    @property
    def n(self) -> int:
        return len(self.length)

    @classmethod
    def empty(cls) -> "LeafSet":
        z3 = np.zeros((0, 3))
        z1 = np.zeros(0)
        return cls(z3, z3, z3, z3, z1, z1, np.zeros(0, np.int64), np.zeros(0, bool))


@dataclass
class Skeleton:
    species: str
    seed: int
    params: TreeParams
    scale: float                     # sampled Scale +- ScaleV (metres, before garden scaling)
    levels: list[StemLevel]
    leaf_counts: np.ndarray          # (N_last,) full-detail leaves per last-level stem
    leaves: LeafSet = field(default_factory=LeafSet.empty)
    leaf_aggregation: float = 1.0    # leaves merged into one (>= 1)

    @property
    def n_leaves_full(self) -> int:
        return int(self.leaf_counts.sum())

    def children_per_stem(self, level: int) -> np.ndarray:
        """Number of level-``level`` stems (clones excluded) whose parent is each row of level-1."""
        child = self.levels[level]
        orig = ~child.is_clone
        return np.bincount(child.parent[orig], minlength=self.levels[level - 1].n)


def _interp_spine(points: np.ndarray, frames: np.ndarray, rows: np.ndarray, t: np.ndarray):
    """Position, segment index and fraction at stem fractions ``t`` on ``rows``."""
    R = frames.shape[1]
    x = np.clip(t, 0.0, 1.0) * R
    j = np.minimum(np.floor(x).astype(np.int64), R - 1)
    u = x - j
    p0 = points[rows, j]
    p1 = points[rows, j + 1]
    return p0 + (p1 - p0) * u[:, None], j


def _taper(p: TreeParams, level: int, r0: np.ndarray, L: np.ndarray, Z: np.ndarray) -> np.ndarray:
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
        radius = radius * (1.0 + flare * (100.0 ** y - 1.0) / 100.0)
    return radius


def _radius_at(p: TreeParams, lvl: StemLevel, rows: np.ndarray, t: np.ndarray) -> np.ndarray:
    R = lvl.res
    j = np.minimum(np.floor(np.clip(t, 0, 1) * R).astype(np.int64), R - 1)
    r = _taper(p, lvl.level, lvl.radius[rows], lvl.length[rows], np.clip(t, 0, 1))
    return r * lvl.rfac[rows, j]


class _Rand:
    """Uniform helpers on one generator."""

    def __init__(self, rng: np.random.Generator):
        self.rng = rng

    def sym(self, n, scale=1.0):
        """U(-scale, scale), shape n."""
        return (self.rng.random(n) * 2.0 - 1.0) * scale

    def u(self, n):
        return self.rng.random(n)


def _grow_level(p: TreeParams, d: int, scale: float, origins, frames0, lengths, meta: dict, rnd: _Rand) -> StemLevel:
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
                counts, carry = _carry_round(np.full(n_now, seg_splits), carry)
            counts = _limit_family(counts, family, MAX_TRUNK_STEMS if d == 0 else MAX_FAMILY)
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
                Fr = _axis_angle(axis, tilt) @ F[rows]
                if d >= 1:
                    psi = (20.0 + 0.75 * (30.0 + np.abs(decl - 90.0)) * rnd.u(len(rows)) ** 2) * DEG
                    sign = np.where(b % 2 == 1, 1.0, -1.0)
                    psi = np.where(b == 0, 0.0, psi * sign)
                    Fr = _axis_angle(np.tile(UP, (len(rows), 1)), psi) @ Fr
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
            F = F @ _rot_local(0, ax) @ _rot_local(1, ay)
        if d == 0 and np.any(upcorr > 0):
            decl = np.arccos(np.clip(F[:, 2, 2], -1, 1))
            F = _toward_up(F, np.minimum(upcorr, decl))
        if att != 0.0:
            decl = np.arccos(np.clip(F[:, 2, 2], -1, 1))
            ang = att * decl / R
            ang = np.where(ang > 0, np.minimum(ang, decl), np.maximum(ang, -(np.pi - decl)))
            F = _toward_up(F, ang)
        frames[:, s] = F
        pos[:, s + 1] = pos[:, s] + F[:, :, 2] * (L / R)[:, None]

    # ---- pruning (envelope, then ground): scale whole stem families about their origin
    if d >= 1:
        prune_ratio = float(p["PruneRatio"])
        if prune_ratio > 0:
            f = _prune_factor(pos, start, family, lambda q: ~_envelope_inside(q, p, scale))
            f = prune_ratio * f + (1.0 - prune_ratio)
            pos, L = _apply_prune(pos, L, f)
        ground = 0.01 * scale
        f = _prune_factor(pos, start, family, lambda q: q[..., 2] < ground)
        pos, L = _apply_prune(pos, L, f)

    return StemLevel(
        level=d, points=pos, frames=frames, length=L, radius=np.zeros(len(L)), rfac=rfac, start=start,
        parent=meta["parent"].astype(np.int64), offset=meta["offset"], parent_length=meta["parent_length"],
        lmax=meta["lmax"], family=family, radius_cap=meta["radius_cap"],
    )


def _limit_family(counts: np.ndarray, family: np.ndarray, cap: int) -> np.ndarray:
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


def _prune_factor(pos, start, family, outside_fn, iterations: int = 6) -> np.ndarray:
    """Length factor per row so that no owned spine point is outside (family minimum)."""
    N, M = pos.shape[:2]
    R = M - 1
    origin = pos[:, :1]
    f = np.ones(N)
    k_idx = np.arange(M)[None, :]
    owned = (k_idx >= np.maximum(start, 1)[:, None])
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


def _apply_prune(pos, L, f):
    origin = pos[:, :1]
    return origin + (pos - origin) * f[:, None, None], L * f


def _place_children(p: TreeParams, parent: StemLevel, d_child: int, scale: float, rnd: _Rand):
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
    counts, _ = _carry_round(expected / thin)
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
    position, j = _interp_spine(parent.points, parent.frames, rows, t)
    Fseg = parent.frames[rows, j]
    F = Fseg @ _rot_local(2, rot * DEG) @ _rot_local(0, down * DEG)
    cap = _radius_at(p, parent, rows, t)
    keep = length > 2e-3 * scale  # zero shape ratio (e.g. flame crowns at the base): no stem
    if not keep.any():
        return None
    meta = dict(parent=rows[keep], offset=off[keep], parent_length=L_par[keep], lmax=lmax[keep], radius_cap=cap[keep])
    return position[keep], F[keep], length[keep], meta, thin


def _set_radii(p: TreeParams, lvl: StemLevel, parent: StemLevel, scale: float) -> None:
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
    rnd_g = _Rand(rng_for(seed, "tree", species, "global"))
    scale = float(p["Scale"]) + float(rnd_g.sym(1, float(p["ScaleV"]))[0])
    scale = max(scale, 0.25 * float(p["Scale"]), 0.5)
    trunk_len = max((float(p.lv["nLength"][0]) + float(rnd_g.sym(1, float(p.lv["nLengthV"][0]))[0])) * scale, 0.1)
    scale0 = float(p["0Scale"]) + float(rnd_g.sym(1, float(p["0ScaleV"]))[0])

    levels: list[StemLevel] = []
    frames0 = np.eye(3)[None].copy()
    # a small random heading so that the trunk's curvature plane varies with the seed
    frames0 = _rot_local(2, rnd_g.u(1) * 2 * np.pi) @ frames0
    meta0 = dict(parent=np.array([-1]), offset=np.zeros(1), parent_length=np.array([trunk_len]),
                 lmax=np.array([1.0]), radius_cap=np.array([np.inf]))
    trunk = _grow_level(p, 0, scale, np.zeros((1, 3)), frames0, np.array([trunk_len]), meta0,
                        _Rand(rng_for(seed, "tree", species, "level", 0)))
    trunk.radius = np.full(trunk.n, max(trunk_len * float(p["Ratio"]) * max(scale0, 0.05), MIN_RADIUS * scale))
    levels.append(trunk)
    for d in range(1, p.levels):
        placed = _place_children(p, levels[-1], d, scale, _Rand(rng_for(seed, "tree", species, "children", d)))
        if placed is None:
            break
        origins, F, lengths, meta, thin = placed
        lvl = _grow_level(p, d, scale, origins, F, lengths, meta, _Rand(rng_for(seed, "tree", species, "level", d)))
        lvl.weight = levels[-1].weight * thin
        _set_radii(p, lvl, levels[-1], scale)
        levels.append(lvl)

    last = levels[-1]
    leaf_counts = _leaf_counts(p, last)
    return Skeleton(species=species, seed=seed, params=p, scale=scale, levels=levels, leaf_counts=leaf_counts)


def _leaf_counts(p: TreeParams, last: StemLevel) -> np.ndarray:
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
    counts, _ = _carry_round(dens * coverage * last.weight)
    return counts


def place_leaves(skel: Skeleton, max_leaves: int | None = None, max_area_growth: float = None) -> LeafSet:
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
    counts, _ = _carry_round(full / agg)
    if max_leaves is not None and counts.sum() > max_leaves:  # rounding overshoot
        excess = int(counts.sum() - max_leaves)
        nz = np.nonzero(counts)[0][::-1][:excess]
        counts[nz] -= 1
    n = int(counts.sum())
    if n == 0:
        skel.leaves, skel.leaf_aggregation = LeafSet.empty(), agg
        return skel.leaves
    agg = total / n
    rnd = _Rand(rng_for(skel.seed, "tree", skel.species, "leaves"))
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
        F = Fseg @ _rot_local(0, tilt) @ _rot_local(1, alpha)
        bend = 0.0
    else:
        a0 = float(p["LeafStart"])
        a = np.maximum(a0, last.start / R)[rows]
        t = a + (1.0 - a) * (k + 0.5 + rnd.sym(n, 0.35)) / cnt
        t = np.clip(t, 0.0, 1.0)
        position, j = _interp_spine(last.points, last.frames, rows, t)
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
        F = Fseg @ _rot_local(2, rot * DEG) @ _rot_local(0, down * DEG)
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
        X, Y, Z = (_rotate_vectors(v, upz, ang) for v in (X, Y, Z))
        axis = np.cross(Y, UP)
        norm = np.linalg.norm(axis, axis=1)
        ok = norm > 1e-9
        axis = np.where(ok[:, None], axis / np.maximum(norm, 1e-12)[:, None], np.array([1.0, 0, 0]))
        phi = np.arccos(np.clip(Y[:, 2], -1, 1)) * bend * ok
        X, Y, Z = (_rotate_vectors(v, axis, phi) for v in (X, Y, Z))
    shape = LEAF_SHAPES.get(str(p["leaf_shape"]), LEAF_SHAPES["elliptic"])
    size = float(p["LeafScale"]) / np.sqrt(max(float(p["LeafQuality"]), 1e-3))
    length = size * (1.0 + rnd.sym(n, 0.12))
    width = length * float(p["LeafScaleX"])
    # merged leaves keep the foliage area up to a point; beyond it the crown just gets sparser
    a_len = shape["agg_len"]
    grow = min(agg, MAX_LEAF_AREA_GROWTH if max_area_growth is None else max_area_growth)
    length = length * grow ** a_len
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


# ----------------------------------------------------------------------------- leaf shapes
def _fan(outline, fold=None):
    """Template from an outline around vertex 0 (the leaf base): fan triangles."""
    pts = np.asarray(outline, dtype=np.float64)
    w = np.zeros(len(pts)) if fold is None else np.asarray(fold, dtype=np.float64)
    verts = np.column_stack([pts, w])
    m = len(pts)
    faces = np.array([[0, i, i + 1] for i in range(1, m - 1)], dtype=np.int64)
    return verts, faces


def _make_shapes() -> dict:
    shapes = {}

    def add(name, verts_faces, agg_len=0.5):
        v, f = verts_faces
        shapes[name] = {"verts": v, "faces": f, "agg_len": agg_len}

    # (u across the width in [-0.5, 0.5], v along the length in [0, 1], w along the normal)
    add("elliptic", _fan([(0, 0), (0.42, 0.2), (0.48, 0.58), (0, 1), (-0.48, 0.58), (-0.42, 0.2)],
                         [0, 0.03, 0.05, 0.0, 0.05, 0.03]))
    add("ovate", _fan([(0, 0), (0.5, 0.28), (0.36, 0.68), (0, 1), (-0.36, 0.68), (-0.5, 0.28)],
                      [0, 0.04, 0.05, 0.0, 0.05, 0.04]))
    add("lanceolate", _fan([(0, 0), (0.5, 0.3), (0.3, 0.72), (0, 1), (-0.3, 0.72), (-0.5, 0.3)],
                           [0, 0.05, 0.04, 0, 0.04, 0.05]), agg_len=0.35)
    add("deltoid", _fan([(0, 0), (0.5, 0.12), (0.36, 0.5), (0, 1), (-0.36, 0.5), (-0.5, 0.12)],
                        [0, 0.03, 0.04, 0, 0.04, 0.03]))
    add("round", _fan([(0, 0), (0.45, 0.12), (0.5, 0.55), (0.22, 0.95), (-0.22, 0.95), (-0.5, 0.55), (-0.45, 0.12)],
                      [0, 0.03, 0.05, 0.04, 0.04, 0.05, 0.03]))
    # three-lobed (sassafras mitten / oak-like)
    add("lobed", _fan([(0, 0), (0.3, 0.25), (0.5, 0.65), (0.16, 0.55), (0, 1), (-0.16, 0.55), (-0.5, 0.65),
                       (-0.3, 0.25)],
                      [0, 0.03, 0.06, 0.02, 0.0, 0.02, 0.06, 0.03]))
    # palmate (maple): five lobes around the petiole point
    ang = np.radians([-115, -80, -55, -25, 0, 25, 55, 80, 115])
    rad = np.array([0.65, 0.32, 0.9, 0.38, 1.0, 0.38, 0.9, 0.32, 0.65])
    pal = [(0.0, 0.0)] + [(0.55 * r * np.sin(a), r * np.cos(a)) for a, r in zip(ang, rad)]
    add("palmate", _fan(pal, [0] + [0.04] * 9))
    add("needle", _fan([(0, 0), (0.5, 0.5), (0, 1), (-0.5, 0.5)], [0, 0.0, 0, 0.0]), agg_len=0.25)
    # palm leaflet: long, folded along the midrib (V section)
    add("palm", _fan([(0, 0), (0.5, 0.3), (0.25, 0.75), (0, 1), (-0.25, 0.75), (-0.5, 0.3)],
                     [0, -0.45, -0.3, 0, -0.3, -0.45]), agg_len=0.4)
    add("disc", _fan([(0, 0), (0.5, 0.25), (0.5, 0.75), (0, 1), (-0.5, 0.75), (-0.5, 0.25)]))
    # tiny closed blob (desert bush): a tetrahedron spanning the leaf box
    sv = np.array([[0.0, 0.0, 0.0], [0.5, 0.6, -0.3], [-0.5, 0.6, -0.3], [0.0, 0.7, 0.55], [0.0, 1.0, 0.0]])
    sf = np.array([[0, 1, 3], [0, 3, 2], [0, 2, 1], [4, 3, 1], [4, 2, 3], [4, 1, 2]])
    shapes["sphere"] = {"verts": sv, "faces": sf, "agg_len": 0.5}
    return shapes


LEAF_SHAPES = _make_shapes()


# ----------------------------------------------------------------------------- geometry
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


def _tube_mesh(p: TreeParams, lvl: StemLevel, z: np.ndarray, sides: int, min_radius: float):
    """Vertices (V,3), faces (F,3) and the stem row of each face for one level's tubes."""
    N, R = lvl.n, lvl.res
    M = len(z)
    x = z * R
    j = np.minimum(np.floor(x + 1e-9).astype(np.int64), R - 1)
    u = x - j
    P = lvl.points
    centers = P[:, j] + (P[:, j + 1] - P[:, j]) * u[None, :, None]      # (N, M, 3)
    seg_dir = lvl.frames[:, :, :, 2]                                     # (N, R, 3)
    dirs = seg_dir[:, j]
    joint = (np.abs(u) < 1e-6) & (j > 0)
    if np.any(joint):
        jj = j[joint]
        dirs[:, joint] = _normalize(seg_dir[:, jj - 1] + seg_dir[:, jj])
    # ring frames by parallel transport of the first segment's x axis
    U = np.empty((N, M, 3))
    V = np.empty((N, M, 3))
    prev = lvl.frames[:, 0, :, 0]
    for m in range(M):
        dm = dirs[:, m]
        um = prev - dm * np.sum(prev * dm, axis=1, keepdims=True)
        um = _normalize(um)
        U[:, m] = um
        V[:, m] = np.cross(dm, um)
        prev = um
    Zb = np.broadcast_to(z[None, :], (N, M))
    radius = _taper(p, lvl.level, lvl.radius[:, None], lvl.length[:, None], Zb) * lvl.rfac[:, j]
    radius = np.maximum(radius, min_radius)
    if sides >= 3:
        phi = np.arange(sides) * (2 * np.pi / sides)
    else:
        phi = np.array([0.0, np.pi])
    cos, sin = np.cos(phi), np.sin(phi)
    rr = np.broadcast_to(radius[:, :, None], (N, M, len(phi)))
    if lvl.level == 0 and float(p["LobeDepth"]) > 0 and int(p["Lobes"]) > 0:
        rr = rr * (1.0 + float(p["LobeDepth"]) * np.sin(int(p["Lobes"]) * phi))[None, None, :]
    verts = centers[:, :, None, :] + rr[..., None] * (cos[None, None, :, None] * U[:, :, None, :]
                                                     + sin[None, None, :, None] * V[:, :, None, :])
    ns = len(phi)
    nq = ns if ns >= 3 else 1
    m_idx, k_idx = np.meshgrid(np.arange(M - 1), np.arange(nq), indexing="ij")
    a = m_idx * ns + k_idx
    b = m_idx * ns + (k_idx + 1) % ns
    c = (m_idx + 1) * ns + (k_idx + 1) % ns
    e = (m_idx + 1) * ns + k_idx
    tmpl = np.stack([np.stack([a, b, c], -1), np.stack([a, c, e], -1)], axis=2).reshape(-1, 3)  # (Q*2, 3)
    ring_of_face = np.repeat(m_idx.reshape(-1), 2)
    zs = lvl.start / R
    valid = z[ring_of_face][None, :] >= zs[:, None] - RING_EPS                                  # (N, Q*2)
    faces = tmpl[None] + (np.arange(N) * (M * ns))[:, None, None]
    stem_of_face = np.broadcast_to(np.arange(N)[:, None], valid.shape)
    return verts.reshape(-1, 3), faces[valid], stem_of_face[valid]


def _hsv_jitter(rgb: np.ndarray, dh, ds, dv) -> np.ndarray:
    """Shift hue (turns), scale saturation and value of RGB rows (vectorised)."""
    rgb = np.atleast_2d(np.asarray(rgb, dtype=np.float64))
    mx = rgb.max(axis=1)
    mn = rgb.min(axis=1)
    delta = mx - mn
    r, g, b = rgb.T
    h = np.zeros(len(rgb))
    nz = delta > 1e-12
    rm = nz & (mx == r)
    gm = nz & (mx == g) & ~rm
    bm = nz & ~rm & ~gm
    h[rm] = ((g - b)[rm] / delta[rm]) % 6
    h[gm] = (b - r)[gm] / delta[gm] + 2
    h[bm] = (r - g)[bm] / delta[bm] + 4
    h = h / 6.0
    s = np.where(mx > 1e-12, delta / np.maximum(mx, 1e-12), 0.0)
    v = mx
    h = (h + dh) % 1.0
    s = np.clip(s * ds, 0, 1)
    v = np.clip(v * dv, 0, 1)
    i = np.floor(h * 6).astype(int) % 6
    f = h * 6 - np.floor(h * 6)
    pp, q, t = v * (1 - s), v * (1 - f * s), v * (1 - (1 - f) * s)
    out = np.select([i[:, None] == k for k in range(6)],
                    [np.stack(c, 1) for c in ((v, t, pp), (q, v, pp), (pp, v, t), (pp, q, v), (t, pp, v), (v, pp, q))])
    return out


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
    for drop in range(0, n_levels):
        keep_levels = n_levels - drop
        for deep, steps in _DETAIL:
            sides = [base[0]] + list(deep)
            zsets = [_ring_z(p, lvl, steps[lvl.level]) for lvl in skel.levels[:keep_levels]]
            tris = sum(_tube_tris(lvl, z, sides[lvl.level]) for lvl, z in zip(skel.levels[:keep_levels], zsets))
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


def build_tree(species: str, seed: int, height_range: tuple[float, float] | None = None,
               triangle_budget: int = 150_000) -> Mesh:
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
    shape = LEAF_SHAPES.get(str(p["leaf_shape"]), LEAF_SHAPES["elliptic"])
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
    bark = _hsv_jitter(np.asarray(p["bark_color"], np.float64), rng_c.uniform(-0.02, 0.02),
                       rng_c.uniform(0.85, 1.15), rng_c.uniform(0.8, 1.2))[0]
    for lvl, z in zip(skel.levels[:keep_levels], zsets):
        v, f, stem = _tube_mesh(p, lvl, z, sides[lvl.level], 0.4 * MIN_RADIUS * skel.scale)
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
        lv_verts = (leaves.position[:, None, :]
                    + tv[None, :, 0:1] * W * leaves.x[:, None, :]
                    + tv[None, :, 1:2] * Lg * leaves.z[:, None, :]
                    + tv[None, :, 2:3] * W * leaves.y[:, None, :])                      # (K, m, 3)
        above = lv_verts[:, :, 2].min(axis=1) > 0.0
        lv_verts = lv_verts[above]
        alt = leaves.alt[above]
        K = len(lv_verts)
        m = tv.shape[0]
        lf = tf[None] + (np.arange(K) * m)[:, None, None] + n_v
        verts.append(lv_verts.reshape(-1, 3))
        faces.append(lf.reshape(-1, 3))
        n_v += K * m
        base_leaf = _hsv_jitter(np.asarray(p["leaf_color"], np.float64), rng_c.uniform(-0.025, 0.025),
                                rng_c.uniform(0.85, 1.15), rng_c.uniform(0.8, 1.2))[0]
        cols = np.tile(base_leaf, (K, 1))
        if p["leaf_color_alt"] is not None and alt.any():
            cols[alt] = np.asarray(p["leaf_color_alt"], np.float64)
        cols = _hsv_jitter(cols, rng_c.uniform(-0.012, 0.012, K), rng_c.uniform(0.92, 1.08, K),
                           rng_c.uniform(0.88, 1.12, K))
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
    target = float(h_rng.uniform(float(lo), float(hi)))
    top = float(V[:, 2].max())
    V = V * (target / max(top, 1e-9))
    n_f = len(Fc)
    return Mesh(V, Fc, np.full(n_f, labels.TREE, np.uint8), np.concatenate(mats), np.concatenate(albedo),
                np.concatenate(transl), np.concatenate(spec))
