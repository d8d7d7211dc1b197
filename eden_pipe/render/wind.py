"""Wind-blown foliage: a seeded, deterministic deformation of the garden's mesh, a function of time.

docs/design.md, "Wind", is the contract. Each family answers the wind in the way real-time
foliage animation models it (hierarchical sway, as in GPU Gems 3, ch. 16):

- trees sway as a whole, bending like a cantilever ((h/H)^2 of the height above the base),
  at a natural frequency that falls with height; their branches bob with a phase from their
  position, more the further from the trunk; their leaves flutter;
- hedges and topiaries rustle: a small coherent field over the bush, growing with height;
- grass and flowers bend with a gust field that travels downwind across the garden;
- everything else (ground, lawn soil, pavement, fences, obstacles, the background) is rigid:
  its vertices are never written, so its pixels keep today's ground truth bit for bit.

The drag on a plant grows with the square of the wind speed: every amplitude below is the one
at ``REFERENCE_SPEED_MPS`` and scales with (speed / reference)^2, capped at ``MAX_SPEED_MPS``.
Positions depend on the time alone (no state from earlier frames), so frames render in any
order and a job resumes anywhere.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np
from numba import njit

from eden_pipe import labels
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.render.kernels import kernel
from eden_pipe.rng import rng_for

REFERENCE_SPEED_MPS = 5.0  # the speed the response amplitudes are given at
MAX_SPEED_MPS = 15.0  # beyond a gale the amplitudes stop growing (plants would break, not bend further)
GUST_PERIOD_S = 6.0  # the travelling gust field's period (gusts pass every few seconds)
GRASS_CELL_M = 0.1  # the lawn's local ground: the lowest lawn vertex in cells this wide
GRASS_REFERENCE_HEIGHT_M = 0.15  # a blade this tall bends by the grass response's sway at its tip
MAX_BLADE_BEND = 1.5  # taller lawn plants (weeds) bend as if 1.5 times the reference height
DETAIL_WAVELENGTH_M = 0.8  # branches and bush patches move together over about this distance
FLUTTER_WAVELENGTH_M = 0.15  # leaves flutter together over about this distance (one leaf, not its vertices)
SWAY, DETAIL, FLUTTER = 0, 1, 2  # per-vertex weight columns

# Which faces flutter (thin parts) and which never move, among the families' materials.
FLUTTERING = frozenset(MATERIALS[m] for m in ("leaf", "petal", "grass"))
RIGID_MATERIALS = frozenset(MATERIALS[m] for m in ("grass_soil", "dirt", "gravel", "pebbles", "pavement", "rock"))


@dataclass(frozen=True)
class Response:
    """How one family answers the wind at ``REFERENCE_SPEED_MPS`` (metres of displacement, hertz).

    ``sway`` is a fraction of the plant's height (its top moves by sway x height), except for
    grass, whose blades have no instance: there it is metres at a blade of ``GRASS_REFERENCE_HEIGHT_M``.
    """

    sway: float  # whole-plant bend at the top
    sway_hz: float  # natural frequency (trees: at 4 m, scaled by sqrt(4 m / height))
    detail_m: float  # branch or bush-patch motion
    detail_hz: float
    flutter_m: float  # leaf, petal and blade flutter
    flutter_hz: float
    profile: int  # the bend along the height: 2 = cantilever (h/H)^2, 1 = linear
    model: int  # how the fields combine in the kernel (TREE_MODEL, BUSH_MODEL, BLADE_MODEL)


TREE_MODEL, BUSH_MODEL, BLADE_MODEL = 0, 1, 2
# Tree tops sway a few centimetres in a moderate breeze (5 m/s, Beaufort 3), hedges rustle by
# millimetres to a centimetre, blades bend by a few centimetres; leaves flutter at a few hertz.
RESPONSES: dict[int, Response] = {
    labels.TREE: Response(0.012, 0.5, 0.02, 1.1, 0.006, 3.0, profile=2, model=TREE_MODEL),
    labels.HEDGE: Response(0.004, 0.8, 0.006, 1.3, 0.004, 3.5, profile=1, model=BUSH_MODEL),
    labels.TOPIARY: Response(0.003, 0.9, 0.004, 1.4, 0.003, 3.5, profile=1, model=BUSH_MODEL),
    labels.FLOWER: Response(0.06, 1.2, 0.005, 2.0, 0.004, 3.0, profile=2, model=BLADE_MODEL),
    labels.GRASS: Response(0.05, 1.0, 0.004, 2.0, 0.003, 4.0, profile=2, model=BLADE_MODEL),
}


@dataclass(frozen=True)
class WindParams:
    """One garden's wind under one lighting (``lighting.wind_mps``, ``wind_direction_deg``,
    ``gust_strength``, drawn per garden), published in lighting.json."""

    speed_mps: float
    direction_deg: float  # where the wind blows to, counter-clockwise from world +x
    gust_strength: float  # the gusts' swing as a fraction of the mean drag

    @property
    def amplitude(self) -> float:
        """The factor on every response amplitude: drag ~ speed^2, relative to the reference speed."""
        speed = min(self.speed_mps, MAX_SPEED_MPS)
        return (speed / REFERENCE_SPEED_MPS) ** 2

    def facts(self) -> dict:
        return {**asdict(self), "reference_speed_mps": REFERENCE_SPEED_MPS, "gust_period_s": GUST_PERIOD_S}


def draw_wind(lighting, seed: int) -> WindParams | None:
    """The wind of a garden under ``lighting`` (a lighting config read by attribute), or None when
    there is none (``wind_mps`` 0: nothing moves and nothing is drawn, so datasets without wind stay
    as they were). Drawn with its own generator: the sky's draws never shift."""
    from eden_pipe.lighting import SCENARIO_TABLE, WIND_KEYS, value_range

    scenario = SCENARIO_TABLE[lighting.name]
    rng = rng_for(seed, "wind", lighting.name)
    drawn = {}
    for key in WIND_KEYS:  # one draw per key, always, in this order
        lo, hi = value_range(key, getattr(lighting, key), scenario)
        drawn[key] = float(rng.uniform(lo, hi))
    if drawn["wind_mps"] <= 0.0:
        return None
    return WindParams(drawn["wind_mps"], drawn["wind_direction_deg"], drawn["gust_strength"])


