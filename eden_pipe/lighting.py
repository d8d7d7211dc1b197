"""The lighting scenarios: one table, the lighting config schema and its one check.

``SCENARIO_TABLE`` holds, per scenario (clear, cloudy, overcast, sunset,
twilight: the paper's five, ``DEFAULT_SWEEP``; and night), everything that
differs between scenarios: the sky model, the direct light (sun, moon or
none) and the cloud layer, the limits of every key and the defaults (the
values shipped in ``conf/lighting/<name>.yaml``). Everything
else reads this table: :func:`check_lighting` (called by ``config.validate``
before any stage runs, and by ``render.sky.sample_lighting`` for direct
callers), the sky (``eden_pipe.render.sky``) and the tests.

A drawn lighting key (``DRAWN_KEYS``) is a number or a ``[lo, hi]`` range
(YAML, degrees where named ``*_deg``, kelvin where ``*_k``); a garden's value
is drawn uniformly from the range with the lighting's seeded generator. The
image keys (``environment``, ``scenery``) name files, read and checked here
before any stage runs (``eden_pipe.io.hdr``); their content hashes
(:func:`lighting_files`) are part of the render cache key.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping, Sequence
from dataclasses import MISSING, dataclass, field, fields
from pathlib import Path
from types import MappingProxyType, SimpleNamespace
from typing import Any

from eden_pipe.errors import ConfigError

# Keys drawn per garden (number or [lo, hi]), in drawing order: a key's draw never shifts
# another's. Keys added later come last, so the draws of the older keys stay as they were.
DRAWN_KEYS = (
    "sun_elevation_deg",
    "sun_azimuth_deg",
    "turbidity",
    "sun_intensity",
    "sky_intensity",
    "cloud_cover",
    "cloud_speed",
    "sun_angular_diameter_deg",
    "sun_temperature_k",
    "environment_rotation_deg",
    "moon_phase",
)
# The wind (docs/design.md, "Wind"): number or [lo, hi] like the drawn keys, drawn per garden by a
# generator of their own (render.wind.draw_wind), so the sky's draws never shift. wind_mps 0 (every
# scenario's default): nothing moves, and the dataset is what it was without these keys.
WIND_KEYS = ("wind_mps", "wind_direction_deg", "gust_strength")
# Keys naming image files or modes (not drawn): image-based lighting and the scenery.
FILE_KEYS = ("environment", "scenery")
ENVIRONMENT_SUN_MODES = ("auto", "none", "explicit")
SCENERY_MODES = ("procedural", "none")  # besides a path; unset: procedural, or the map itself under an environment
# Keys a lighting config holds (the fields of LightingConfig).
LIGHTING_KEYS = ("name",) + DRAWN_KEYS + FILE_KEYS + ("environment_sun",) + WIND_KEYS
# Drawn keys only some scenarios use: unset (None) elsewhere.
SCENARIO_ONLY_KEYS = {"moon_phase": "moon"}

SUN_DIAMETER_DEG = 0.53  # the real sun (and moon, 0.52) seen from the ground
REFERENCE_TEMPERATURE_K = 5778  # the sun above the atmosphere: the colour the sky model takes as white


@dataclass(frozen=True)
class Scenario:
    """One lighting scenario: what the sky does and what a config may ask of it."""

    name: str
    description: str
    sky_model: str  # "preetham" | "cie_overcast" | "twilight" | "night" (render.sky.SKY_MODELS)
    direct_light: str  # "sun" | "moon" (the sun_* keys describe the moon) | "none" (sun_intensity unused)
    has_clouds: bool  # an fBm cloud layer when cloud_cover > 0 (Preetham skies only)
    elevation_limits_deg: tuple[float, float]  # the sky model needs the sun above (or below) the horizon
    turbidity_limits: tuple[float, float]  # below ~1.7 the Perez Y term goes negative; fit up to 10
    cloud_cover_limits: tuple[float, float]
    defaults: Mapping[str, Any]  # key -> number or [lo, hi]; the shipped conf/lighting/<name>.yaml
    default_sweep: bool = True  # one of the five scenarios of the paper (night is extra)
    # Limits shared by every scenario (a key with no physical bound here is only kept finite).
    azimuth_limits_deg: tuple[float, float] = (-360.0, 720.0)
    intensity_limits: tuple[float, float] = (0.0, 1e6)
    cloud_speed_limits: tuple[float, float] = (0.0, 1e3)
    # 0: a point (hard shadows); Blender-style sun sizes for soft shadows go to a few degrees.
    diameter_limits_deg: tuple[float, float] = (0.0, 10.0)
    # The range of the Planckian-locus fit the colour tint uses (render.sky.sun.planck_xy).
    temperature_limits_k: tuple[float, float] = (1667.0, 25000.0)
    moon_phase_limits: tuple[float, float] = (0.0, 1.0)  # illuminated fraction: 0 new, 1 full
    wind_limits_mps: tuple[float, float] = (0.0, 40.0)  # calm to a hurricane (amplitudes stop growing at 15)
    gust_limits: tuple[float, float] = (0.0, 1.0)  # the gusts' swing, a fraction of the mean drag

    @property
    def has_sun(self) -> bool:
        """Whether there is a direct light (the sun, or the moon at night)."""
        return self.direct_light != "none"

    def uses(self, key: str) -> bool:
        """Whether this scenario draws ``key`` (keys of SCENARIO_ONLY_KEYS only where they apply)."""
        return key not in SCENARIO_ONLY_KEYS or SCENARIO_ONLY_KEYS[key] == self.direct_light

    def limits(self, key: str) -> tuple[tuple[float, float], str]:
        """(lo, hi) allowed for a lighting key, and its unit."""
        return {
            "sun_elevation_deg": (self.elevation_limits_deg, " deg"),
            "sun_azimuth_deg": (self.azimuth_limits_deg, " deg"),
            "turbidity": (self.turbidity_limits, ""),
            "sun_intensity": (self.intensity_limits, ""),
            "sky_intensity": (self.intensity_limits, ""),
            "cloud_cover": (self.cloud_cover_limits, ""),
            "cloud_speed": (self.cloud_speed_limits, " m/s"),
            "sun_angular_diameter_deg": (self.diameter_limits_deg, " deg"),
            "sun_temperature_k": (self.temperature_limits_k, " K"),
            "environment_rotation_deg": (self.azimuth_limits_deg, " deg"),
            "moon_phase": (self.moon_phase_limits, ""),
            "wind_mps": (self.wind_limits_mps, " m/s"),
            "wind_direction_deg": (self.azimuth_limits_deg, " deg"),
            "gust_strength": (self.gust_limits, ""),
        }[key]


def _defaults(
    elevation,
    turbidity,
    cloud_cover,
    sun_intensity,
    cloud_speed=1,
    diameter=SUN_DIAMETER_DEG,
    temperature=REFERENCE_TEMPERATURE_K,
    sky_intensity=1,
    gust=0.3,
    **extra,
) -> Mapping[str, Any]:
    return MappingProxyType(
        dict(
            sun_elevation_deg=elevation,
            sun_azimuth_deg=[0, 360],
            turbidity=turbidity,
            sun_intensity=sun_intensity,
            sky_intensity=sky_intensity,
            cloud_cover=cloud_cover,
            cloud_speed=cloud_speed,
            sun_angular_diameter_deg=diameter,
            sun_temperature_k=temperature,
            **extra,
            wind_mps=0,
            wind_direction_deg=[0, 360],
            gust_strength=gust,
        )
    )


_ABOVE = (0.5, 90.0)  # Preetham and the overcast reference need the sun above the horizon
_TURBIDITY = (1.7, 10.0)
_COVER = (0.0, 1.0)

# The sun's sampled ranges (docs/lighting.md): intensity a factor on the modelled direct irradiance
# (aerosol and water-vapour variation the turbidity fit leaves out, the yearly +-3.4 % of the
# Earth-sun distance, thin haze); angular diameter from the real 0.53 deg up to Blender-style
# sun sizes for the softer shadows of hazy and broken-cloud skies; colour temperature of the
# light above the atmosphere (5778 K: the model's white), reddened further by the atmosphere's
# transmittance along the air mass, so noon stays near white and sunset warm.
SCENARIO_TABLE: Mapping[str, Scenario] = MappingProxyType(
    {
        s.name: s
        for s in (
            Scenario(
                "clear",
                "Preetham sky, high sun, low turbidity",
                sky_model="preetham",
                direct_light="sun",
                has_clouds=True,
                elevation_limits_deg=_ABOVE,
                turbidity_limits=_TURBIDITY,
                cloud_cover_limits=_COVER,
                defaults=_defaults(
                    [35, 60], [2, 3], [0, 0], sun_intensity=[0.9, 1.1], diameter=[0.53, 1.5], temperature=[5300, 6300]
                ),
            ),
            Scenario(
                "cloudy",
                "Preetham sky with a drifting fBm cloud layer and its shadows",
                sky_model="preetham",
                direct_light="sun",
                has_clouds=True,
                elevation_limits_deg=_ABOVE,
                turbidity_limits=_TURBIDITY,
                cloud_cover_limits=_COVER,
                defaults=_defaults(
                    [25, 50],
                    [3, 5],
                    [0.3, 0.6],
                    sun_intensity=[0.8, 1.05],
                    cloud_speed=1.5,
                    diameter=[0.8, 3],
                    temperature=[5500, 6800],
                    gust=0.5,
                ),
            ),
            Scenario(
                "overcast",
                "CIE overcast sky, neutral white, no direct sun",
                sky_model="cie_overcast",
                direct_light="none",
                has_clouds=False,
                elevation_limits_deg=_ABOVE,
                turbidity_limits=_TURBIDITY,
                cloud_cover_limits=_COVER,
                defaults=_defaults([30, 60], [4, 6], [1, 1], sun_intensity=0, gust=0.4),
            ),
            Scenario(
                "sunset",
                "Preetham sky, sun low above the horizon, red-shifted by a long air mass",
                sky_model="preetham",
                direct_light="sun",
                has_clouds=True,
                elevation_limits_deg=_ABOVE,
                turbidity_limits=_TURBIDITY,
                cloud_cover_limits=_COVER,
                defaults=_defaults(
                    [2, 8],
                    [2.5, 4],
                    [0, 0],
                    sun_intensity=[0.8, 1.1],
                    diameter=[0.53, 2],
                    temperature=[4500, 5800],
                    gust=0.2,
                ),
            ),
            Scenario(
                "twilight",
                "sun below the horizon, no direct sun, dim blue sky with a glow",
                sky_model="twilight",
                direct_light="none",
                has_clouds=False,
                elevation_limits_deg=(-12.0, -0.5),
                turbidity_limits=_TURBIDITY,
                cloud_cover_limits=_COVER,
                defaults=_defaults([-6, -1], [2, 4], [0, 0], sun_intensity=0, gust=0.2),
            ),
            # Night: the sun_* keys describe the moon (direction, size, colour, intensity factor);
            # moon_phase (illuminated fraction) sets its brightness by the lunar phase law. Moonlight
            # is drawn bluish, as night photography shows it: a colour temperature high enough that the
            # atmosphere's reddening (moon >= 20 deg up, clear night air) still leaves it blue.
            Scenario(
                "night",
                "moon: a dim bluish directional light set by its phase; moonlit sky and light-polluted glow",
                sky_model="night",
                direct_light="moon",
                has_clouds=False,
                elevation_limits_deg=_ABOVE,
                turbidity_limits=_TURBIDITY,
                cloud_cover_limits=_COVER,
                defaults=_defaults(
                    [20, 70],
                    [2, 3],
                    [0, 0],
                    sun_intensity=[0.9, 1.1],
                    diameter=[0.5, 1],
                    temperature=[10000, 14000],
                    sky_intensity=[0.5, 2],
                    moon_phase=[0.3, 1],
                    gust=0.2,
                ),
                default_sweep=False,
            ),
        )
    }
)
SCENARIOS = tuple(SCENARIO_TABLE)
# The paper's five scenarios: what a sweep over "every lighting" means (night is asked for by name).
DEFAULT_SWEEP = tuple(name for name, s in SCENARIO_TABLE.items() if s.default_sweep)


def _clear(key: str):
    """The clear scenario's default for ``key`` (the schema's default: ``lighting: clear``)."""
    value = SCENARIO_TABLE["clear"].defaults.get(key)
    return field(default_factory=lambda: list(value)) if isinstance(value, list) else field(default=value)


@dataclass
class LightingConfig:
    """The ``lighting`` config group (schema); defaults are the clear scenario's.

    A drawn key is a number or a ``[lo, hi]`` range (``Any``: the check below, not the schema,
    says what is allowed). ``environment``: an equirectangular HDR map (Radiance ``.hdr`` or
    OpenEXR) lighting the garden instead of the scenario's sky model, with ``environment_sun``
    auto (the sun taken from the map's brightest region), none (the map as it is) or explicit
    (the scenario's sun from the sun_* keys); ``environment_rotation_deg`` turns the map (and
    the scenery panorama) about the vertical. ``scenery``: the distant background beyond the
    garden: procedural, none, or a panorama image (alpha, if any, marks the scenery).
    """

    name: str = "clear"
    sun_elevation_deg: Any = _clear("sun_elevation_deg")
    sun_azimuth_deg: Any = _clear("sun_azimuth_deg")
    turbidity: Any = _clear("turbidity")
    sun_intensity: Any = _clear("sun_intensity")
    sky_intensity: Any = _clear("sky_intensity")
    cloud_cover: Any = _clear("cloud_cover")
    cloud_speed: Any = _clear("cloud_speed")
    sun_angular_diameter_deg: Any = _clear("sun_angular_diameter_deg")
    sun_temperature_k: Any = _clear("sun_temperature_k")
    environment_rotation_deg: Any = 0.0
    moon_phase: Any = None
    environment: str | None = None
    scenery: str | None = None
    environment_sun: str = "auto"
    wind_mps: Any = _clear("wind_mps")
    wind_direction_deg: Any = _clear("wind_direction_deg")
    gust_strength: Any = _clear("gust_strength")

    @classmethod
    def for_scenario(cls, name: str = "clear", **values: Any) -> LightingConfig:
        """A scenario's defaults (SCENARIO_TABLE) with ``values`` on top; raises ConfigError on
        an unknown scenario or key."""
        _check_name(name)
        unknown = sorted(set(values) - set(LIGHTING_KEYS))
        if unknown:
            _fail(unknown[0], values[unknown[0]], "one of the keys " + ", ".join(LIGHTING_KEYS))
        base = {
            f.name: (f.default_factory() if f.default_factory is not MISSING else f.default)
            for f in fields(cls)
            if f.name != "name"
        }
        return cls(name=name, **{**base, **SCENARIO_TABLE[name].defaults, **values})


# ----------------------------------------------------------------------- check
def _fail(key: str, value: Any, allowed: str) -> None:
    raise ConfigError(f"invalid config: lighting.{key}={value!r}; allowed: {allowed}")


def _is_number(v: object) -> bool:
    return isinstance(v, numbers.Real) and not isinstance(v, bool) and math.isfinite(float(v))


def _shown(value: Any) -> Any:
    """A value as the user wrote it: sequences as '[a, b]' (numbers without a trailing .0)."""
    if isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        return "[" + ", ".join(f"{v:g}" if _is_number(v) else repr(v) for v in value) + "]"
    return value


def _check_name(name: Any) -> Scenario:
    if name not in SCENARIO_TABLE:
        _fail("name", name, "one of " + ", ".join(SCENARIOS))
    return SCENARIO_TABLE[name]


def value_range(key: str, value: Any, scenario: Scenario) -> tuple[float, float]:
    """A lighting value (number or [lo, hi]) as floats (lo, hi), checked against the scenario's
    limits for the key; raises ConfigError naming the key, the value and what is allowed."""
    (lo_lim, hi_lim), unit = scenario.limits(key)
    allowed = f"a number or [lo, hi] with lo <= hi, within [{lo_lim:g}, {hi_lim:g}]{unit} for scenario {scenario.name}"
    if _is_number(value):
        lo = hi = float(value)
    elif isinstance(value, Sequence) and not isinstance(value, (str, bytes)):
        items = list(value)
        if len(items) != 2 or not all(_is_number(v) for v in items):
            _fail(key, _shown(items), allowed)
        lo, hi = float(items[0]), float(items[1])
    else:
        _fail(key, value, allowed)
    if lo > hi or lo < lo_lim or hi > hi_lim:
        _fail(key, _shown(value), allowed)
    return lo, hi


def check_lighting(lighting) -> None:
    """Raise ConfigError on the first lighting value its scenario does not allow.

    ``lighting``: a LightingConfig, a (typed or plain) DictConfig, or any object
    with the LIGHTING_KEYS as attributes; attribute access only. Image files
    (``environment``, ``scenery``) are opened and checked here, before any work.
    """
    scenario = _check_name(getattr(lighting, "name", None))
    for key in DRAWN_KEYS:
        value = getattr(lighting, key, None)
        if not scenario.uses(key):
            if value is not None:
                users = ", ".join(n for n, s in SCENARIO_TABLE.items() if s.uses(key))
                _fail(key, _shown(value), f"unset (null): only scenario {users} uses it, not {scenario.name}")
            continue
        value_range(key, value, scenario)
    for key in WIND_KEYS:
        value_range(key, getattr(lighting, key, None), scenario)
    mode = getattr(lighting, "environment_sun", None)
    if mode not in ENVIRONMENT_SUN_MODES:
        _fail("environment_sun", mode, "one of " + ", ".join(ENVIRONMENT_SUN_MODES))
    environment = getattr(lighting, "environment", None)
    if environment is not None:
        check_image("environment", environment, hdr_only=True)
    scenery = getattr(lighting, "scenery", None)
    if scenery is not None and scenery not in SCENERY_MODES:
        check_image("scenery", scenery, hdr_only=False)


def wind_blows(lighting) -> bool:
    """Whether ``lighting.wind_mps`` can be above 0 (a number > 0, or a range reaching above it)."""
    value = getattr(lighting, "wind_mps", None)
    if value is None:
        return False
    return (float(value) if _is_number(value) else max(float(v) for v in value)) > 0


def without_still_wind(plain: dict) -> dict:
    """A plain lighting config (a dict) as a dataset made before the wind existed had it: without the
    wind's keys when the wind does not blow (the render key and the published config.yaml)."""
    if wind_blows(SimpleNamespace(**plain)):
        return plain
    return {k: v for k, v in plain.items() if k not in WIND_KEYS}


def check_image(key: str, path: Any, hdr_only: bool) -> None:
    """ConfigError unless ``path`` is a readable equirectangular (2:1) image of the allowed kind."""
    from eden_pipe.io.hdr import HDR_EXTENSIONS, PANORAMA_EXTENSIONS, PanoramaError, read_panorama

    kinds = HDR_EXTENSIONS if hdr_only else PANORAMA_EXTENSIONS
    what = f"the path of a readable equirectangular image (width = 2 x height) of type {', '.join(kinds)}" + (
        "" if hdr_only else f", or one of {', '.join(SCENERY_MODES)}"
    )
    if not isinstance(path, str) or not path:
        _fail(key, path, what)
    if Path(path).suffix.lower() not in kinds:
        _fail(key, path, what)
    try:
        read_panorama(path)
    except (OSError, PanoramaError) as exc:
        _fail(key, path, f"{what} ({exc})")


def lighting_files(lighting) -> dict[str, dict[str, str]]:
    """The image files a lighting reads: key -> {"path", "sha256"} (empty without any).

    Part of the render cache key and of lighting.json: a changed file renders again."""
    from eden_pipe.io.hdr import file_sha256

    files = {}
    for key in FILE_KEYS:
        path = getattr(lighting, key, None)
        if path is not None and path not in SCENERY_MODES:
            files[key] = {"path": str(path), "sha256": file_sha256(path)}
    return files
