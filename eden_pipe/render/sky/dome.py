"""The ``Sky`` of one garden under one lighting: what the renderer asks of the sky.

It assembles, from ``LightingParams`` and the scenario's entry in
``eden_pipe.lighting.SCENARIO_TABLE``: the sky model (``SKY_MODELS``), the
direct sun, the cloud layer (``clouds``), the radiance of every direction
(below the horizon a distant-ground colour), the ambient irradiance lookup,
the distant scenery (``scenery``) and the exposure (``exposure``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Protocol

import numpy as np

from eden_pipe.colour import luminance
from eden_pipe.geometry import spherical_direction
from eden_pipe.lighting import SCENARIO_TABLE
from eden_pipe.render.sky.ambient import AmbientTable, sh9_project
from eden_pipe.render.sky.clouds import CloudLayer, cloud_layer_xy
from eden_pipe.render.sky.common import smoothstep, sphere_quadrature, unit_vectors
from eden_pipe.render.sky.exposure import exposure
from eden_pipe.render.sky.night import NightSky
from eden_pipe.render.sky.overcast_twilight import OvercastSky, TwilightSky
from eden_pipe.render.sky.preetham import PreethamSky
from eden_pipe.render.sky.scenarios import LightingParams
from eden_pipe.render.sky.scenery import make_scenery
from eden_pipe.render.sky.sun import direct_light_irradiance


class SkyModel(Protocol):
    """What the dome asks of a sky model: built from the drawn values and the sun's direction."""

    def radiance(self, d: np.ndarray) -> np.ndarray: ...


# Scenario.sky_model -> the radiance model (constructed from LightingParams and the sun direction).
SKY_MODELS: dict[str, Callable[[LightingParams, np.ndarray], SkyModel]] = {
    "preetham": PreethamSky,
    "cie_overcast": OvercastSky,
    "twilight": TwilightSky,
    "night": NightSky,
}
GROUND_ALBEDO = np.array([0.13, 0.13, 0.08])


