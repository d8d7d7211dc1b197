"""Preetham (1999) analytic daylight sky, the direct sun's colour and the render-unit scale.

The clear, cloudy and sunset scenarios use this sky (``PreethamSky``); the sun
is coloured by Rayleigh + aerosol transmittance along the air mass. ``K_SCALE``
maps photometric units (kcd/m^2 for sky luminance, klux for sun illuminance)
to render units: the clear sun at 60 deg elevation, turbidity 2.5 and
``sun_intensity=1`` has a luminance irradiance of exactly pi. The same factor
scales the sky, so the sky/sun ratio is the physical Preetham one.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from eden_pipe.colour import LUMA
from eden_pipe.geometry import spherical_direction
from eden_pipe.render.sky.common import sphere_quadrature

LAMBDA_RGB_UM = np.array([0.65, 0.57, 0.475])
XYZ_TO_SRGB = np.array(
    [
        [3.2406, -1.5372, -0.4986],
        [-0.9689, 1.8758, 0.0415],
        [0.0557, -0.2040, 1.0570],
    ]
)
E0_KLUX = 133.8  # luminous solar constant (extraterrestrial normal illuminance), klux
T_REF = 2.5  # reference turbidity of the scale convention
ELEV_REF = math.radians(60.0)


def perez_coefficients(turbidity: float) -> np.ndarray:
    """(3, 5) Perez A..E for Y, x, y (Preetham 1999, linear in turbidity)."""
    t = float(turbidity)
    return np.array(
        [
            [
                0.1787 * t - 1.4630,
                -0.3554 * t + 0.4275,
                -0.0227 * t + 5.3251,
                0.1206 * t - 2.5771,
                -0.0670 * t + 0.3703,
            ],
            [
                -0.0193 * t - 0.2592,
                -0.0665 * t + 0.0008,
                -0.0004 * t + 0.2125,
                -0.0641 * t - 0.8989,
                -0.0033 * t + 0.0452,
            ],
            [
                -0.0167 * t - 0.2608,
                -0.0950 * t + 0.0092,
                -0.0079 * t + 0.2102,
                -0.0441 * t - 1.6537,
                -0.0109 * t + 0.0529,
            ],
        ]
    )


def perez(cos_theta: np.ndarray, gamma: np.ndarray, coeffs: np.ndarray) -> np.ndarray:
    """Perez F(theta, gamma) for one row of coefficients; cos_theta > 0."""
    a, b, c, d, e = coeffs
    cg = np.cos(gamma)
    return (1.0 + a * np.exp(b / cos_theta)) * (1.0 + c * np.exp(d * gamma) + e * cg * cg)


def zenith_luminance(theta_s: float, turbidity: float) -> float:
    """Preetham zenith luminance Yz in kcd/m^2."""
    t = float(turbidity)
    chi = (4.0 / 9.0 - t / 120.0) * (math.pi - 2.0 * theta_s)
    return (4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192


def zenith_chromaticity(theta_s: float, turbidity: float) -> tuple[float, float]:
    """Preetham zenith chromaticity (xz, yz): cubic in theta_s, quadratic in T."""
    t = np.array([turbidity**2, turbidity, 1.0])
    th = np.array([theta_s**3, theta_s**2, theta_s, 1.0])
    mx = np.array(
        [
            [0.00166, -0.00375, 0.00209, 0.0],
            [-0.02903, 0.06377, -0.03202, 0.00394],
            [0.11693, -0.21196, 0.06052, 0.25886],
        ]
    )
    my = np.array(
        [
            [0.00275, -0.00610, 0.00317, 0.0],
            [-0.04214, 0.08970, -0.04153, 0.00516],
            [0.15346, -0.26756, 0.06670, 0.26688],
        ]
    )
    return float(t @ mx @ th), float(t @ my @ th)


def air_mass(theta_s: float) -> float:
    """Kasten-style relative optical air mass for a sun zenith angle (rad)."""
    ts_deg = math.degrees(theta_s)
    return 1.0 / (math.cos(theta_s) + 0.15 * (93.885 - ts_deg) ** -1.253)


def sun_transmittance(theta_s: float, turbidity: float) -> np.ndarray:
    """(3,) Rayleigh x aerosol transmittance of the direct sun at lambda R, G, B."""
    m = air_mass(theta_s)
    beta = 0.04608 * turbidity - 0.04586
    lam = LAMBDA_RGB_UM
    return np.exp(-m * (0.008735 * lam**-4.08 + beta * lam**-1.3))


def xyY_to_rgb(Y: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(N,) CIE Yxy -> (N, 3) linear sRGB (negative components clipped)."""
    y = np.maximum(y, 1e-6)
    X = x / y * Y
    Z = (1.0 - x - y) / y * Y
    rgb = np.stack([X, Y, Z], axis=-1) @ XYZ_TO_SRGB.T
    return np.maximum(rgb, 0.0)


