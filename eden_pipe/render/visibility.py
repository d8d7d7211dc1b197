"""Sky visibility and bounce light baked once per garden, lit by any sky at render time.

The default render's Dind (``render.indirect_samples=0``) is the sky seen from
each point, with the sky hidden where geometry hides it and light bounced off
that geometry in its place. Nothing here depends on the lighting: the bake is
done once per garden (stage ``sky_visibility``) and every lighting and frame
combines it with its own sky and sun.

Where: a garden has millions of tiny faces (lawn blades, leaves), too many to
trace enough rays from each. Two ray sets share the work:

- *outside-in bundles* (``sky_hits``): for ``directions`` stratified sky
  directions, a grid of parallel rays ``spacing_m`` apart enters the garden's
  box from that direction; a face side is hit by about ``V area cos / spacing^2``
  of them, so hit counts give every face side's cosine-weighted visible sky
  (coherent rays: several times cheaper than scattered ones);
- *probes*: faces whose centroids share a cell (``cell_m`` wide,
  ``cell_height_m`` tall: the lawn's height matters more than its extent), whose
  side normals share a major axis and (for opaque faces) which side, once per
  side of each face (faces are two-sided). A probe pools its faces' bundle hits
  into an SH shape, and sends ``rays`` cosine rays from area-sampled points of
  its faces for the bounce.

What (Sloan et al. 2002, precomputed radiance transfer, order 4 SH;
:mod:`eden_pipe.render.sh`):

- per probe ``transfer`` T (16): the cosine-weighted visible sky,
  ``T_i = int V(w) cos(w)/pi Y_i(w) dw``. A sky with SH radiance L gives sky
  irradiance/pi ``T . L``. A pixel's own normal n corrects for the probe's mean
  normal: ``T + v (T_open(n) - T_open(nbar))`` with v the probe's visible fraction;
- per face side ``exposure``: its own visible sky over its probe's (hit counts
  shrunk toward the probe's where few rays reached a tiny face): the probe gives
  the shape, the face the amount; with ``camera_views``, scaled per probe to the
  sky seen at the points that cameras at the rig's height see (``camera_gain``:
  they see the parts of a leaf that open toward them, which see more sky than
  the leaf's average); faces wider than ``lightmap_cell_m`` squared (fence
  planks and rails, trunks, the lawn's soil) take it from their own lightmap
  instead, a grid of nodes over the face (:mod:`eden_pipe.render.lightmap`),
  since their sky changes from their foot to their top;
- per probe ``bounce`` beta (16) and ``tint`` c (3): what the blocked rays hit, as
  light seen from here: ``beta = mean over blocked rays of lum(rho m) (T_hit + t T_hit_back)``
  with rho, t the albedo and translucency of the face hit, T_hit its transfer
  on the side facing us and on the other side (light through leaves), and
  m = 1/(1 - a) a multi-bounce factor from the hit probe's own blocked albedo a.
  The bounce is ``c * beta . (L + E_sun cloud Y(sun))``: sky light that reached
  the hit points, plus sun whose visibility at the hit points is the
  band-limited V(s) cos(s) their transfer holds (a smooth stand-in for their
  sun shadow, exact on average over sun directions).

The foliage back side (translucency T) reads the other side's probe, so
transmitted light sees the same sky and bounce model as the front.

The flat land outside the garden's box (the skirt) has a *ground map*
(``GroundGrid``): nodes every ``ground_cell_m`` with their own cosine rays,
blended bilinearly per pixel, since one of its faces spans metres over which
the garden hides less and less of the sky.
"""

from __future__ import annotations

import functools
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from eden_pipe.render import lut, sh, vec
from eden_pipe.render.lightmap import Lightmaps, bake_lightmaps
from eden_pipe.render.embree import RayTracer

LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)
EPS = 1e-3
MAX_BLOCKED_ALBEDO = 0.8  # caps the multi-bounce factor 1/(1 - a)
MIN_BLOCKED = 0.05  # the least blocked fraction a face's bounce is divided by (blocked_radiance)
MIN_OPEN_TRANSFER = 0.02  # the least open transfer along a direction mirror_fraction divides by (about 1/17 of head-on)
# sh.open_transfer(n) . sh.basis(w) as a polynomial in cos(n, w): (1 + 2c + 0.625 (3c^2 - 1)) / (4 pi)
OPEN_ALONG = np.array([1.0 - 0.625, 2.0, 1.875], np.float32) / np.float32(4.0 * np.pi)
RAYS_PER_WAVE = 1 << 20
ON_GROUND_MAP = np.float32(np.inf)  # a side's exposure in the sides table: its face is lit through the ground map
MIN_SEEN_V = 0.05  # the least mean visible fraction camera_gain's pseudo-rays assume (no gain from nothing)
MAX_SEEN_GAIN = 3.0  # camera_gain's cap


