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

from eden_pipe.lighting import LIGHTING_KEYS, SCENARIO_TABLE, SCENARIOS, LightingConfig, check_lighting, value_range

__all__ = ["LIGHTING_KEYS", "SCENARIOS", "SCENARIO_TABLE", "LightingParams", "sample_lighting"]


@dataclass
class LightingParams:
    """Lighting of one garden, resolved from the lighting config ranges."""

    scenario: str             # clear | cloudy | overcast | sunset | twilight (a key of SCENARIO_TABLE)
    sun_elevation: float      # radians (negative below horizon)
    sun_azimuth: float        # radians, measured from +x toward +y
    turbidity: float
    sun_intensity: float = 1.0
    sky_intensity: float = 1.0
    cloud_cover: float = 0.0  # 0..1
    cloud_speed: float = 1.0  # m/s drift of the cloud layer


def sample_lighting(lighting, rng: np.random.Generator) -> LightingParams:
    """Draw one garden's lighting from a lighting config (YAML ranges, degrees).

    ``lighting``: a LightingConfig or a (typed) DictConfig, read by attribute;
    a plain dict is taken as ``LightingConfig.for_scenario(**dict)`` (missing
    keys get the scenario's defaults; keys starting with ``_`` are ignored). It is checked by
    :func:`eden_pipe.lighting.check_lighting` (ConfigError naming the key).
    Every key is drawn in a fixed order whether or not its range is
    degenerate, so one key's draw never shifts another's.
    """
    if isinstance(lighting, Mapping) and not isinstance(lighting, DictConfig):
        lighting = LightingConfig.for_scenario(**{str(k): v for k, v in lighting.items() if not str(k).startswith("_")})
    check_lighting(lighting)
    scenario = SCENARIO_TABLE[lighting.name]
    elev, azim, turb, sun_i, sky_i, cover, speed = (
        value_range(key, getattr(lighting, key), scenario) for key in LIGHTING_KEYS[1:])

    draw = lambda r: float(rng.uniform(r[0], r[1]))  # noqa: E731  one draw per key, always
    return LightingParams(
        scenario=scenario.name,
        sun_elevation=math.radians(draw(elev)),
        sun_azimuth=math.radians(draw(azim)),
        turbidity=draw(turb),
        sun_intensity=draw(sun_i),
        sky_intensity=draw(sky_i),
        cloud_cover=draw(cover),
        cloud_speed=draw(speed),
    )