def preetham_rgb(directions: np.ndarray, sun_dir: np.ndarray, turbidity: float) -> np.ndarray:
    """(N, 3) Preetham sky in kcd/m^2-scaled linear sRGB for directions with z >= 0."""
    d = np.asarray(directions, dtype=np.float64)
    theta_s = math.acos(min(max(float(sun_dir[2]), -1.0), 1.0))
    coeffs = perez_coefficients(turbidity)
    yz_lum = zenith_luminance(theta_s, turbidity)
    xz, yz = zenith_chromaticity(theta_s, turbidity)
    cos_t = np.clip(d[:, 2], 1e-3, 1.0)
    gamma = np.arccos(np.clip(d @ sun_dir, -1.0, 1.0))
    out = []
    for row, zen in zip(coeffs, (yz_lum, xz, yz), strict=True):
        f0 = perez(np.array(1.0), np.array(theta_s), row)
        out.append(zen * perez(cos_t, gamma, row) / f0)
    return xyY_to_rgb(np.maximum(out[0], 0.0), out[1], out[2])


@lru_cache(maxsize=64)
def _clear_reference(elev_rounded: float, turbidity: float) -> tuple[float, float]:
    """(sun, sky) horizontal luminance irradiance, klux, of a clear Preetham sky."""
    elev = math.radians(elev_rounded)
    s = spherical_direction(elev, 0.0)
    dirs, w = sphere_quadrature(48, 0, 96)
    rgb = preetham_rgb(dirs, s, turbidity)
    sky = float(((rgb @ LUMA) * dirs[:, 2] * w).sum())
    sun = E0_KLUX * float(sun_transmittance(math.pi / 2 - elev, turbidity) @ LUMA) * math.sin(elev)
    return sun, sky


# Render units per (klux or kcd/m^2): clear sun at 60 deg, T 2.5 -> luminance pi.
K_SCALE = math.pi / (E0_KLUX * float(sun_transmittance(math.pi / 2 - ELEV_REF, T_REF) @ LUMA))


def clear_reference_irradiance(elevation: float = ELEV_REF, turbidity: float = T_REF) -> float:
    """Horizontal luminance irradiance (render units) of a clear sky + sun."""
    sun, sky = _clear_reference(round(math.degrees(max(elevation, math.radians(2.0))), 3), round(turbidity, 4))
    return K_SCALE * (sun + sky)


class PreethamSky:
    """Clear Preetham sky radiance (render units) for one sun and turbidity; no clouds, no sun disc."""

    def __init__(self, params, sun_direction: np.ndarray):
        self.params = params
        self.sun_direction = sun_direction

    def radiance(self, d: np.ndarray) -> np.ndarray:
        """(N, 3) unit directions with z >= 0 -> (N, 3) linear radiance."""
        p = self.params
        return K_SCALE * p.sky_intensity * preetham_rgb(d, self.sun_direction, p.turbidity)
