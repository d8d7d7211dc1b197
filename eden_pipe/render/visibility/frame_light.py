"""A frame's light: the bake's per-probe light under one frame's sky and sun, made as views need it.

:class:`FrameLight` makes the rows of :meth:`SkyVisibility.frame_rows
<eden_pipe.render.visibility.store.SkyVisibility.frame_rows>` probe by probe,
:class:`FrameLights` shares them between the frames of a job under the same
sky, :class:`ProbeLight` holds them one contiguous array per term.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from eden_pipe.render import kernels, sh, vec

if TYPE_CHECKING:
    from eden_pipe.render.visibility.store import SkyVisibility


def sh_dot(coeffs: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """(..., 16, N) SH coefficients of N points, points last, times (16, C) radiance -> (..., C, N)
    float32, summed term by term in a fixed order: a row's value does not depend on how many rows
    are made with it (a BLAS product's blocking does), so light made for a view's probes equals
    light made for all of them. Points last, each term is one product over long rows (2.3 times
    faster than points first, whose rows of three or four are too short to vectorise)."""
    radiance = np.asarray(radiance, np.float32)[:, :, None]
    out = coeffs[..., 0:1, :] * radiance[0]
    for k in range(1, sh.COUNT):
        out += coeffs[..., k : k + 1, :] * radiance[k]
    return out


@dataclass
class ProbeLight:
    """A frame's light of N probes or face sides (``SkyVisibility.frame_rows``, gathered by
    ``FrameLight.rows``, blended by ``GroundGrid.blend``), one contiguous array per term: a pixel's
    arithmetic on (N, 3) arrays runs on numpy's contiguous loops, where the columns of one (N, 13)
    table each ran a strided loop three wide (2-3 times slower)."""

    sky: np.ndarray  # (N, 3) the sky term T . L - v open(nbar)
    visible: np.ndarray  # (N,) the probe's cosine-weighted visible fraction v
    bounce_sky: np.ndarray  # (N, 3) the bounce of sky light
    bounce_sun: np.ndarray  # (N, 3) the bounce of the sun, per unit cloud transmittance
    open: np.ndarray | None = None  # (N, 3) open(nbar), with own_sun (SkyVisibility.surface_light)
    sun: np.ndarray | None = None  # (N, 3) the band-limited sun per unit cloud transmittance, with own_sun

    TERMS = ("sky", "visible", "bounce_sky", "bounce_sun", "open", "sun")

    @classmethod
    def empty(cls, own_sun: bool) -> ProbeLight:
        three = lambda: np.zeros((0, 3), np.float32)  # noqa: E731
        return cls(
            three(),
            np.zeros(0, np.float32),
            three(),
            three(),
            three() if own_sun else None,
            three() if own_sun else None,
        )

    def __len__(self) -> int:
        return len(self.visible)

    def terms(self) -> dict[str, np.ndarray]:
        return {k: getattr(self, k) for k in self.TERMS if getattr(self, k) is not None}

    def take(self, index: np.ndarray) -> ProbeLight:
        """The rows ``index`` (N,) (a signed integer array): for float32 terms in one compiled pass
        (``kernels.take_light_rows``), each (N, 3) term a contiguous block of one array."""
        terms = self.terms()
        wide = [k for k in terms if k != "visible"]
        index = np.asarray(index)
        if (
            index.ndim == 1
            and index.dtype.kind == "i"
            and all(
                v.dtype == np.float32 and v.flags.c_contiguous and v.shape == (len(self), 3)
                for v in (terms[k] for k in wide)
            )
            and self.visible.dtype == np.float32
        ):
            rows, visible = kernels.take_light_rows(tuple(terms[k] for k in wide), self.visible, index)
            return ProbeLight(visible=visible, **{k: rows[j] for j, k in enumerate(wide)})
        return ProbeLight(**{k: vec.take(v, index) for k, v in terms.items()})

    def put(self, index: np.ndarray, rows: ProbeLight) -> None:
        """Rows ``index`` replaced by ``rows``."""
        for k, v in self.terms().items():
            v[index] = getattr(rows, k)

    def columns(self) -> np.ndarray:
        """(N, C) float32 the terms side by side, in ``TERMS`` order (:meth:`from_columns` splits them)."""
        return np.column_stack(list(self.terms().values())).astype(np.float32, copy=False)

    def from_columns(self, columns: np.ndarray) -> ProbeLight:
        """Rows laid out as this light's :meth:`columns`, split into contiguous terms."""
        out, at = {}, 0
        for k, v in self.terms().items():
            width = v.shape[1] if v.ndim == 2 else 1
            out[k] = np.ascontiguousarray(columns[:, at] if v.ndim == 1 else columns[:, at : at + width])
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

    def __init__(
        self, vis: SkyVisibility, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray, own_sun: bool = False
    ):
        self.vis, self.own_sun = vis, own_sun
        self.light = (np.asarray(sky_sh, np.float32), np.asarray(sun_sh, np.float32), np.asarray(sun_rgb, np.float32))
        self.slot = np.full(vis.n_probes, -1, np.int32)  # each probe's row in ``made``; -1: not made yet
        self._store = ProbeLight.empty(own_sun)  # rows 0..count-1 made, the rest room to grow
        self._count = 0
        self._lock = threading.Lock()  # frame threads may share a frame's light
        self._span: tuple[int, ProbeLight, np.ndarray] | None = None
        self._fit: np.ndarray | None = None

    def hemisphere_fit(self, radiance) -> np.ndarray:
        """(1 + MOMENTS, 3) this light's sky fitted over the upper hemisphere
        (``shadow_maps.hemisphere_fit`` of ``radiance``, the sky's radiance function), made once: the
        frames that share this light share its sky."""
        if self._fit is None:
            from eden_pipe.render.visibility.shadow_maps import hemisphere_fit

            fit = hemisphere_fit(radiance)
            with self._lock:
                if self._fit is None:
                    self._fit = fit
        return self._fit

    def matches(
        self, vis: SkyVisibility, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray, own_sun: bool
    ) -> bool:
        """Whether this is the light of ``vis`` under exactly this sky and sun."""
        return (
            self.vis is vis
            and self.own_sun == own_sun
            and all(  # self.light holds these three, in this order
                np.array_equal(a, np.asarray(b, np.float32))
                for a, b in zip(self.light, (sky_sh, sun_sh, sun_rgb), strict=True)
            )
        )

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
        slots = vec.take(self.slot, probes)
        missing = np.flatnonzero(slots < 0)
        if len(missing):
            with self._lock:
                asked = vec.take(probes, missing)
                todo = asked[vec.take(self.slot, asked) < 0]  # another frame thread may have made some meanwhile
                if len(todo):
                    new = distinct(todo, len(self.slot))
                    self._append(self.vis.frame_rows(new, *self.light, own_sun=self.own_sun))
                    self.slot[new] = np.arange(self._count - len(new), self._count, dtype=np.int32)
                slots[missing] = vec.take(self.slot, asked)
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
            v[count : count + len(rows)] = getattr(rows, k)
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

    def get(
        self, vis: SkyVisibility, sky_sh: np.ndarray, sun_sh: np.ndarray, sun_rgb: np.ndarray, own_sun: bool = False
    ) -> FrameLight:
        with self._lock:
            for light in self._lights:
                if light.matches(vis, sky_sh, sun_sh, sun_rgb, own_sun):
                    return light
            light = vis.frame_light(sky_sh, sun_sh, sun_rgb, own_sun=own_sun)
            self._lights = [light] + self._lights[: self.keep - 1]
            return light
