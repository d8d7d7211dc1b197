"""The direct light of a scenario: the sun (or the moon at night), its colour and its irradiance.

Irradiance at normal incidence, render units (``preetham.K_SCALE``):

    E = K_SCALE * E0 * intensity * transmittance(air mass, turbidity) * tint(temperature) [* moon]

* ``transmittance``: Rayleigh + aerosol along the air mass (``preetham.sun_transmittance``),
  which reddens the light toward the horizon;
* ``tint``: the colour of a black body at the drawn temperature relative to
  ``REFERENCE_TEMPERATURE_K`` (5778 K, the sun above the atmosphere, which the sky model
  takes as white), with luminance 1 so that the temperature changes colour only. The
  chromaticity is the Planckian locus by the cubic fit of Kim et al. (US 7,024,034;
  1667-25000 K), converted to linear sRGB;
* ``moon`` (night): ``MOON_FULL_FRACTION`` of the sun at full moon, times the lunar phase
  law (Allen 1976: magnitude 0.026|a| + 4e-9 a^4 at phase angle a in degrees; the
  half moon gives ~9 % of the full moon's light). Real moonlight is ~2.5e-6 of sunlight;
  the render scale is compressed, like twilight's, so night images stay legible in an
  8-bit PNG within the exposure limit of 16 (``exposure``): the ratios within a night
  (phase, elevation, sky glow) are kept, the one to daylight is not.
"""

from __future__ import annotations

import math

import numpy as np

from eden_pipe.colour import LUMA
from eden_pipe.lighting import REFERENCE_TEMPERATURE_K
from eden_pipe.render.sky.preetham import E0_KLUX, K_SCALE, sun_transmittance, xyY_to_rgb

MOON_FULL_FRACTION = 0.01  # full-moon irradiance / sun irradiance, same elevation (render scale, see above)


def planck_xy(temperature_k: float) -> tuple[float, float]:
    """CIE 1931 (x, y) of a black body, 1667-25000 K (Kim et al. cubic fit of the Planckian locus)."""
    t = 1000.0 / float(temperature_k)
    if t >= 0.25:  # T <= 4000 K
        x = -0.2661239 * t**3 - 0.2343589 * t**2 + 0.8776956 * t + 0.179910
    else:
        x = -3.0258469 * t**3 + 2.1070379 * t**2 + 0.2226347 * t + 0.240390
    if t >= 0.45:  # T <= 2222 K
        y = -1.1063814 * x**3 - 1.34811020 * x**2 + 2.18555832 * x - 0.20219683
    elif t >= 0.25:
        y = -0.9549476 * x**3 - 1.37418593 * x**2 + 2.09137015 * x - 0.16748867
    else:
        y = 3.0817580 * x**3 - 5.87338670 * x**2 + 3.75112997 * x - 0.37001483
    return x, y


def _planck_rgb(temperature_k: float) -> np.ndarray:
    x, y = planck_xy(temperature_k)
    return xyY_to_rgb(np.array([1.0]), np.array([x]), np.array([y]))[0]


def temperature_tint(temperature_k: float) -> np.ndarray:
    """(3,) linear sRGB factor of luminance 1: a black body at ``temperature_k`` relative to
    the reference (5778 K -> exactly (1, 1, 1)); lower is warmer, higher bluer."""
    rgb = _planck_rgb(temperature_k) / _planck_rgb(REFERENCE_TEMPERATURE_K)
    return rgb / float(rgb @ LUMA)


def moon_phase_factor(illuminated_fraction: float) -> float:
    """Moonlight relative to the full moon for an illuminated fraction (0 new .. 1 full)."""
    k = min(max(float(illuminated_fraction), 0.0), 1.0)
    alpha = math.degrees(math.acos(2.0 * k - 1.0))  # phase angle: 0 full, 180 new
    return 10.0 ** (-0.4 * (0.026 * alpha + 4e-9 * alpha**4))


def direct_light_irradiance(params, scenario) -> np.ndarray:
    """(3,) normal irradiance of the scenario's direct light (zeros without one)."""
    if not scenario.has_sun:
        return np.zeros(3)
    theta = math.pi / 2 - params.sun_elevation
    e = (
        K_SCALE
        * E0_KLUX
        * params.sun_intensity
        * sun_transmittance(theta, params.turbidity)
        * temperature_tint(params.sun_temperature)
    )
    if scenario.direct_light == "moon":
        e = e * moon_scale(params)
    return e


def moon_scale(params) -> float:
    """The moon's light relative to the sun's at the same elevation (render scale, phase law)."""
    return MOON_FULL_FRACTION * moon_phase_factor(params.moon_phase)
