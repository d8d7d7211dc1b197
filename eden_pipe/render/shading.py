"""The paper's image formation, per pixel in linear RGB (docs/design.md, Image formation):

    I = Dcol*(Ddir + Dind) + Gcol*(Gdir + Gind) + Tcol*(Tdir + Tind) + B + E

- Dcol: face albedo; Ddir: sun (disc-sampled visibility, cloud shadows) and
  Dind: with ``indirect_samples`` 0, the garden's baked sky visibility and
  bounce (:mod:`eden_pipe.render.visibility`, ``BakedIndirect``) or, without a
  bake, the sky's unoccluded ambient irradiance; else one-bounce path-traced
  indirect light (sky and lit surfaces);
- G: glossy sun highlight and the light along the mirror direction for
  specular faces (wet grass, pavement, waxy leaves): with the bake, the sky
  where the mirror escapes, the light of what hides the sky where not, decided
  by the bake's visibility along it and an any-hit ray where that is unsure
  (``glossy_mirror`` predicted), or by an any-hit ray for every pixel (any_hit),
  or a closest-hit ray (traced);
- T: light transmitted through thin translucent faces lit from behind;
- B: sky (and distant scenery) seen directly; E: emission (none in gardens).
Shading values are irradiance/pi, so a white Lambertian surface has radiance
``shading``. All sampling is driven by the generator passed in, so images are
reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from eden_pipe import modalities
from eden_pipe.colour import linear_to_srgb, srgb_to_uint8  # noqa: F401  (re-exported for callers)
from eden_pipe.config import RenderConfig
from eden_pipe.config.schema import GLOSSY_MIRRORS  # noqa: F401  (re-exported for callers)
from eden_pipe.render import kernels, lut, sh, vec
from eden_pipe.render.baked_light import (  # noqa: F401  (moved; callers import them from here)
    EPS,
    SHARE_BLOCK,
    SHARE_COS,
    BakedIndirect,
    largest_share,
)
from eden_pipe.render.embree import Hits, RayTracer
from eden_pipe.render.offsets import leave
from eden_pipe.render.pixel_sky import (
    Penumbrae,
    paired_sun_rays,
    sun_disc_directions,
    sun_disc_rays,
    sun_ray_origins,
)
from eden_pipe.render.textures import apply_terrain_textures

if TYPE_CHECKING:
    from eden_pipe.render.pixel_sky import PairSky
    from eden_pipe.render.sky.clouds import CloudShadowMap
    from eden_pipe.render.visibility.frame_light import FrameLight, FrameLights
    from eden_pipe.render.visibility.store import SkyVisibility

# The glossy sun lobe's Beckmann roughness (alpha; Blender's roughness is its square root): as wide as the
# normalised Blinn-Phong lobe of exponent 60 the renderers used before (alpha = sqrt(2 / (60 + 2)), Walter et
# al. 2007), now Cycles' own microfacet lobe (docs/design.md, Image formation; docs/realism.md, Cycles).
GLOSS_ALPHA = (2.0 / 62.0) ** 0.5


class EnvironmentMap:
    """The sky's radiance at one time, tabulated on a latitude-longitude grid.

    Glossy reflections and indirect rays that escape to the sky look it up
    (bilinear) instead of evaluating the sky model per pixel; pixels that see
    the sky directly (B) still evaluate it exactly. 512 x 256 is 0.7 deg per
    texel, finer than the blur of a glossy lobe or a cosine-weighted bounce.
    """

    def __init__(self, sky, time: float = 0.0, width: int = 512, height: int = 256):
        self.width, self.height = width, height
        phi = (np.arange(width) + 0.5) / width * 2.0 * np.pi - np.pi
        theta = (np.arange(height) + 0.5) / height * np.pi  # from the zenith
        t, p = np.meshgrid(theta, phi, indexing="ij")
        dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
        self.table = lut.wrap_columns(np.asarray(sky.radiance(dirs, time), np.float32).reshape(height, width, 3))

    def sh(self) -> np.ndarray:
        """(16, 3) float32 SH coefficients of the radiance (computed once per map)."""
        if getattr(self, "_sh", None) is None:
            self._sh = sh.project_latlong(self.table[:, : self.width]).astype(np.float32)
        return self._sh

    def radiance(self, directions: np.ndarray) -> np.ndarray:
        """(N, 3) directions of any length -> (N, 3) float32 radiance."""
        d = np.asarray(directions, dtype=np.float32)
        length = vec.length(d)
        rows = np.arccos(np.clip(d[:, 2] / length, -1.0, 1.0)) * np.float32(self.height / np.pi) - np.float32(0.5)
        cols = lut.periodic(
            (np.arctan2(d[:, 1], d[:, 0]) + np.float32(np.pi)) * np.float32(self.width / (2 * np.pi)) - np.float32(0.5),
            self.width,
        )
        return lut.sample(self.table, cols, rows)


RENDER_DEFAULTS = RenderConfig()  # the render.* keys' defaults: one source, config.schema
# The right camera takes the left's sun answers where the left pixel's same-face window of this
# radius agreed; chosen on the tuning views (docs/scale-out.md, the right view's shadow answers).
HARD_SHARE_RADIUS = 2


@dataclass
class ShadingSettings:
    indirect_samples: int = RENDER_DEFAULTS.indirect_samples
    soft_shadow_samples: int = RENDER_DEFAULTS.soft_shadow_samples
    soft_shadow_radius: int = RENDER_DEFAULTS.soft_shadow_radius  # one disc ray a pixel, pooled this far
    time: float = 0.0
    environment: EnvironmentMap | None = None  # the sky at ``time`` for glossy and indirect lookups
    clouds: CloudShadowMap | None = None  # at ``time``: tabulated cloud shadows
    mode: str = RENDER_DEFAULTS.mode  # or "reference": path traced (eden_pipe.render.pathtrace)
    reference_samples: int = RENDER_DEFAULTS.reference_samples
    reference_bounces: int = RENDER_DEFAULTS.reference_bounces
    sky_visibility: SkyVisibility | None = None  # the garden's bake: Dind from it (indirect_samples 0)
    glossy_mirror: str = RENDER_DEFAULTS.glossy_mirror  # with the bake: one of GLOSSY_MIRRORS
    mirror_rays: float = RENDER_DEFAULTS.mirror_rays  # with glossy_mirror predicted: the share of upward hits tested
    pixel_sky_rays: int = RENDER_DEFAULTS.pixel_sky_rays  # with the bake: rays a pixel for its own visible sky
    pixel_sky_radius: int = RENDER_DEFAULTS.pixel_sky_radius  # ... pooled over this many pixels around it

    baked_frame: FrameLight | None = None  # the bake's light of this frame, made on first use
    frame_lights: FrameLights | None = None  # a job's frame lights: frames under one sky share one

    def sky_sh(self, sky) -> np.ndarray:
        """(16, 3) SH radiance of the sky at ``time`` (the environment map's, else tabulated now)."""
        if self.environment is None:
            self.environment = EnvironmentMap(sky, self.time)
        return self.environment.sh()

    def baked_light(self, sky):
        """The bake's per-probe light under this frame's sky and sun (a
        ``visibility.frame_light.FrameLight``: rows made as the frame's views need them, shared by its
        views, and with ``frame_lights`` by the job's frames under exactly the same sky and sun)."""
        vis = self.sky_visibility
        own_sun = self.glossy_mirror == "traced"  # the light of the surfaces traced mirror rays meet
        light = self.baked_frame
        if light is None or light.vis is not vis or light.own_sun != own_sun:
            args = (
                self.sky_sh(sky),
                sh.basis(np.asarray(sky.sun_direction, np.float32)[None])[0],
                np.asarray(sky.sun_irradiance, np.float32),
            )
            light = (
                vis.frame_light(*args, own_sun=own_sun)
                if self.frame_lights is None
                else self.frame_lights.get(vis, *args, own_sun=own_sun)
            )
            self.baked_frame = light
        return light

    def cloud_transmittance(self, sky, points: np.ndarray) -> np.ndarray:
        if self.clouds is not None:
            return self.clouds.transmittance(points)
        return sky.cloud_transmittance(points, self.time)

    def sky_radiance(self, sky, directions: np.ndarray) -> np.ndarray:
        if self.environment is not None:
            return self.environment.radiance(directions)
        return sky.radiance(directions, self.time)


def cosine_hemisphere(n: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """One cosine-distributed direction about each unit normal."""
    u1, u2 = rng.random(len(n)), rng.random(len(n))
    r, phi = np.sqrt(u1), 2.0 * np.pi * u2
    t, b = vec.orthonormal_basis(n)
    return (
        t * (r * np.cos(phi))[:, None]
        + b * (r * np.sin(phi))[:, None]
        + n * np.sqrt(np.maximum(0.0, 1.0 - u1))[:, None]
    )


def sun_directions(sky, count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, N?) directions toward uniformly sampled points of the sun disc."""
    axis = np.asarray(sky.sun_direction, dtype=np.float64)
    if count <= 1 or sky.sun_angular_radius <= 0:
        return axis[None, :]
    t, b = vec.orthonormal_basis(axis[None, :])
    r = np.tan(sky.sun_angular_radius) * np.sqrt(rng.random(count))
    phi = 2.0 * np.pi * rng.random(count)
    d = axis[None] + t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None]
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def direct_sun(
    tracer: RayTracer,
    points: np.ndarray,
    normals: np.ndarray,
    sky,
    settings: ShadingSettings,
    rng: np.random.Generator,
    geometric: np.ndarray | None = None,
    back_lit: np.ndarray | None = None,
    cloud: np.ndarray | None = None,
    visible=None,
    image: tuple[np.ndarray, tuple[int, int], np.ndarray, np.ndarray] | None = None,
    pair: PairSky | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Sun irradiance/pi on the front (n.l > 0) and back (n.l < 0) of each point, shadows included.

    ``normals`` are shading normals (bumped); shadow rays leave along the
    ``geometric`` normals (default: the same). Returns (front, back) as
    (N, 3) float32; ``back`` lights thin translucent faces, so it is only
    traced where ``back_lit`` (N,) is true (default: everywhere) and is zero
    elsewhere: an opaque face turned away from the sun needs no shadow ray. ``cloud`` (N,): the
    points' cloud transmittance where the caller has it already (default: tabulated here).
    ``visible(idx, sign, to_sun) -> bool``: the reference's own shadow test (``pathtrace``: its own
    face skipped too); default: an any-hit ray leaving the geometric normal's ``sign`` side by
    ``offsets.leave`` (not ``EPS``: a millimetre stepped over blades and boards closer than that).
    The shadow rays share one direction per sample, so the tracer sends them as coherent packets
    of neighbouring rays (``embree_kernels.plane_order``).

    ``image`` (:func:`sun_image`: the points' row-major pixels, the image's shape, their faces and
    footprints): with ``soft_shadow_radius`` > 0 (and one sample), each point traces one ray to its
    pixel's stratum of the sun's disc, and the share of the disc it sees is the mean over the
    pixels on its face side within its penumbra (:func:`_pooled_disc`; docs/realism.md, "The
    sun's penumbra from one ray a pixel"). ``pair``: the other camera's shares to take where it saw
    the same face side lit (``sun_partner``), and where this view's are recorded (``sun_estimated``).
    """
    points = np.asarray(points, np.float32)
    normals = np.asarray(normals, np.float32)
    geometric = normals if geometric is None else np.asarray(geometric, np.float32)
    n = len(points)
    sun = np.asarray(sky.sun_irradiance, dtype=np.float32)
    if n == 0 or not np.any(sun > 0):
        return np.zeros((n, 3), np.float32), np.zeros((n, 3), np.float32)
    if cloud is None:
        cloud = settings.cloud_transmittance(sky, points)
    if (
        image is not None
        and visible is None
        and settings.soft_shadow_radius > 0
        and settings.soft_shadow_samples == 1
        and sky.sun_angular_radius > 0
    ):
        return _pooled_disc(tracer, points, normals, geometric, sky, settings, back_lit, cloud, image, sun, pair)
    dirs = sun_directions(sky, settings.soft_shadow_samples, rng)
    weight = np.zeros(n, np.float32)
    back_weight = np.zeros(n, np.float32)
    for to_sun in dirs.astype(np.float32):
        cos = normals @ to_sun
        idx = np.nonzero(_sun_lit(cos, back_lit))[0]
        if len(idx) == 0:
            continue
        c = cos[idx]
        if visible is None and pair is not None and image is not None and len(dirs) == 1:
            seen = paired_sun_rays(tracer, points, geometric, idx, c, to_sun, image, pair, HARD_SHARE_RADIUS)
        elif visible is None:
            seen = ~tracer.occluded(sun_ray_origins(points, geometric, idx, c), to_sun[None, :])
        else:
            seen = visible(idx, np.sign(c), to_sun)
        kernels.add_sun_fractions(weight, back_weight, idx, c, seen.astype(np.float32))
    return kernels.sun_light(weight, back_weight, cloud, np.pi * len(dirs), sun)


def _sun_lit(cos: np.ndarray, back_lit: np.ndarray | None) -> np.ndarray:
    """(N,) bool: the points whose shadow rays the sun needs: n.l > 0, or n.l < 0 where ``back_lit``
    (default: everywhere; thin translucent faces lit through)."""
    lit = cos > 1e-6
    lit |= (cos < -1e-6) if back_lit is None else (cos < -1e-6) & back_lit
    return lit


def sun_image(s: Surface, hits: Hits, directions: np.ndarray, n_rays: int, width: int):
    """:func:`direct_sun`'s ``image`` for the hits ``s`` of an image's row-major rays: their pixels,
    the image's shape, their faces and the metres a pixel spans at each (its distance times the
    angle between the two middle pixels of the middle row)."""
    middle = (n_rays // width // 2) * width + width // 2 - 1
    d = np.asarray(directions[middle : middle + 2], np.float64)
    angle = float(np.arccos(np.clip(d[0] @ d[1] / np.linalg.norm(d[0]) / np.linalg.norm(d[1]), -1.0, 1.0)))
    return s.idx, (n_rays // width, width), s.prim, vec.take(hits.t, s.idx) * angle


def _pooled_disc(tracer, points, normals, geometric, sky, settings, back_lit, cloud, image, sun, pair):
    """:func:`direct_sun` with soft shadows from one ray a pixel: the rays of each SUN_BLOCK x
    SUN_BLOCK block of pixels go to the disc's SUN_BLOCK**2 strata, and a pixel's visible share of
    the disc is the mean of the rays of the pixels on its face side within its penumbra's
    half-width, at most ``soft_shadow_radius`` (``pixel_sky.Penumbrae``). The disc's centre
    decides where no neighbour's ray can help: a pixel alone on its face side within the radius
    traces it instead of a stratum (``pixel_sky.sun_disc_rays``), and one whose penumbra is under a
    pixel traces it after (the hard shadow's answer there). Where the pair's other
    camera offers a share for the same face side lit (``pair.sun_partner``), it is taken instead of
    a ray; this view offers those of its pixels whose windows' rays all agreed (``sun_estimated``)."""
    pixels, shape, faces, footprint = image
    axis = np.asarray(sky.sun_direction, np.float32)
    cos = normals @ axis  # the disc's centre weighs the cosine; the rays only decide visibility
    idx = np.nonzero(_sun_lit(cos, back_lit))[0]
    c = cos[idx]
    at = vec.take(pixels, idx)
    sides = vec.take(faces, idx).astype(np.int64) * 2 + (c < 0)
    share = np.empty(len(idx), np.float32)
    own = np.arange(len(idx))
    if pair is not None and pair.sun_partner is not None:
        # A shadow ray leaves the sun's side of the face, so the share is the point's whichever
        # camera sees it; the other view's nearest pixel stands for it, as for the own sky.
        shared = pair.sun_partner.lookup(vec.gather(points, idx), sides)
        taken = np.isfinite(shared)
        share[taken] = shared[taken]
        own = np.flatnonzero(~taken)
    if len(own):
        at_own, c_own, sides_own = vec.take(at, own), vec.take(c, own), vec.take(sides, own)
        i_own = vec.take(idx, own)
        dirs = sun_disc_directions(sky.sun_direction, sky.sun_angular_radius).astype(np.float32)
        origins = leave(
            vec.gather(points, i_own), vec.gather(geometric, i_own) * np.sign(c_own)[:, None], np.zeros(len(own))
        )
        # The disc's directions lie within its radius of the axis, so the rays go out packed as one
        # direction's would. Occlusion rays first; the blockers' distances, which set a penumbra's
        # width, only where a pixel's window saw the sun from some rays and not others.
        dirs = np.concatenate([dirs, axis[None, :]])  # row DISC_CENTRE: for pixels alone on their face side
        to_sun = vec.take(dirs, sun_disc_rays(at_own, shape, sides_own, settings.soft_shadow_radius))
        seen = ~tracer.occluded(origins, to_sun, along=axis)
        penumbrae = Penumbrae.of(at_own, shape, sides_own, seen, settings.soft_shadow_radius)
        blocker = np.zeros(len(own), np.float32)
        far = penumbrae.far
        if len(far):
            met = tracer.intersect(vec.gather(origins, far), vec.gather(to_sun, far), settle_ties=False, along=axis)
            blocker[far] = np.where(met.hit, met.t, 0.0)  # the same rays: a miss here would be Embree's edge case
        share[own] = penumbrae.fraction(blocker, vec.take(footprint, i_own), float(np.tan(sky.sun_angular_radius)))
        sharp = np.flatnonzero(np.isnan(share[own]))  # penumbrae under a pixel: the disc's centre decides
        if len(sharp):
            share[vec.take(own, sharp)] = ~tracer.occluded(vec.gather(origins, sharp), axis[None, :])
        if pair is not None:
            # Only shares of 0 or 1 whose neighbours agree: the same half a pixel away, where a
            # penumbra's would move with the pixel grid (docs/realism.md, The sun's penumbra).
            agreed = ~penumbrae.mixed
            pair.sun_estimated = (at_own[agreed], sides_own[agreed], share[own][agreed])
    weight, back_weight = np.zeros(len(points), np.float32), np.zeros(len(points), np.float32)
    kernels.add_sun_fractions(weight, back_weight, idx, c, share)
    return kernels.sun_light(weight, back_weight, cloud, np.pi, sun)


def sky_and_background(sky, directions: np.ndarray, time: float = 0.0) -> np.ndarray:
    """Radiance seen along rays that leave the scene: sky, distant scenery, sun disc."""
    d = vec.normalize(np.asarray(directions))
    radiance = sky.radiance(d, time)
    mask, scenery_rgb = sky.scenery(d)
    radiance = np.where(mask[:, None], scenery_rgb, radiance)
    sun = np.asarray(sky.sun_irradiance, dtype=np.float64)
    if np.any(sun > 0) and sky.sun_angular_radius > 0:
        in_disc = (d @ np.asarray(sky.sun_direction)) > np.cos(sky.sun_angular_radius)
        solid_angle = np.pi * sky.sun_angular_radius**2
        radiance = np.where((in_disc & ~mask)[:, None], radiance + sun / solid_angle, radiance)
    return radiance


# The image formation's layers come from the modality table (their role there); background is the light of
# the rays that miss, every other layer a term of the surface hit.
LAYERS = modalities.shading_passes()
SURFACE_LAYERS = tuple(k for k in LAYERS if k != "background")


@dataclass
class Surface:
    """The primary hits of a batch of rays, ready to light (every array has one row per hit)."""

    idx: np.ndarray  # (H,) indices of the rays that hit
    prim: np.ndarray  # (H,) face ids
    d: np.ndarray  # (H, 3) unit view directions
    points: np.ndarray  # (H, 3) hit points
    n: np.ndarray  # (H, 3) geometric normals facing the viewer (faces are two-sided)
    n_shade: np.ndarray  # (H, 3) shading normals (terrain textures bump them)
    albedo: np.ndarray  # (H, 3) Dcol, textured
    trans: np.ndarray  # (H,) translucency
    spec: np.ndarray  # (H,) specular colour
    back_side: np.ndarray  # (H,) bool: the viewer is behind the winding's normal (Embree's Ng), on side 1


def primary_surface(mesh, hits: Hits, origins: np.ndarray, directions: np.ndarray) -> Surface:
    idx = np.nonzero(hits.hit)[0]  # may be empty: every step below takes empty arrays
    prim = hits.prim[idx]
    d, points, n, back_side = kernels.primary_hits(idx, origins, directions, hits.t, hits.normal)
    albedo, n_shade = apply_terrain_textures(vec.take(mesh.material, prim), points, vec.gather(mesh.albedo, prim), n)
    return Surface(
        idx,
        prim,
        d,
        points,
        n,
        n_shade,
        albedo,
        vec.take(mesh.translucency, prim),
        vec.take(mesh.specular, prim),
        back_side,
    )


def background_of(sky, directions: np.ndarray, hit: np.ndarray, time: float) -> np.ndarray:
    """B: (N, 3) radiance of the rays that leave the scene, zero on hits."""
    n_rays = len(directions)
    miss = np.nonzero(~hit)[0]
    if not len(miss):
        return np.zeros((n_rays, 3), np.float32)
    sky_rgb = sky_and_background(sky, vec.gather(directions, miss), time).astype(np.float32)
    return vec.Scatter(miss, n_rays).expand(sky_rgb)


def compose(
    n_rays: int,
    surface: Surface,
    background: np.ndarray,
    shading: np.ndarray,
    back: np.ndarray,
    gloss: np.ndarray,
    layers,
) -> dict[str, np.ndarray]:
    """The image formation on per-hit terms: shading = Ddir + Dind (front irradiance/pi), ``back`` the
    irradiance/pi behind translucent hits (rows of opaque hits unused), ``gloss`` Gdir + Gind per unit
    specular colour (rows of non-specular hits unused). Returns ``linear`` and the ``layers`` asked for,
    expanded to every ray."""
    source = np.full(n_rays, -1, np.int64)  # each ray's hit row, -1 on a miss
    source[surface.idx] = np.arange(len(surface.idx))
    linear, values = kernels.compose_layers(
        source,
        surface.albedo,
        surface.trans,
        back,
        surface.spec,
        gloss,
        shading.astype(np.float32, copy=False),
        background,
        np.array([k in layers for k in kernels.COMPOSED_LAYERS]),
    )
    # A surface layer of the modality table that the kernel does not compose raises here (tuple.index).
    out = {k: values[kernels.COMPOSED_LAYERS.index(k)] for k in SURFACE_LAYERS if k in layers}
    out["linear"] = linear
    if "background" in layers:
        out["background"] = background
    return out


def shade(
    tracer: RayTracer,
    mesh,
    hits: Hits,
    origins: np.ndarray,
    directions: np.ndarray,
    sky,
    settings: ShadingSettings,
    rng: np.random.Generator,
    layers=LAYERS,
    image_width: int | None = None,
    pair_sky: PairSky | None = None,
) -> dict[str, np.ndarray]:
    """Linear layers for a batch of primary rays (N rays -> (N, 3) float32 arrays).

    Returns ``linear`` (the composite I) and each of ``layers`` asked for.
    Surface terms are computed on the hit rays only and expanded back to every
    ray at the end, in one gather for all of them. ``image_width``: the rays are
    an image's pixels in row-major order, this wide (neighbours may share rays,
    ``BakedIndirect.escapes``); None: any batch. ``pair_sky``: with ``pixel_sky_rays``, the other
    camera's own-sky factors to take, and where this view's are recorded (``pixel_sky.PairSky``).
    """
    n_rays = len(origins)
    background = background_of(sky, directions, hits.hit, settings.time)
    s = primary_surface(mesh, hits, origins, directions)
    n_hit = len(s.idx)
    has_trans = s.trans > 0
    # The hits' cloud shadows, tabulated once for the sun and the bake's sun bounce.
    cloud = (
        settings.cloud_transmittance(sky, s.points) if n_hit and np.any(np.asarray(sky.sun_irradiance) > 0) else None
    )
    front, back = direct_sun(
        tracer,
        s.points,
        s.n_shade,
        sky,
        settings,
        rng,
        geometric=s.n,
        back_lit=has_trans,
        cloud=cloud,
        image=sun_image(s, hits, directions, n_rays, image_width)
        if image_width and (settings.soft_shadow_radius > 0 or pair_sky is not None)
        else None,  # the soft sun and the pair's shared answers read it: no work per view without them
        pair=pair_sky,
    )
    t_idx = np.nonzero(has_trans)[0]
    g_idx = np.nonzero(s.spec > 0)[0]
    mirrored = None
    back_ind: np.ndarray | None  # the translucent hits' indirect light behind them; None: there are none
    if settings.sky_visibility is not None and settings.indirect_samples == 0:
        baked = BakedIndirect(settings, sky, s, tracer, mesh, cloud, image_width)
        image = (n_rays // image_width, image_width) if image_width else None
        if (settings.pixel_sky_rays > 0 or baked.vis.shadow_maps.present) and image is not None:
            estimated = baked.own_sky(image, rng, pair_sky.partner if pair_sky else None)
            if pair_sky is not None:
                pair_sky.estimated = estimated
        elif len(baked.vis.face_sky):
            baked.face_sky()
        shading = front + baked.irradiance(None)
        back_ind = baked.irradiance(t_idx)
        if settings.glossy_mirror == "traced":
            mirrored = lambda r, w: baked.mirrored(g_idx, r)  # noqa: E731  (the glossy hits' mirror rays)
        elif settings.glossy_mirror == "any_hit":
            mirrored = lambda r, w: baked.mirror_escapes(g_idx, r)  # noqa: E731
        else:
            mirrored = lambda r, w: baked.predicted(g_idx, r, w)  # noqa: E731
    else:
        shading = front + indirect(tracer, mesh, s.points, s.n, sky, settings, rng)
        back_ind = (
            indirect(tracer, mesh, vec.gather(s.points, t_idx), -vec.gather(s.n, t_idx), sky, settings, rng)
            if len(t_idx)
            else None
        )
    back_total = np.zeros((n_hit, 3), np.float32)
    if len(t_idx):
        back_total = vec.Scatter(t_idx, n_hit).expand(vec.gather(back, t_idx) + back_ind)
    gloss = np.zeros((n_hit, 3), np.float32)
    if len(g_idx):
        g = glossy(
            vec.gather(s.n_shade, g_idx),
            vec.gather(s.d, g_idx),
            vec.gather(front, g_idx),
            sky,
            settings,
            mirrored=mirrored,
        )
        gloss = vec.Scatter(g_idx, n_hit).expand(g)
    return compose(n_rays, s, background, shading, back_total, gloss, layers)


def indirect(
    tracer: RayTracer,
    mesh,
    points: np.ndarray,
    normals: np.ndarray,
    sky,
    settings: ShadingSettings,
    rng: np.random.Generator,
) -> np.ndarray:
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
            n2 = vec.facing(n2, dirs[h])
            f2, _ = direct_sun(
                tracer,
                p2,
                n2,
                sky,
                ShadingSettings(time=settings.time, environment=settings.environment, clouds=settings.clouds),
                rng,
                back_lit=np.zeros(len(h), bool),
            )
            # Light arriving at the secondary point beyond one bounce: unoccluded sky, dimmed.
            ambient2 = 0.5 * sky.ambient_irradiance(n2) / np.pi
            radiance[h] = mesh.albedo[hits.prim[h]] * (f2 + ambient2)
        # Cosine-weighted sampling: E/pi is estimated by the mean radiance.
        total += radiance
    return total / settings.indirect_samples


def glossy_parts(n: np.ndarray, d: np.ndarray, front_sun: np.ndarray, sky) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The glossy lobe per unit specular colour (F0 = 1): (Gdir (N, 3), mirror directions (N, 3),
    mirror weights (N,)). Gdir is the sun's light through a Beckmann microfacet BRDF of roughness
    ``GLOSS_ALPHA`` (Smith shadowing, no Fresnel: Cycles' Glossy BSDF) on the sun-lit front irradiance;
    Gind is the radiance arriving along the mirror direction times its weight (a capped Schlick
    Fresnel ratio). The default render looks the sky up along the mirror; the reference traces it."""
    n = np.ascontiguousarray(n, np.float32)
    d = np.ascontiguousarray(d, np.float32)
    front_sun = np.ascontiguousarray(front_sun)
    g_dir = np.empty(front_sun.shape, np.result_type(front_sun.dtype, np.float32))
    mirror, weight = np.empty((len(n), 3), np.float32), np.empty(len(n), np.float32)
    to_sun = np.asarray(sky.sun_direction, np.float32)
    kernels.glossy_lobe(n, d, to_sun, front_sun, np.float32(GLOSS_ALPHA**2), g_dir, mirror, weight)
    return g_dir, mirror, weight


def glossy(
    n: np.ndarray, d: np.ndarray, front_sun: np.ndarray, sky, settings: ShadingSettings, mirrored=None
) -> np.ndarray:
    """Gdir + Gind per unit specular colour: the sun lobe and the radiance along the mirror direction:
    ``mirrored(directions, weights) -> (N, 3)`` where given (from the bake, ``render.glossy_mirror``:
    ``BakedIndirect.predicted``, ``.mirror_escapes`` or ``.mirrored``), else the sky, dimmed by a
    heuristic (without a bake, see below)."""
    g_dir, r, weight = glossy_parts(n, d, front_sun, sky)
    if mirrored is not None:
        return g_dir + mirrored(r, weight) * weight[:, None]
    # Mirrored sky, dimmed where the point is in shadow: a shadowed point mostly sits under
    # a canopy or beside an object that also hides the sky it would mirror.
    sunless = not np.any(np.asarray(sky.sun_irradiance) > 0)
    open_sky = np.where(sunless | (front_sun @ np.ones(3, np.float32) > 0), np.float32(1.0), np.float32(0.3))
    return g_dir + settings.sky_radiance(sky, r) * (weight * open_sky)[:, None]