def _per_vertex(mesh: Mesh, per_face: np.ndarray) -> np.ndarray:
    """A per-face attribute on the vertices (a mesh's objects share no vertices)."""
    out = np.zeros(len(mesh.vertices), per_face.dtype)
    out[mesh.faces.ravel()] = np.repeat(per_face, 3)
    return out


def _group_extent(ids: np.ndarray, values: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(min, max) of ``values`` per group id in [0, n)."""
    lo = np.full(n, np.inf, np.float64)
    hi = np.full(n, -np.inf, np.float64)
    np.minimum.at(lo, ids, values)
    np.maximum.at(hi, ids, values)
    return lo, hi


@dataclass
class WindField:
    """The garden's moving vertices and their weights: built once per job, evaluated per time.

    Per moving vertex (``index``): ``weights`` (M, 3) metres at the reference speed (sway, detail,
    flutter), ``height`` above its plant's base (blades: above the lawn's local ground), its
    ``family`` (a row of the response tables) and ``plant`` (a row of the plant tables: its own
    phase and natural frequency; 0 for the lawn)."""

    params: WindParams
    rest: np.ndarray  # (V, 3) float32: the mesh's vertices, where they stand without wind
    index: np.ndarray  # (M,) int32
    weights: np.ndarray  # (M, 3) float32
    height: np.ndarray  # (M,) float32
    family: np.ndarray  # (M,) uint8
    plant: np.ndarray  # (M,) int32
    plant_phase: np.ndarray  # (plants,) float64 radians
    plant_hz: np.ndarray  # (plants,) float64
    family_model: np.ndarray  # (families,) int64: TREE_MODEL, BUSH_MODEL or BLADE_MODEL
    family_hz: np.ndarray  # (families, 2) float64: detail and flutter frequencies

    @classmethod
    def build(cls, mesh: Mesh, instance: np.ndarray, params: WindParams, seed: int) -> WindField:
        vertices = mesh.vertices
        semantic = _per_vertex(mesh, mesh.semantic)
        material = _per_vertex(mesh, mesh.material)
        owner = _per_vertex(mesh, np.asarray(instance, np.int64))
        families = np.array(sorted(RESPONSES), np.uint8)
        moving = np.isin(semantic, families) & ~np.isin(material, np.array(sorted(RIGID_MATERIALS), np.uint8))
        index = np.nonzero(moving)[0].astype(np.int32)
        sem, mat, inst = semantic[index], material[index], owner[index]
        pos = vertices[index].astype(np.float64)
        n_inst = int(owner.max()) + 1 if len(owner) else 1

        # Each plant's base, height and trunk axis (its bounding box's centre), from its own vertices.
        base, top = _group_extent(inst, pos[:, 2], n_inst)
        x_lo, x_hi = _group_extent(inst, pos[:, 0], n_inst)
        y_lo, y_hi = _group_extent(inst, pos[:, 1], n_inst)
        for extent in (base, top, x_lo, x_hi, y_lo, y_hi):
            extent[~np.isfinite(extent)] = 0.0  # ids without a moving vertex (rigid instances)
        plant_height = np.maximum(top - base, 1e-3)
        radius = np.maximum(0.5 * np.maximum(x_hi - x_lo, y_hi - y_lo), 1e-3)
        axis_x, axis_y = 0.5 * (x_lo + x_hi), 0.5 * (y_lo + y_hi)
        height = pos[:, 2] - base[inst]
        frac = np.clip(height / plant_height[inst], 0.0, 1.0)
        reach = np.hypot(pos[:, 0] - axis_x[inst], pos[:, 1] - axis_y[inst]) / radius[inst]

        # Blades have no instance: their base is the lawn's local ground (the lowest lawn vertex nearby).
        lawn = inst == 0
        if lawn.any():
            lawn_all = (semantic == labels.GRASS) & (owner == 0)
            cells_all = np.floor(vertices[lawn_all, :2] / GRASS_CELL_M).astype(np.int64)
            keys, inverse = np.unique(cells_all, axis=0, return_inverse=True)
            ground = np.full(len(keys), np.inf)
            np.minimum.at(ground, inverse.ravel(), vertices[lawn_all, 2].astype(np.float64))
            cells = np.floor(pos[lawn, :2] / GRASS_CELL_M).astype(np.int64)
            found = np.searchsorted(_row_keys(keys), _row_keys(cells))
            height[lawn] = np.maximum(pos[lawn, 2] - ground[found], 0.0)
            frac[lawn] = np.minimum(height[lawn] / GRASS_REFERENCE_HEIGHT_M, MAX_BLADE_BEND)
            reach[lawn] = 0.0

        weights = np.zeros((len(index), 3), np.float32)
        family = np.zeros(len(index), np.uint8)
        flutters = np.isin(mat, np.array(sorted(FLUTTERING), np.uint8))
        responses = list(RESPONSES.items())
        plant_hz = np.ones(n_inst)
        for row, (s, r) in enumerate(responses):
            m = sem == s
            if not m.any():
                continue
            # Plants bend by a fraction of their height; blades (no instance) by metres at the reference height.
            size = np.where(inst[m] == 0, 1.0, plant_height[inst[m]])
            weights[m, SWAY] = r.sway * frac[m] ** r.profile * size
            along = np.clip(reach[m], 0.0, 1.5) if r.model == TREE_MODEL else 1.0
            weights[m, DETAIL] = r.detail_m * frac[m] * along
            weights[m, FLUTTER] = np.where(flutters[m], r.flutter_m * np.minimum(frac[m], 1.0), 0.0)
            family[m] = row
            owners = np.unique(inst[m])
            # Taller trees sway more slowly (a cantilever's first mode falls with its length).
            tall = np.sqrt(4.0 / np.maximum(plant_height[owners], 0.2)) if r.model == TREE_MODEL else 1.0
            plant_hz[owners] = r.sway_hz * tall
        rng = rng_for(seed, "wind", "plants")
        return cls(
            params=params,
            rest=vertices,
            index=index,
            weights=weights,
            height=height.astype(np.float32),
            family=family,
            plant=inst.astype(np.int32),
            plant_phase=rng.uniform(0.0, 2.0 * np.pi, n_inst),
            plant_hz=plant_hz,
            family_model=np.array([r.model for _, r in responses], np.int64),
            family_hz=np.array([(r.detail_hz, r.flutter_hz) for _, r in responses], np.float64),
        )

    def move(self, time: float, out: np.ndarray) -> None:
        """Write the moving vertices' positions at ``time`` seconds into ``out`` (V, 3) float32, which
        holds the rest positions elsewhere (the rigid vertices are never written)."""
        p = self.params
        angle = math.radians(p.direction_deg)
        _move(
            self.rest,
            self.index,
            self.weights,
            self.height,
            self.family,
            self.plant,
            self.plant_phase,
            self.plant_hz,
            self.family_model,
            self.family_hz,
            np.array([time, p.amplitude, p.gust_strength, math.cos(angle), math.sin(angle), max(p.speed_mps, 0.1)]),
            out,
        )

    def positions(self, time: float) -> np.ndarray:
        """Every vertex at ``time`` (a new (V, 3) float32 array)."""
        out = self.rest.copy()
        self.move(time, out)
        return out


def _row_keys(cells: np.ndarray) -> np.ndarray:
    """One sortable int64 per (i, j) cell row, in np.unique(axis=0)'s order."""
    return (cells[:, 0] << 32) + (cells[:, 1] - np.int64(-(2**31)))


