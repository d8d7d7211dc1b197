"""The cloud layer of the cloudy sky and its shadows on the garden.

``CloudLayer``: an fBm cloud field on a flat layer ``CLOUD_ALTITUDE`` m up,
thresholded to the drawn cloud cover, drifting with the wind; it shades the
sky (sunlit diffuse clouds with silver linings) and attenuates the sun.
``CloudShadowMap``: the layer's sun transmittance at one time, tabulated over
a scene's extent for the renderer. Used by any scenario whose table entry has
``has_clouds`` (Preetham skies) when its cloud cover is > 0.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numba import njit

from eden_pipe.colour import luminance
from eden_pipe.models.noise import Perlin, fbm2
from eden_pipe.render import lut
from eden_pipe.render.sky.common import smoothstep
from eden_pipe.rng import rng_for

if TYPE_CHECKING:
    from eden_pipe.render.sky.dome import Sky

# Cloud layer: altitude and base feature size chosen so cumulus look ~20 deg
# across at the zenith while their shadows still have metre-scale edges that
# drift visibly across a 10 m garden.
CLOUD_ALTITUDE = 250.0  # m
CLOUD_SCALE = 60.0  # m per noise lattice unit (first octave)
CLOUD_OCTAVES = 5
CLOUD_EDGE = 0.035  # half-width of the fBm threshold ramp (sets shadow edge softness)
CLOUD_MIN_TRANSMITTANCE = 0.12
CLOUD_ALBEDO = 0.85
CLOUD_ORIGIN = np.array([5.0, 5.0, 0.0])  # garden centre: where the sky is seen from


class CloudLayer:
    """A garden's cloud layer: seeded by the garden seed; cover and wind speed from the lighting."""

    def __init__(self, seed: int, cloud_cover: float, cloud_speed: float):
        self.cover = float(cloud_cover)
        rng = rng_for(seed, "clouds")
        self._perlin = Perlin(rng)
        wind_az = float(rng.uniform(0.0, 2.0 * math.pi))
        self._wind = cloud_speed * np.array([math.cos(wind_az), math.sin(wind_az)])
        self._cloud_offset = rng.uniform(0.0, 200.0, size=2)
        samples = rng.uniform(0.0, 256.0, size=(8192, 2))
        n = fbm2(self._perlin, samples[:, 0], samples[:, 1], octaves=CLOUD_OCTAVES)
        cover = self.cover
        self._cloud_threshold = float(np.quantile(n, 1.0 - cover)) if cover < 1.0 else float(n.min()) - CLOUD_EDGE
        alpha = smoothstep(self._cloud_threshold - CLOUD_EDGE, self._cloud_threshold + CLOUD_EDGE, n)
        self.mean_sun_transmittance = float(np.mean(1.0 - (1.0 - CLOUD_MIN_TRANSMITTANCE) * alpha))

    def _cloud_field(self, xy: np.ndarray, time: float, dz: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Cloud opacity alpha and core depth (0..1) at layer points (N, 2)."""
        n = self.noise(xy, time, dz)
        thr = self._cloud_threshold
        return smoothstep(thr - CLOUD_EDGE, thr + CLOUD_EDGE, n), smoothstep(thr, thr + 0.3, n)

    def noise(self, xy: np.ndarray, time: float, dz: np.ndarray | None = None) -> np.ndarray:
        """The cloud layer's fBm at layer points (N, 2); clouds are where it exceeds a threshold.

        ``dz`` (the view direction's z, sky lookups only) fades out octaves
        whose features would be smaller than ~0.5 deg on screen (they only
        alias near the horizon); shadows always use every octave.
        """
        u = (xy - self._wind * float(time)) / CLOUD_SCALE + self._cloud_offset
        # Same sum as noise.fbm2 (z slice 0.37, octave offset 17.31 o), with per-octave LOD weights.
        pts = np.stack([u[:, 0], u[:, 1], np.full(len(u), 0.37)], axis=-1)
        total = np.zeros(len(u))
        amp, norm = 1.0, 0.0
        for o in range(CLOUD_OCTAVES):
            size = CLOUD_SCALE / 2.0**o
            w: float | np.ndarray
            if dz is None:
                w = 1.0
            else:
                w = smoothstep(0.004, 0.009, size * dz * dz / (CLOUD_ALTITUDE - CLOUD_ORIGIN[2]))
                if not np.any(w > 0.0):
                    norm += amp
                    amp *= 0.5
                    continue
            total += amp * w * self._perlin.noise(pts * 2.0**o + 17.31 * o)
            norm += amp
            amp *= 0.5
        return total / norm

    def apply(
        self,
        d: np.ndarray,
        sky: np.ndarray,
        time: float,
        sun_direction: np.ndarray,
        sun_irradiance: np.ndarray,
        sky_up_clear: np.ndarray,
    ) -> np.ndarray:
        """Clouds over clear-sky radiance ``sky`` (N, 3) for unit directions d (N, 3), z >= 0.

        ``sky_up_clear``: the clear sky's horizontal irradiance (lights the clouds from below).
        """
        cover = self.cover
        haze = 0.4 * cover  # whitening/greying of the blue sky between clouds
        sky = sky * (1.0 - haze) + luminance(sky)[:, None] * haze
        alpha = np.full(len(d), 0.8 * cover)
        core = np.full(len(d), 0.5)
        vis = d[:, 2] > 0.03
        if np.any(vis):
            dv = d[vis]
            xy = CLOUD_ORIGIN[:2] + dv[:, :2] * ((CLOUD_ALTITUDE - CLOUD_ORIGIN[2]) / dv[:, 2])[:, None]
            a, c = self._cloud_field(xy, time, dv[:, 2])
            fade = smoothstep(0.03, 0.25, dv[:, 2])  # distant clouds blur into a hazy band
            alpha[vis] = a * fade + (1.0 - fade) * 0.8 * cover
            core[vis] = c * fade + (1.0 - fade) * 0.5
        cos_g = np.clip(d @ sun_direction, -1.0, 1.0)
        # Sunlit diffuse reflection (darker toward thick cores) + sky light, plus
        # forward scattering through the thin edges (Henyey-Greenstein, g=0.75):
        # silver linings around the sun.
        g = 0.75
        hg = (1.0 - g * g) / (4.0 * math.pi * (1.0 + g * g - 2.0 * g * cos_g) ** 1.5)
        diffuse = (
            CLOUD_ALBEDO
            * (sun_irradiance[None, :] * (0.3 * (1.0 - 0.6 * core))[:, None] + 0.9 * sky_up_clear[None, :])
            / math.pi
        )
        cloud = diffuse + sun_irradiance[None, :] * (0.6 * hg * (1.0 - core))[:, None]
        return sky * (1.0 - alpha[:, None]) + cloud * alpha[:, None]

    def layer_transmittance(self, layer_xy: np.ndarray, time: float = 0.0) -> np.ndarray:
        """Fraction of the sun let through at cloud-layer points (N, 2)."""
        return self.transmittance_of_noise(self.noise(np.asarray(layer_xy, np.float64).reshape(-1, 2), time))

    def transmittance_of_noise(self, noise: np.ndarray) -> np.ndarray:
        thr = self._cloud_threshold
        return 1.0 - (1.0 - CLOUD_MIN_TRANSMITTANCE) * smoothstep(thr - CLOUD_EDGE, thr + CLOUD_EDGE, noise)


def cloud_layer_xy(points: np.ndarray, sun_direction: np.ndarray) -> np.ndarray:
    """Where the ray from each world point toward the sun crosses the cloud layer (N, 2) float64."""
    pts = np.asarray(points).reshape(-1, 3)
    out = np.empty((len(pts), 2))
    _layer_xy(pts, np.asarray(sun_direction, np.float64), out)
    return out


@njit(nogil=True, cache=True, inline="always")
def _crossing(point, sun):
    """Where the ray from ``point`` (3,) toward ``sun`` (3,) crosses the cloud layer, float64: the
    one formula of :func:`cloud_layer_xy` and the shadow tables' lookup."""
    along = (CLOUD_ALTITUDE - np.float64(point[2])) / sun[2]
    return np.float64(point[0]) + sun[0] * along, np.float64(point[1]) + sun[1] * along


@njit(nogil=True, cache=True)
def _layer_xy(points, sun, out):
    for i in range(points.shape[0]):
        out[i, 0], out[i, 1] = _crossing(points[i], sun)


class CloudShadowMap:
    """Cloud transmittance of the sun at one time, tabulated over a scene's extent.

    ``Sky.cloud_transmittance`` sums five octaves of Perlin noise per shaded
    point: 4 s of a 9 s cloudy frame. The transmittance is a smooth function of
    where a point's sun ray crosses the cloud layer (shadow edges ramp over
    metres), so the cloud noise is sampled once per frame on grids in layer
    coordinates and interpolated (bilinear, ``cv2.remap``), and the cloud
    threshold applied to the interpolated noise: the noise is far smoother than
    the thresholded shadow. ``regions`` are world boxes
    ``((xmin, ymin, zmin), (xmax, ymax, zmax), spacing_m)``, finest first;
    points outside every table are evaluated exactly.
    """

    MAX_SAMPLES = 2_000_000  # beyond this a table costs more than it saves: evaluate exactly

    def __init__(self, sky: Sky, time: float, regions):
        self.sky, self.time = sky, float(time)
        self.tables = []  # (origin (2,), spacing, table (ny, nx, 1))
        self._frames = (np.zeros((0, 2)), np.zeros(0), np.zeros((0, 2), np.int64))  # _table_coordinates'
        if not sky.casts_cloud_shadows:
            return
        for lo, hi, spacing in regions:
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            layer = sky.cloud_layer_xy(corners)
            origin = layer.min(axis=0) - spacing
            shape = np.ceil((layer.max(axis=0) + spacing - origin) / spacing).astype(int) + 1  # (nx, ny)
            if shape.prod() > self.MAX_SAMPLES:  # a sun near the horizon smears the footprint out
                continue
            gx = origin[0] + spacing * np.arange(shape[0])
            gy = origin[1] + spacing * np.arange(shape[1])
            grid = np.stack(np.meshgrid(gx, gy, indexing="xy"), axis=-1).reshape(-1, 2)
            table = sky.cloud_noise(grid, self.time).astype(np.float32).reshape(shape[1], shape[0], 1)
            self.tables.append((origin, float(spacing), table))
        self._frames = (  # each table's origin, spacing and texels across and down, as the lookup reads them
            np.array([origin for origin, _, _ in self.tables], np.float64).reshape(-1, 2),
            np.array([spacing for _, spacing, _ in self.tables], np.float64),
            np.array([table.shape[1::-1] for _, _, table in self.tables], np.int64).reshape(-1, 2),
        )

    def transmittance(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points -> (N,) float32 fraction of the sun not blocked by clouds."""
        pts = np.asarray(points).reshape(-1, 3)
        if not self.sky.casts_cloud_shadows:
            return np.ones(len(pts), np.float32)
        out = np.empty(len(pts), np.float32)
        which = np.empty(len(pts), np.int64)
        fx, fy = np.empty(len(pts), np.float32), np.empty(len(pts), np.float32)
        _table_coordinates(pts, np.asarray(self.sky.sun_direction, np.float64), *self._frames, which, fx, fy)
        for k, (_, _, table) in enumerate(self.tables):
            idx = np.flatnonzero(which == k)
            noise = lut.sample(table, fx[idx], fy[idx])[:, 0]
            out[idx] = self.sky.transmittance_of_noise(noise)
        rest = np.flatnonzero(which < 0)
        if len(rest):
            out[rest] = self.sky.layer_transmittance(self.sky.cloud_layer_xy(pts[rest]), self.time)
        return out


@njit(nogil=True, cache=True)
def _table_coordinates(points, sun, origins, spacings, sizes, which, fx, fy):
    """For each world point (N, 3): where its sun ray crosses the cloud layer (``cloud_layer_xy``,
    float64), the first table k that holds it (``origins`` (K, 2), ``spacings`` (K,), ``sizes``
    (K, 2) its texels across and down) in ``which`` (-1: none), and its texel coordinates there,
    float32, in ``fx``, ``fy``: the numpy of ``CloudShadowMap.transmittance`` before it, in one pass."""
    for i in range(points.shape[0]):
        lx, ly = _crossing(points[i], sun)
        which[i] = -1
        for k in range(origins.shape[0]):
            u = (lx - origins[k, 0]) / spacings[k]
            v = (ly - origins[k, 1]) / spacings[k]
            if u >= 0.0 and u <= sizes[k, 0] - 1 and v >= 0.0 and v <= sizes[k, 1] - 1:
                which[i] = k
                fx[i], fy[i] = np.float32(u), np.float32(v)
                break
