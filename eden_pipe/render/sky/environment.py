"""Image-based lighting: an equirectangular HDR map as sky radiance, ambient light, background and sun.

``lighting.environment=PATH`` (Radiance ``.hdr`` or OpenEXR; orientation: ``equirect``)
replaces the scenario's sky model. :class:`EnvironmentSky` offers the renderer the same
interface as ``dome.Sky``:

* radiance: the map itself, in every direction (its lower half is the background
  below the horizon unless a scenery panorama or the procedural scenery is asked for);
* ambient irradiance for any normal: the exact cosine convolution of the (sun-free)
  map, tabulated over normals (``ambient.AmbientTable``, as for the model skies), from
  the map averaged down to ``AMBIENT_MAP_WIDTH`` (energy kept); its 9-coefficient
  spherical-harmonic form (Ramamoorthi & Hanrahan 2001) goes into lighting.json;
* the sun, by ``lighting.environment_sun``:
  ``auto``: taken from the map's brightest region (:func:`extract_sun`): direction =
  the energy-weighted centroid of the region, irradiance = its energy above the
  surrounding sky, angular radius = that of a cap of solid angle energy / peak; the
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

from eden_pipe.colour import LUMA, luminance
from eden_pipe.io.hdr import file_sha256, read_panorama
from eden_pipe.render.sky.ambient import AmbientTable, sh9_project_panorama
from eden_pipe.render.sky.common import unit_vectors
from eden_pipe.render.sky.dome import Sky, direct_light_facts
from eden_pipe.render.sky.equirect import Panorama, pixel_directions, pixel_solid_angles
from eden_pipe.render.sky.exposure import exposure
from eden_pipe.render.sky.scenery import make_scenery

SUN_MIN_CONTRAST = 50.0  # a sun's peak radiance / the median sky radiance (luminance), at least
SUN_RING_PIXELS = 2  # width of the ring around the sun region whose median fills it
AMBIENT_MAP_WIDTH = 128  # the map is integrated at this width for the ambient table (the cosine is smooth)


@dataclass
class ExtractedSun:
    """The sun found in a map: world direction, normal irradiance (map units), angular radius."""

    direction: np.ndarray  # (3,) unit, world frame
    irradiance: np.ndarray  # (3,) the region's energy above the surrounding sky (integral of L dw)
    angular_radius: float  # radians: a cap of solid angle energy / peak radiance
    solid_angle: float  # steradians of that cap
    pixels: int


def extract_sun(
    image: np.ndarray, rotation: float = 0.0, min_contrast: float = SUN_MIN_CONTRAST
) -> tuple[ExtractedSun | None, np.ndarray]:
    """The sun of an equirectangular map and the map with its region filled by the surrounding sky.

    The sun is searched above the horizon: the brightest pixel must be ``min_contrast``
    times the median sky there (else ``(None, image)``); its region is the connected set of
    pixels brighter than the geometric mean of the peak and the median (8-connected, across
    the azimuth seam); the fill is the median of a ring ``SUN_RING_PIXELS`` wide around it.
    Direction: the centroid of the region's energy above the fill; irradiance: that energy;
    angular radius: a cap of solid angle energy / peak radiance.
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
    weight = luminance(excess) * solid
    direction = unit_vectors((dirs * weight[:, None]).sum(axis=0))[0]
    # A uniformly bright disc: solid angle = energy / its radiance (the peak, when a pixel is
    # wholly inside it; a sun smaller than a pixel comes out one pixel wide).
    omega = float(weight.sum()) / float(luminance(excess).max())
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
        small = downsample_panorama(image, AMBIENT_MAP_WIDTH)
        h, w = small.shape[:2]
        ambient = AmbientTable(
            pixel_directions(h, w, p.environment_rotation), pixel_solid_angles(h, w), small.reshape(-1, 3)
        )
        up = np.array([[0.0, 0.0, 1.0]])
        map_sky_up = ambient.irradiance(up)[0].astype(np.float64)
        if mode == "explicit":
            target = float(luminance(model.sky_horizontal_irradiance))
            map_total = float(luminance(map_sky_up))
        else:
            target = float(luminance(model.horizontal_irradiance))
            map_sun_up = 0.0
            if self.extracted is not None:
                map_sun_up = float(luminance(self.extracted.irradiance)) * max(float(self.extracted.direction[2]), 0.0)
            map_total = float(luminance(map_sky_up)) + map_sun_up
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
        self._ambient = ambient.scaled(self.scale)
        self.ambient_sh9 = sh9_project_panorama(image, p.environment_rotation) * self.scale
        self.map_size = image.shape[1], image.shape[0]

        self.has_clouds = False
        self.mean_sun_transmittance = 1.0
        self.sky_horizontal_irradiance = self._ambient.irradiance(up)[0].astype(np.float64)
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
        """(N, 3) unit normals -> (N, 3) float32 unoccluded irradiance from the whole (sun-free) map."""
        return self._ambient.irradiance(normals)

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
            "path": str(self.params.environment),
            "sha256": self.environment_sha256,
            "width": int(self.map_size[0]),
            "height": int(self.map_size[1]),
            "rotation_deg": math.degrees(self.params.environment_rotation),
            "sun_mode": self.params.environment_sun,
            "scale": float(self.scale),
            "convention": "equirectangular, row 0 = zenith, centre column = +x, +y a quarter width left of it "
            "(Blender's); rotation turns the map about +z",
            "sun_found": None
            if found is None
            else {
                "direction": [float(v) for v in found.direction],
                "irradiance_rgb_map_units": [float(v) for v in found.irradiance],
                "angular_diameter_deg": math.degrees(2.0 * found.angular_radius),
                "pixels": found.pixels,
            },
        }
        out["ambient_sh9_rgb"] = np.round(self.ambient_sh9, 9).tolist()
        out.update(self._scenery.facts())
        return out


