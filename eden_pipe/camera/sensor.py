"""The sensor and ISP between the rendered light and the display PNG (docs/design.md, Camera effects).

``Sensor.apply`` turns the exposed linear RGB (``exposure * I``) into the 8-bit PNG, in this order:

1. lateral chromatic aberration (optics): the red and blue images magnified by ``1 + ca_red`` and
   ``1 + ca_blue`` about the principal point (green is the reference), resampled with ``cv2.remap``;
2. vignetting (optics): times the relative illumination ``cos^4(theta)`` or ``1 + k1 r^2 + k2 r^4``
   (``r^2 = x^2 + y^2`` in normalised image coordinates, ``theta`` the ray's angle to the axis);
3. photo-electrons: ``Poisson(x * full_well_e / gain)``;
4. read noise: ``+ Normal(0, read_noise_e)`` electrons;
5. the ADC: ``DN = round(e * gain * (white - black) / full_well_e + black)``, clipped to
   ``[0, 2^bits - 1]``, with ``white = 2^bits - 1`` and ``black = round(black_level * white)``;
6. the ISP: ``y = clip((DN - black) / (white - black), 0, 1)``, the tone curve, ``round(255 * tone(y))``.

So x = 1 is the white point whatever the gain (gain is ISO: the same brightness from fewer
electrons), and in units of x the noise variance is ``x * gain / full_well_e + (read_noise_e *
gain / full_well_e)^2`` before quantisation. Every step is vectorised over the image; the noise
comes from the generator the caller passes (the render stage's ``rng_for(seed, "sensor", ...)``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

from eden_pipe.camera.rig import Intrinsics
from eden_pipe.colour import linear_to_srgb


def aces_filmic(x):
    """Narkowicz's fit of the ACES filmic curve, ``x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14)``."""
    return x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14)


#: y in [0, 1] -> display value in [0, 1]; ``filmic`` is the ACES fit scaled so 1 stays 1, then sRGB-encoded.
TONE_CURVES = {
    "srgb": lambda y, gamma: linear_to_srgb(y),
    "gamma": lambda y, gamma: np.power(y, 1.0 / gamma),
    "filmic": lambda y, gamma: linear_to_srgb(aces_filmic(y) / aces_filmic(np.float64(1.0))),
}


@dataclass(frozen=True)
class Sensor:
    """The ``camera.sensor`` keys (``config.SensorConfig`` holds the defaults and domains)."""

    full_well_e: float = 10000.0
    read_noise_e: float = 3.0
    gain: float = 1.0
    black_level: float = 0.0625
    bits: int = 10
    vignetting: str = "none"
    vignetting_k1: float = -0.3
    vignetting_k2: float = 0.0
    ca_red: float = 0.0
    ca_blue: float = 0.0
    tone_curve: str = "srgb"
    gamma: float = 2.2

    @classmethod
    def from_config(cls, sensor_cfg) -> Sensor | None:
        """The sensor of ``camera.sensor``, or None when it is off (the PNG is sRGB(exposure * I))."""
        if not bool(sensor_cfg.enabled):
            return None
        return cls(**{name: getattr(sensor_cfg, name) for name in cls.__dataclass_fields__})

    def facts(self) -> dict:
        """The parameters as published in ``camera.json``, with the ADC levels they give."""
        return {**asdict(self), "white_dn": self.white_dn, "black_dn": self.black_dn}

    @property
    def white_dn(self) -> int:
        return (1 << int(self.bits)) - 1

    @property
    def black_dn(self) -> int:
        return int(round(self.black_level * self.white_dn))

    # ------------------------------------------------------------------ optics
    def relative_illumination(self, intr: Intrinsics) -> np.ndarray | None:
        """(H, W) vignetting factor (1 at the principal point), or None without vignetting."""
        if self.vignetting == "none":
            return None
        u, v = intr.pixel_grid()
        r2 = ((u - intr.cx) / intr.fx) ** 2 + ((v - intr.cy) / intr.fy) ** 2
        if self.vignetting == "cos4":
            return 1.0 / (1.0 + r2) ** 2  # cos(theta)^2 = 1 / (1 + r^2)
        return np.maximum(1.0 + self.vignetting_k1 * r2 + self.vignetting_k2 * r2 * r2, 0.0)

    def aberrate(self, image: np.ndarray, intr: Intrinsics) -> np.ndarray:
        """Lateral chromatic aberration: channel c magnified by 1 + s_c about (cx, cy), so a point at
        radius rho from the principal point appears at rho * (1 + s_c); edges replicate."""
        out = image
        for channel, scale in ((0, self.ca_red), (2, self.ca_blue)):
            if scale == 0.0:
                continue
            if out is image:
                out = image.copy()
            u, v = intr.pixel_grid()
            map_x = (intr.cx + (u - intr.cx) / (1.0 + scale)).astype(np.float32)
            map_y = (intr.cy + (v - intr.cy) / (1.0 + scale)).astype(np.float32)
            source = np.ascontiguousarray(image[..., channel], dtype=np.float32)
            out[..., channel] = cv2.remap(source, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return out

    def optics(self, exposed: np.ndarray, intr: Intrinsics) -> np.ndarray:
        """Steps 1-2: the light reaching each pixel, (H, W, 3) float64."""
        x = self.aberrate(np.asarray(exposed, np.float64), intr)
        falloff = self.relative_illumination(intr)
        return x if falloff is None else x * falloff[..., None]

    # ------------------------------------------------------------------ sensor and ISP
    def electrons_per_unit(self) -> float:
        """Mean photo-electrons per unit of x at this gain."""
        return float(self.full_well_e) / float(self.gain)

    def digitise(self, x: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Steps 3-5: the ADC's values (same shape as x, float64 holding integers)."""
        per_unit = self.electrons_per_unit()
        electrons = rng.poisson(np.maximum(x, 0.0) * per_unit).astype(np.float64)
        if self.read_noise_e > 0:
            electrons += rng.normal(0.0, float(self.read_noise_e), size=x.shape)
        scale = (self.white_dn - self.black_dn) / per_unit
        return np.clip(np.round(electrons * scale + self.black_dn), 0, self.white_dn)

    def to_display(self, dn: np.ndarray) -> np.ndarray:
        """Step 6: the ISP, ADC values -> uint8."""
        y = np.clip((dn - self.black_dn) / float(self.white_dn - self.black_dn), 0.0, 1.0)
        return self.tone(y)

    def tone(self, y: np.ndarray) -> np.ndarray:
        """The tone curve of linear values y (clipped to [0, 1]) as uint8."""
        curve = TONE_CURVES[self.tone_curve](np.clip(y, 0.0, 1.0), float(self.gamma))
        return np.round(curve * 255.0).astype(np.uint8)

    def noise_sigma(self, x: np.ndarray) -> np.ndarray:
        """The model's noise standard deviation in units of x (shot and read noise; before the ADC)."""
        per_unit = self.electrons_per_unit()
        return np.sqrt(np.maximum(x, 0.0) / per_unit + (float(self.read_noise_e) / per_unit) ** 2)

    def apply(self, exposed: np.ndarray, intr: Intrinsics, rng: np.random.Generator) -> np.ndarray:
        """The display PNG (H, W, 3) uint8 of the exposed linear RGB ``exposure * I`` (every step above)."""
        return self.to_display(self.digitise(self.optics(exposed, intr), rng))