@dataclass
class SkyVisibility:
    """The bake: ``face_probe`` (F, 2) probe of each face side (0: the side its winding's normal
    points to, 1: the other); per probe ``transfer`` (P, 16), ``normal`` (P, 3) mean side normal,
    ``bounce`` (P, 16) and ``tint`` (P, 3)."""

    face_probe: np.ndarray
    exposure: np.ndarray
    transfer: np.ndarray
    normal: np.ndarray
    bounce: np.ndarray
    tint: np.ndarray
    ground_faces: np.ndarray  # (K,) int32 faces lit through the ground map (none: empty)
    ground_grid: np.ndarray   # (6,) float64 x0, y0, cell, nx, ny, first probe of the map's nodes
    lightmaps: Lightmaps      # the visible sky over large faces, node by node (none: Lightmaps.none())

    FIELDS = ("face_probe", "exposure", "transfer", "normal", "bounce", "tint")
    EXACT = ("ground_faces", "ground_grid")  # kept at full precision

    def save(self, path: Path) -> None:
        np.savez(path, face_probe=self.face_probe, **{k: getattr(self, k) for k in self.EXACT},
                 **{k: getattr(self, k).astype(np.float16) for k in self.FIELDS[1:]},
                 **{f"lightmap_{k}": getattr(self.lightmaps, k) for k in Lightmaps.FIELDS})

    @classmethod
    def load(cls, path: Path) -> "SkyVisibility":
        with np.load(path) as data:
            return cls(data["face_probe"], *(data[k].astype(np.float32) for k in cls.FIELDS[1:]),
                       *(data[k] for k in cls.EXACT), Lightmaps(*(data[f"lightmap_{k}"] for k in Lightmaps.FIELDS)))

    @property
    def n_probes(self) -> int:
        return len(self.transfer)

    @functools.cached_property
    def _sides(self) -> np.ndarray:
        """(2F, 2) int32: each face side's probe and its exposure's float32 bits, side by side: a
        view's hits read both with one gather from this table instead of two (half the cache misses
        of two 6-million-face tables, ~2.5 ms a lookup). A side with a lightmap holds -1 - its
        lightmap's row instead of an exposure (:meth:`lookup` makes its exposure at the point), a side
        of the ground map's faces ``ON_GROUND_MAP`` (:meth:`lookup` blends the map's nodes there)."""
        exposure = np.array(self.exposure, np.float32)
        exposure[self.lightmaps.faces] = -1.0 - np.arange(len(self.lightmaps.faces), dtype=np.float32)[:, None]
        exposure[self.ground_faces] = ON_GROUND_MAP
        return np.stack([self.face_probe.ravel().astype(np.int32), exposure.ravel().view(np.int32)], axis=1)

    def frame_light(self, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray,
                    own_sun: bool = False) -> "FrameLight":
        """The per-probe light of one frame (:meth:`frame_rows`), made as the frame's views need it."""
        return FrameLight(self, sky_sh, sun_sh, sun_rgb, own_sun)

    def frame_rows(self, probes: np.ndarray, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray,
                   own_sun: bool = False) -> "ProbeLight":
        """The light of the ``probes`` (N,) under one frame's sky and sun (a :class:`ProbeLight`): the
        sky term ``T . L - v open(nbar)``, the probe's visible fraction v, the bounce of sky light and of
        the sun (per unit cloud transmittance); with ``own_sun`` also the open sky of the probe's mean
        normal ``open(nbar) = T_open(nbar) . L`` and its band-limited sun ``E_sun max(T . Y(sun), 0)``
        (per unit cloud transmittance: the light of the surfaces a mirror ray hits). A pixel only
        gathers a row and adds its own normal's open sky (the exact ``ambient``) times v: an open
        probe's sky term is exactly zero, its pixels see exactly the open sky. A row depends on its
        probe alone (``sh_dot``), whatever other probes it is made with."""
        transfer, tint = np.take(self.transfer, probes, axis=0), np.take(self.tint, probes, axis=0)
        # The transfer, the open transfer of the mean normal and the bounce against the sky (3) and
        # the sun (1), probes last.
        coeffs = np.stack([transfer, sh.open_transfer(np.take(self.normal, probes, axis=0)),
                           np.take(self.bounce, probes, axis=0)]).transpose(0, 2, 1).copy()
        lit = sh_dot(coeffs, np.concatenate([sky_sh, sun_sh[:, None]], axis=1)).transpose(2, 0, 1)  # (N, 3, 4)
        visible = np.multiply(transfer[:, 0], np.float32(1.0 / sh.basis(np.zeros((1, 3)))[0, 0]))
        open_ = np.ascontiguousarray(lit[:, 1, 0:3])
        sky = np.ascontiguousarray(lit[:, 0, 0:3])
        sky -= visible[:, None] * open_
        sun = np.maximum(lit[:, 2, 3:4], np.float32(0.0))
        return ProbeLight(sky, visible, lit[:, 2, 0:3] * tint, np.multiply(tint, sun * sun_rgb),
                          open_ if own_sun else None,
                          np.multiply(np.maximum(lit[:, 0, 3:4], np.float32(0.0)), sun_rgb) if own_sun else None)

    def lookup(self, light: "FrameLight", prim: np.ndarray, back: np.ndarray, points: np.ndarray,
               sides: tuple[np.ndarray, np.ndarray] | None = None) -> tuple["ProbeLight", np.ndarray]:
        """(the frame's ``light`` of N face sides (a :class:`ProbeLight`), exposures (N,)) for face
        sides (``back`` (N,) true for side 1) seen at ``points`` (N, 3): points on a face with a
        lightmap take their exposure from
        its nodes (their visible sky over the probe's), points on the ground map's faces blend its
        four nearest nodes. ``sides``: the sides' probes and exposures where the caller has them
        (:meth:`sides_of`)."""
        probes, exposure = self.sides_of(prim, back) if sides is None else sides
        rows, exposure = light.rows(probes), exposure.copy()
        mapped = np.flatnonzero(exposure < 0) if len(self.lightmaps.faces) else ()
        if len(mapped):  # sides with a lightmap: their visible sky at the point over the probe's
            visible = self.lightmaps.visible_at((np.float32(-1.0) - np.take(exposure, mapped)).astype(np.int32),
                                                np.take(back, mapped), vec.gather(points, mapped))
            exposure[mapped] = exposure_of(visible, np.take(rows.visible, mapped))
        if len(self.ground_faces):
            on_map = np.flatnonzero(self.on_ground_map(exposure))
            if len(on_map):
                rows.put(on_map, GroundGrid.blend(self.ground_grid, light, vec.gather(points, on_map)))
                exposure[on_map] = 1.0
        return rows, exposure

    @staticmethod
    def bounce_light(rows: "ProbeLight", cloud: np.ndarray | None) -> np.ndarray:
        """(N, 3) the bounce from :meth:`lookup` rows: of sky light, and of sun light times ``cloud``
        (N,) (None: no sun), at least zero."""
        if cloud is None:
            bounce = rows.bounce_sky.copy()
        else:
            bounce = np.multiply(rows.bounce_sun, cloud[:, None])
            bounce += rows.bounce_sky  # the same sum as bounce_sky + ...: float addition commutes exactly
        return np.maximum(bounce, np.float32(0.0), out=bounce)

    @staticmethod
    def irradiance(rows: "ProbeLight", exposure: np.ndarray, ambient_n: np.ndarray, bounce: np.ndarray) -> np.ndarray:
        """Dind (N, 3) from :meth:`lookup` rows: the visible sky, corrected from the probe's mean
        normal to the pixel's (``ambient_n``: the open sky's irradiance/pi at its normal), scaled by
        the face side's exposure; plus ``bounce`` (:meth:`bounce_light`)."""
        light = ambient_n * rows.visible[:, None]
        light += rows.sky
        light *= exposure[:, None]
        np.maximum(light, np.float32(0.0), out=light)
        light += bounce
        return light

    @staticmethod
    def open_fraction(probe_visible: np.ndarray, exposure: np.ndarray) -> np.ndarray:
        """(N,) the cosine-weighted visible fraction of the sky of face sides: their probe's (a
        :meth:`lookup` row's ``visible``) times their ``exposure``."""
        return np.clip(probe_visible * exposure, np.float32(0.0), np.float32(1.0))

    @staticmethod
    def on_ground_map(side_exposure: np.ndarray) -> np.ndarray:
        """(N,) bool: the sides whose exposure (:meth:`sides_of`) says their face is lit through the
        ground map."""
        return side_exposure == ON_GROUND_MAP

    def sides_of(self, prim: np.ndarray, back: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N,) probe, (N,) exposure) of each face side (``back`` (N,) true for side 1); a side with
        a lightmap has -1 - its lightmap's row for exposure, one of the ground map's faces
        ``ON_GROUND_MAP`` (:meth:`lookup` replaces both)."""
        both = np.take(self._sides, prim.astype(np.int64) * 2 + back, axis=0)
        return np.ascontiguousarray(both[:, 0]), np.ascontiguousarray(both[:, 1]).view(np.float32)

    def mirror_fraction(self, probes: np.ndarray, exposure: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """(N,) the visible fraction of the sky along unit ``directions`` (N, 3) from face sides of
        ``probes`` and ``exposure`` (N,) (:meth:`sides_of`, :meth:`lookup`), no ray: the probe's
        transfer over the open transfer of its mean normal, both evaluated along the direction
        (``V cos`` and ``cos`` band-limited alike, so their ratio is a smoothed ``V`` there: low
        toward the hedge beside a lawn, high toward the open zenith), times the side's exposure.
        Where the open transfer is too small to divide by (a direction grazing or behind the
        probe's mean surface): NaN, for the caller to fill (with the side's cosine-weighted visible
        fraction, ``BakedIndirect.mirror_fraction``)."""
        seen = np.einsum("ij,ij->i", np.take(self.transfer, probes, axis=0), sh.basis(directions))
        # The open transfer along w depends on cos(nbar, w) alone: sum_l COSINE_l (2l+1)/(4 pi) P_l(cos).
        cos = vec.dot(np.take(self.normal, probes, axis=0), directions)
        open_ = cos * OPEN_ALONG[2]
        open_ += OPEN_ALONG[1]
        open_ *= cos
        open_ += OPEN_ALONG[0]
        usable = open_ > np.float32(MIN_OPEN_TRANSFER)
        seen /= np.maximum(open_, np.float32(MIN_OPEN_TRANSFER), out=open_)
        np.clip(seen, np.float32(0.0), np.float32(1.0), out=seen)
        seen *= exposure
        fraction = np.minimum(seen, np.float32(1.0), out=seen)
        return np.where(usable, fraction, np.float32(np.nan))

    @staticmethod
    def blocked_radiance(bounce: np.ndarray, probe_visible: np.ndarray, exposure: np.ndarray) -> np.ndarray:
        """(N, 3) mean radiance of what hides the sky of face sides: their ``bounce``
        (:meth:`bounce_light`) over their cosine-weighted blocked fraction (from their probe's
        visible fraction, a :meth:`lookup` row's ``visible``, and their ``exposure``; kept above
        ``MIN_BLOCKED``: an open face's bounce is near zero, its mean is not)."""
        visible = SkyVisibility.open_fraction(probe_visible, exposure)
        return bounce / np.maximum(np.float32(1.0) - visible, np.float32(MIN_BLOCKED))[:, None]

    @staticmethod
    def surface_light(rows: "ProbeLight", exposure: np.ndarray, cloud: np.ndarray | None) -> np.ndarray:
        """(N, 3) irradiance/pi of face sides seen along secondary rays, from :meth:`lookup` rows (of a
        ``frame_light(own_sun=True)``) at the probe's mean normal: sky, bounce and the band-limited sun
        (``cloud`` (N,), None: no sun)."""
        light = (rows.sky + rows.open * rows.visible[:, None]) * exposure[:, None] + np.maximum(rows.bounce_sky, np.float32(0.0))
        if cloud is not None:
            light = light + (rows.bounce_sun + rows.sun * exposure[:, None]) * cloud[:, None]
        return np.maximum(light, np.float32(0.0))


def exposure_of(visible: np.ndarray, probe_visible: np.ndarray) -> np.ndarray:
    """A face side's exposure: its cosine-weighted visible sky over its probe's (0 where the probe
    sees none)."""
    return np.where(probe_visible > 1e-6, visible / np.maximum(probe_visible, 1e-6), 0.0)


def sh_dot(coeffs: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """(..., 16, N) SH coefficients of N points, points last, times (16, C) radiance -> (..., C, N)
    float32, summed term by term in a fixed order: a row's value does not depend on how many rows
    are made with it (a BLAS product's blocking does), so light made for a view's probes equals
    light made for all of them. Points last, each term is one product over long rows (2.3 times
    faster than points first, whose rows of three or four are too short to vectorise)."""
    radiance = np.asarray(radiance, np.float32)[:, :, None]
    out = coeffs[..., 0:1, :] * radiance[0]
    for k in range(1, sh.COUNT):
        out += coeffs[..., k:k + 1, :] * radiance[k]
    return out


@dataclass
class ProbeLight:
    """A frame's light of N probes or face sides (``SkyVisibility.frame_rows``, gathered by
    ``FrameLight.rows``, blended by ``GroundGrid.blend``), one contiguous array per term: a pixel's
    arithmetic on (N, 3) arrays runs on numpy's contiguous loops, where the columns of one (N, 13)
    table each ran a strided loop three wide (2-3 times slower)."""

    sky: np.ndarray          # (N, 3) the sky term T . L - v open(nbar)
    visible: np.ndarray      # (N,) the probe's cosine-weighted visible fraction v
    bounce_sky: np.ndarray   # (N, 3) the bounce of sky light
    bounce_sun: np.ndarray   # (N, 3) the bounce of the sun, per unit cloud transmittance
    open: np.ndarray | None = None  # (N, 3) open(nbar), with own_sun (SkyVisibility.surface_light)
    sun: np.ndarray | None = None   # (N, 3) the band-limited sun per unit cloud transmittance, with own_sun

    TERMS = ("sky", "visible", "bounce_sky", "bounce_sun", "open", "sun")

    @classmethod
    def empty(cls, own_sun: bool) -> "ProbeLight":
        three = lambda: np.zeros((0, 3), np.float32)  # noqa: E731
        return cls(three(), np.zeros(0, np.float32), three(), three(), three() if own_sun else None,
                   three() if own_sun else None)

    def __len__(self) -> int:
        return len(self.visible)

    def terms(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in self.TERMS if getattr(self, k) is not None}

    def take(self, index: np.ndarray) -> "ProbeLight":
        """The rows ``index`` (N,), each term gathered on its own."""
        return ProbeLight(**{k: np.take(v, index, axis=0) for k, v in self.terms().items()})

    def put(self, index: np.ndarray, rows: "ProbeLight") -> None:
        """Rows ``index`` replaced by ``rows``."""
        for k, v in self.terms().items():
            v[index] = getattr(rows, k)

    def columns(self) -> np.ndarray:
        """(N, C) float32 the terms side by side, in ``TERMS`` order (:meth:`from_columns` splits them)."""
        return np.column_stack(list(self.terms().values())).astype(np.float32, copy=False)

    def from_columns(self, columns: np.ndarray) -> "ProbeLight":
        """Rows laid out as this light's :meth:`columns`, split into contiguous terms."""
        out, at = {}, 0
        for k, v in self.terms().items():
            width = v.shape[1] if v.ndim == 2 else 1
            out[k] = np.ascontiguousarray(columns[:, at] if v.ndim == 1 else columns[:, at:at + width])
            at += width
        return ProbeLight(**out)


class FrameLight:
    """The bake's per-probe light under one frame's sky and sun (``SkyVisibility.frame_rows``), made
    row by row as the frame's views first need each probe: a view sees 1-2 % of a garden's probes,
    so the frame pays for the few percent its ten views see, not for the whole table. The rows it
    made are kept compact (a table over every probe would fault in most of its pages for them), in
    buffers that grow by doubling: frames under the same sky share one (``FrameLights``), so it
    holds every probe a job's views have seen."""

    FIRST_ROOM = 4096  # rows of the store's first buffers

    def __init__(self, vis: SkyVisibility, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray,
                 own_sun: bool = False):
        self.vis, self.own_sun = vis, own_sun
        self.light = (np.asarray(sky_sh, np.float32), np.asarray(sun_sh, np.float32), np.asarray(sun_rgb, np.float32))
        self.slot = np.full(vis.n_probes, -1, np.int32)  # each probe's row in ``made``; -1: not made yet
        self._store = ProbeLight.empty(own_sun)  # rows 0..count-1 made, the rest room to grow
        self._count = 0
        self._lock = threading.Lock()  # frame threads may share a frame's light
        self._span: tuple[int, ProbeLight, np.ndarray] | None = None

    def matches(self, vis: SkyVisibility, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray,
                own_sun: bool) -> bool:
        """Whether this is the light of ``vis`` under exactly this sky and sun."""
        return (self.vis is vis and self.own_sun == own_sun
                and all(np.array_equal(a, np.asarray(b, np.float32)) for a, b in zip(self.light, (sky_sh, sun_sh, sun_rgb))))

    @property
    def made(self) -> ProbeLight:
        """The rows made so far, in the order they were made."""
        count = self._count
        return ProbeLight(**{k: v[:count] for k, v in self._store.terms().items()})

    def span(self, first: int, count: int) -> ProbeLight:
        """The rows of the consecutive probes ``first``.. (the ground map's nodes), all made
        once a frame: a third of a view's pixels blend four of them each, and a blend from this
        small table costs a fraction of a gather through :meth:`rows`."""
        return self._made_span(first, count)[1]

    def span_columns(self, first: int, count: int) -> np.ndarray:
        """(count, C) :meth:`span`'s rows as :meth:`ProbeLight.columns`, laid out once a frame."""
        return self._made_span(first, count)[2]

    def _made_span(self, first: int, count: int) -> tuple[int, ProbeLight, np.ndarray]:
        span = self._span
        if span is None or span[0] != first or len(span[1]) != count:
            with self._lock:
                span = self._span
                if span is None or span[0] != first or len(span[1]) != count:
                    rows = self.vis.frame_rows(np.arange(first, first + count), *self.light, own_sun=self.own_sun)
                    span = (first, rows, rows.columns())
                    self._span = span
        return span

    def rows(self, probes: np.ndarray) -> ProbeLight:
        """The rows of ``probes`` (N,), made where not yet made this frame."""
        slots = np.take(self.slot, probes)
        missing = np.flatnonzero(slots < 0)
        if len(missing):
            with self._lock:
                asked = np.take(probes, missing)
                todo = asked[np.take(self.slot, asked) < 0]  # another frame thread may have made some meanwhile
                if len(todo):
                    new = distinct(todo, len(self.slot))
                    self._append(self.vis.frame_rows(new, *self.light, own_sun=self.own_sun))
                    self.slot[new] = np.arange(self._count - len(new), self._count, dtype=np.int32)
                slots[missing] = np.take(self.slot, asked)
        # Read after the slots: the store then holds every row they point to (rows are written before
        # their slots, and a grown store replaces the old one before its new slots are set).
        return self._store.take(slots)

    def _append(self, rows: ProbeLight) -> None:
        """Rows written after the made ones (under the lock), the store doubled when full: readers
        only read rows whose slots are set, so they never see a row being written."""
        count, store = self._count, self._store
        if count + len(rows) > len(store):
            room = max(2 * len(store), count + len(rows), self.FIRST_ROOM)
            grown = {k: np.empty((room,) + v.shape[1:], np.float32) for k, v in store.terms().items()}
            for k, v in grown.items():
                v[:count] = getattr(store, k)[:count]
            store = ProbeLight(**grown)
        for k, v in store.terms().items():
            v[count:count + len(rows)] = getattr(rows, k)
        self._store, self._count = store, count + len(rows)


def distinct(values: np.ndarray, bound: int) -> np.ndarray:
    """The sorted distinct ``values`` (N,) of 0..bound-1: a sort when they are few (a view's probes
    not yet made, once a job's frames share their light), a mark over ``bound`` when they are many."""
    if len(values) * 256 < bound:  # a sort beats a pass over 1.5 million marks below about 6,000
        return np.unique(values)
    mark = np.zeros(bound, bool)
    mark[values] = True
    return np.flatnonzero(mark)


class FrameLights:
    """A job's frame lights: frames whose sky and sun are exactly the same (every lighting but those
    whose clouds drift across the sky) share one ``FrameLight``, so a probe's row is made once a job
    rather than once a frame. Keeps the last ``keep`` (two frame threads may be on two skies)."""

    def __init__(self, keep: int = 2):
        self.keep = keep
        self._lights: list[FrameLight] = []
        self._lock = threading.Lock()

    def get(self, vis: SkyVisibility, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray,
            own_sun: bool = False) -> FrameLight:
        with self._lock:
            for light in self._lights:
                if light.matches(vis, sky_sh, sun_sh, sun_rgb, own_sun):
                    return light
            light = vis.frame_light(sky_sh, sun_sh, sun_rgb, own_sun=own_sun)
            self._lights = [light] + self._lights[: self.keep - 1]
            return light


# ---------------------------------------------------------------------------------------- bake
def face_frames(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit normals (F, 3) along the winding, areas (F,), centroids (F, 3)), float64."""
    v = mesh.vertices.astype(np.float64)
    f = mesh.faces
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    cross = np.cross(b - a, c - a)
    area2 = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(area2, 1e-30)[:, None]
    return normals, 0.5 * area2, (a + b + c) / 3.0


def assign_probes(normals: np.ndarray, centroids: np.ndarray, opaque: np.ndarray, cell_m: float,
                  cell_height_m: float) -> tuple[np.ndarray, int]:
    """(face_probe (F, 2) int32, probe count): probe = (cell, major axis of the side normal, and
    for opaque faces which side: the inside of a closed solid never shares a probe with an outside)."""
    n_faces = len(normals)
    cell = np.floor(centroids / np.array([cell_m, cell_m, cell_height_m])).astype(np.int64)
    if n_faces:
        cell -= cell.min(axis=0)
    span = cell.max(axis=0) + 1 if n_faces else np.ones(3, np.int64)
    keys = []
    for side, sign in enumerate((1.0, -1.0)):
        sn = sign * normals
        axis = np.argmax(np.abs(sn), axis=1)
        positive = sn[np.arange(n_faces), axis] > 0
        inside = opaque & (side == 1)
        bin_ = (axis * 2 + positive) * 2 + inside
        keys.append(((cell[:, 0] * span[1] + cell[:, 1]) * span[2] + cell[:, 2]) * 12 + bin_)
    unique, inverse = np.unique(np.stack(keys, axis=1).ravel(), return_inverse=True)
    return inverse.reshape(n_faces, 2).astype(np.int32), len(unique)


def sky_directions(count: int, rng: np.random.Generator) -> np.ndarray:
    """(count, 3) directions over the upper hemisphere, stratified in (cos theta, phi): equal solid angles."""
    # rows x cols strata of equal solid angle, exactly ``count`` of them (a partial row would bias the estimate)
    rows = min((r for r in range(1, count + 1) if count % r == 0), key=lambda r: abs(r - np.sqrt(count / 2)))
    cols = count // rows
    k = np.arange(count)
    z = (k // cols + rng.random(count)) / rows
    phi = 2.0 * np.pi * (k % cols + rng.random(count)) / cols
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def sky_hits(mesh, tracer: RayTracer, normals: np.ndarray, areas: np.ndarray, face_probe: np.ndarray, n_probes: int,
             box: tuple[np.ndarray, np.ndarray], rng: np.random.Generator, *, directions: int, spacing_m: float):
    """Outside-in visibility: for each sky direction, a grid of parallel rays (``spacing_m`` apart)
    enters ``box`` from that direction; a face side is hit by about ``V area cos / spacing^2`` of
    them. Returns (hits (F, 2), expected hits if nothing occluded (F, 2), per-probe SH sums (P, 16))."""
    lo, hi = box
    centre, radius = (lo + hi) / 2, float(np.linalg.norm(hi - lo) / 2) + 1.0
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    n_faces = len(normals)
    hits = np.zeros(2 * n_faces)
    open_hits = np.zeros((n_faces, 2))
    sh_sums = np.zeros((n_probes, sh.COUNT))
    probe_of_side = face_probe.ravel()
    for w in sky_directions(directions, rng):
        helper = np.array([1.0, 0.0, 0.0]) if abs(w[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(w, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(w, e1)
        u, v = (corners - centre) @ e1, (corners - centre) @ e2
        offset = rng.random(2) * spacing_m
        gu = np.arange(u.min() - spacing_m, u.max() + spacing_m, spacing_m) + offset[0]
        gv = np.arange(v.min() - spacing_m, v.max() + spacing_m, spacing_m) + offset[1]
        cos = normals @ w
        open_hits[:, 0] += np.maximum(cos, 0.0)
        open_hits[:, 1] += np.maximum(-cos, 0.0)
        for v0 in range(0, len(gv), max(1, RAYS_PER_WAVE // len(gu))):  # bounded memory per call
            V, U = np.meshgrid(gv[v0:v0 + max(1, RAYS_PER_WAVE // len(gu))], gu, indexing="ij")
            origins = (centre + radius * w + U.reshape(-1, 1) * e1 + V.reshape(-1, 1) * e2).astype(np.float32)
            res = tracer.intersect(origins, (-w).astype(np.float32)[None].repeat(len(origins), 0))
            prim = res.prim[res.hit]
            side = (res.normal[res.hit] @ w.astype(np.float32) < 0).astype(np.int64)  # 1: hit from behind the winding
            key = prim * 2 + side
            counts = np.bincount(key, minlength=2 * n_faces)
            hits += counts
            touched = np.nonzero(counts)[0]
            y = sh.basis(w[None])[0].astype(np.float64)
            sh_sums += np.bincount(probe_of_side[touched], weights=counts[touched], minlength=n_probes)[:, None] * y
    open_hits *= (areas / spacing_m**2)[:, None]
    return hits.reshape(n_faces, 2), open_hits, sh_sums


def camera_gain(mesh, tracer: RayTracer, rng: np.random.Generator, normals: np.ndarray, face_probe: np.ndarray,
                n_probes: int, v_face: np.ndarray, box, *, views: int, rays: int, height_m: float,
                elevation_deg: tuple[float, float], prior_rays: float) -> np.ndarray:
    """(P,) per probe: the sky seen by the points of its faces that cameras see, over those face
    sides' own visible fraction (``v_face`` (F, 2)). A camera sees the parts of a leaf or a fence
    that open toward it, and they see more sky than the face's average (hedges: 0.253 at the
    pixels against 0.199 over their faces), which one value per face cannot hold. ``views``
    cameras stand ``height_m`` over random walkable points of the garden (grass, ground or
    pavement with nothing above) and trace ``rays`` rays each at random headings within the rig's
    elevations; from each point hit, one cosine ray tests the sky. Each probe's escapes over its
    sampled sides' visible fractions, shrunk toward 1 by ``prior_rays`` pseudo-rays (at least
    ``MIN_SEEN_V`` visible) and capped at ``MAX_SEEN_GAIN``; 1 where no camera ray lands."""
    from eden_pipe import labels
    from eden_pipe.render.pathtrace import cosine_directions

    lo, hi = box
    n_sides = 2 * len(normals)
    top = np.column_stack([lo[:2] + rng.random((views, 2)) * (hi[:2] - lo[:2]), np.full(views, hi[2] + 1.0)])
    down = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (views, 1))
    floor = tracer.intersect(top.astype(np.float32), down)
    walkable = floor.hit & np.isin(np.take(mesh.semantic, np.maximum(floor.prim, 0)),
                                   [labels.GRASS, labels.GROUND, labels.PAVEMENT])
    eyes = top[walkable] - np.column_stack([np.zeros((walkable.sum(), 2)), floor.t[walkable] - height_m])
    count, escapes = np.zeros(n_sides), np.zeros(n_sides)
    per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    for first in range(0, len(eyes), per_wave):
        origin = np.repeat(eyes[first:first + per_wave], rays, axis=0)
        yaw = rng.random(len(origin)) * 2.0 * np.pi
        up = np.radians(elevation_deg[0] + (elevation_deg[1] - elevation_deg[0]) * rng.random(len(origin)))
        d = np.column_stack([np.cos(up) * np.cos(yaw), np.cos(up) * np.sin(yaw), np.sin(up)]).astype(np.float32)
        res = tracer.intersect(origin.astype(np.float32), d)
        h = np.flatnonzero(res.hit)
        dh = d[h]
        back = vec.dot(res.normal[h], dh) > 0  # the ray meets side 1
        side_normal = normals[res.prim[h]] * np.where(back, -1.0, 1.0)[:, None]
        points = origin[h] + dh * res.t[h, None]
        sky = cosine_directions(side_normal, rng.random(len(h)), rng.random(len(h)))
        free = ~tracer.occluded((points + side_normal * EPS).astype(np.float32), sky)
        side = res.prim[h] * 2 + back
        count += np.bincount(side, minlength=n_sides)
        escapes += np.bincount(side, weights=free, minlength=n_sides)
    probe = face_probe.ravel()
    seen = np.bincount(probe, weights=escapes, minlength=n_probes)
    expected = np.bincount(probe, weights=count * v_face.ravel(), minlength=n_probes)
    samples = np.bincount(probe, weights=count, minlength=n_probes)
    prior = prior_rays * np.maximum(expected / np.maximum(samples, 1e-12), MIN_SEEN_V)
    return np.minimum((seen + prior) / (expected + prior), MAX_SEEN_GAIN)


def bake(mesh, tracer: RayTracer, rng: np.random.Generator, *, directions: int, spacing_m: float, rays: int,
         cell_m: float, cell_height_m: float, ground_cell_m: float = 0.5, ground_reach_m: float = 30.0,
         ground_rays: int = 128, camera_views: int = 0, camera_rays: int = 4096, camera_height_m: float = 0.8,
         camera_elevation_deg: tuple[float, float] = (-31.0, 11.0), lightmap_cell_m: float = 0.0,
         lightmap_rays: int = 128, prior_hits: float = 4.0, prior_rays: float = 8.0) -> SkyVisibility:
    """The bake (see the module doc): the sky transfer from outside-in ray bundles, the bounce from
    ``rays`` cosine rays per probe (all rays of a wave in one Embree call); with ``camera_views``,
    each face side's exposure is scaled to the sky of the points of it that cameras see
    (:func:`camera_gain`); with ``lightmap_cell_m``, faces wider than a cell get a lightmap
    (:mod:`eden_pipe.render.lightmap`)."""
    from eden_pipe import labels

    normals, areas, centroids = face_frames(mesh)
    n_faces = len(normals)
    opaque = mesh.translucency <= 0
    face_probe, n_probes = assign_probes(normals, centroids, opaque, cell_m, cell_height_m)
    side_area = np.repeat(areas, 2)
    sign = np.array([1.0, -1.0])
    mean_normal = np.zeros((n_probes, 3))
    for k in range(3):
        mean_normal[:, k] = np.bincount(face_probe.ravel(), weights=side_area * np.outer(normals[:, k], sign).ravel(),
                                        minlength=n_probes)
    mean_normal = vec.normalize(mean_normal, 1e-12)

    # Sky transfer, outside-in, over the garden's box; faces outside it (the skirt of distant ground)
    # get a ground map (``ground_map``) where they are flat, else the open sky.
    garden = mesh.semantic != labels.BACKGROUND
    pad = 0.01
    if np.any(garden):
        used = mesh.vertices[mesh.faces[garden].ravel()]
        box = (used.min(axis=0).astype(np.float64) - pad, used.max(axis=0).astype(np.float64) + pad)
        v = mesh.vertices[mesh.faces]
        covered = np.all((v >= box[0]) & (v <= box[1]), axis=(1, 2))
    else:
        box, covered = None, np.zeros(n_faces, bool)
    hits = np.zeros((n_faces, 2))
    open_hits = np.zeros((n_faces, 2))
    sh_sums = np.zeros((n_probes, sh.COUNT))
    if box is not None:
        hits, open_hits, sh_sums = sky_hits(mesh, tracer, normals, areas, face_probe, n_probes, box, rng,
                                            directions=directions, spacing_m=spacing_m)
    hits[~covered], open_hits[~covered] = 0.0, 0.0
    probe_hits = np.bincount(face_probe.ravel(), weights=hits.ravel(), minlength=n_probes)
    probe_open = np.bincount(face_probe.ravel(), weights=open_hits.ravel(), minlength=n_probes)
    probe_covered = np.bincount(face_probe.ravel(), weights=np.repeat(covered, 2) * side_area, minlength=n_probes)
    # T_p = area-weighted mean transfer of the probe's covered sides: hits * spacing^2 / area * 2/J
    transfer = sh_sums * (spacing_m**2 * 2.0 / max(directions, 1)) / np.maximum(probe_covered, 1e-12)[:, None]
    uncovered = probe_covered <= 0
    transfer[uncovered] = sh.open_transfer(mean_normal[uncovered].astype(np.float32))
    visible = np.where(probe_open > 0, probe_hits / np.maximum(probe_open, 1e-12), 1.0)
    # Each side's own cosine-weighted visible sky (its hit fraction, shrunk toward its probe's by
    # ``prior_hits`` pseudo-hits where few rays reach a tiny face, times its own open-sky factor
    # 2/J sum cos+), as a ratio to its probe's transfer: the probe gives the shape, the face the amount.
    v_probe = visible[face_probe]
    open_factor = open_hits * (spacing_m**2 * 2.0 / max(directions, 1)) / np.maximum(areas, 1e-12)[:, None]
    v_face = (hits + prior_hits * v_probe) / (open_hits + prior_hits) * open_factor
    probe_visible = transfer[:, 0] / sh.basis(np.zeros((1, 3)))[0, 0]
    exposure = exposure_of(v_face, probe_visible[face_probe])
    exposure[~covered] = 1.0
    # What the render reads: the camera's share of each side. The bounce below keeps the plain
    # exposure (the points random bounce rays meet are not drawn by a camera).
    seen_exposure = exposure
    if camera_views > 0 and box is not None:
        gain = camera_gain(mesh, tracer, rng.spawn(1)[0], normals, face_probe, n_probes, v_face, box, views=camera_views,
                           rays=camera_rays, height_m=camera_height_m, elevation_deg=camera_elevation_deg,
                           prior_rays=prior_rays)
        limit = 1.0 / np.maximum(probe_visible[face_probe], 1e-6)  # a side sees at most all of its sky
        seen_exposure = np.where(covered[:, None], np.minimum(exposure * gain[face_probe], limit), 1.0)
    # Its own generator (after camera_gain's): the bounce and ground map below draw what they drew without it.
    lightmaps = bake_lightmaps(mesh, tracer, rng.spawn(1)[0], normals, areas, covered, cell_m=lightmap_cell_m,
                               rays=lightmap_rays)

    # Bounce: cosine rays from each probe; what the blocked ones hit, lit as that face side is lit.
    blocked_albedo = np.zeros((n_probes, 3))
    sides = np.argsort(face_probe.ravel(), kind="stable")
    side_probe = face_probe.ravel()[sides]
    cum_area = np.cumsum(np.maximum(side_area[sides], 1e-12))
    first = np.searchsorted(side_probe, np.arange(n_probes))
    last = np.append(first[1:], len(sides)) - 1
    area_before = np.where(first > 0, cum_area[np.maximum(first - 1, 0)], 0.0)
    span = cum_area[last] - area_before
    hit_face = np.full((n_probes, rays), -1, np.int32)
    hit_back = np.zeros((n_probes, rays), bool)
    probes_per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    from eden_pipe.render.pathtrace import cosine_directions, stratified_uniforms

    for p0 in range(0, n_probes if rays else 0, probes_per_wave):
        probes = np.arange(p0, min(n_probes, p0 + probes_per_wave))
        n = len(probes)
        tiled = np.tile(probes, rays)
        target = area_before[tiled] + rng.random(len(tiled)) * span[tiled]
        member = np.clip(np.searchsorted(cum_area, target), first[tiled], last[tiled])
        face, back = sides[member] // 2, sides[member] % 2 == 1
        side_normal = normals[face] * np.where(back, -1.0, 1.0)[:, None]
        r1, r2 = rng.random(len(face)), rng.random(len(face))
        s1 = np.sqrt(r1)
        tri = mesh.faces[face]
        vtx = mesh.vertices
        point = ((1 - s1)[:, None] * vtx[tri[:, 0]] + (s1 * (1 - r2))[:, None] * vtx[tri[:, 1]]
                 + (s1 * r2)[:, None] * vtx[tri[:, 2]])
        u1, u2 = stratified_uniforms(n, 0, rays, rays, rng)
        dirs = cosine_directions(side_normal, u1.ravel(), u2.ravel())
        res = tracer.intersect((point + side_normal * EPS).astype(np.float32), dirs)
        alb = mesh.albedo[np.where(res.hit, res.prim, 0)] * res.hit[:, None]
        for k in range(3):
            blocked_albedo[probes, k] += np.bincount(tiled - p0, weights=alb[:, k], minlength=n)
        hit_face[probes] = np.where(res.hit, res.prim, -1).reshape(rays, n).T
        # The hit face's side that faces the ray's origin: 1 when the ray travels along its winding normal.
        hit_back[probes] = (vec.dot(res.normal, dirs) > 0).reshape(rays, n).T
    blocked_albedo /= max(rays, 1)
    multi = 1.0 / (1.0 - np.minimum(blocked_albedo, MAX_BLOCKED_ALBEDO))
    bounce, tint = bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure)
    ground = ground_map(mesh, tracer, rng, normals, covered, box, face_probe, transfer, exposure, multi, rays=ground_rays,
                        cell_m=ground_cell_m, reach_m=ground_reach_m)
    if ground is not None:
        transfer, mean_normal = np.concatenate([transfer, ground.transfer]), np.concatenate([mean_normal, ground.normal])
        bounce, tint = np.concatenate([bounce, ground.bounce]), np.concatenate([tint, ground.tint])
    return SkyVisibility(face_probe, seen_exposure.astype(np.float32), transfer.astype(np.float32),
                         mean_normal.astype(np.float32), bounce.astype(np.float32), tint.astype(np.float32),
                         *(ground.grid_fields(n_probes) if ground is not None else GroundGrid.none()), lightmaps)


@dataclass
class GroundGrid:
    """Sky transfer and bounce of a flat ground outside the bake's box (the skirt of distant land
    around the garden), on a grid of nodes: one face covers metres there, and its sky is hidden by
    the garden's hedges, trees and fence by an amount that falls with the distance to them."""

    x0: float
    y0: float
    cell: float
    nx: int
    ny: int
    transfer: np.ndarray  # (ny * nx, 16), rows of y then x
    normal: np.ndarray
    bounce: np.ndarray
    tint: np.ndarray
    faces: np.ndarray     # (K,) the faces it lights

    def grid_fields(self, first: int) -> tuple[np.ndarray, np.ndarray]:
        return self.faces, np.array([self.x0, self.y0, self.cell, self.nx, self.ny, first], np.float64)

    @staticmethod
    def none() -> tuple[np.ndarray, np.ndarray]:
        return np.zeros(0, np.int32), np.zeros(6, np.float64)

    @staticmethod
    def blend(grid: np.ndarray, light: FrameLight, points: np.ndarray) -> ProbeLight:
        """The bilinear blend of the nodes' rows of the frame's ``light`` at ``points`` (N, 3)
        (clamped to the grid, whose outer ring is open sky): every term in one table lookup
        (``lut.sample``, 2.3 times faster than four gathers and weighted sums)."""
        x0, y0, cell, nx, ny, first = grid
        nx, ny, first = int(nx), int(ny), int(first)
        fx = np.clip((points[:, 0] - x0) / cell, 0.0, nx - 1.000001).astype(np.float32)
        fy = np.clip((points[:, 1] - y0) / cell, 0.0, ny - 1.000001).astype(np.float32)
        table = light.span_columns(first, nx * ny)
        return light.span(first, nx * ny).from_columns(lut.sample(table.reshape(ny, nx, -1), fx, fy))


