"""The lighting scenarios: one table, the lighting config schema and its one check.

``SCENARIO_TABLE`` holds, per scenario (clear, cloudy, overcast, sunset,
twilight), everything that differs between scenarios: the sky model, whether
there is a direct sun and a cloud layer, the limits of every key and the
defaults (the values shipped in ``conf/lighting/<name>.yaml``). Everything
else reads this table: :func:`check_lighting` (called by ``config.validate``
before any stage runs, and by ``render.sky.sample_lighting`` for direct
callers), the sky (``eden_pipe.render.sky``) and the tests.

A lighting key is a number or a ``[lo, hi]`` range (YAML, degrees where named
``*_deg``); a garden's value is drawn uniformly from the range.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, List, Mapping

from eden_pipe.errors import ConfigError

# Keys a lighting config holds (the fields of LightingConfig), in drawing order.
LIGHTING_KEYS = (
    "name", "sun_elevation_deg", "sun_azimuth_deg", "turbidity", "sun_intensity",
    "sky_intensity", "cloud_cover", "cloud_speed",
)


@dataclass(frozen=True)
class Scenario:
    """One lighting scenario: what the sky does and what a config may ask of it."""

    name: str
    description: str
    sky_model: str                 # "preetham" | "cie_overcast" | "twilight" (render.sky.SKY_MODELS)
    has_sun: bool                  # a direct sun (disc, irradiance, cast shadows); else sun_intensity is unused
    has_clouds: bool               # an fBm cloud layer when cloud_cover > 0 (Preetham skies only)
    elevation_limits_deg: tuple[float, float]   # the sky model needs the sun above (or below) the horizon
    turbidity_limits: tuple[float, float]       # below ~1.7 the Perez Y term goes negative; fit up to 10
    cloud_cover_limits: tuple[float, float]
    defaults: Mapping[str, Any]    # key -> number or [lo, hi]; the shipped conf/lighting/<name>.yaml
    # Limits shared by every scenario (a key with no physical bound here is only kept finite).
    azimuth_limits_deg: tuple[float, float] = (-360.0, 720.0)
    intensity_limits: tuple[float, float] = (0.0, 1e6)
    cloud_speed_limits: tuple[float, float] = (0.0, 1e3)

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
        }[key]


def _defaults(elevation, turbidity, cloud_cover, sun_intensity=1.0, cloud_speed=1.0) -> Mapping[str, Any]:
    return MappingProxyType(dict(
        sun_elevation_deg=elevation, sun_azimuth_deg=[0.0, 360.0], turbidity=turbidity,
        sun_intensity=sun_intensity, sky_intensity=1.0, cloud_cover=cloud_cover, cloud_speed=cloud_speed,
    ))


_ABOVE = (0.5, 90.0)   # Preetham and the overcast reference need the sun above the horizon
_TURBIDITY = (1.7, 10.0)
_COVER = (0.0, 1.0)

SCENARIO_TABLE: Mapping[str, Scenario] = MappingProxyType({s.name: s for s in (
    Scenario("clear", "Preetham sky, high sun, low turbidity",
             sky_model="preetham", has_sun=True, has_clouds=True,
             elevation_limits_deg=_ABOVE, turbidity_limits=_TURBIDITY, cloud_cover_limits=_COVER,
             defaults=_defaults([35.0, 60.0], [2.0, 3.0], [0.0, 0.0])),
    Scenario("cloudy", "Preetham sky with a drifting fBm cloud layer and its shadows",
             sky_model="preetham", has_sun=True, has_clouds=True,
             elevation_limits_deg=_ABOVE, turbidity_limits=_TURBIDITY, cloud_cover_limits=_COVER,
             defaults=_defaults([25.0, 50.0], [3.0, 5.0], [0.3, 0.6], cloud_speed=1.5)),
    Scenario("overcast", "CIE overcast sky, neutral white, no direct sun",
             sky_model="cie_overcast", has_sun=False, has_clouds=False,
             elevation_limits_deg=_ABOVE, turbidity_limits=_TURBIDITY, cloud_cover_limits=_COVER,
             defaults=_defaults([30.0, 60.0], [4.0, 6.0], [1.0, 1.0], sun_intensity=0.0)),
    Scenario("sunset", "Preetham sky, sun low above the horizon, red-shifted by a long air mass",
             sky_model="preetham", has_sun=True, has_clouds=True,
             elevation_limits_deg=_ABOVE, turbidity_limits=_TURBIDITY, cloud_cover_limits=_COVER,
             defaults=_defaults([2.0, 8.0], [2.5, 4.0], [0.0, 0.0])),
    Scenario("twilight", "sun below the horizon, no direct sun, dim blue sky with a glow",
             sky_model="twilight", has_sun=False, has_clouds=False,
             elevation_limits_deg=(-12.0, -0.5), turbidity_limits=_TURBIDITY, cloud_cover_limits=_COVER,
             defaults=_defaults([-6.0, -1.0], [2.0, 4.0], [0.0, 0.0], sun_intensity=0.0)),
)})
SCENARIOS = tuple(SCENARIO_TABLE)


@dataclass
class LightingConfig:
    """The ``lighting`` config group (schema); defaults are the clear scenario's."""

    name: str = "clear"
    sun_elevation_deg: List[float] = field(default_factory=lambda: [35.0, 60.0])
    sun_azimuth_deg: List[float] = field(default_factory=lambda: [0.0, 360.0])
    turbidity: List[float] = field(default_factory=lambda: [2.0, 3.0])
    sun_intensity: float = 1.0
    sky_intensity: float = 1.0
    cloud_cover: List[float] = field(default_factory=lambda: [0.0, 0.0])
    cloud_speed: float = 1.0

    @classmethod
    def for_scenario(cls, name: str = "clear", **values: Any) -> "LightingConfig":
        """A scenario's defaults (SCENARIO_TABLE) with ``values`` on top; raises ConfigError on
        an unknown scenario or key."""
        _check_name(name)
        unknown = sorted(set(values) - set(LIGHTING_KEYS))
        if unknown:
            _fail(unknown[0], values[unknown[0]], "one of the keys " + ", ".join(LIGHTING_KEYS))
        return cls(name=name, **{**SCENARIO_TABLE[name].defaults, **values})


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
    allowed = (f"a number or [lo, hi] with lo <= hi, within [{lo_lim:g}, {hi_lim:g}]{unit}"
               f" for scenario {scenario.name}")
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
    with the LIGHTING_KEYS as attributes; attribute access only.
    """
    scenario = _check_name(getattr(lighting, "name", None))
    for key in LIGHTING_KEYS[1:]:
        value_range(key, getattr(lighting, key, None), scenario)
