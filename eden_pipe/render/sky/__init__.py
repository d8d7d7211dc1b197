"""Sky, sun, clouds and distant scenery for the five lighting scenarios.

Scenarios (the table, limits and defaults: :mod:`eden_pipe.lighting`):
``clear``, ``cloudy``, ``sunset`` (Preetham 1999 analytic sky with a sun
coloured by Rayleigh + aerosol transmittance; cloudy adds a drifting fBm cloud
layer), ``overcast`` (CIE overcast sky, no direct sun) and ``twilight`` (sun
below the horizon, no direct sun, dim blue sky with a glow toward the sun's
azimuth).

Modules, by job:

* ``scenarios``: ``LightingParams`` and ``sample_lighting`` (config -> one garden's values)
* ``preetham``: Preetham sky, sun colour, the render-unit scale ``K_SCALE``
* ``overcast_twilight``: the CIE overcast and twilight sky models
* ``clouds``: the cloud layer and ``CloudShadowMap``
* ``scenery``: distant wall / tree line / hills / ground beyond the garden
* ``exposure``: the exposure factor
* ``dome``: ``Sky``, which assembles them for the renderer
* ``common``: directions, smoothstep, sphere quadrature

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

from eden_pipe.colour import LUMA
from eden_pipe.render.sky.ambient import AmbientTable, sh9_irradiance, sh9_project, sh9_project_panorama
from eden_pipe.render.sky.clouds import (
    CLOUD_ALBEDO,
    CLOUD_ALTITUDE,
    CLOUD_EDGE,
    CLOUD_MIN_TRANSMITTANCE,
    CLOUD_OCTAVES,
    CLOUD_ORIGIN,
    CLOUD_SCALE,
    CloudLayer,
    CloudShadowMap,
)
from eden_pipe.render.sky.common import SUN_ANGULAR_RADIUS, sphere_quadrature
from eden_pipe.render.sky.dome import GROUND_ALBEDO, SKY_MODELS, Sky
from eden_pipe.render.sky.environment import EnvironmentSky, bake_panorama, extract_sun
from eden_pipe.render.sky.exposure import EXPOSURE_POWER
from eden_pipe.render.sky.night import NightSky
from eden_pipe.render.sky.overcast_twilight import OVERCAST_FRACTION, OvercastSky, TwilightSky
from eden_pipe.render.sky.preetham import (
    E0_KLUX,
    ELEV_REF,
    K_SCALE,
    LAMBDA_RGB_UM,
    T_REF,
    XYZ_TO_SRGB,
    PreethamSky,
    air_mass,
    clear_reference_irradiance,
    perez,
    perez_coefficients,
    preetham_rgb,
    sun_transmittance,
    xyY_to_rgb,
    zenith_chromaticity,
    zenith_luminance,
)
from eden_pipe.render.sky.scenarios import LIGHTING_KEYS, SCENARIO_TABLE, SCENARIOS, LightingParams, sample_lighting
from eden_pipe.render.sky.scenery import SCENERY_EYE_HEIGHT, NoScenery, PanoramaScenery, Scenery, make_scenery
from eden_pipe.render.sky.sun import direct_light_irradiance, moon_phase_factor, temperature_tint


def build_sky(params: LightingParams, seed: int):
    """The sky of one garden under one lighting: an ``EnvironmentSky`` when the lighting names
    an HDR map, else the scenario's model ``Sky``; both offer the renderer the same interface."""
    return EnvironmentSky(params, seed) if params.environment else Sky(params, seed)


__all__ = [
    "CLOUD_ALBEDO",
    "CLOUD_ALTITUDE",
    "CLOUD_EDGE",
    "CLOUD_MIN_TRANSMITTANCE",
    "CLOUD_OCTAVES",
    "CLOUD_ORIGIN",
    "CLOUD_SCALE",
    "E0_KLUX",
    "ELEV_REF",
    "EXPOSURE_POWER",
    "GROUND_ALBEDO",
    "K_SCALE",
    "LAMBDA_RGB_UM",
    "LIGHTING_KEYS",
    "LUMA",
    "OVERCAST_FRACTION",
    "SCENARIOS",
    "SCENARIO_TABLE",
    "SCENERY_EYE_HEIGHT",
    "SKY_MODELS",
    "SUN_ANGULAR_RADIUS",
    "T_REF",
    "XYZ_TO_SRGB",
    "AmbientTable",
    "CloudLayer",
    "CloudShadowMap",
    "EnvironmentSky",
    "LightingParams",
    "NightSky",
    "NoScenery",
    "OvercastSky",
    "PanoramaScenery",
    "PreethamSky",
    "Scenery",
    "Sky",
    "TwilightSky",
    "air_mass",
    "bake_panorama",
    "build_sky",
    "clear_reference_irradiance",
    "direct_light_irradiance",
    "extract_sun",
    "make_scenery",
    "moon_phase_factor",
    "perez",
    "perez_coefficients",
    "preetham_rgb",
    "sample_lighting",
    "sh9_irradiance",
    "sh9_project",
    "sh9_project_panorama",
    "sphere_quadrature",
    "sun_transmittance",
    "temperature_tint",
    "xyY_to_rgb",
    "zenith_chromaticity",
    "zenith_luminance",
]
