"""The paper's image formation, per pixel in linear RGB (DESIGN section 4):

    I = Dcol*(Ddir + Dind) + Gcol*(Gdir + Gind) + Tcol*(Tdir + Tind) + B + E

- Dcol: face albedo; Ddir: sun (disc-sampled visibility, cloud shadows) and
  Dind: one-bounce path-traced indirect light (sky and lit surfaces), or the
  sky's unoccluded ambient irradiance when ``indirect_samples`` is 0;
- G: glossy sun highlight and mirrored sky for specular faces (wet grass,
  pavement, waxy leaves);
- T: light transmitted through thin translucent faces lit from behind;
- B: sky (and distant scenery) seen directly; E: emission (none in gardens).
Shading values are irradiance/pi, so a white Lambertian surface has radiance
``shading``. All sampling is driven by the generator passed in, so images are
reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe.render.raytrace import Hits, RayTracer
from eden_pipe.render.textures import apply_terrain_textures

EPS = 1e-3
GLOSS_EXPONENT = 60.0


class EnvironmentMap:
    """The sky's radiance at one time, tabulated on a latitude-longitude grid.

    Glossy reflections and indirect rays that escape to the sky look it up
    (nearest texel) instead of evaluating the sky model per pixel; pixels that see
    the sky directly (B) still evaluate it exactly. 512 x 256 is 0.7 deg per
    texel, finer than the blur of a glossy lobe or a cosine-weighted bounce.
    """

    def __init__(self, sky, time: float = 0.0, width: int = 512, height: int = 256):
        self.width, self.height = width, height
        phi = (np.arange(width) + 0.5) / width * 2.0 * np.pi - np.pi
        theta = (np.arange(height) + 0.5) / height * np.pi  # from the zenith
        t, p = np.meshgrid(theta, phi, indexing="ij")
        dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
        self.table = np.asarray(sky.radiance(dirs, time), dtype=np.float32)

    def radiance(self, directions: np.ndarray) -> np.ndarray:
        """Nearest-texel lookup: one gather per direction (bilinear cost 4x for no visible gain)."""
        d = np.asarray(directions, dtype=np.float32)
        length = np.linalg.norm(d, axis=1)
        i = (np.arccos(np.clip(d[:, 2] / length, -1.0, 1.0)) * np.float32(self.height / np.pi)).astype(np.int64)
        j = ((np.arctan2(d[:, 1], d[:, 0]) + np.float32(np.pi)) * np.float32(self.width / (2 * np.pi))).astype(np.int64)
        return self.table[np.minimum(i, self.height - 1) * self.width + np.minimum(j, self.width - 1)]


@dataclass
class ShadingSettings:
    indirect_samples: int = 0
    soft_shadow_samples: int = 1
    time: float = 0.0
    environment: EnvironmentMap | None = None  # the sky at ``time`` for glossy and indirect lookups

    def sky_radiance(self, sky, directions: np.ndarray) -> np.ndarray:
        if self.environment is not None:
            return self.environment.radiance(directions)
        return sky.radiance(directions, self.time)


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """DESIGN section 4 transfer, clipped to [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def srgb_to_uint8(linear: np.ndarray) -> np.ndarray:
    return np.round(linear_to_srgb(linear) * 255.0).astype(np.uint8)


def _orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t = np.cross(n, helper)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def cosine_hemisphere(n: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One cosine-distributed direction about each unit normal."""
    u1, u2 = rng.random(len(n)), rng.random(len(n))
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    t, b = _orthonormal_basis(n)
    return t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None] + n * np.sqrt(np.maximum(0.0, 1.0 - u1))[:, None]


def sun_directions(sky, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, N?) directions toward uniformly sampled points of the sun disc."""
    l = np.asarray(sky.sun_direction, dtype=np.float64)
    if count <= 1 or sky.sun_angular_radius <= 0:
        return l[None, :]
    t, b = _orthonormal_basis(l[None, :])
    r = np.tan(sky.sun_angular_radius) * np.sqrt(rng.random(count))
    phi = 2.0 * np.pi * rng.random(count)
    d = l[None] + t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def direct_sun(tracer: RayTracer, points: np.ndarray, normals: np.ndarray, sky, settings: ShadingSettings,
               rng: np.random.Generator, geometric: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Sun irradiance/pi on the front (n.l > 0) and back (n.l < 0) of each point, shadows included.

    ``normals`` are shading normals (bumped); shadow rays leave along the
    ``geometric`` normals (default: the same). Returns (front, back) as
    (N, 3); ``back`` lights thin translucent faces.
    """
    geometric = normals if geometric is None else geometric
    n = len(points)
    front = np.zeros((n, 3), np.float32)
    back = np.zeros((n, 3), np.float32)
    sun = np.asarray(sky.sun_irradiance, dtype=np.float32)
    if n == 0 or not np.any(sun > 0):
        return front, back
    dirs = sun_directions(sky, settings.soft_shadow_samples, rng)
    cloud = sky.cloud_transmittance(points, settings.time)
    weight = np.zeros(n, np.float32)
    back_weight = np.zeros(n, np.float32)
    for l in dirs.astype(np.float32):
        cos = normals @ l
        lit = np.abs(cos) > 1e-6
        idx = np.nonzero(lit)[0]
        if len(idx) == 0:
            continue
        side = np.sign(cos[idx])[:, None]
        origins = points[idx] + geometric[idx] * side * EPS
        blocked = tracer.occluded(origins, np.broadcast_to(l, (len(idx), 3)))
        vis = (~blocked).astype(np.float32) * np.abs(cos[idx])
        weight[idx] += np.where(cos[idx] > 0, vis, 0.0)
        back_weight[idx] += np.where(cos[idx] < 0, vis, 0.0)
    scale = (cloud / (np.pi * len(dirs))).astype(np.float32)
    return (weight * scale)[:, None] * sun, (back_weight * scale)[:, None] * sun


def sky_and_background(sky, directions: np.ndarray, time: float = 0.0) -> np.ndarray:
    """Radiance seen along rays that leave the scene: sky, distant scenery, sun disc."""
    d = directions / np.linalg.norm(directions, axis=1, keepdims=True)
    radiance = sky.radiance(d, time)
    mask, scenery_rgb = sky.scenery(d)
    radiance = np.where(mask[:, None], scenery_rgb, radiance)
    sun = np.asarray(sky.sun_irradiance, dtype=np.float64)
    if np.any(sun > 0) and sky.sun_angular_radius > 0:
        in_disc = (d @ np.asarray(sky.sun_direction)) > np.cos(sky.sun_angular_radius)
        solid_angle = np.pi * sky.sun_angular_radius**2
        radiance = np.where((in_disc & ~mask)[:, None], radiance + sun / solid_angle, radiance)
    return radiance


def shade(tracer: RayTracer, mesh, hits: Hits, origins: np.ndarray, directions: np.ndarray, sky,
          settings: ShadingSettings, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """All linear layers for a batch of primary rays (N rays -> (N, 3) arrays)."""
    n_rays = len(origins)
    # float32 throughout: half the memory traffic of float64, far below the noise of any layer.
    layers = {k: np.zeros((n_rays, 3), np.float32) for k in ("albedo", "shading", "glossy", "translucency", "background")}
    hit = hits.hit
    miss = ~hit
    if np.any(miss):
        layers["background"][miss] = sky_and_background(sky, directions[miss], settings.time)
    idx = np.nonzero(hit)[0]
    if len(idx) == 0:
        return _compose(layers)
    prim = hits.prim[idx]
    dirs_hit = directions[idx].astype(np.float32)
    d = dirs_hit / np.linalg.norm(dirs_hit, axis=1, keepdims=True)
    points = origins[idx].astype(np.float32) + dirs_hit * hits.t[idx, None]
    # Faces are two-sided: shade the side that faces the viewer.
    n = hits.normal[idx]
    n = np.where((np.einsum("ij,ij->i", n, d) > 0)[:, None], -n, n)
    trans = mesh.translucency[prim][:, None]
    spec = mesh.specular[prim][:, None]
    albedo, n_shade = apply_terrain_textures(mesh.material[prim], points, mesh.albedo[prim], n)

    front, back = direct_sun(tracer, points, n_shade, sky, settings, rng, geometric=n)
    indirect_front = indirect(tracer, mesh, points, n, sky, settings, rng)
    has_trans = trans[:, 0] > 0
    indirect_back = np.zeros_like(indirect_front)
    if np.any(has_trans):
        t_idx = np.nonzero(has_trans)[0]
        indirect_back[t_idx] = indirect(tracer, mesh, points[t_idx], -n[t_idx], sky, settings, rng)

    layers["albedo"][idx] = albedo
    layers["shading"][idx] = front + indirect_front
    layers["translucency"][idx] = albedo * trans * (back + indirect_back)
    if np.any(spec > 0):
        g_idx = np.nonzero(spec[:, 0] > 0)[0]
        layers["glossy"][idx[g_idx]] = spec[g_idx] * glossy(n_shade[g_idx], d[g_idx], front[g_idx], sky, settings)
    return _compose(layers)


def indirect(tracer: RayTracer, mesh, points: np.ndarray, normals: np.ndarray, sky, settings: ShadingSettings,
             rng: np.random.Generator) -> np.ndarray:
    """Dind: irradiance/pi from everything but the sun, one bounce."""
    if settings.indirect_samples <= 0:
        return sky.ambient_irradiance(normals) / np.pi
    total = np.zeros((len(points), 3))
    origins = points + normals * EPS
    for _ in range(settings.indirect_samples):
        dirs = cosine_hemisphere(normals, rng)
        hits = tracer.intersect(origins, dirs)
        miss = ~hits.hit
        radiance = np.zeros((len(points), 3))
        if np.any(miss):
            radiance[miss] = settings.sky_radiance(sky, dirs[miss])
        h = np.nonzero(hits.hit)[0]
        if len(h):
            p2 = origins[h] + dirs[h] * hits.t[h, None]
            n2 = hits.normal[h].astype(np.float64)
            n2 = np.where((np.sum(n2 * dirs[h], axis=1) > 0)[:, None], -n2, n2)
            f2, _ = direct_sun(tracer, p2, n2, sky, ShadingSettings(time=settings.time, environment=settings.environment), rng)
            # Light arriving at the secondary point beyond one bounce: unoccluded sky, dimmed.
            ambient2 = 0.5 * sky.ambient_irradiance(n2) / np.pi
            radiance[h] = mesh.albedo[hits.prim[h]] * (f2 + ambient2)
        # Cosine-weighted sampling: E/pi is estimated by the mean radiance.
        total += radiance
    return total / settings.indirect_samples


def glossy(n: np.ndarray, d: np.ndarray, front_sun: np.ndarray, sky, settings: ShadingSettings) -> np.ndarray:
    """Gdir + Gind per unit specular colour (F0 = 1): a normalised Blinn-Phong sun lobe and the mirrored sky."""
    l = np.asarray(sky.sun_direction, dtype=np.float64)
    h = l[None] - d
    h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
    lobe = (GLOSS_EXPONENT + 8.0) / 8.0 * np.maximum(0.0, np.sum(n * h, axis=1)) ** GLOSS_EXPONENT
    g_dir = front_sun * lobe[:, None]
    r = d - 2.0 * np.sum(d * n, axis=1, keepdims=True) * n
    cos_view = np.clip(-np.sum(d * n, axis=1), 0.0, 1.0)
    fresnel = 0.04 + 0.96 * (1.0 - cos_view) ** 5
    # Mirrored sky, dimmed where the point is in shadow: a shadowed point mostly sits under
    # a canopy or beside an object that also hides the sky it would mirror. (An occlusion ray
    # per glossy pixel cost ~15% of the frame for an effect one bounce of noise would hide.)
    open_sky = np.where(np.any(front_sun > 0, axis=1) | ~np.any(np.asarray(sky.sun_irradiance) > 0), 1.0, 0.3)
    g_ind = settings.sky_radiance(sky, r) * (np.minimum(fresnel / 0.04, 2.0) * open_sky)[:, None]
    return g_dir + g_ind


def _compose(layers: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    layers["linear"] = layers["albedo"] * layers["shading"] + layers["glossy"] + layers["translucency"] + layers["background"]
    return layers
