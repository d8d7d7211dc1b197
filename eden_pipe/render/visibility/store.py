"""The bake's store: :class:`SkyVisibility`, its file, and what a render reads from it.

The bake (:mod:`eden_pipe.render.visibility.bake`) makes one per garden; the
render stage loads it and looks up each hit's probe, exposure and light (see
:mod:`eden_pipe.render.visibility` for the method).
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from eden_pipe.io.half_float import widen
from eden_pipe.render import kernels, sh, vec
from eden_pipe.render.lightmap import Lightmaps
from eden_pipe.render.visibility.frame_light import FrameLight, ProbeLight, sh_dot
from eden_pipe.render.visibility.ground_map import GroundGrid
from eden_pipe.render.visibility.shadow_maps import ShadowMaps

MIN_BLOCKED = 0.05  # the least blocked fraction a probe's bounce is divided by (blocked_radiance)
MIN_OPEN_TRANSFER = 0.02  # the least open transfer along a direction mirror_fraction divides by (about 1/17 of head-on)
# sh.open_transfer(n) . sh.basis(w) as a polynomial in cos(n, w): (1 + 2c + 0.625 (3c^2 - 1)) / (4 pi)
OPEN_ALONG = np.array([1.0 - 0.625, 2.0, 1.875], np.float32) / np.float32(4.0 * np.pi)
ON_GROUND_MAP = np.float32(np.inf)  # a side's exposure in the sides table: its face is lit through the ground map


@dataclass
class SkyVisibility:
    """The bake: ``face_probe`` (F, 2) probe of each face side (0: the side its winding's normal
    points to, 1: the other); per probe ``transfer`` (P, 16), ``normal`` (P, 3) mean side normal,
    ``bounce`` (P, 16) of sky light, ``sun_bounce`` (P, 16) of the sun's (without the multi-bounce
    factor unless the bake was asked for it) and ``tint`` (P, 3)."""

    face_probe: np.ndarray
    exposure: np.ndarray
    transfer: np.ndarray
    normal: np.ndarray
    bounce: np.ndarray
    sun_bounce: np.ndarray
    tint: np.ndarray
    ground_faces: np.ndarray  # (K,) int32 faces lit through the ground map (none: empty)
    ground_grid: np.ndarray  # (6,) float64 x0, y0, cell, nx, ny, first probe of the map's nodes
    lightmaps: Lightmaps  # the visible sky over large faces, node by node (none: Lightmaps.none())
    shadow_maps: ShadowMaps = dataclasses.field(default_factory=ShadowMaps.none)  # the bundles' depth maps
    # (F, 2, 3) uint16 each face side's sky at three points of it (face_sky.face_sky_table); (0, 2, 3): none;
    # (F, 2, 8) with the directions' moments (render.sky_visibility.face_sky_moments, face_sky.side_moments)
    face_sky: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 2, 3), np.uint16))

    FIELDS = ("face_probe", "exposure", "transfer", "normal", "bounce", "sun_bounce", "tint")
    EXACT = ("ground_faces", "ground_grid")  # kept at full precision

    def save(self, path: Path) -> None:
        table: dict[str, Any] = {"face_sky": self.face_sky} if len(self.face_sky) else {}  # none: as before
        np.savez(
            path,
            face_probe=self.face_probe,
            **{k: getattr(self, k) for k in self.EXACT},
            **{k: getattr(self, k).astype(np.float16) for k in self.FIELDS[1:]},
            **{f"lightmap_{k}": getattr(self.lightmaps, k) for k in Lightmaps.FIELDS},
            **self.shadow_maps.arrays(),
            **table,
        )

    @classmethod
    def load(cls, path: Path) -> SkyVisibility:
        """The bake from its file, as the render reads it: the sides table (:meth:`sides_of`) made
        now, ``face_probe`` a view of it and ``exposure`` the file's float16 (the render reads
        both through that table: one copy of each instead of two, 70 MB less for the default
        garden); the probes' fields float32."""
        with np.load(path) as data:
            vis = cls(
                face_probe=data["face_probe"],
                exposure=data["exposure"],
                **{k: widen(data[k]) for k in cls.FIELDS[2:]},
                **{k: data[k] for k in cls.EXACT},
                lightmaps=Lightmaps(*(data[f"lightmap_{k}"] for k in Lightmaps.FIELDS)),
                shadow_maps=ShadowMaps.read(data),
                **({"face_sky": data["face_sky"]} if "face_sky" in data.files else {}),
            )
        vis.face_probe = vis._sides[:, 0].reshape(-1, 2)
        return vis

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
        exposure = widen(self.exposure) if self.exposure.dtype == np.float16 else np.array(self.exposure, np.float32)
        exposure[self.lightmaps.faces] = -1.0 - np.arange(len(self.lightmaps.faces), dtype=np.float32)[:, None]
        exposure[self.ground_faces] = ON_GROUND_MAP
        return np.stack([self.face_probe.ravel().astype(np.int32), exposure.ravel().view(np.int32)], axis=1)

    def frame_light(
        self, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray, own_sun: bool = False
    ) -> FrameLight:
        """The per-probe light of one frame (:meth:`frame_rows`), made as the frame's views need it."""
        return FrameLight(self, sky_sh, sun_sh, sun_rgb, own_sun)

    def frame_rows(
        self, probes: np.ndarray, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray, own_sun: bool = False
    ) -> ProbeLight:
        """The light of the ``probes`` (N,) under one frame's sky and sun (a :class:`ProbeLight`): the
        sky term ``T . L - v open(nbar)``, the probe's visible fraction v, the bounce of sky light and of
        the sun (per unit cloud transmittance); with ``own_sun`` also the open sky of the probe's mean
        normal ``open(nbar) = T_open(nbar) . L`` and its band-limited sun ``E_sun max(T . Y(sun), 0)``
        (per unit cloud transmittance: the light of the surfaces a mirror ray hits). A pixel only
        gathers a row and adds its own normal's open sky (the exact ``ambient``) times v: an open
        probe's sky term is exactly zero, its pixels see exactly the open sky. A row depends on its
        probe alone (``sh_dot``), whatever other probes it is made with."""
        transfer, tint = vec.take(self.transfer, probes), vec.take(self.tint, probes)
        # The transfer, the open transfer of the mean normal, the bounce and the sun's bounce against
        # the sky (3) and the sun (1), probes last (the sun's bounce is read against the sun only).
        coeffs = (
            np.stack(
                [
                    transfer,
                    sh.open_transfer(vec.take(self.normal, probes)),
                    vec.take(self.bounce, probes),
                    vec.take(self.sun_bounce, probes),
                ]
            )
            .transpose(0, 2, 1)
            .copy()
        )
        lit = sh_dot(coeffs, np.concatenate([sky_sh, sun_sh[:, None]], axis=1)).transpose(2, 0, 1)  # (N, 4, 4)
        visible = np.multiply(transfer[:, 0], np.float32(1.0 / sh.basis(np.zeros((1, 3)))[0, 0]))
        open_ = np.ascontiguousarray(lit[:, 1, 0:3])
        sky = np.ascontiguousarray(lit[:, 0, 0:3])
        sky -= visible[:, None] * open_
        sun = np.maximum(lit[:, 3, 3:4], np.float32(0.0))  # the sun's bounce
        return ProbeLight(
            sky,
            visible,
            lit[:, 2, 0:3] * tint,
            np.multiply(tint, sun * sun_rgb),
            open_ if own_sun else None,
            np.multiply(np.maximum(lit[:, 0, 3:4], np.float32(0.0)), sun_rgb) if own_sun else None,
        )

    def lookup(
        self,
        light: FrameLight,
        prim: np.ndarray,
        back: np.ndarray,
        points: np.ndarray,
        sides: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> tuple[ProbeLight, np.ndarray]:
        """(the frame's ``light`` of N face sides (a :class:`ProbeLight`), exposures (N,)) for face
        sides (``back`` (N,) true for side 1) seen at ``points`` (N, 3): points on a face with a
        lightmap take their exposure from
        its nodes (their visible sky over the probe's), points on the ground map's faces blend its
        four nearest nodes. ``sides``: the sides' probes and exposures where the caller has them
        (:meth:`sides_of`)."""
        probes, exposure = self.sides_of(prim, back) if sides is None else sides
        rows, exposure = light.rows(probes), exposure.copy()
        if len(self.lightmaps.faces) and len(mapped := np.flatnonzero(exposure < 0)):
            # Sides with a lightmap: their visible sky at the point over the probe's.
            visible = self.lightmaps.visible_at(
                (np.float32(-1.0) - vec.take(exposure, mapped)).astype(np.int32),
                vec.take(back, mapped),
                vec.gather(points, mapped),
            )
            exposure[mapped] = exposure_of(visible, vec.take(rows.visible, mapped))
        if len(self.ground_faces):
            on_map = np.flatnonzero(self.on_ground_map(exposure))
            if len(on_map):
                rows.put(on_map, GroundGrid.blend(self.ground_grid, light, vec.gather(points, on_map)))
                exposure[on_map] = 1.0
        return rows, exposure

    @staticmethod
    def bounce_light(rows: ProbeLight, cloud: np.ndarray | None) -> np.ndarray:
        """(N, 3) the bounce from :meth:`lookup` rows: of sky light, and of sun light times ``cloud``
        (N,) (None: no sun), at least zero."""
        return kernels.bounce_light(rows.bounce_sky, rows.bounce_sun, cloud)

    @staticmethod
    def irradiance(rows: ProbeLight, exposure: np.ndarray, ambient_n: np.ndarray, bounce: np.ndarray) -> np.ndarray:
        """Dind (N, 3) from :meth:`lookup` rows: the visible sky, corrected from the probe's mean
        normal to the pixel's (``ambient_n``: the open sky's irradiance/pi at its normal), scaled by
        the face side's exposure; plus ``bounce`` (:meth:`bounce_light`)."""
        return kernels.indirect_light(rows.sky, rows.visible, exposure, ambient_n, bounce)

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

    @property
    def has_side_moments(self) -> bool:
        """Whether the face table holds each side's sky directions (``face_sky_table``'s moments)."""
        from eden_pipe.render.visibility.face_sky import SIDE_COLUMNS

        return len(self.face_sky) > 0 and self.face_sky.shape[2] == SIDE_COLUMNS

    def sides_of(self, prim: np.ndarray, back: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """((N,) probe, (N,) exposure) of each face side (``back`` (N,) true for side 1); a side with
        a lightmap has -1 - its lightmap's row for exposure, one of the ground map's faces
        ``ON_GROUND_MAP`` (:meth:`lookup` replaces both)."""
        both = vec.take(self._sides, prim.astype(np.int64) * 2 + back)
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
        seen = sh.along(self.transfer, probes, directions)
        # The open transfer along w depends on cos(nbar, w) alone: sum_l COSINE_l (2l+1)/(4 pi) P_l(cos).
        cos = vec.dot(vec.take(self.normal, probes), directions)
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
    def blocked_radiance(bounce: np.ndarray, probe_visible: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
        """(N, 3) float32 mean radiance of what hides the sky of face sides: rows ``index`` (N,; None:
        all) of their ``bounce`` (M, 3) float32 (:meth:`bounce_light`) over their probe's cosine-weighted
        blocked fraction (from its visible fraction ``probe_visible`` (M,) float32, a :meth:`lookup`
        row's ``visible``; kept above ``MIN_BLOCKED``: an open probe's bounce is near zero, its
        mean is not), in one compiled pass. The bounce is the probe's, one value for all its
        sides, so it is divided by the probe's fraction, not by the side's own: 1 / (1 - v) grows
        fast as a side's visible fraction v nears 1, and the sides that see more sky than their
        probe read far more light than the others lose (docs/realism.md, The light a blocked mirror
        reads)."""
        rows = np.arange(len(probe_visible)) if index is None else index
        return kernels.blocked_radiance(bounce, probe_visible, rows, np.float32(MIN_BLOCKED))

    @staticmethod
    def surface_light(rows: ProbeLight, exposure: np.ndarray, cloud: np.ndarray | None) -> np.ndarray:
        """(N, 3) irradiance/pi of face sides seen along secondary rays, from :meth:`lookup` rows (of a
        ``frame_light(own_sun=True)``) at the probe's mean normal: sky, bounce and the band-limited sun
        (``cloud`` (N,), None: no sun)."""
        light = (rows.sky + rows.open * rows.visible[:, None]) * exposure[:, None] + np.maximum(
            rows.bounce_sky, np.float32(0.0)
        )
        if cloud is not None:
            light = light + (rows.bounce_sun + rows.sun * exposure[:, None]) * cloud[:, None]
        return np.maximum(light, np.float32(0.0))


def exposure_of(visible: np.ndarray, probe_visible: np.ndarray) -> np.ndarray:
    """A face side's exposure: its cosine-weighted visible sky over its probe's (0 where the probe
    sees none)."""
    return np.where(probe_visible > 1e-6, visible / np.maximum(probe_visible, 1e-6), 0.0)
