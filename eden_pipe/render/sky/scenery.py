"""Distant scenery seen beyond the garden, chosen by ``lighting.scenery`` (:func:`make_scenery`).

* ``procedural`` (the default under a sky model): ``Scenery``, a wall/fence, a tree
  line, hills and the ground. Silhouettes are seeded by the garden seed only (the
  same for every lighting) and tabulated over azimuth once; they are lit by the
  garden's sky (ambient + sun, with aerial haze toward the horizon sky colour).
* a panorama image (``PanoramaScenery``): an equirectangular LDR or HDR image (the
  orientation convention of ``equirect``, turned by ``environment_rotation_deg``)
  as distant background. Where the image has an alpha channel, alpha > 0.5 marks
  scenery and the sky shows elsewhere; without one, it covers every direction below
  the horizon. Its linear values are taken relative to a white surface under the
  garden's light: radiance = value x horizontal irradiance / pi, so a daylight
  photograph dims and reddens with the scenario.
* ``none`` (the default under an HDR environment, whose lower half is the background):
  no scenery (``NoScenery``).

Each is a pure function of direction, like the sky itself.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from eden_pipe.models.noise import Perlin
from eden_pipe.render.sky.common import smoothstep, unit_vectors
from eden_pipe.render.sky.equirect import Panorama
from eden_pipe.rng import rng_for

if TYPE_CHECKING:
    from eden_pipe.render.sky.dome import Sky

SCENERY_EYE_HEIGHT = 1.0  # m, camera height assumed for the scenery's foot below the horizon


class Scenery:
    """Seeded silhouette layers of one garden and their shading under a sky."""

    def __init__(self, seed: int, turbidity: float):
        rng = rng_for(seed, "scenery")
        self._scn_perlin = Perlin(rng)
        r = lambda lo, hi: float(rng.uniform(lo, hi))  # noqa: E731
        deg = math.radians
        self._scn = dict(
            hills=rng.uniform() < 0.75,
            hill_base=deg(r(0.8, 2.0)),
            hill_amp=deg(r(1.0, 3.0)),
            hill_z=r(0.0, 50.0),
            hill_dist=r(1500.0, 4000.0),
            tree_cover=r(0.35, 0.95),
            tree_base=deg(r(1.5, 3.0)),
            tree_amp=deg(r(0.8, 2.0)),
            tree_z=r(50.0, 100.0),
            tree_dist=r(60.0, 150.0),
            wall=rng.uniform() < 0.4,
            wall_cover=r(0.15, 0.45),
            wall_height=deg(r(0.6, 1.3)),
            wall_z=r(100.0, 150.0),
            wall_dist=r(30.0, 60.0),
            wall_albedo=np.array([[0.30, 0.14, 0.09], [0.32, 0.30, 0.27], [0.20, 0.13, 0.08]])[rng.integers(3)],
            tree_albedo=np.array([0.045, 0.080, 0.030]) * r(0.8, 1.25),
            hill_albedo=np.array([0.08, 0.11, 0.05]) * r(0.8, 1.25),
            field_albedo=np.array([0.10, 0.13, 0.06]) * r(0.8, 1.25),
        )
        # Coverage thresholds from samples of the presence noise around the circle.
        phi = np.linspace(0.0, 2.0 * math.pi, 720, endpoint=False)
        s = self._scn
        s["tree_thr"] = float(np.quantile(self._circle_noise(phi, 1.2, s["tree_z"], 3), 1.0 - s["tree_cover"]))
        s["wall_thr"] = float(np.quantile(self._circle_noise(phi, 1.0, s["wall_z"], 2), 1.0 - s["wall_cover"]))
        # Haze colour at the horizon per azimuth comes from the sky itself.
        self._vis_km = 12.0 / max(turbidity, 1.0)
        # Silhouettes are tabulated once over azimuth (0.022 deg steps, finer than a pixel):
        # evaluating fBm per pixel and view was the renderer's most expensive background term.
        table_phi = np.linspace(-math.pi, math.pi, self._SIL_N + 1)
        self._sil_table = self._silhouettes_exact(table_phi)

    _SIL_N = 16384

    def _silhouettes(self, phi: np.ndarray) -> dict[str, np.ndarray]:
        """Silhouette heights (radians) by linear interpolation in the azimuth table."""
        f = (np.mod(phi + math.pi, 2.0 * math.pi)) / (2.0 * math.pi) * self._SIL_N
        i0 = np.minimum(np.floor(f).astype(np.int64), self._SIL_N - 1)
        w = f - i0
        return {k: v[i0] * (1.0 - w) + v[i0 + 1] * w for k, v in self._sil_table.items()}

    def _circle_noise(self, phi: np.ndarray, radius: float, z: float, octaves: int, elev=None) -> np.ndarray:
        """fBm on a circle of the given radius (periodic in azimuth), ~[-1, 1]."""
        pts = np.stack(
            [radius * np.cos(phi), radius * np.sin(phi), np.full(phi.shape, z) if elev is None else z + elev], axis=-1
        )
        return self._scn_perlin.fbm(pts, octaves)

    def _silhouettes_exact(self, phi: np.ndarray) -> dict[str, np.ndarray]:
        s = self._scn
        h = {}
        h["hills"] = (
            np.maximum(s["hill_base"] + s["hill_amp"] * self._circle_noise(phi, 1.5, s["hill_z"], 3), math.radians(0.3))
            if s["hills"]
            else np.zeros_like(phi)
        )
        pres = self._circle_noise(phi, 1.2, s["tree_z"], 3)
        taper = smoothstep(s["tree_thr"], s["tree_thr"] + 0.06, pres)
        # |noise| ("billow"): rounded crowns with sharp notches between them.
        crowns = np.clip(2.5 * np.abs(self._circle_noise(phi, 16.0, s["tree_z"] + 7.7, 3)), 0.0, 1.0)
        h["trees"] = taper * (s["tree_base"] + s["tree_amp"] * crowns)
        if s["wall"]:
            wp = self._circle_noise(phi, 1.0, s["wall_z"], 2)
            h["wall"] = np.where(wp > s["wall_thr"], s["wall_height"], 0.0)
        else:
            h["wall"] = np.zeros_like(phi)
        return h

    def facts(self) -> dict:
        return {"scenery": "procedural"}

    def shade(self, directions: np.ndarray, sky: Sky) -> tuple[np.ndarray, np.ndarray]:
        """Distant scenery seen beyond the garden: (mask (N,), linear rgb (N, 3)).

        Layers, nearest first: an optional wall/fence, a tree line, hills and
        the distant ground (every direction below the horizon). A pure
        function of direction, seeded by the garden seed; lit by this sky
        (ambient + sun, with aerial haze toward the horizon sky colour).
        """
        d = unit_vectors(directions)
        N = len(d)
        elev = np.arcsin(np.clip(d[:, 2], -1.0, 1.0))
        dxy = d[:, :2]
        rxy = np.maximum(np.hypot(dxy[:, 0], dxy[:, 1]), 1e-9)
        phi = np.arctan2(dxy[:, 1], dxy[:, 0])
        mask = elev < 0.0
        rgb = np.zeros((N, 3))
        # Only directions near the horizon can be covered by a silhouette.
        cand = np.nonzero(elev < math.radians(12.0))[0]
        if len(cand) == 0:
            return mask, rgb
        s = self._scn
        ph, el = phi[cand], elev[cand]
        h = self._silhouettes(ph)
        layer = np.zeros(len(cand), dtype=np.int64)  # 0 none, 1 ground, 2 hills, 3 trees, 4 wall
        layer[el < 0.0] = 1
        # Each layer covers [base, top]: its foot is below the horizon by the eye height.
        for code, name, dist_key in ((2, "hills", "hill_dist"), (3, "trees", "tree_dist"), (4, "wall", "wall_dist")):
            base = -math.atan(SCENERY_EYE_HEIGHT / s[dist_key])
            layer[(h[name] > 1e-5) & (el < h[name]) & (el >= base)] = code
        covered = layer > 0
        mask[cand] = covered
        idx = np.nonzero(covered)[0]
        if len(idx) == 0:
            return mask, rgb
        ph, el, layer = ph[idx], el[idx], layer[idx]
        toward = -np.stack([dxy[cand[idx], 0], dxy[cand[idx], 1]], -1) / rxy[cand[idx], None]  # facing the viewer
        z = np.zeros((len(idx), 1))

        def facing(up: float) -> np.ndarray:
            return unit_vectors(np.concatenate([toward, z + up], axis=1))

        normal = np.empty((len(idx), 3))
        albedo = np.empty((len(idx), 3))
        dist = np.empty(len(idx))
        sun_w = np.empty(len(idx))
        sel = {k: layer == v for k, v in (("ground", 1), ("hills", 2), ("trees", 3), ("wall", 4))}
        tex = 0.6 + 0.8 * (0.5 + 0.5 * self._circle_noise(ph, 120.0, 300.0, 3, elev=el * 120.0))
        normal[:] = (0.0, 0.0, 1.0)  # distant ground
        for k, up in (("hills", 2.5), ("trees", 0.6), ("wall", 0.0)):
            if np.any(sel[k]):
                normal[sel[k]] = facing(up)[sel[k]]
        ns = np.clip(normal @ sky.sun_direction, 0.0, None)
        sun_w[:] = ns
        if np.any(sel["trees"]):
            m = sel["trees"]
            albedo[m] = s["tree_albedo"] * tex[m, None]
            dist[m] = s["tree_dist"]
            sun_w[m] = 0.25 + 0.75 * ns[m]  # foliage: wrapped, translucent-ish
        if np.any(sel["hills"]):
            m = sel["hills"]
            albedo[m] = s["hill_albedo"] * (0.85 + 0.3 * (tex[m, None] - 1.0))
            dist[m] = s["hill_dist"]
        if np.any(sel["wall"]):
            m = sel["wall"]
            albedo[m] = s["wall_albedo"] * (0.9 + 0.2 * (tex[m, None] - 1.0))
            dist[m] = s["wall_dist"]
        if np.any(sel["ground"]):
            m = sel["ground"]
            albedo[m] = s["field_albedo"] * (0.85 + 0.3 * (tex[m, None] - 1.0))
            dist[m] = np.minimum(SCENERY_EYE_HEIGHT / np.tan(np.maximum(-el[m], 1e-4)), 5000.0)
        sun = sky.sun_irradiance * sky.mean_sun_transmittance
        irr = sky.ambient_irradiance(normal) + sun_w[:, None] * sun[None, :]
        lit = albedo * irr / math.pi
        # Aerial perspective toward the sky colour just above the horizon at that azimuth.
        hz = unit_vectors(np.concatenate([-toward, z + math.tan(math.radians(1.5))], axis=1))
        haze = sky.upper_radiance(hz, 0.0)
        t = np.exp(-(dist / 1000.0) / self._vis_km)[:, None]
        rgb[cand[idx]] = lit * t + haze * (1.0 - t)
        return mask, rgb


class NoScenery:
    """No scenery: the sky (or the environment map) is the background everywhere."""

    def facts(self) -> dict:
        return {"scenery": "none"}

    def shade(self, directions: np.ndarray, sky) -> tuple[np.ndarray, np.ndarray]:
        n = len(np.asarray(directions).reshape(-1, 3))
        return np.zeros(n, bool), np.zeros((n, 3))


class PanoramaScenery:
    """A user's equirectangular panorama as distant background (see the module docstring)."""

    def __init__(self, path: str, rotation: float = 0.0):
        from eden_pipe.io.hdr import file_sha256, read_panorama

        image = read_panorama(path)
        self.path, self.sha256 = str(path), file_sha256(path)
        self.has_alpha = image.shape[2] == 4
        self._panorama = Panorama(image, rotation)

    def facts(self) -> dict:
        return {"scenery": {"path": self.path, "sha256": self.sha256, "alpha": self.has_alpha}}

    def shade(self, directions: np.ndarray, sky) -> tuple[np.ndarray, np.ndarray]:
        d = unit_vectors(directions)
        values = self._panorama.lookup(d)
        mask = values[:, 3] > 0.5 if self.has_alpha else d[:, 2] < 0.0
        rgb = values[:, :3].astype(np.float64) * (np.asarray(sky.horizontal_irradiance) / math.pi)[None, :]
        return mask, np.where(mask[:, None], rgb, 0.0)


def make_scenery(params, seed: int, environment: bool):
    """The scenery ``params.scenery`` asks for; unset: procedural, or none under an HDR environment."""
    choice = params.scenery
    if choice is None:
        choice = "none" if environment else "procedural"
    if choice == "none":
        return NoScenery()
    if choice == "procedural":
        return Scenery(seed, params.turbidity)
    return PanoramaScenery(choice, params.environment_rotation)
