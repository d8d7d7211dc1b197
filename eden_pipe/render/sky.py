"""Sky, sun, clouds and distant scenery for the five lighting scenarios.

Scenarios: ``clear``, ``cloudy``, ``sunset`` (Preetham 1999 analytic sky with a
sun coloured by Rayleigh + aerosol transmittance; cloudy adds a drifting fBm
cloud layer), ``overcast`` (CIE overcast sky, no direct sun) and ``twilight``
(sun below the horizon, no direct sun, dim blue sky with a glow toward the
sun's azimuth).

Units and scale (the renderer's contract):

* Everything is linear sRGB (D65). A white Lambertian surface reflects
  ``albedo / pi * irradiance``.
* One global factor ``K_SCALE`` maps photometric units (Preetham's kcd/m^2 for sky
  luminance, klux for sun illuminance) to render units. It is chosen so that
  the clear sun at 60 deg elevation, turbidity 2.5, ``sun_intensity=1`` has a
  luminance irradiance ``0.2126 R + 0.7152 G + 0.0722 B`` of exactly ``pi``
  (direct shading ~1). The same ``K_SCALE`` scales the sky, so the sky/sun ratio is
  the physical Preetham one.
* Overcast is set to ``OVERCAST_FRACTION`` of the clear-sky horizontal
  illuminance at the same sun elevation; twilight to a fraction of the clear
  reference (60 deg) that falls from ~3 % at -1 deg to ~1 % at -6 deg.
* ``Sky.exposure = clip((key_ref / key) ** EXPOSURE_POWER, 0.5, 16)`` with
  key = sky horizontal + sun normal irradiance x max(sin elevation, 0.25) x
  mean cloud transmittance (luminance), key_ref the clear 60 deg reference:
  a partial compensation, so image brightness keeps the order
  twilight < overcast < clear.
* ``Sky.horizontal_irradiance`` (extra, (3,)) is the sky + mean sun
  irradiance on the ground plane.

Directions are world unit vectors (Z up); the sun azimuth is measured from +x
toward +y. Functions of direction are pure functions of direction (the sky is
at infinity): they move by camera rotation only.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from eden_pipe.models.noise import Perlin, fbm2
from eden_pipe.render import lut, vec
from eden_pipe.rng import rng_for

SCENARIOS = ("clear", "cloudy", "overcast", "sunset", "twilight")
PREETHAM_SCENARIOS = ("clear", "cloudy", "sunset")

# Keys a lighting config may hold (Hydra keys starting with "_" are ignored).
LIGHTING_KEYS = (
    "name", "sun_elevation_deg", "sun_azimuth_deg", "turbidity", "sun_intensity",
    "sky_intensity", "cloud_cover", "cloud_speed",
)

# Per-scenario defaults for keys the config leaves out ([lo, hi] or scalar).
SCENARIO_DEFAULTS: dict[str, dict[str, object]] = {
    "clear": dict(sun_elevation_deg=[35.0, 60.0], turbidity=[2.0, 3.0], cloud_cover=0.0),
    "cloudy": dict(sun_elevation_deg=[25.0, 50.0], turbidity=[3.0, 5.0], cloud_cover=[0.3, 0.6]),
    "overcast": dict(sun_elevation_deg=[35.0, 60.0], turbidity=[3.0, 3.0], cloud_cover=1.0),
    "sunset": dict(sun_elevation_deg=[1.0, 6.0], turbidity=[3.0, 5.0], cloud_cover=0.0),
    "twilight": dict(sun_elevation_deg=[-6.0, -1.0], turbidity=[2.0, 3.0], cloud_cover=0.0),
}
COMMON_DEFAULTS: dict[str, object] = dict(
    sun_azimuth_deg=[0.0, 360.0], sun_intensity=1.0, sky_intensity=1.0, cloud_speed=1.0,
)

# Allowed sun elevations (deg) per scenario: Preetham needs the sun above the
# horizon; twilight needs it below.
ELEVATION_LIMITS_DEG = {
    "clear": (0.5, 90.0), "cloudy": (0.5, 90.0), "overcast": (0.5, 90.0),
    "sunset": (0.5, 90.0), "twilight": (-12.0, -0.5),
}
TURBIDITY_LIMITS = (1.7, 10.0)  # below ~1.7 the Perez Y term goes negative

SUN_ANGULAR_RADIUS = math.radians(0.53) / 2.0
LAMBDA_RGB_UM = np.array([0.65, 0.57, 0.475])
LUMA = np.array([0.2126, 0.7152, 0.0722])
XYZ_TO_SRGB = np.array([
    [3.2406, -1.5372, -0.4986],
    [-0.9689, 1.8758, 0.0415],
    [0.0557, -0.2040, 1.0570],
])
E0_KLUX = 133.8             # luminous solar constant (extraterrestrial normal illuminance), klux
T_REF = 2.5                 # reference turbidity of the scale convention
ELEV_REF = math.radians(60.0)
OVERCAST_FRACTION = 0.3     # overcast / clear horizontal illuminance, same sun
GROUND_ALBEDO = np.array([0.13, 0.13, 0.08])
EXPOSURE_POWER = 0.5       # 0: no compensation, 1: full (every scenario as bright as clear)

# Cloud layer: altitude and base feature size chosen so cumulus look ~20 deg
# across at the zenith while their shadows still have metre-scale edges that
# drift visibly across a 10 m garden.
CLOUD_ALTITUDE = 250.0      # m
CLOUD_SCALE = 60.0          # m per noise lattice unit (first octave)
CLOUD_OCTAVES = 5
CLOUD_EDGE = 0.035          # half-width of the fBm threshold ramp (sets shadow edge softness)
CLOUD_MIN_TRANSMITTANCE = 0.12
CLOUD_ALBEDO = 0.85
CLOUD_ORIGIN = np.array([5.0, 5.0, 0.0])  # garden centre: where the sky is seen from
SCENERY_EYE_HEIGHT = 1.0    # m, camera height assumed for the scenery's foot below the horizon


# ---------------------------------------------------------------- Preetham ---

def perez_coefficients(turbidity: float) -> np.ndarray:
    """(3, 5) Perez A..E for Y, x, y (Preetham 1999, linear in turbidity)."""
    t = float(turbidity)
    return np.array([
        [0.1787 * t - 1.4630, -0.3554 * t + 0.4275, -0.0227 * t + 5.3251, 0.1206 * t - 2.5771, -0.0670 * t + 0.3703],
        [-0.0193 * t - 0.2592, -0.0665 * t + 0.0008, -0.0004 * t + 0.2125, -0.0641 * t - 0.8989, -0.0033 * t + 0.0452],
        [-0.0167 * t - 0.2608, -0.0950 * t + 0.0092, -0.0079 * t + 0.2102, -0.0441 * t - 1.6537, -0.0109 * t + 0.0529],
    ])


def perez(cos_theta: np.ndarray, gamma: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """Perez F(theta, gamma) for one row of coefficients; cos_theta > 0."""
    a, b, c, d, e = coeffs
    cg = np.cos(gamma)
    return (1.0 + a * np.exp(b / cos_theta)) * (1.0 + c * np.exp(d * gamma) + e * cg * cg)


def zenith_luminance(theta_s: float, turbidity: float) -> float:
    """Preetham zenith luminance Yz in kcd/m^2."""
    t = float(turbidity)
    chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * theta_s)
    return (4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192


def zenith_chromaticity(theta_s: float, turbidity: float) -> tuple[float, float]:
    """Preetham zenith chromaticity (xz, yz): cubic in theta_s, quadratic in T."""
    t = np.array([turbidity**2, turbidity, 1.0])
    th = np.array([theta_s**3, theta_s**2, theta_s, 1.0])
    mx = np.array([[0.00166, -0.00375, 0.00209, 0.0],
                   [-0.02903, 0.06377, -0.03202, 0.00394],
                   [0.11693, -0.21196, 0.06052, 0.25886]])
    my = np.array([[0.00275, -0.00610, 0.00317, 0.0],
                   [-0.04214, 0.08970, -0.04153, 0.00516],
                   [0.15346, -0.26756, 0.06670, 0.26688]])
    return float(t @ mx @ th), float(t @ my @ th)


def air_mass(theta_s: float) -> float:
    """Kasten-style relative optical air mass for a sun zenith angle (rad)."""
    ts_deg = math.degrees(theta_s)
    return 1.0 / (math.cos(theta_s) + 0.15 * (93.885 - ts_deg) ** -1.253)


def sun_transmittance(theta_s: float, turbidity: float) -> np.ndarray:
    """(3,) Rayleigh x aerosol transmittance of the direct sun at lambda R, G, B."""
    m = air_mass(theta_s)
    beta = 0.04608 * turbidity - 0.04586
    lam = LAMBDA_RGB_UM
    return np.exp(-m * (0.008735 * lam**-4.08 + beta * lam**-1.3))


def xyY_to_rgb(Y: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(N,) CIE Yxy -> (N, 3) linear sRGB (negative components clipped)."""
    y = np.maximum(y, 1e-6)
    X = x / y * Y
    Z = (1.0 - x - y) / y * Y
    rgb = np.stack([X, Y, Z], axis=-1) @ XYZ_TO_SRGB.T
    return np.maximum(rgb, 0.0)