def ground_map(mesh, tracer: RayTracer, rng: np.random.Generator, normals: np.ndarray, covered: np.ndarray, box,
               face_probe: np.ndarray, transfer: np.ndarray, exposure: np.ndarray, multi: np.ndarray, *,
               rays: int, cell_m: float, reach_m: float) -> GroundGrid | None:
    """The ground map of the flat, upward faces outside ``box`` (None if there are none): nodes
    every ``cell_m`` out to ``reach_m`` beyond the box, each with ``rays`` stratified cosine rays
    from the ground's plane (the transfer is their mean ``V Y``, the bounce what the blocked ones
    hit, as for a probe). Nodes under the box's footprint sit on its outline (no pixel of the map
    lies there but the blend reaches them); the outer ring is open sky, so the map fades to it."""
    faces = np.nonzero(~covered & (np.abs(normals[:, 2]) > 0.999))[0]
    if box is None or not len(faces) or rays <= 0:
        return None
    z = float(np.median(mesh.vertices[mesh.faces[faces]][..., 2]))
    lo, hi = box[0][:2] - reach_m, box[1][:2] + reach_m
    nx, ny = (np.ceil((hi - lo) / cell_m).astype(int) + 1).tolist()
    gy, gx = np.meshgrid(lo[1] + cell_m * np.arange(ny), lo[0] + cell_m * np.arange(nx), indexing="ij")
    xy = np.stack([gx.ravel(), gy.ravel()], axis=1)
    # Nodes under the box's footprint move out to its outline (the ground there is the garden's own).
    inner_lo, inner_hi = box[0][:2], box[1][:2]
    inside = np.all((xy > inner_lo) & (xy < inner_hi), axis=1)
    gap = np.stack([xy - inner_lo, inner_hi - xy], axis=1)  # (N, 2 sides, 2 axes)
    nearest = np.argmin(gap.reshape(-1, 4), axis=1)
    snapped = xy.copy()
    axis, upper = nearest % 2, nearest // 2
    rows = np.arange(len(xy))
    snapped[rows, axis] = np.where(upper == 1, inner_hi[axis] + 0.01, inner_lo[axis] - 0.01)
    xy = np.where(inside[:, None], snapped, xy)
    border = (gx == gx.min()) | (gx == gx.max()) | (gy == gy.min()) | (gy == gy.max())
    traced = np.nonzero(~border.ravel())[0]
    n = len(xy)
    up = np.array([0.0, 0.0, 1.0])
    node_transfer = np.tile(sh.open_transfer(up[None].astype(np.float32)), (n, 1)).astype(np.float64)
    hit_face = np.full((n, rays), -1, np.int32)
    hit_back = np.zeros((n, rays), bool)
    from eden_pipe.render.pathtrace import cosine_directions, stratified_uniforms

    per_wave = max(1, RAYS_PER_WAVE // rays)
    for p0 in range(0, len(traced), per_wave):
        nodes = traced[p0:p0 + per_wave]
        m = len(nodes)
        u1, u2 = stratified_uniforms(m, 0, rays, rays, rng)
        dirs = cosine_directions(np.broadcast_to(up, (m * rays, 3)), u1.ravel(), u2.ravel())
        origins = np.tile(np.column_stack([xy[nodes], np.full(m, z + EPS)]), (rays, 1)).astype(np.float32)
        res = tracer.intersect(origins, dirs)
        open_ = (~res.hit).astype(np.float64)
        node_transfer[nodes] = ((sh.basis(dirs).astype(np.float64) * open_[:, None]).reshape(rays, m, sh.COUNT)
                                .mean(axis=0))
        hit_face[nodes] = np.where(res.hit, res.prim, -1).reshape(rays, m).T
        hit_back[nodes] = (vec.dot(res.normal, dirs) > 0).reshape(rays, m).T
    bounce, tint = bounce_transfer(mesh, hit_face, hit_back, multi, face_probe, transfer, exposure)
    return GroundGrid(float(lo[0]), float(lo[1]), cell_m, nx, ny, node_transfer, np.tile(up, (n, 1)), bounce, tint,
                      faces=faces.astype(np.int32))


def bounce_transfer(mesh, hit_face: np.ndarray, hit_back: np.ndarray, multi: np.ndarray, face_probe: np.ndarray,
                    transfer: np.ndarray, exposure: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(bounce (R, 16), tint (R, 3)) of R receivers from what their cosine rays hit (``hit_face``
    (R, rays), -1 where a ray escaped; ``hit_back`` the side of the hit face facing the receiver):
    the hit face side's light as seen from the receiver (see the module doc); ``multi`` (P, 3) is each
    probe's multi-bounce factor, applied where it is hit. In waves of bounded memory."""
    n_recv, rays = hit_face.shape
    bounce = np.zeros((n_recv, sh.COUNT))
    tint = np.zeros((n_recv, 3))
    per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    for p0 in range(0, n_recv if rays else 0, per_wave):
        p1 = min(n_recv, p0 + per_wave)
        f = hit_face[p0:p1].ravel()
        rows = np.repeat(np.arange(p1 - p0), rays)
        blocked = f >= 0
        f, b, rows = f[blocked], hit_back[p0:p1].ravel()[blocked].astype(np.int64), rows[blocked]
        near, far = face_probe[f, b], face_probe[f, 1 - b]
        weight_rgb = mesh.albedo[f] * multi[near]
        light = (transfer[near] * exposure[f, b][:, None]
                 + (mesh.translucency[f] * exposure[f, 1 - b])[:, None] * transfer[far])
        weight = weight_rgb @ LUMA
        for k in range(sh.COUNT):
            bounce[p0:p1, k] = np.bincount(rows, weights=weight * light[:, k], minlength=p1 - p0)
        for k in range(3):
            tint[p0:p1, k] = np.bincount(rows, weights=weight_rgb[:, k], minlength=p1 - p0)
    bounce /= max(rays, 1)
    tint_luma = tint @ LUMA
    tint = np.where(tint_luma[:, None] > 1e-9, tint / np.maximum(tint_luma, 1e-9)[:, None], 1.0)
    return bounce, tint
