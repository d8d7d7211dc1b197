"""Dind from the garden's baked sky visibility (docs/design.md, Image formation): ``BakedIndirect``,
the primary hits' indirect light, translucency and the light along glossy's mirror direction from
the bake (:mod:`eden_pipe.render.visibility`), and ``largest_share``, which picks the glossy pixels
that ask an any-hit ray (``glossy_mirror`` predicted, docs/realism.md). Moved out of
:mod:`eden_pipe.render.shading`, which imports these names back for its callers.
"""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, cast

import numpy as np

from eden_pipe.render import vec
from eden_pipe.render.embree import RayTracer

if TYPE_CHECKING:
    from eden_pipe.render.pixel_sky import SkyShare
    from eden_pipe.render.shading import ShadingSettings, Surface
    from eden_pipe.render.visibility.store import SkyVisibility

EPS = 1e-3  # how far a secondary ray starts off the surface it leaves (shading and its callers use it too)
SHARE_BLOCK = 2  # pixels per side of the image blocks whose mirror directions may share an any-hit ray
SHARE_COS = 0.99  # ... where within 8 degrees of the block's first (BakedIndirect.escapes)
# Each pixel's own sky from the bake's depth maps (render.sky_visibility.shadow_maps): the share of
# their directions a pixel reads (1 / MAP_SUBSETS), the pixels around it on the same face its
# estimate is pooled with, and the bake's weight against it at the pixel (docs/realism.md).
MAP_SUBSETS = 1  # every direction a pixel: a quarter, pooled within 2, was coarser on trees and hedges
MAP_RADIUS = 1
MAP_PRIOR = 0.0