def preetham_rgb(directions: np.ndarray, sun_dir: np.ndarray, turbidity: float) -> np.ndarray:
    """(N, 3) Preetham sky in kcd/m^2-scaled linear sRGB for directions with z >= 0."""
    d = np.asarray(directions, dtype=np.float64)
    theta_s = math.acos(min(max(float(sun_dir[2]), -1.0), 1.0))
    coeffs = perez_coefficients(turbidity)
    yz_lum = zenith_luminance(theta_s, turbidity)
    xz, yz = zenith_chromaticity(theta_s, turbidity)
    cos_t = np.clip(d[:, 2], 1e-3, 1.0)
    gamma = np.arccos(np.clip(d @ sun_dir, -1.0, 1.0))
    out = []
    for row, zen in zip(coeffs, (yz_lum, xz, yz)):
        f0 = perez(np.array(1.0), np.array(theta_s), row)
        out.append(zen * perez(cos_t, gamma, row) / f0)
    return xyY_to_rgb(np.maximum(out[0], 0.0), out[1], out[2])


def _sun_dir(elevation: float, azimuth: float) -> np.ndarray:
    ce = math.cos(elevation)
    return np.array([ce * math.cos(azimuth), ce * math.sin(azimuth), math.sin(elevation)])


# ------------------------------------------------------------- quadrature ---

