"""The two sun-less sky models: CIE overcast and twilight.

* ``OvercastSky`` (scenario overcast): the CIE overcast luminance distribution
  L(theta) = Lz (1 + 2 cos theta) / 3, neutral white, scaled to
  ``OVERCAST_FRACTION`` of the clear-sky horizontal illuminance at the same
  sun elevation.
* ``TwilightSky`` (scenario twilight): the sun below the horizon; a dim blue
  dome with a warm glow toward the sun's azimuth and a faint purple
  antitwilight arch opposite, scaled to a fraction of the clear reference
  (60 deg) that falls from ~3 % at -1 deg to ~1 % at -6 deg.

Both take the garden's LightingParams and sun direction and give radiance for
directions with z >= 0 (``radiance(d)``), like ``preetham.PreethamSky``.
"""

from __future__ import annotations

import math

import numpy as np

from eden_pipe.colour import luminance
from eden_pipe.render.sky.common import sphere_quadrature
from eden_pipe.render.sky.preetham import clear_reference_irradiance

OVERCAST_FRACTION = 0.3  # overcast / clear horizontal illuminance, same sun


class OvercastSky:
    """CIE overcast sky: luminance rises from the horizon to the zenith, no sun."""

    def __init__(self, params, sun_direction: np.ndarray):
        p = params
        target = OVERCAST_FRACTION * clear_reference_irradiance(p.sun_elevation) * p.sky_intensity
        self._overcast_lz = target / (7.0 * math.pi / 9.0)  # E_h = 7 pi / 9 Lz

    def radiance(self, d: np.ndarray) -> np.ndarray:
        lz = self._overcast_lz * (1.0 + 2.0 * np.clip(d[:, 2], 0.0, 1.0)) / 3.0
        return np.repeat(lz[:, None], 3, axis=1)


class TwilightSky:
    """Twilight sky: blue dome, warm glow toward the sun's azimuth, antitwilight arch."""

    def __init__(self, params, sun_direction: np.ndarray):
        p = params
        sh = sun_direction[:2]
        self._sun_h = sh / max(np.linalg.norm(sh), 1e-12)
        depth = -math.degrees(p.sun_elevation)  # 0.5 .. 12
        self._tw_glow = 4.0 * math.exp(-(depth - 1.0) / 2.5)
        self._tw_scale = 1.0
        frac = 0.03 * math.exp(-(depth - 1.0) / 5.0)
        target = frac * clear_reference_irradiance() * p.sky_intensity
        dirs, w = sphere_quadrature(32, 0, 128)
        e_unit = float((luminance(self.radiance(dirs)) * dirs[:, 2] * w).sum())
        self._tw_scale = target / e_unit

    def radiance(self, d: np.ndarray) -> np.ndarray:
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
