"""Image-based lighting: an equirectangular HDR map as sky radiance, ambient light, background and sun.

``lighting.environment=PATH`` (Radiance ``.hdr`` or OpenEXR; orientation: ``equirect``)
replaces the scenario's sky model. :class:`EnvironmentSky` offers the renderer the same
interface as ``dome.Sky``:

* radiance: the map itself, in every direction (its lower half is the background
  below the horizon unless a scenery panorama or the procedural scenery is asked for);
* ambient irradiance for any normal: 9-coefficient spherical harmonics of the map
  (Ramamoorthi & Hanrahan 2001, "An efficient representation for irradiance
  environment maps"): the map is projected once onto the real SH basis up to l = 2
  and the cosine lobe's convolution weights (pi, 2 pi / 3, pi / 4) applied; exact for
  the l <= 1 part of any map, and the l >= 3 odd terms of a clamped cosine are zero;
* the sun, by ``lighting.environment_sun``:
  ``auto``: taken from the map's brightest region (:func:`extract_sun`): direction =
  the energy-weighted centroid of the region, irradiance = its energy above the
  surrounding sky, angular radius = that of a cap of the region's solid angle; the
  region is filled with the surrounding sky so its light is not counted twice. A map
  whose peak is not ``SUN_MIN_CONTRAST`` times its median sky has no sun (overcast maps).
  ``none``: no direct sun; the map lights by its ambient term alone (a sun in it then
  casts no shadow). ``explicit``: the scenario's sun from the sun_* keys (direction,
  size, colour, intensity), as without a map.
* scale: a map's absolute units are unknown, so the map is scaled to the illuminance of
  the light it replaces: its horizontal illuminance (with its extracted sun; without a
  sun under ``explicit``) is set to that of the scenario's sky model at the garden's
  drawn values (sky, plus its sun except under ``explicit``, whose sun stays the
  model's). ``sky_intensity`` and the scenario keep their meaning (a night map under
  ``lighting=night`` renders as dark as the night sky); ``sun_intensity`` then scales
  an extracted sun. The exposure follows as for the model skies.

No clouds are added to a map (it has its own).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from eden_pipe.io.hdr import file_sha256, read_panorama
from eden_pipe.render.sky.common import LUMA, _lum, _normalize
from eden_pipe.render.sky.dome import Sky, direct_light_facts
from eden_pipe.render.sky.equirect import Panorama, pixel_directions, pixel_solid_angles
from eden_pipe.render.sky.exposure import exposure
from eden_pipe.render.sky.scenery import make_scenery

SUN_MIN_CONTRAST = 50.0   # a sun's peak radiance / the median sky radiance (luminance), at least
SUN_RING_PIXELS = 2       # width of the ring around the sun region whose median fills it

# Real SH basis up to l = 2, in the order (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2).
_SH_C0, _SH_C1, _SH_C2, _SH_C20, _SH_C22 = 0.282095, 0.488603, 1.092548, 0.315392, 0.546274
# Clamped-cosine convolution per band (Ramamoorthi & Hanrahan 2001): A0 = pi, A1 = 2 pi / 3, A2 = pi / 4.
SH_COSINE_WEIGHTS = np.array([math.pi] + [2.0 * math.pi / 3.0] * 3 + [math.pi / 4.0] * 5)


def sh9_basis(directions: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions -> (N, 9) real spherical harmonics up to l = 2."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack([
        np.full(len(d), _SH_C0), _SH_C1 * y, _SH_C1 * z, _SH_C1 * x,
        _SH_C2 * x * y, _SH_C2 * y * z, _SH_C20 * (3.0 * z * z - 1.0), _SH_C2 * x * z, _SH_C22 * (x * x - y * y),
    ], axis=-1)


def sh9_project_panorama(image: np.ndarray, rotation: float = 0.0, rows_per_block: int = 128) -> np.ndarray:
    """(9, 3) SH coefficients of an equirectangular map's radiance (world frame after ``rotation``)."""
    h, w = image.shape[:2]
    coeffs = np.zeros((9, 3))
    solid = pixel_solid_angles(h, w).reshape(h, w)
    for r0 in range(0, h, rows_per_block):  # blocks of rows: (pixels, 9) float64 stays small
        rows = slice(r0, min(h, r0 + rows_per_block))
        weighted = image[rows, :, :3].reshape(-1, 3).astype(np.float64) * solid[rows].reshape(-1, 1)
        coeffs += sh9_basis(pixel_directions(h, w, rotation, rows)).T @ weighted
    return coeffs


