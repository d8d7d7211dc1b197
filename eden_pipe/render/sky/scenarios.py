"""Scenario parameters: one garden's lighting drawn from the lighting config.

The scenario table, its limits and defaults, and the one check of a lighting
config live in :mod:`eden_pipe.lighting`; this module draws a garden's values
from the checked ranges (``sample_lighting``) into ``LightingParams``, which is
all the sky (``Sky``) takes.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from omegaconf import DictConfig

from eden_pipe.lighting import (
    DRAWN_KEYS,
    LIGHTING_KEYS,
    REFERENCE_TEMPERATURE_K,
    SCENARIO_TABLE,
    SCENARIOS,
    SUN_DIAMETER_DEG,
    LightingConfig,
    check_lighting,
    value_range,
)

__all__ = ["DRAWN_KEYS", "LIGHTING_KEYS", "SCENARIOS", "SCENARIO_TABLE", "LightingParams", "sample_lighting"]


@dataclass
class LightingParams:
    """Lighting of one garden, resolved from the lighting config ranges."""

    scenario: str  # clear | cloudy | overcast | sunset | twilight | night (a key of SCENARIO_TABLE)
    sun_elevation: float  # radians (negative below horizon); the moon's at night
    sun_azimuth: float  # radians, measured from +x toward +y
    turbidity: float
    sun_intensity: float = 1.0
    sky_intensity: float = 1.0
    cloud_cover: float = 0.0  # 0..1
    cloud_speed: float = 1.0  # m/s drift of the cloud layer
    sun_angular_diameter: float = math.radians(SUN_DIAMETER_DEG)  # radians (0: a point, hard shadows)
    sun_temperature: float = REFERENCE_TEMPERATURE_K  # kelvin, above the atmosphere
    environment_rotation: float = 0.0  # radians: the map's (and scenery panorama's) turn about +z
    moon_phase: float | None = None  # illuminated fraction (night only)
    environment: str | None = None  # an HDR map lighting the garden (None: the scenario's sky model)
    environment_sun: str = "auto"  # auto | none | explicit (see render.sky.environment)
    scenery: str | None = None  # None (default) | procedural | none | a panorama path


def sample_lighting(lighting, rng: np.random.Generator) -> LightingParams:
    """Draw one garden's lighting from a lighting config (YAML ranges, degrees).

    ``lighting``: a LightingConfig or a (typed) DictConfig, read by attribute;
    a plain dict is taken as ``LightingConfig.for_scenario(**dict)`` (missing
    keys get the scenario's defaults; keys starting with ``_`` are ignored). It is checked by
    :func:`eden_pipe.lighting.check_lighting` (ConfigError naming the key).
    Every key the scenario uses (``Scenario.uses``) is drawn in the fixed order of
    DRAWN_KEYS whether or not its range is degenerate, so one key's draw never shifts
    another's; keys added later are drawn last, so older keys keep their values.
    """
    if isinstance(lighting, Mapping) and not isinstance(lighting, DictConfig):
        lighting = LightingConfig.for_scenario(**{str(k): v for k, v in lighting.items() if not str(k).startswith("_")})
    check_lighting(lighting)
    scenario = SCENARIO_TABLE[lighting.name]
    drawn = {}
    for key in DRAWN_KEYS:  # one draw per key the scenario uses, always, in this order
        if scenario.uses(key):
            lo, hi = value_range(key, getattr(lighting, key), scenario)
            drawn[key] = float(rng.uniform(lo, hi))
    return LightingParams(
        scenario=scenario.name,
        sun_elevation=math.radians(drawn["sun_elevation_deg"]),
        sun_azimuth=math.radians(drawn["sun_azimuth_deg"]),
        turbidity=drawn["turbidity"],
        sun_intensity=drawn["sun_intensity"],
        sky_intensity=drawn["sky_intensity"],
        cloud_cover=drawn["cloud_cover"],
        cloud_speed=drawn["cloud_speed"],
        sun_angular_diameter=math.radians(drawn["sun_angular_diameter_deg"]),
        sun_temperature=drawn["sun_temperature_k"],
        environment_rotation=math.radians(drawn["environment_rotation_deg"]),
        moon_phase=drawn.get("moon_phase"),
        environment=getattr(lighting, "environment", None),
        environment_sun=str(getattr(lighting, "environment_sun", "auto")),
        scenery=getattr(lighting, "scenery", None),
    )