TWO_PI = 2.0 * math.pi


@njit(inline="always")
def _sin(x):
    """sin(x) within 4e-6, without a library call, so the vertex loop vectorises: x folded to
    [-pi/2, pi/2] by a multiple of pi, then its Taylor polynomial to the 9th order."""
    k = math.floor(x * (1.0 / math.pi) + 0.5)
    r = x - k * math.pi
    r2 = r * r
    s = r * (1.0 + r2 * (-1.0 / 6 + r2 * (1.0 / 120 + r2 * (-1.0 / 5040 + r2 * (1.0 / 362880)))))
    return s * (1.0 - 2.0 * (k - 2.0 * math.floor(k * 0.5)))


@njit(inline="always")
def _field(x, y, z, wavelength, salt):
    """A smooth phase field over space: a plant's parts within ``wavelength`` move together."""
    k = TWO_PI / wavelength
    return k * (0.71 * x + 0.53 * y + 0.47 * z) + 1.7 * _sin(k * (0.37 * x - 0.83 * y) + salt)


@kernel
def _move(rest, index, weights, height, family, plant, plant_phase, plant_hz, family_model, family_hz, setting, out):
    t, amp, gust, wx, wy, speed = setting[0], setting[1], setting[2], setting[3], setting[4], setting[5]
    # Unit vectors: downwind (wx, wy, 0), across (-wy, wx, 0), up (0, 0, 1).
    for j in range(len(index)):
        v = index[j]
        x, y, z = np.float64(rest[v, 0]), np.float64(rest[v, 1]), np.float64(rest[v, 2])
        # The gust field travels downwind at the wind's speed; plants lean with the mean drag and swing with it.
        lag = t - (x * wx + y * wy) / speed
        g = 1.0 + gust * (
            0.7 * _sin(TWO_PI * lag / GUST_PERIOD_S) + 0.3 * _sin(TWO_PI * lag / (0.37 * GUST_PERIOD_S) + 1.3)
        )
        w_sway, w_detail, w_flutter = weights[j, 0] * amp, weights[j, 1] * amp, weights[j, 2] * amp
        fam, p = family[j], plant[j]
        ph, hz = plant_phase[p], plant_hz[p]
        blade = family_model[fam] == BLADE_MODEL
        osc = _sin(TWO_PI * hz * t + ph)
        down = w_sway * ((0.8 * g + 0.2 * osc) if blade else (0.6 * g + 0.4 * osc))
        cross = (0.15 if blade else 0.25) * w_sway * _sin(TWO_PI * 1.3 * hz * t + 1.7 * ph)
        detail = w_detail * g * _sin(TWO_PI * family_hz[fam, 0] * t + _field(x, y, z, DETAIL_WAVELENGTH_M, ph))
        f2 = _field(x, y, z, FLUTTER_WAVELENGTH_M, 2.3)
        flutter = w_flutter * g * _sin(TWO_PI * family_hz[fam, 1] * t + f2)
        flutter2 = w_flutter * g * _sin(TWO_PI * 1.37 * family_hz[fam, 1] * t + 1.9 * f2)
        dx = (down + 0.5 * detail) * wx - (cross + 0.6 * flutter2) * wy
        dy = (down + 0.5 * detail) * wy + (cross + 0.6 * flutter2) * wx
        dz = 0.8 * detail + flutter
        if blade:
            # A bent blade keeps its length: its tip drops as it leans (to second order).
            h = max(np.float64(height[j]), 0.01)
            dz -= min(0.5 * (dx * dx + dy * dy) / h, 0.5 * h)
        out[v, 0] = np.float32(x + dx)
        out[v, 1] = np.float32(y + dy)
        out[v, 2] = np.float32(z + dz)