class Sky:
    """Sky radiance, sun, cloud shadows and distant scenery of one garden.

    ``params`` come from ``sample_lighting`` (checked there); the sky does not
    check them again.
    """

    def __init__(self, params: LightingParams, seed: int):
        p = params
        self.params = p
        self.seed = int(seed)
        self.scenario = p.scenario
        scenario = SCENARIO_TABLE[p.scenario]
        self.sun_direction = spherical_direction(p.sun_elevation, p.sun_azimuth)
        self.sun_angular_radius = 0.5 * p.sun_angular_diameter
        self.direct_light = scenario.direct_light  # sun | moon | none
        self.sun_irradiance = direct_light_irradiance(p, scenario)  # (3,) the sun's, or the moon's at night
        self._model = SKY_MODELS[scenario.sky_model](p, self.sun_direction)

        self.has_clouds = scenario.has_clouds and p.cloud_cover > 0.0
        self.mean_sun_transmittance = 1.0  # mean fraction of the sun the clouds let through
        self._clouds: CloudLayer | None = None
        if self.has_clouds:
            self._clouds = CloudLayer(self.seed, p.cloud_cover, p.cloud_speed)
            self.mean_sun_transmittance = self._clouds.mean_sun_transmittance

        # Clear part of the sky's horizontal irradiance (lights the clouds).
        dirs, w = sphere_quadrature(32, 0, 128)
        self._sky_up_clear = (self.upper_radiance(dirs, 0.0, clouds=False) * (dirs[:, 2] * w)[:, None]).sum(0)
        if self.has_clouds:
            dirs, w = sphere_quadrature(64, 0, 256)
            self._sky_up = (self.upper_radiance(dirs, 0.0) * (dirs[:, 2] * w)[:, None]).sum(0)
        else:
            self._sky_up = self._sky_up_clear
        self.sky_horizontal_irradiance = self._sky_up  # (3,) the sky alone on the ground plane
        sun_h = self.sun_irradiance * max(math.sin(p.sun_elevation), 0.0) * self.mean_sun_transmittance
        self.horizontal_irradiance = self._sky_up + sun_h  # (3,) sky + mean sun on the ground plane
        self._ground_rgb = GROUND_ALBEDO * self.horizontal_irradiance / math.pi

        self._init_ambient()
        self._scenery = make_scenery(p, self.seed, environment=False)
        self.exposure = exposure(self._sky_up, self.sun_irradiance, p.sun_elevation, self.mean_sun_transmittance)

    # ----------------------------------------------------------- radiance ---
    def upper_radiance(self, d: np.ndarray, time: float, clouds: bool = True) -> np.ndarray:
        """Sky radiance for unit directions with z >= 0 (no sun disc)."""
        rgb = self._model.radiance(d)
        if clouds and self.has_clouds:
            rgb = self._cloud_layer.apply(d, rgb, time, self.sun_direction, self.sun_irradiance, self._sky_up_clear)
        return rgb

    def radiance(self, directions: np.ndarray, time: float = 0.0) -> np.ndarray:
        """(N, 3) world directions -> (N, 3) linear sky radiance, sun disc excluded.

        Below the horizon the horizon colour fades (within ~3 deg) into a
        distant-ground colour (ground albedo x horizontal irradiance / pi).
        """
        d = unit_vectors(directions)
        below = d[:, 2] < 0.0
        dh = d.copy()
        dh[below, 2] = 0.0
        dh = unit_vectors(dh)
        rgb = self.upper_radiance(dh, time)
        if np.any(below):
            w = smoothstep(0.0, 0.06, -d[below, 2])[:, None]
            rgb[below] = (1.0 - w) * rgb[below] + w * self._ground_rgb
        return rgb

    # ------------------------------------------------------------- clouds ---
    @property
    def _cloud_layer(self) -> CloudLayer:
        if self._clouds is None:
            raise ValueError(f"the {self.scenario} sky has no clouds")
        return self._clouds

    @property
    def casts_cloud_shadows(self) -> bool:
        return self.has_clouds and self.sun_direction[2] > 1e-6

    def cloud_noise(self, xy: np.ndarray, time: float, dz: np.ndarray | None = None) -> np.ndarray:
        """The cloud layer's fBm at layer points (N, 2) (see ``clouds.CloudLayer.noise``)."""
        return self._cloud_layer.noise(xy, time, dz)

    def cloud_layer_xy(self, points: np.ndarray) -> np.ndarray:
        """Where the ray from each world point toward the sun crosses the cloud layer (N, 2)."""
        return cloud_layer_xy(points, self.sun_direction)

    def layer_transmittance(self, layer_xy: np.ndarray, time: float = 0.0) -> np.ndarray:
        """Fraction of the sun let through at cloud-layer points (N, 2)."""
        return self._cloud_layer.layer_transmittance(layer_xy, time)

    def transmittance_of_noise(self, noise: np.ndarray) -> np.ndarray:
        return self._cloud_layer.transmittance_of_noise(noise)

    def cloud_transmittance(self, points: np.ndarray, time: float = 0.0) -> np.ndarray:
        """(N, 3) world points -> (N,) fraction of the sun not blocked by clouds."""
        if not self.casts_cloud_shadows:
            return np.ones(len(np.asarray(points).reshape(-1, 3)))
        return self.layer_transmittance(self.cloud_layer_xy(points), time)

    # ------------------------------------------------------------ ambient ---
    def _init_ambient(self) -> None:
        n_up, n_phi = (64, 256) if self.has_clouds else (32, 128)
        dirs, w = sphere_quadrature(n_up, 16, n_phi)
        radiance = self.radiance(dirs, 0.0)
        self._ambient = AmbientTable(dirs, w, radiance)
        self.ambient_sh9 = sh9_project(dirs, w, radiance)  # (9, 3): the compact form, for lighting.json

    def ambient_irradiance(self, normals: np.ndarray) -> np.ndarray:
        """(N, 3) unit normals -> (N, 3) float32 unoccluded cosine-weighted irradiance from
        the sky dome and the distant ground below the horizon (no sun, no scenery)."""
        return self._ambient.irradiance(normals)

    # ------------------------------------------------------------ scenery ---
    def scenery(self, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distant scenery seen beyond the garden: (mask (N,), linear rgb (N, 3)); see ``scenery``."""
        return self._scenery.shade(directions, self)

    def facts(self) -> dict:
        """What the sky derived from the drawn values (the direct light's irradiance, colour and
        size; the scenery), for lighting.json."""
        return {
            **direct_light_facts(self),
            "ambient_sh9_rgb": np.round(self.ambient_sh9, 9).tolist(),
            **self._scenery.facts(),
        }


def direct_light_facts(sky) -> dict:
    """The direct light of a sky as plain numbers: irradiance, colour (luminance 1), angular diameter."""
    e = np.asarray(sky.sun_irradiance, np.float64)
    lum = float(luminance(e))
    return {
        "direct_light": sky.direct_light if lum > 0 else "none",
        "sun_irradiance_rgb": [float(c) for c in e],
        "sun_colour_rgb": [float(c) for c in (e / lum if lum > 0 else np.zeros(3))],
        "sun_angular_diameter_deg": float(np.degrees(2.0 * sky.sun_angular_radius)),
    }
