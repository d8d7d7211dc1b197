"""Exposure: a partial compensation of each sky's brightness toward the clear reference.

``exposure = clip((key_ref / key) ** EXPOSURE_POWER, 0.5, 16)`` with key = sky
horizontal + sun normal irradiance x max(sin elevation, 0.25) x mean cloud
transmittance (luminance) and key_ref the clear 60 deg reference, so image
brightness keeps the order twilight < overcast < clear. The renderer
multiplies the linear image by it before the sRGB transfer.
"""

from __future__ import annotations

import math

import numpy as np

from eden_pipe.colour import luminance
from eden_pipe.render.sky.preetham import clear_reference_irradiance

EXPOSURE_POWER = 0.5  # 0: no compensation, 1: full (every scenario as bright as clear)


def exposure(
    sky_up: np.ndarray, sun_irradiance: np.ndarray, sun_elevation: float, mean_sun_transmittance: float
) -> float:
    """Exposure factor from the sky's horizontal irradiance (3,) and the sun's normal irradiance (3,)."""
    key = (
        float(luminance(sky_up))
        + float(luminance(sun_irradiance)) * max(math.sin(sun_elevation), 0.25) * mean_sun_transmittance
    )
    key_ref = clear_reference_irradiance()
    return float(np.clip((key_ref / max(key, 1e-9)) ** EXPOSURE_POWER, 0.5, 16.0))