def sh9_irradiance(coeffs: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) cosine-weighted irradiance for unit normals from (9, 3) radiance coefficients (>= 0)."""
    return np.maximum(sh9_basis(normals) @ (SH_COSINE_WEIGHTS[:, None] * coeffs), 0.0)


@dataclass
class ExtractedSun:
    """The sun found in a map: world direction, normal irradiance (map units), angular radius."""

    direction: np.ndarray     # (3,) unit, world frame
    irradiance: np.ndarray    # (3,) the region's energy above the surrounding sky (integral of L dw)
    angular_radius: float     # radians: a cap of the region's solid angle
    solid_angle: float        # steradians of the region
    pixels: int


def extract_sun(image: np.ndarray, rotation: float = 0.0,
                min_contrast: float = SUN_MIN_CONTRAST) -> tuple[ExtractedSun | None, np.ndarray]:
    """The sun of an equirectangular map and the map with its region filled by the surrounding sky.

    The sun is searched above the horizon: the brightest pixel must be ``min_contrast``
    times the median sky there (else ``(None, image)``); its region is the connected set of
    pixels brighter than the geometric mean of the peak and the median (8-connected, across
    the azimuth seam); the fill is the median of a ring ``SUN_RING_PIXELS`` wide around it.
    """
    h, w = image.shape[:2]
    rgb = image[..., :3]
    lum = rgb @ LUMA.astype(np.float32)
    n_up = max(1, h // 2)
    upper = lum[:n_up]
    peak_row, peak_col = np.unravel_index(int(np.argmax(upper)), upper.shape)
    peak = float(upper[peak_row, peak_col])
    sky_level = float(np.median(upper))
    if sky_level <= 0.0:
        positive = upper[upper > 0]
        sky_level = float(positive.min()) if positive.size else 0.0
    if peak <= 0.0 or peak < min_contrast * sky_level:
        return None, image
    threshold = math.sqrt(peak * max(sky_level, peak * 1e-12))
    # Centre the peak's column so neither the region nor its ring crosses the azimuth seam.
    shift = w // 2 - int(peak_col)
    bright = np.roll((lum > threshold).astype(np.uint8), shift, axis=1)
    _, labels = cv2.connectedComponents(bright, connectivity=8)
    region_c = labels == labels[peak_row, w // 2]
    kernel = np.ones((3, 3), np.uint8)
    ring_c = cv2.dilate(region_c.astype(np.uint8), kernel, iterations=SUN_RING_PIXELS).astype(bool) & ~region_c
    region = np.roll(region_c, -shift, axis=1)
    ring = np.roll(ring_c, -shift, axis=1)
    fill = np.median(rgb[ring].astype(np.float64), axis=0) if ring.any() else np.zeros(3)
    solid = pixel_solid_angles(h, w).reshape(h, w)[region]
    excess = np.maximum(rgb[region].astype(np.float64) - fill, 0.0)
    energy = (excess * solid[:, None]).sum(axis=0)
    dirs = pixel_directions(h, w, rotation).reshape(h, w, 3)[region]
    weight = _lum(excess) * solid
    direction = _normalize((dirs * weight[:, None]).sum(axis=0))[0]
    omega = float(solid.sum())
    radius = math.acos(max(-1.0, 1.0 - omega / (2.0 * math.pi)))
    out = np.array(image, dtype=np.float32, copy=True)
    out[..., :3][region] = fill.astype(np.float32)
    return ExtractedSun(direction, energy, radius, omega, int(region.sum())), out


class EnvironmentSky:
    """A garden lit by an HDR map (see the module docstring); the renderer's sky interface."""

    def __init__(self, params, seed: int):
        p = params
        self.params, self.seed, self.scenario = p, int(seed), p.scenario
        model = Sky(p, seed)  # the scenario's sky at the drawn values: the scale, and the explicit sun
        image = np.asarray(read_panorama(p.environment)[..., :3], np.float32)
        self.environment_sha256 = file_sha256(p.environment)
        mode = p.environment_sun
        self.extracted: ExtractedSun | None = None
        if mode == "auto":
            self.extracted, image = extract_sun(image, p.environment_rotation)
        coeffs = sh9_project_panorama(image, p.environment_rotation)
        up = np.array([[0.0, 0.0, 1.0]])
        map_sky_up = sh9_irradiance(coeffs, up)[0]
        if mode == "explicit":
            target = float(_lum(model.sky_horizontal_irradiance))
            map_total = float(_lum(map_sky_up))
        else:
            target = float(_lum(model.horizontal_irradiance))
            map_sun_up = 0.0
            if self.extracted is not None:
                map_sun_up = float(_lum(self.extracted.irradiance)) * max(float(self.extracted.direction[2]), 0.0)
            map_total = float(_lum(map_sky_up)) + map_sun_up
        self.scale = target / map_total if map_total > 0.0 else 1.0

        if mode == "explicit":
            self.sun_direction = model.sun_direction
            self.sun_irradiance = model.sun_irradiance
            self.sun_angular_radius = model.sun_angular_radius
        elif self.extracted is not None:
            self.sun_direction = self.extracted.direction
            self.sun_irradiance = self.extracted.irradiance * self.scale * p.sun_intensity
            self.sun_angular_radius = self.extracted.angular_radius
        else:
            self.sun_direction = model.sun_direction  # unused: no sun
            self.sun_irradiance = np.zeros(3)
            self.sun_angular_radius = model.sun_angular_radius
        self.direct_light = "sun" if np.any(self.sun_irradiance > 0) else "none"
        self._panorama = Panorama(image * np.float32(self.scale), p.environment_rotation)
        self._sh = coeffs * self.scale
        self.map_size = image.shape[1], image.shape[0]

        self.has_clouds = False
        self.mean_sun_transmittance = 1.0
        self.sky_horizontal_irradiance = sh9_irradiance(self._sh, up)[0]
        sun_h = self.sun_irradiance * max(float(self.sun_direction[2]), 0.0)
        self.horizontal_irradiance = self.sky_horizontal_irradiance + sun_h
        elevation = math.asin(min(max(float(self.sun_direction[2]), -1.0), 1.0))
        self.exposure = exposure(self.sky_horizontal_irradiance, self.sun_irradiance, elevation, 1.0)
        self._scenery = make_scenery(p, self.seed, environment=True)

    # ----------------------------------------------------------- radiance ---
    def radiance(self, directions: np.ndarray, time: float = 0.0) -> np.ndarray:
        """(N, 3) world directions -> (N, 3) radiance of the (scaled, sun-free) map."""
        return self._panorama.lookup(directions).astype(np.float64)

    def upper_radiance(self, d: np.ndarray, time: float, clouds: bool = True) -> np.ndarray:
        return self.radiance(d, time)

    def ambient_irradiance(self, normals: np.ndarray) -> np.ndarray:
        """(N, 3) unit normals -> (N, 3) float32 irradiance from the whole map (SH, 9 coefficients)."""
        return sh9_irradiance(self._sh, normals).astype(np.float32)

    # ------------------------------------------------------------- clouds ---
    casts_cloud_shadows = False

    def cloud_transmittance(self, points: np.ndarray, time: float = 0.0) -> np.ndarray:
        return np.ones(len(np.asarray(points).reshape(-1, 3)))

    # ------------------------------------------------------------ scenery ---
    def scenery(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return self._scenery.shade(directions, self)

    def facts(self) -> dict:
        """What the sky derived, for lighting.json."""
        out = direct_light_facts(self)
        found = self.extracted
        out["environment"] = {
            "path": str(self.params.environment), "sha256": self.environment_sha256,
            "width": int(self.map_size[0]), "height": int(self.map_size[1]),
            "rotation_deg": math.degrees(self.params.environment_rotation),
            "sun_mode": self.params.environment_sun, "scale": float(self.scale),
            "convention": "equirectangular, row 0 = zenith, centre column = +x, +y a quarter width left of it "
                          "(Blender's); rotation turns the map about +z",
            "sun_found": None if found is None else {
                "direction": [float(v) for v in found.direction],
                "irradiance_rgb_map_units": [float(v) for v in found.irradiance],
                "angular_diameter_deg": math.degrees(2.0 * found.angular_radius), "pixels": found.pixels},
        }
        out.update(self._scenery.facts())
        return out