def sphere_quadrature(n_up: int, n_down: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    """Lat-long midpoint quadrature: (M, 3) directions, (M,) solid angles.

    The horizon is a band edge, so the upper hemisphere integrates exactly the
    z >= 0 half (no band straddles the sky/ground seam). Below the horizon a
    quarter of the bands resolve the ~3 deg horizon-to-ground blend.
    """
    edges = [np.linspace(0.0, math.pi / 2, n_up + 1)]
    if n_down:
        fine = max(n_down // 4, 1)
        edges.append(np.concatenate([np.linspace(math.pi / 2, math.pi / 2 + 0.07, fine + 1),
                                     np.linspace(math.pi / 2 + 0.07, math.pi, n_down - fine + 1)[1:]]))
    dirs, weights = [], []
    phi = (np.arange(n_phi) + 0.5) * (2 * math.pi / n_phi)
    for e in edges:
        t0, t1 = e[:-1], e[1:]
        tm = 0.5 * (t0 + t1)
        w = (np.cos(t0) - np.cos(t1)) * (2 * math.pi / n_phi)
        T, P = np.meshgrid(tm, phi, indexing="ij")
        st = np.sin(T)
        dirs.append(np.stack([st * np.cos(P), st * np.sin(P), np.cos(T)], -1).reshape(-1, 3))
        weights.append(np.repeat(w, n_phi))
    return np.concatenate(dirs), np.concatenate(weights)


@lru_cache(maxsize=64)
def _clear_reference(elev_rounded: float, turbidity: float) -> tuple[float, float]:
    """(sun, sky) horizontal luminance irradiance, klux, of a clear Preetham sky."""
    elev = math.radians(elev_rounded)
    s = _sun_dir(elev, 0.0)
    dirs, w = sphere_quadrature(48, 0, 96)
    rgb = preetham_rgb(dirs, s, turbidity)
    sky = float(((rgb @ LUMA) * dirs[:, 2] * w).sum())
    sun = E0_KLUX * float(sun_transmittance(math.pi / 2 - elev, turbidity) @ LUMA) * math.sin(elev)
    return sun, sky


# Render units per (klux or kcd/m^2): clear sun at 60 deg, T 2.5 -> luminance pi.
K_SCALE = math.pi / (E0_KLUX * float(sun_transmittance(math.pi / 2 - ELEV_REF, T_REF) @ LUMA))


def clear_reference_irradiance(elevation: float = ELEV_REF, turbidity: float = T_REF) -> float:
    """Horizontal luminance irradiance (render units) of a clear sky + sun."""
    sun, sky = _clear_reference(round(math.degrees(max(elevation, math.radians(2.0))), 3), round(turbidity, 4))
    return K_SCALE * (sun + sky)


# -------------------------------------------------------------- lighting ---

@dataclass
class LightingParams:
    """Lighting of one garden, resolved from the lighting config ranges."""

    scenario: str             # clear | cloudy | overcast | sunset | twilight
    sun_elevation: float      # radians (negative below horizon)
    sun_azimuth: float        # radians, measured from +x toward +y
    turbidity: float
    sun_intensity: float = 1.0
    sky_intensity: float = 1.0
    cloud_cover: float = 0.0  # 0..1
    cloud_speed: float = 1.0  # m/s drift of the cloud layer


def _is_number(v: object) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(float(v))


def _range(key: str, value: object, lo_lim: float, hi_lim: float, unit: str = "") -> tuple[float, float]:
    """Parse a scalar or [lo, hi] into (lo, hi) within [lo_lim, hi_lim]."""
    allowed = f"a number or [lo, hi] with lo <= hi, within [{lo_lim:g}, {hi_lim:g}]{unit}"
    if _is_number(value):
        lo = hi = float(value)
    elif isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        items = list(value)
        if len(items) != 2 or not all(_is_number(v) for v in items):
            raise ValueError(f"lighting.{key}={items!r} is not a pair of finite numbers; allowed: {allowed}")
        lo, hi = float(items[0]), float(items[1])
        if lo > hi:
            raise ValueError(f"lighting.{key}={items!r} has lo > hi; allowed: {allowed}")
    else:
        raise ValueError(f"lighting.{key}={value!r} is not a number or a [lo, hi] pair; allowed: {allowed}")
    if lo < lo_lim or hi > hi_lim:
        raise ValueError(f"lighting.{key}={value!r} is out of range; allowed: {allowed}")
    return lo, hi


def sample_lighting(cfg: Mapping, rng: np.random.Generator) -> LightingParams:
    """Draw one garden's lighting from a lighting config (YAML ranges, degrees).

    Every key is drawn in a fixed order whether or not its range is degenerate,
    so one key's draw never shifts another's. Missing keys take the scenario's
    defaults (SCENARIO_DEFAULTS, COMMON_DEFAULTS). Raises ValueError naming
    the key, the value and what is allowed.
    """
    if not isinstance(cfg, Mapping):
        try:
            cfg = dict(cfg)  # OmegaConf DictConfig and the like
        except Exception as exc:  # noqa: BLE001
            raise ValueError(f"lighting config must be a mapping, got {type(cfg).__name__}") from exc
    cfg = {str(k): v for k, v in cfg.items() if not str(k).startswith("_")}
    unknown = sorted(set(cfg) - set(LIGHTING_KEYS))
    if unknown:
        raise ValueError(f"lighting config has unknown key(s) {unknown}; allowed keys: {list(LIGHTING_KEYS)}")
    name = cfg.get("name")
    if name not in SCENARIOS:
        raise ValueError(f"lighting.name={name!r} is not a known scenario; allowed: {list(SCENARIOS)}")
    merged = {**COMMON_DEFAULTS, **SCENARIO_DEFAULTS[name], **cfg}

    elim = ELEVATION_LIMITS_DEG[name]
    elev = _range("sun_elevation_deg", merged["sun_elevation_deg"], *elim, f" deg for scenario {name}")
    azim = _range("sun_azimuth_deg", merged["sun_azimuth_deg"], -360.0, 720.0, " deg")
    turb = _range("turbidity", merged["turbidity"], *TURBIDITY_LIMITS)
    sun_i = _range("sun_intensity", merged["sun_intensity"], 0.0, 1e6)
    sky_i = _range("sky_intensity", merged["sky_intensity"], 0.0, 1e6)
    cover = _range("cloud_cover", merged["cloud_cover"], 0.0, 1.0)
    speed = _range("cloud_speed", merged["cloud_speed"], 0.0, 1e3, " m/s")

    draw = lambda r: float(rng.uniform(r[0], r[1]))  # noqa: E731  one draw per key, always
    return LightingParams(
        scenario=name,
        sun_elevation=math.radians(draw(elev)),
        sun_azimuth=math.radians(draw(azim)),
        turbidity=draw(turb),
        sun_intensity=draw(sun_i),
        sky_intensity=draw(sky_i),
        cloud_cover=draw(cover),
        cloud_speed=draw(speed),
    )


# ------------------------------------------------------------------- sky ---

def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _normalize(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    return vec.normalize(v, 1e-12)


def _lum(rgb: np.ndarray) -> np.ndarray:
    return rgb @ LUMA


class CloudShadowMap:
    """Cloud transmittance of the sun at one time, tabulated over a scene's extent.

    ``Sky.cloud_transmittance`` sums five octaves of Perlin noise per shaded
    point: 4 s of a 9 s cloudy frame. The transmittance is a smooth function of
    where a point's sun ray crosses the cloud layer (shadow edges ramp over
    metres), so the cloud noise is sampled once per frame on grids in layer
    coordinates and interpolated (bilinear, ``cv2.remap``), and the cloud
    threshold applied to the interpolated noise: the noise is far smoother than
    the thresholded shadow. ``regions`` are world boxes
    ``((xmin, ymin, zmin), (xmax, ymax, zmax), spacing_m)``, finest first;
    points outside every table are evaluated exactly.
    """

    MAX_SAMPLES = 2_000_000  # beyond this a table costs more than it saves: evaluate exactly

    def __init__(self, sky: "Sky", time: float, regions):
        self.sky, self.time = sky, float(time)
        self.tables = []  # (origin (2,), spacing, table (ny, nx, 1))
        if not sky.casts_cloud_shadows:
            return
        for lo, hi, spacing in regions:
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            layer = sky.cloud_layer_xy(corners)
            origin = layer.min(axis=0) - spacing
            shape = np.ceil((layer.max(axis=0) + spacing - origin) / spacing).astype(int) + 1  # (nx, ny)
            if shape.prod() > self.MAX_SAMPLES:  # a sun near the horizon smears the footprint out
                continue
            gx = origin[0] + spacing * np.arange(shape[0])
            gy = origin[1] + spacing * np.arange(shape[1])
            grid = np.stack(np.meshgrid(gx, gy, indexing="xy"), axis=-1).reshape(-1, 2)
            table = sky.cloud_noise(grid, self.time).astype(np.float32).reshape(shape[1], shape[0], 1)
            self.tables.append((origin, float(spacing), table))

    def transmittance(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points -> (N,) float32 fraction of the sun not blocked by clouds."""
        pts = np.asarray(points).reshape(-1, 3)
        if not self.sky.casts_cloud_shadows:
            return np.ones(len(pts), np.float32)
        layer = self.sky.cloud_layer_xy(pts)
        out = np.empty(len(pts), np.float32)
        todo = np.arange(len(pts))
        for origin, spacing, table in self.tables:
            f = (layer[todo] - origin) / spacing
            ny, nx = table.shape[:2]
            inside = (f[:, 0] >= 0) & (f[:, 0] <= nx - 1) & (f[:, 1] >= 0) & (f[:, 1] <= ny - 1)
            idx = todo[inside]
            noise = lut.sample(table, f[inside, 0].astype(np.float32), f[inside, 1].astype(np.float32))[:, 0]
            out[idx] = self.sky.transmittance_of_noise(noise)
            todo = todo[~inside]
        if len(todo):
            out[todo] = self.sky.layer_transmittance(layer[todo], self.time)
        return out


class Sky:
    """Sky radiance, sun, cloud shadows and distant scenery of one garden."""

    # Ambient lookup: irradiance on a grid of normals (theta rows incl. poles, phi cols).
    _AMB_NT, _AMB_NP = 33, 64

    def __init__(self, params: LightingParams, seed: int):
        p = params
        if p.scenario not in SCENARIOS:
            raise ValueError(f"scenario={p.scenario!r} is not known; allowed: {list(SCENARIOS)}")
        if p.scenario in PREETHAM_SCENARIOS and p.sun_elevation <= 0.0:
            raise ValueError(f"sun_elevation={p.sun_elevation!r} rad must be > 0 for scenario {p.scenario}")
        if p.scenario == "twilight" and p.sun_elevation >= 0.0:
            raise ValueError(f"sun_elevation={p.sun_elevation!r} rad must be < 0 for scenario twilight")
        self.params = p
        self.seed = int(seed)
        self.scenario = p.scenario
        self.sun_direction = _sun_dir(p.sun_elevation, p.sun_azimuth)
        self.sun_angular_radius = SUN_ANGULAR_RADIUS
        theta_s = math.pi / 2 - p.sun_elevation
        sh = self.sun_direction[:2]
        self._sun_h = sh / max(np.linalg.norm(sh), 1e-12)

        if self.scenario in PREETHAM_SCENARIOS:
            self.sun_irradiance = K_SCALE * E0_KLUX * p.sun_intensity * sun_transmittance(theta_s, p.turbidity)
        else:
            self.sun_irradiance = np.zeros(3)

        if self.scenario == "overcast":
            target = OVERCAST_FRACTION * clear_reference_irradiance(p.sun_elevation) * p.sky_intensity
            self._overcast_lz = target / (7.0 * math.pi / 9.0)  # E_h = 7 pi / 9 Lz
        if self.scenario == "twilight":
            depth = -math.degrees(p.sun_elevation)  # 0.5 .. 12
            self._tw_glow = 4.0 * math.exp(-(depth - 1.0) / 2.5)
            self._tw_scale = 1.0
            frac = 0.03 * math.exp(-(depth - 1.0) / 5.0)
            target = frac * clear_reference_irradiance() * p.sky_intensity
            dirs, w = sphere_quadrature(32, 0, 128)
            e_unit = float((_lum(self._sky_upper(dirs, 0.0)) * dirs[:, 2] * w).sum())
            self._tw_scale = target / e_unit

        # Clouds (any Preetham scenario with cover > 0).
        self.has_clouds = self.scenario in PREETHAM_SCENARIOS and p.cloud_cover > 0.0
        self._mean_sun_transmittance = 1.0
        if self.has_clouds:
            self._init_clouds()

        # Clear part of the sky's horizontal irradiance (lights the clouds).
        dirs, w = sphere_quadrature(32, 0, 128)
        self._sky_up_clear = (self._sky_upper(dirs, 0.0, clouds=False) * (dirs[:, 2] * w)[:, None]).sum(0)
        if self.has_clouds:
            dirs, w = sphere_quadrature(64, 0, 256)
            self._sky_up = (self._sky_upper(dirs, 0.0) * (dirs[:, 2] * w)[:, None]).sum(0)
        else:
            self._sky_up = self._sky_up_clear
        sun_h = self.sun_irradiance * max(math.sin(p.sun_elevation), 0.0) * self._mean_sun_transmittance
        self.horizontal_irradiance = self._sky_up + sun_h  # (3,) sky + mean sun on the ground plane
        self._ground_rgb = GROUND_ALBEDO * self.horizontal_irradiance / math.pi

        self._init_ambient()
        self._init_scenery()

        # Exposure: partial compensation of the scene key toward the clear reference.
        key = float(_lum(self._sky_up)) + float(_lum(self.sun_irradiance)) * max(
            math.sin(p.sun_elevation), 0.25) * self._mean_sun_transmittance
        key_ref = clear_reference_irradiance()
        self.exposure = float(np.clip((key_ref / max(key, 1e-9)) ** EXPOSURE_POWER, 0.5, 16.0))

    # ----------------------------------------------------------- radiance ---
    def _sky_upper(self, d: np.ndarray, time: float, clouds: bool = True) -> np.ndarray:
        """Sky radiance for unit directions with z >= 0 (no sun disc)."""
        p = self.params
        if self.scenario in PREETHAM_SCENARIOS:
            rgb = K_SCALE * p.sky_intensity * preetham_rgb(d, self.sun_direction, p.turbidity)
            if clouds and self.has_clouds:
                rgb = self._apply_clouds(d, rgb, time)
            return rgb
        if self.scenario == "overcast":
            lz = self._overcast_lz * (1.0 + 2.0 * np.clip(d[:, 2], 0.0, 1.0)) / 3.0
            return np.repeat(lz[:, None], 3, axis=1)
        # twilight
        h = np.clip(d[:, 2], 0.0, 1.0)
        dh = d[:, :2]
        dh_norm = np.maximum(np.hypot(dh[:, 0], dh[:, 1]), 1e-9)
        ca = (dh @ self._sun_h) / dh_norm
        ca = np.where(dh_norm > 1e-6, ca, 0.0)
        blue = np.array([0.25, 0.40, 1.0]) / 0.4115
        warm = np.array([1.0, 0.45, 0.15]) / 0.5453
        anti = np.array([0.55, 0.40, 0.75]) / 0.4580  # faint purple antitwilight arch
        base = 1.0 + 0.8 * (1.0 - h) ** 3
        glow = self._tw_glow * np.exp(-(1.0 - ca) / 0.45) * np.exp(-h / 0.12)
        arch = 0.25 * np.exp(-(1.0 + ca) / 0.5) * np.exp(-h / 0.12)
        rgb = base[:, None] * blue + glow[:, None] * warm + arch[:, None] * anti
        return self._tw_scale * rgb

    def radiance(self, directions: np.ndarray, time: float = 0.0) -> np.ndarray:
        """(N, 3) world directions -> (N, 3) linear sky radiance, sun disc excluded.

        Below the horizon the horizon colour fades (within ~3 deg) into a
        distant-ground colour (ground albedo x horizontal irradiance / pi).
        """
        d = _normalize(directions)
        below = d[:, 2] < 0.0
        dh = d.copy()
        dh[below, 2] = 0.0
        dh = _normalize(dh)
        rgb = self._sky_upper(dh, time)
        if np.any(below):
            w = _smoothstep(0.0, 0.06, -d[below, 2])[:, None]
            rgb[below] = (1.0 - w) * rgb[below] + w * self._ground_rgb
        return rgb

    # ------------------------------------------------------------- clouds ---
    def _init_clouds(self) -> None:
        rng = rng_for(self.seed, "clouds")
        self._perlin = Perlin(rng)
        wind_az = float(rng.uniform(0.0, 2.0 * math.pi))
        self._wind = self.params.cloud_speed * np.array([math.cos(wind_az), math.sin(wind_az)])
        self._cloud_offset = rng.uniform(0.0, 200.0, size=2)
        samples = rng.uniform(0.0, 256.0, size=(8192, 2))
        n = fbm2(self._perlin, samples[:, 0], samples[:, 1], octaves=CLOUD_OCTAVES)
        cover = float(self.params.cloud_cover)
        self._cloud_threshold = float(np.quantile(n, 1.0 - cover)) if cover < 1.0 else float(n.min()) - CLOUD_EDGE
        alpha = _smoothstep(self._cloud_threshold - CLOUD_EDGE, self._cloud_threshold + CLOUD_EDGE, n)
        self._mean_sun_transmittance = float(np.mean(1.0 - (1.0 - CLOUD_MIN_TRANSMITTANCE) * alpha))

    def _cloud_field(self, xy: np.ndarray, time: float, dz: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Cloud opacity alpha and core depth (0..1) at layer points (N, 2)."""
        n = self.cloud_noise(xy, time, dz)
        thr = self._cloud_threshold
        return _smoothstep(thr - CLOUD_EDGE, thr + CLOUD_EDGE, n), _smoothstep(thr, thr + 0.3, n)

    def cloud_noise(self, xy: np.ndarray, time: float, dz: np.ndarray | None = None) -> np.ndarray:
        """The cloud layer's fBm at layer points (N, 2); clouds are where it exceeds a threshold.

        ``dz`` (the view direction's z, sky lookups only) fades out octaves
        whose features would be smaller than ~0.5 deg on screen (they only
        alias near the horizon); shadows always use every octave.
        """
        u = (xy - self._wind * float(time)) / CLOUD_SCALE + self._cloud_offset
        # Same sum as noise.fbm2 (z slice 0.37, octave offset 17.31 o), with per-octave LOD weights.
        pts = np.stack([u[:, 0], u[:, 1], np.full(len(u), 0.37)], axis=-1)
        total = np.zeros(len(u))
        amp, norm = 1.0, 0.0
        for o in range(CLOUD_OCTAVES):
            size = CLOUD_SCALE / 2.0**o
            if dz is None:
                w = 1.0
            else:
                w = _smoothstep(0.004, 0.009, size * dz * dz / (CLOUD_ALTITUDE - CLOUD_ORIGIN[2]))
                if not np.any(w > 0.0):
                    norm += amp
                    amp *= 0.5
                    continue
            total += amp * w * self._perlin.noise(pts * 2.0**o + 17.31 * o)
            norm += amp
            amp *= 0.5
        return total / norm

    def _apply_clouds(self, d: np.ndarray, sky: np.ndarray, time: float) -> np.ndarray:
        cover = float(self.params.cloud_cover)
        haze = 0.4 * cover  # whitening/greying of the blue sky between clouds
        sky = sky * (1.0 - haze) + _lum(sky)[:, None] * haze
        alpha = np.full(len(d), 0.8 * cover)
        core = np.full(len(d), 0.5)
        vis = d[:, 2] > 0.03
        if np.any(vis):
            dv = d[vis]
            xy = CLOUD_ORIGIN[:2] + dv[:, :2] * ((CLOUD_ALTITUDE - CLOUD_ORIGIN[2]) / dv[:, 2])[:, None]
            a, c = self._cloud_field(xy, time, dv[:, 2])
            fade = _smoothstep(0.03, 0.25, dv[:, 2])  # distant clouds blur into a hazy band
            alpha[vis] = a * fade + (1.0 - fade) * 0.8 * cover
            core[vis] = c * fade + (1.0 - fade) * 0.5
        cos_g = np.clip(d @ self.sun_direction, -1.0, 1.0)
        # Sunlit diffuse reflection (darker toward thick cores) + sky light, plus
        # forward scattering through the thin edges (Henyey-Greenstein, g=0.75):
        # silver linings around the sun.
        g = 0.75
        hg = (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * cos_g) ** 1.5)
        diffuse = CLOUD_ALBEDO * (self.sun_irradiance[None, :] * (0.3 * (1.0 - 0.6 * core))[:, None]
                                  + 0.9 * self._sky_up_clear[None, :]) / math.pi
        cloud = diffuse + self.sun_irradiance[None, :] * (0.6 * hg * (1.0 - core))[:, None]
        return sky * (1.0 - alpha[:, None]) + cloud * alpha[:, None]

    @property
    def casts_cloud_shadows(self) -> bool:
        return self.has_clouds and self.sun_direction[2] > 1e-6

    def cloud_layer_xy(self, points: np.ndarray) -> np.ndarray:
        """Where the ray from each world point toward the sun crosses the cloud layer (N, 2)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        s = self.sun_direction
        return pts[:, :2] + s[None, :2] * ((CLOUD_ALTITUDE - pts[:, 2]) / s[2])[:, None]

    def layer_transmittance(self, layer_xy: np.ndarray, time: float = 0.0) -> np.ndarray:
        """Fraction of the sun let through at cloud-layer points (N, 2)."""
        return self.transmittance_of_noise(self.cloud_noise(np.asarray(layer_xy, np.float64).reshape(-1, 2), time))

    def transmittance_of_noise(self, noise: np.ndarray) -> np.ndarray:
        thr = self._cloud_threshold
        return 1.0 - (1.0 - CLOUD_MIN_TRANSMITTANCE) * _smoothstep(thr - CLOUD_EDGE, thr + CLOUD_EDGE, noise)

    def cloud_transmittance(self, points: np.ndarray, time: float = 0.0) -> np.ndarray:
        """(N, 3) world points -> (N,) fraction of the sun not blocked by clouds."""
        if not self.casts_cloud_shadows:
            return np.ones(len(np.asarray(points).reshape(-1, 3)))
        return self.layer_transmittance(self.cloud_layer_xy(points), time)

    # ------------------------------------------------------------ ambient ---
    def _init_ambient(self) -> None:
        n_up, n_phi = (64, 256) if self.has_clouds else (32, 128)
        dirs, w = sphere_quadrature(n_up, 16, n_phi)
        lw = self.radiance(dirs, 0.0) * w[:, None]
        th = np.linspace(0.0, math.pi, self._AMB_NT)
        ph = np.arange(self._AMB_NP) * (2.0 * math.pi / self._AMB_NP)
        T, P = np.meshgrid(th, ph, indexing="ij")
        normals = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
        out = np.empty((len(normals), 3))
        for i in range(0, len(normals), 256):
            cos = np.clip(normals[i:i + 256] @ dirs.T, 0.0, None)
            out[i:i + 256] = cos @ lw
        self._amb_lut = lut.wrap_columns(out.reshape(self._AMB_NT, self._AMB_NP, 3))

    def ambient_irradiance(self, normals: np.ndarray) -> np.ndarray:
        """(N, 3) unit normals -> (N, 3) float32 unoccluded cosine-weighted irradiance from
        the sky dome and the distant ground below the horizon (no sun, no scenery)."""
        # Bilinear in the (theta, phi) table; this runs for every shaded pixel of every view.
        n = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
        rows = np.arccos(np.clip(n[:, 2], -1.0, 1.0)) * np.float32((self._AMB_NT - 1) / math.pi)
        cols = (np.arctan2(n[:, 1], n[:, 0]) * np.float32(self._AMB_NP / (2.0 * math.pi))) % np.float32(self._AMB_NP)
        return lut.sample(self._amb_lut, cols, rows)

    # ------------------------------------------------------------ scenery ---
    def _init_scenery(self) -> None:
        """Seeded silhouette layers; depend on the garden seed only (same for every lighting)."""
        rng = rng_for(self.seed, "scenery")
        self._scn_perlin = Perlin(rng)
        r = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
        deg = math.radians
        self._scn = dict(
            hills=rng.uniform() < 0.75,
            hill_base=deg(r(0.8, 2.0)), hill_amp=deg(r(1.0, 3.0)), hill_z=r(0.0, 50.0),
            hill_dist=r(1500.0, 4000.0),
            tree_cover=r(0.35, 0.95), tree_base=deg(r(1.5, 3.0)), tree_amp=deg(r(0.8, 2.0)),
            tree_z=r(50.0, 100.0), tree_dist=r(60.0, 150.0),
            wall=rng.uniform() < 0.4, wall_cover=r(0.15, 0.45), wall_height=deg(r(0.6, 1.3)),
            wall_z=r(100.0, 150.0), wall_dist=r(30.0, 60.0),
            wall_albedo=np.array([[0.30, 0.14, 0.09], [0.32, 0.30, 0.27], [0.20, 0.13, 0.08]])[rng.integers(3)],
            tree_albedo=np.array([0.045, 0.080, 0.030]) * r(0.8, 1.25),
            hill_albedo=np.array([0.08, 0.11, 0.05]) * r(0.8, 1.25),
            field_albedo=np.array([0.10, 0.13, 0.06]) * r(0.8, 1.25),
        )
        # Coverage thresholds from samples of the presence noise around the circle.
        phi = np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
        s = self._scn
        s["tree_thr"] = float(np.quantile(self._circle_noise(phi, 1.2, s["tree_z"], 3), 1.0 - s["tree_cover"]))
        s["wall_thr"] = float(np.quantile(self._circle_noise(phi, 1.0, s["wall_z"], 2), 1.0 - s["wall_cover"]))
        # Haze colour at the horizon per azimuth comes from the sky itself.
        self._vis_km = 12.0 / max(self.params.turbidity, 1.0)
        # Silhouettes are tabulated once over azimuth (0.022 deg steps, finer than a pixel):
        # evaluating fBm per pixel and view was the renderer's most expensive background term.
        table_phi = np.linspace(-math.pi, math.pi, self._SIL_N + 1)
        self._sil_table = self._silhouettes_exact(table_phi)

    _SIL_N = 16384

    def _silhouettes(self, phi: np.ndarray) -> dict[str, np.ndarray]:
        """Silhouette heights (radians) by linear interpolation in the azimuth table."""
        f = (np.mod(phi + math.pi, 2.0 * math.pi)) / (2.0 * math.pi) * self._SIL_N
        i0 = np.minimum(np.floor(f).astype(np.int64), self._SIL_N - 1)
        w = f - i0
        return {k: v[i0] * (1.0 - w) + v[i0 + 1] * w for k, v in self._sil_table.items()}

    def _circle_noise(self, phi: np.ndarray, radius: float, z: float, octaves: int, elev=None) -> np.ndarray:
        """fBm on a circle of the given radius (periodic in azimuth), ~[-1, 1]."""
        pts = np.stack([radius * np.cos(phi), radius * np.sin(phi),
                        np.full(phi.shape, z) if elev is None else z + elev], axis=-1)
        return self._scn_perlin.fbm(pts, octaves)

    def _silhouettes_exact(self, phi: np.ndarray) -> dict[str, np.ndarray]:
        s = self._scn
        h = {}
        h["hills"] = (np.maximum(s["hill_base"] + s["hill_amp"] * self._circle_noise(phi, 1.5, s["hill_z"], 3),
                                 math.radians(0.3)) if s["hills"] else np.zeros_like(phi))
        pres = self._circle_noise(phi, 1.2, s["tree_z"], 3)
        taper = _smoothstep(s["tree_thr"], s["tree_thr"] + 0.06, pres)
        # |noise| ("billow"): rounded crowns with sharp notches between them.
        crowns = np.clip(2.5 * np.abs(self._circle_noise(phi, 16.0, s["tree_z"] + 7.7, 3)), 0.0, 1.0)
        h["trees"] = taper * (s["tree_base"] + s["tree_amp"] * crowns)
        if s["wall"]:
            wp = self._circle_noise(phi, 1.0, s["wall_z"], 2)
            h["wall"] = np.where(wp > s["wall_thr"], s["wall_height"], 0.0)
        else:
            h["wall"] = np.zeros_like(phi)
        return h

    def scenery(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distant scenery seen beyond the garden: (mask (N,), linear rgb (N, 3)).

        Layers, nearest first: an optional wall/fence, a tree line, hills and
        the distant ground (every direction below the horizon). A pure
        function of direction, seeded by the garden seed; lit by this sky
        (ambient + sun, with aerial haze toward the horizon sky colour).
        """
        d = _normalize(directions)
        N = len(d)
        elev = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
        dxy = d[:, :2]
        rxy = np.maximum(np.hypot(dxy[:, 0], dxy[:, 1]), 1e-9)
        phi = np.arctan2(dxy[:, 1], dxy[:, 0])
        mask = elev < 0.0
        rgb = np.zeros((N, 3))
        # Only directions near the horizon can be covered by a silhouette.
        cand = np.nonzero(elev < math.radians(12.0))[0]
        if len(cand) == 0:
            return mask, rgb
        s = self._scn
        ph, el = phi[cand], elev[cand]
        h = self._silhouettes(ph)
        layer = np.zeros(len(cand), dtype=np.int64)       # 0 none, 1 ground, 2 hills, 3 trees, 4 wall
        layer[el < 0.0] = 1
        # Each layer covers [base, top]: its foot is below the horizon by the eye height.
        for code, name, dist_key in ((2, "hills", "hill_dist"), (3, "trees", "tree_dist"), (4, "wall", "wall_dist")):
            base = -math.atan(SCENERY_EYE_HEIGHT / s[dist_key])
            layer[(h[name] > 1e-5) & (el < h[name]) & (el >= base)] = code
        covered = layer > 0
        mask[cand] = covered
        idx = np.nonzero(covered)[0]
        if len(idx) == 0:
            return mask, rgb
        ph, el, layer = ph[idx], el[idx], layer[idx]
        toward = -np.stack([dxy[cand[idx], 0], dxy[cand[idx], 1]], -1) / rxy[cand[idx], None]  # facing the viewer
        z = np.zeros((len(idx), 1))

        def facing(up: float) -> np.ndarray:
            return _normalize(np.concatenate([toward, z + up], axis=1))

        normal = np.empty((len(idx), 3))
        albedo = np.empty((len(idx), 3))
        dist = np.empty(len(idx))
        sun_w = np.empty(len(idx))
        sel = {k: layer == v for k, v in (("ground", 1), ("hills", 2), ("trees", 3), ("wall", 4))}
        tex = 0.6 + 0.8 * (0.5 + 0.5 * self._circle_noise(ph, 120.0, 300.0, 3, elev=el * 120.0))
        normal[:] = (0.0, 0.0, 1.0)  # distant ground
        for k, up in (("hills", 2.5), ("trees", 0.6), ("wall", 0.0)):
            if np.any(sel[k]):
                normal[sel[k]] = facing(up)[sel[k]]
        ns = np.clip(normal @ self.sun_direction, 0.0, None)
        sun_w[:] = ns
        if np.any(sel["trees"]):
            m = sel["trees"]
            albedo[m] = s["tree_albedo"] * tex[m, None]
            dist[m] = s["tree_dist"]
            sun_w[m] = 0.25 + 0.75 * ns[m]  # foliage: wrapped, translucent-ish
        if np.any(sel["hills"]):
            m = sel["hills"]
            albedo[m] = s["hill_albedo"] * (0.85 + 0.3 * (tex[m, None] - 1.0))
            dist[m] = s["hill_dist"]
        if np.any(sel["wall"]):
            m = sel["wall"]
            albedo[m] = s["wall_albedo"] * (0.9 + 0.2 * (tex[m, None] - 1.0))
            dist[m] = s["wall_dist"]
        if np.any(sel["ground"]):
            m = sel["ground"]
            albedo[m] = s["field_albedo"] * (0.85 + 0.3 * (tex[m, None] - 1.0))
            dist[m] = np.minimum(SCENERY_EYE_HEIGHT / np.tan(np.maximum(-el[m], 1e-4)), 5000.0)
        sun = self.sun_irradiance * self._mean_sun_transmittance
        irr = self.ambient_irradiance(normal) + sun_w[:, None] * sun[None, :]
        lit = albedo * irr / math.pi
        # Aerial perspective toward the sky colour just above the horizon at that azimuth.
        hz = _normalize(np.concatenate([-toward, z + math.tan(math.radians(1.5))], axis=1))
        haze = self._sky_upper(hz, 0.0)
        t = np.exp(-(dist / 1000.0) / self._vis_km)[:, None]
        rgb[cand[idx]] = lit * t + haze * (1.0 - t)
        return mask, rgb