@kernel
def _surface_motion(points, prim, hit, faces, now, other, out):
    """Each hit point's displacement to the other time: its barycentric coordinates on its face as
    it stands now, applied to the face's vertices there (0 exactly where the face does not move)."""
    for i in range(len(prim)):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
        out[i, 2] = 0.0
        if not hit[i]:
            continue
        f = prim[i]
        a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
        moved = False
        for k in range(3):
            if now[a, k] != other[a, k] or now[b, k] != other[b, k] or now[c, k] != other[c, k]:
                moved = True
        if not moved:
            continue
        e1 = np.empty(3)
        e2 = np.empty(3)
        q = np.empty(3)
        for k in range(3):
            e1[k] = np.float64(now[b, k]) - np.float64(now[a, k])
            e2[k] = np.float64(now[c, k]) - np.float64(now[a, k])
            q[k] = points[i, k] - np.float64(now[a, k])
        d11 = e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]
        d12 = e1[0] * e2[0] + e1[1] * e2[1] + e1[2] * e2[2]
        d22 = e2[0] * e2[0] + e2[1] * e2[1] + e2[2] * e2[2]
        q1 = q[0] * e1[0] + q[1] * e1[1] + q[2] * e1[2]
        q2 = q[0] * e2[0] + q[1] * e2[1] + q[2] * e2[2]
        det = d11 * d22 - d12 * d12
        if det <= 0.0:
            wb, wc = 1.0 / 3.0, 1.0 / 3.0  # a degenerate face: its centroid's motion
        else:
            wb = (d22 * q1 - d12 * q2) / det
            wc = (d11 * q2 - d12 * q1) / det
        wa = 1.0 - wb - wc
        for k in range(3):
            da = np.float64(other[a, k]) - np.float64(now[a, k])
            db = np.float64(other[b, k]) - np.float64(now[b, k])
            dc = np.float64(other[c, k]) - np.float64(now[c, k])
            out[i, k] = wa * da + wb * db + wc * dc


def surface_motion(points, prim, hit, faces, now, other) -> np.ndarray:
    """(N, 3) float64: how far each hit point (``points`` (N, 3) on face ``prim`` of the mesh with
    vertices ``now``) moves when the vertices become ``other``; 0 on misses and rigid faces."""
    out = np.empty((len(prim), 3), np.float64)
    _surface_motion(
        np.ascontiguousarray(points, np.float64),
        np.ascontiguousarray(prim, np.int64),
        np.ascontiguousarray(hit, np.bool_),
        faces,
        now,
        other,
        out,
    )
    return out