def downsample_panorama(image: np.ndarray, width: int) -> np.ndarray:
    """An equirectangular map averaged down to ``width`` (never up), keeping each block's energy:
    pixels are weighted by their solid angle, which shrinks toward the poles."""
    h, w = image.shape[:2]
    if w <= width:
        return np.asarray(image[..., :3], np.float32)
    height = max(1, width // 2)
    solid = pixel_solid_angles(h, w).reshape(h, w, 1).astype(np.float64)
    energy = cv2.resize(image[..., :3].astype(np.float64) * solid, (width, height), interpolation=cv2.INTER_AREA)
    area = cv2.resize(solid[..., 0], (width, height), interpolation=cv2.INTER_AREA)[..., None]
    return (energy / area).astype(np.float32)


def bake_panorama(sky, width: int, sun: bool = True, supersample: int = 8) -> np.ndarray:
    """(width / 2, width, 3) float32 equirectangular map of a sky: its radiance, scenery and sun disc.

    Generates HDR environments from the model skies (tests, the gallery: nothing is
    downloaded). The sun disc (radiance = irradiance / disc solid angle) is anti-aliased by
    ``supersample``^2 samples per pixel near it, so the map holds the sun's irradiance.
    """
    height = width // 2
    dirs = pixel_directions(height, width)
    rgb = sky.radiance(dirs, 0.0)
    mask, scenery = sky.scenery(dirs)
    rgb = np.where(mask[:, None], scenery, rgb)
    radius = float(sky.sun_angular_radius)
    if sun and np.any(np.asarray(sky.sun_irradiance) > 0) and radius > 0:
        s = np.asarray(sky.sun_direction, np.float64)
        pixel = math.pi / height
        near = np.nonzero(dirs @ s > math.cos(radius + 2.0 * pixel))[0]
        rows, cols = near // width, near % width
        offsets = (np.arange(supersample) + 0.5) / supersample
        du, dv = np.meshgrid(offsets, offsets, indexing="ij")
        theta = (rows[:, None] + du.ravel()[None, :]) * pixel
        phi = (0.5 - (cols[:, None] + dv.ravel()[None, :]) / width) * (2.0 * math.pi)
        sub = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=-1)
        # Sub-samples are uniform in (theta, phi): weight them by sin(theta) for the solid angle.
        weight = np.sin(theta)
        coverage = ((sub @ s > math.cos(radius)) * weight).sum(1) / weight.sum(1)
        disc = 2.0 * math.pi * (1.0 - math.cos(radius))
        rgb[near] = rgb[near] + coverage[:, None] * (np.asarray(sky.sun_irradiance) / disc)[None, :]
    return rgb.reshape(height, width, 3).astype(np.float32)