class BakedIndirect:
    """Dind of the primary hits from the garden's baked sky visibility (``visibility.store.SkyVisibility``)
    under this frame's sky and sun: the side facing the viewer for shading, the other side for
    translucency, the light along glossy's mirror direction. The per-probe light belongs to the
    frame (``ShadingSettings.baked_light``): each probe's row is made once, when a view first sees it."""

    def __init__(
        self,
        settings: ShadingSettings,
        sky,
        s: Surface,
        tracer: RayTracer,
        mesh,
        cloud: np.ndarray | None,
        image_width: int | None = None,
    ):
        vis = cast("SkyVisibility", settings.sky_visibility)  # made only with a bake (shade checks)
        self.vis, self.s, self.settings, self.tracer, self.mesh = vis, s, settings, tracer, mesh
        self.image_width = image_width  # rays in row-major image order, this wide (None: any batch)
        self.light = settings.baked_light(sky)
        self.sky = sky
        sides = self.vis.sides_of(s.prim, s.back_side)
        self.probes, self.side_exposure = sides  # the sides table's (lookup's exposure replaces its markers)
        self.rows, self.exposure = self.vis.lookup(self.light, s.prim, s.back_side, s.points, sides)
        self.cloud = None if cloud is None else cloud.astype(np.float32, copy=False)  # (H,) at the hits; None: no sun
        self.seen_sky: np.ndarray | None = None  # (H, 3) the mean radiance of the sky each side sees (face_sky)

    def own_sky(
        self, image: tuple[int, int], rng: np.random.Generator | None = None, partner: SkyShare | None = None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each pixel's own visible sky in its exposure (``render.pixel_sky_rays``,
        :mod:`eden_pipe.render.pixel_sky`; without rays, from the bake's depth maps where it kept
        them, ``render.sky_visibility.shadow_maps``): the hits are an ``image``'s (height, width)
        pixels. Sides with a lightmap or on the ground map keep the point's sky they have.
        ``partner``: the other camera's factors, taken where it saw the same face side (estimated
        only elsewhere). Returns the estimated hits' pixels, face sides (``face * 2 + side``) and
        factors."""
        from eden_pipe.render.pixel_sky import pixel_exposure_scale

        side = self.side_exposure
        own = np.flatnonzero((side >= 0) & np.isfinite(side))
        pixels, prim = vec.take(self.s.idx, own), vec.take(self.s.prim, own)
        sides = prim.astype(np.int64) * 2 + vec.take(self.s.back_side, own)
        scale = np.ones(len(own), np.float32)
        if len(own) == 0:
            return pixels, sides, scale
        probe_visible = vec.take(self.rows.visible, own)
        exposure = vec.take(self.exposure, own)
        bake = self.vis.open_fraction(probe_visible, exposure)
        traced, known = np.arange(len(own)), None
        if partner is not None:
            shared = partner.lookup(vec.gather(self.s.points, own), sides)
            taken = np.isfinite(shared)
            scale[taken] = shared[taken]
            traced = np.flatnonzero(~taken)
            # The taken pixels' sky joins the windows of the traced ones, as their own rays would.
            known = (pixels[taken], prim[taken], bake[taken] * scale[taken], bake[taken])
        if len(traced) and self.vis.shadow_maps.present and self.settings.pixel_sky_rays == 0:
            # The bundles' depth maps: each pixel reads a share of their directions, pooled with
            # its neighbours on the same face (docs/realism.md, the bundles' depth maps).
            from eden_pipe.render.pixel_sky import map_phase, pooled_scale

            at, estimated = vec.take(own, traced), vec.take(pixels, traced)
            seen = self.vis.shadow_maps.visible_fraction(
                vec.gather(self.s.points, at),
                vec.gather(self.s.n, at),
                map_phase(estimated, image[1], MAP_SUBSETS) if MAP_SUBSETS > 1 else None,  # None: every direction
                MAP_SUBSETS,
            )
            scale[traced] = pooled_scale(
                estimated, image, vec.take(prim, traced), seen, vec.take(bake, traced), MAP_RADIUS, MAP_PRIOR, known
            )
        elif len(traced):
            assert rng is not None, "own-sky rays need a generator"
            at = vec.take(own, traced)
            scale[traced] = pixel_exposure_scale(
                self.tracer,
                vec.take(pixels, traced),
                image,
                vec.gather(self.s.points, at),
                vec.gather(self.s.n, at),
                vec.take(prim, traced),
                vec.take(bake, traced),
                self.settings.pixel_sky_rays,
                self.settings.pixel_sky_radius,
                rng,
                known,
            )
        # At most the whole sky: the visible fraction (probe's times exposure) stays within 1.
        limit = np.float32(1.0) / np.maximum(probe_visible, np.float32(1e-6))
        self.exposure[own] = np.minimum(exposure * scale, limit)
        if self.vis.has_side_moments:
            self.face_sky(fractions=False)  # the pixel's own fraction, its face side's sky directions
        return pixels, sides, scale

    def face_sky(self, fractions: bool = True) -> None:
        """Each hit lit through a probe: the visible sky of its face side blended at the hit from the
        side's three points (``SkyVisibility.face_sky``, ``render.sky_visibility.face_sky``), in its
        exposure, as :meth:`own_sky` puts a pixel's own; sides with a lightmap or on the ground map
        keep theirs. Where the table holds each side's sky directions
        (``render.sky_visibility.face_sky_moments``), also the mean radiance of the sky the side
        sees: its moments' means times this frame's sky fitted by the same polynomials
        (``FrameLight.hemisphere_fit``), for :meth:`irradiance` (the sky weighed by where each side
        sees it, which a probe's transfer does not say deep in a crown; docs/realism.md, "The sky
        by the directions a face side sees it in"). No rays and no window: one compiled pass over
        the hits, which reads a side's moments with its fractions. Without ``fractions``, only the
        sky's mean radiance: the exposures stay (each pixel's own, :meth:`own_sky`)."""
        from eden_pipe.render.pixel_sky import MIN_POOLED
        from eden_pipe.render.visibility.face_sky import face_sky_exposure
        from eden_pipe.render.visibility.shadow_maps import MOMENTS

        if self.vis.has_side_moments:
            fit = self.light.hemisphere_fit(lambda d: self.settings.sky_radiance(self.sky, d))
            self.seen_sky = np.empty((len(self.s.prim), 3), np.float32)
        else:
            fit, self.seen_sky = np.zeros((1 + MOMENTS, 3), np.float32), None
        face_sky_exposure(
            self.vis.face_sky,
            self.mesh.vertices,
            self.mesh.faces,
            self.s.prim,
            self.s.back_side,
            self.s.points,
            self.side_exposure,
            self.rows.visible,
            self.exposure,
            np.float32(MIN_POOLED if fractions else np.inf),  # no fraction is ever blended at least inf
            fit,
            np.zeros((0, 3), np.float32) if self.seen_sky is None else self.seen_sky,
        )

    def sides_sky(self, light: np.ndarray) -> np.ndarray:
        """``light`` (H, 3) Dind of every hit, in place, where :meth:`face_sky` gave its side's sky's
        mean radiance: its visible fraction times that, plus its bounce."""
        from eden_pipe.render.visibility.face_sky import sides_sky_light

        assert self.seen_sky is not None
        return sides_sky_light(self.side_exposure, self.seen_sky, self.rows.visible, self.exposure, self.bounce, light)

    def above(self, index: np.ndarray) -> np.ndarray:
        """(N, 3) origins of secondary rays from the hits ``index``: just off their viewer side."""
        return vec.gather(self.s.points, index) + vec.gather(self.s.n, index) * np.float32(EPS)

    def ambient(self, normals: np.ndarray) -> np.ndarray:
        return self.sky.ambient_irradiance(normals) * np.float32(1.0 / np.pi)

    @functools.cached_property
    def bounce(self) -> np.ndarray:
        """(H, 3) the bounce light on the front of every hit (``SkyVisibility.bounce_light``): the
        front's Dind and, over its probe's blocked fraction, the light of what hides a mirror's sky."""
        return self.vis.bounce_light(self.rows, self.cloud)

    def irradiance(self, index: np.ndarray | None) -> np.ndarray:
        """Dind/pi on the front of every hit (``index`` None) or behind the hits ``index``."""
        if index is None:
            light = self.vis.irradiance(self.rows, self.exposure, self.ambient(self.s.n), self.bounce)
            if self.seen_sky is not None:
                self.sides_sky(light)
            return light
        rows, exposure = self.vis.lookup(
            self.light,
            vec.take(self.s.prim, index),
            ~vec.take(self.s.back_side, index),
            vec.gather(self.s.points, index),
        )
        cloud = None if self.cloud is None else vec.take(self.cloud, index)
        return self.vis.irradiance(
            rows, exposure, self.ambient(-vec.gather(self.s.n, index)), self.vis.bounce_light(rows, cloud)
        )

    def predicted(self, index: np.ndarray, directions: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """(N, 3) radiance arriving at the hits ``index`` along mirror ``directions``
        (``glossy_mirror=predicted``): the sky where the mirror is likelier to escape than not, the
        mean light of what hides the point's sky (:meth:`blocked`) where not, as :meth:`mirror_escapes`
        but decided by the bake (:meth:`mirror_fraction`, whose fraction f is the share of such
        mirrors that escape, calibrated to within a few per cent on the benchmark's views) instead
        of a ray. A decision misses by ``|L - Lblocked|`` with chance ``min(f, 1 - f)``, so the
        ``render.mirror_rays`` share of upward hits where that times the Fresnel ``weights`` (N,)
        and the specular colour is largest asks an any-hit ray (:meth:`escapes`). A downward mirror
        meets the ground (as :meth:`mirror_escapes`). 60 % (the default) keeps the benchmark's
        errors within 0.004 of a ray for every pixel, for half its rays (``docs/realism.md``)."""
        out = self.blocked(index)
        up = np.flatnonzero(directions[:, 2] > 0)
        at = vec.take(index, up)
        along = vec.gather(directions, up)
        fraction = self.mirror_fraction(at, along)
        sky = self.settings.sky_radiance(self.sky, along)
        score = np.minimum(fraction, np.float32(1.0) - fraction)
        score *= vec.take(weights, up)
        score *= vec.take(self.s.spec, at)
        score *= np.abs(sky - vec.gather(out, up)) @ np.ones(3, np.float32)
        free = fraction > np.float32(0.5)
        pick = largest_share(score, self.settings.mirror_rays)
        if len(pick):
            free[pick] = self.escapes(vec.take(at, pick), vec.gather(along, pick))
        escaped = np.flatnonzero(free)
        out[vec.take(up, escaped)] = vec.gather(sky, escaped)
        return out

    def mirror_fraction(self, index: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) the bake's visible fraction of the sky along unit ``directions`` from the hits
        ``index`` (``SkyVisibility.mirror_fraction``: the probe's transfer taken along the direction,
        no ray): a lawn blade's grazing mirror sees little of the sky its open zenith gives its
        cosine-weighted fraction. Where it cannot say (grazing directions) and on the ground map (one
        probe per face there says nothing of a direction): the cosine-weighted visible fraction."""
        exposure = vec.take(self.exposure, index)
        visible = self.vis.mirror_fraction(vec.take(self.probes, index), exposure, directions)
        fallback = np.isnan(visible)
        fallback |= self.vis.on_ground_map(vec.take(self.side_exposure, index))
        fix = np.flatnonzero(fallback)
        visible[fix] = self.vis.open_fraction(
            vec.take(self.rows.visible, vec.take(index, fix)), vec.take(exposure, fix)
        )
        return visible

    def blocked(self, index: np.ndarray) -> np.ndarray:
        """(N, 3) the mean radiance of what hides the sky of the hits ``index``: their bounce over
        their probe's blocked fraction (``SkyVisibility.blocked_radiance``)."""
        return self.vis.blocked_radiance(self.bounce, self.rows.visible, np.asarray(index))

    def mirror_escapes(self, index: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N, 3) radiance arriving at the hits ``index`` along mirror ``directions``
        (``glossy_mirror=any_hit``), a cheap form of :meth:`mirrored`: whether the mirror ray escapes
        decides most of a glossy pixel (the sky is several times brighter than what hides it), what it
        meets matters much less (``docs/realism.md``).
        An upward ray is tested by one any-hit ray (cheaper than a closest hit, and no lookup at
        its end): the sky where it escapes; a blocked or downward one (those meet the ground) sees
        the mean radiance of what hides the point's sky, the bake's bounce over its probe's
        blocked fraction (:meth:`blocked`)."""
        free = np.zeros(len(index), bool)
        up = np.nonzero(directions[:, 2] > 0)[0]
        if len(up):
            free[up] = self.escapes(vec.take(index, up), vec.gather(directions, up))
        out = np.empty((len(index), 3), np.float32)
        escaped = np.nonzero(free)[0]
        out[escaped] = self.settings.sky_radiance(self.sky, vec.gather(directions, escaped))
        hidden = np.flatnonzero(~free)
        out[hidden] = self.blocked(vec.take(index, hidden))
        return out

    def escapes(self, index: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) bool: rays from the hits ``index`` along ``directions`` reach the sky (any-hit rays).
        In an image (``image_width`` known), the hits of each ``SHARE_BLOCK``-pixel square block share
        the ray of its first hit wherever their direction is within ``SHARE_COS`` of its one: mirror
        directions on a smooth surface barely change over a few pixels, and what hides the sky is
        mostly metres away; hits on blades and leaves, whose normals turn from pixel to pixel, keep
        their own ray. About half the rays of a lawn view, a quarter of a fence or ground view."""
        own = np.ones(len(index), bool)
        width = self.image_width or 0  # 0: no image (None)
        share = bool(width) and len(index) > 0
        if share:
            pixel = vec.take(self.s.idx, index)
            block = (pixel // (width * SHARE_BLOCK)) * (-(-width // SHARE_BLOCK)) + (pixel % width) // SHARE_BLOCK
            # Each block's first hit, the lowest position holding it (an unbuffered minimum, no sort).
            position = np.arange(len(block))
            first_of = np.full(int(block.max()) + 1, len(block), np.int64)
            np.minimum.at(first_of, block, position)
            leader = vec.take(first_of, block)
            own = vec.dot(directions, vec.gather(directions, leader)) < np.float32(SHARE_COS)
            own[leader == position] = True
        traced = np.nonzero(own)[0]
        start = self.above(vec.take(index, traced))
        free = np.zeros(len(index), bool)
        free[traced] = ~self.tracer.occluded(start, vec.gather(directions, traced))
        return np.where(own, free, vec.take(free, leader)) if share else free

    def mirrored(self, index: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N, 3) radiance arriving at the hits ``index`` along mirror ``directions``: one traced ray
        each; the sky where it escapes, else the hit surface lit by the bake (its sky, bounce and
        band-limited sun; light through it for translucent faces)."""
        start = self.above(index)
        hits = self.tracer.intersect(start, directions)
        out = np.zeros((len(index), 3), np.float32)
        miss = np.nonzero(~hits.hit)[0]
        if len(miss):
            out[miss] = self.settings.sky_radiance(self.sky, vec.gather(directions, miss))
        h = np.nonzero(hits.hit)[0]
        if len(h):
            prim = hits.prim[h]
            d = vec.gather(directions, h)
            points = vec.gather(start, h) + d * hits.t[h, None]
            facing_back = vec.dot(vec.gather(hits.normal, h), d) > 0  # the ray meets side 1
            cloud = (
                None if self.cloud is None else self.settings.cloud_transmittance(self.sky, points).astype(np.float32)
            )
            rows, exposure = self.vis.lookup(self.light, prim, facing_back, points)
            light = self.vis.surface_light(rows, exposure, cloud)
            trans = vec.take(self.mesh.translucency, prim)
            lit_through = np.nonzero(trans > 0)[0]
            if len(lit_through):
                rows, exposure = self.vis.lookup(
                    self.light,
                    vec.take(prim, lit_through),
                    ~vec.take(facing_back, lit_through),
                    vec.gather(points, lit_through),
                )
                behind = self.vis.surface_light(rows, exposure, None if cloud is None else vec.take(cloud, lit_through))
                light[lit_through] += behind * vec.take(trans, lit_through)[:, None]
            out[h] = vec.gather(self.mesh.albedo, prim) * light
        return out


def largest_share(score: np.ndarray, share: float) -> np.ndarray:
    """Sorted indices of about the ``share`` (0..1) of ``score`` that is largest and above zero:
    every index picked scores more than every one left. The cut is the quantile of a strided
    sample of about 4,096 scores: a full partition of a view's 250,000 glossy hits takes 12 ms."""
    if share <= 0 or not len(score):
        return np.zeros(0, np.int64)
    cut = np.float32(0.0)
    if share < 1:
        sample = np.sort(score[:: max(1, len(score) // 4096)])
        cut = max(cut, sample[min(len(sample) - 1, int(len(sample) * (1.0 - share)))])
    return np.flatnonzero(score > cut)
