"""The night sky: moonlit sky and light-polluted glow (scenario night).

Radiance for directions with z >= 0, like the other sky models:

* moonlit sky: moonlight scattered by the same atmosphere as sunlight, so the
  Preetham sky with the moon as its sun, scaled by the moon's light relative to
  the sun's (``sun.moon_scale``: phase law x render-scale fraction) and tinted
  with the moon's colour (blue, as night photography shows it);
* sky glow: artificial light scattered back by the air, warm (sodium and LED
  street lights), brightest at the horizon and fading within ~10 deg, with a
  faint blue-grey floor (airglow and starlight) up to the zenith. Its horizontal
  irradiance is ``GLOW_FRACTION`` x the clear reference x ``sky_intensity``: about a
  sixth of a high full moon's at ``sky_intensity=1`` (a suburban sky; 0.5-2 spans
  rural to urban), so a new moon leaves the garden lit by the glow alone.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.colour import luminance
from eden_pipe.render.sky.common import sphere_quadrature
from eden_pipe.render.sky.preetham import K_SCALE, clear_reference_irradiance, preetham_rgb
from eden_pipe.render.sky.sun import moon_scale, temperature_tint

GLOW_FRACTION = 0.001  # glow horizontal irradiance / clear reference, sky_intensity = 1
GLOW_RGB = np.array([1.0, 0.62, 0.32])  # warm street-light glow (luminance-normalised below)
FLOOR_RGB = np.array([0.30, 0.38, 0.60])  # airglow and starlight
GLOW_HEIGHT = 0.12  # e-folding of the glow in sin(elevation)
FLOOR_SHARE = 0.15  # floor radiance / glow radiance at the horizon


class NightSky:
    """Moonlit sky plus light-polluted glow; the moon itself is the scenario's direct light."""

    def __init__(self, params, sun_direction: np.ndarray):
        self.params = params
        self.sun_direction = sun_direction
        self._moon = K_SCALE * moon_scale(params) * temperature_tint(params.sun_temperature)
        self._glow_scale = 1.0
        dirs, w = sphere_quadrature(32, 0, 128)
        e_unit = float((luminance(self._glow(dirs)) * dirs[:, 2] * w).sum())
        self._glow_scale = GLOW_FRACTION * clear_reference_irradiance() * params.sky_intensity / e_unit

    def _glow(self, d: np.ndarray) -> np.ndarray:
        h = np.clip(d[:, 2], 0.0, 1.0)
        glow = np.exp(-h / GLOW_HEIGHT)[:, None] * (GLOW_RGB / luminance(GLOW_RGB))
        return self._glow_scale * (glow + FLOOR_SHARE * FLOOR_RGB / luminance(FLOOR_RGB))

    def radiance(self, d: np.ndarray) -> np.ndarray:
        """(N, 3) unit directions with z >= 0 -> (N, 3) linear radiance."""
        moonlit = preetham_rgb(d, self.sun_direction, self.params.turbidity) * self._moon
        return moonlit + self._glow(d)
