"""Ray casting with Intel Embree: the default, all-modality backend.

One Embree scene per garden holds the flattened world triangle soup (Embree 4
via embreex has no instancing). Two paths trace it (``render.tracer``,
docs/design.md "Ray tracing"): ``native`` calls embreex's bundled Embree
library from compiled loops (:mod:`embree_native`, :mod:`embree_kernels`),
sends an image's rays or a subset of its pixels as coherent 16-ray packets
over 4x4 tiles, and shares the mesh's arrays with Embree; ``embreex`` traces
through embreex's per-ray wrapper. Both give the same hits bit for bit (the
native path checks that on a test scene before use; ``auto`` falls back to
embreex with a warning when it cannot). Queries are split into chunks across a
thread pool: both paths release the GIL while they trace.

Directions need not be unit length: ``t`` comes back in units of the
direction's length, which the camera code uses to read z-depth directly.
"""

from __future__ import annotations

import logging
import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from eden_pipe.config.schema import TRACERS
from eden_pipe.models.mesh import Mesh
from eden_pipe.render import kernels

log = logging.getLogger("eden_pipe")
CHUNK = 32768
MIN_SPLIT = 4096  # the fewest rays worth a chunk of their own on another core
CHUNKS_PER_THREAD = 4  # a batch below CHUNK per thread is cut into this many chunks per thread


def _ray_buffer(array: np.ndarray, columns: int = 3) -> np.ndarray:
    """float32, C-contiguous and writeable, as embreex's typed buffers require (copies only if needed)."""
    array = np.require(array, np.float32, ["C", "W"])
    return array.reshape(-1, columns) if columns > 1 else array.reshape(-1)


@dataclass
class Hits:
    t: np.ndarray  # (N,) float32 ray parameter, inf on a miss
    prim: np.ndarray  # (N,) int64 face index, -1 on a miss
    normal: np.ndarray  # (N, 3) float32 unit geometric normal (as wound), zeros on a miss

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


def unit_normals(ng: np.ndarray) -> np.ndarray:
    """Embree's float32 geometric normals (N, 3) scaled to unit length (zero rows stay zero), as
    both paths report them: each row times the reciprocal of its length, in one compiled pass."""
    return kernels.unit_rows(ng)


def _open_native(mesh: Mesh, tracer: str, movable: bool = False, robust: bool = True, lanes: int | None = None):
    """The native scene over ``mesh`` once the start-up check passed; None where ``tracer`` is
    auto and the native path cannot be used (logged), an error where it is native."""
    from eden_pipe.render import embree_native

    try:
        library = embree_native.load_library()
        embree_native.check_against_embreex(library)
        return embree_native.NativeScene(
            library, mesh.vertices, mesh.faces, movable=movable, robust=robust, lanes=lanes
        )
    except embree_native.NativeTracerError as exc:
        if tracer == "native":
            raise
        log.warning(f"[eden-pipe] render.tracer=auto: tracing through embreex ({exc})")
        return None


class RayTracer:
    """Closest-hit and occlusion queries against one static triangle mesh.

    ``tracer``: auto | native | embreex (``render.tracer``): which path traces; every path gives
    the same hits. ``movable``: the mesh's vertices may move (wind): write them into
    :attr:`vertices`, then call :meth:`refit` before the next query. ``robust``: Embree's robust
    (watertight) traversal, as the render's ground truth needs; off, a ray may slip between two
    faces at their shared edge, and rays cost less (the bake's later rays, :meth:`rebuild`).
    ``lanes``: the native path's packet width (8 or 16; None: the widest Embree traverses natively
    on this CPU, ``embree_native.packet_lanes``); the hits are the same at either, but for the
    face an unsettled tie keeps (:meth:`intersect`, ``settle_ties``).
    """

    def __init__(
        self,
        mesh: Mesh,
        threads: int = 0,
        tracer: str = "auto",
        movable: bool = False,
        robust: bool = True,
        lanes: int | None = None,
    ):
        if tracer not in TRACERS:
            raise ValueError(f"tracer must be one of {TRACERS}, not {tracer!r}")
        self.mesh = mesh
        self.threads = threads or os.cpu_count() or 1
        self._native = None
        self._scene = None
        self.robust = robust
        self.movable = movable
        self.vertices = mesh.vertices  # where the vertices stand for the queries (a movable tracer's own copy)
        if mesh.n_faces and tracer != "embreex":
            self._native = _open_native(mesh, tracer, movable, robust, lanes)
        if self._native is not None and movable:
            self.vertices = self._native.vertices  # Embree reads this buffer: refit() picks up what is written
        elif movable:
            self.vertices = mesh.vertices.copy()
        if mesh.n_faces and self._native is None:
            self._build_embreex()
        self.path = "native" if self._native is not None else "embreex"  # the path that traces
        self._pool = ThreadPoolExecutor(max_workers=self.threads) if self.threads > 1 else None
        self._empty = mesh.n_faces == 0

    def _build_embreex(self) -> None:
        scene = rtcs.EmbreeScene(robust=self.robust)
        vertices = np.ascontiguousarray(self.vertices, np.float32)
        TriangleMesh(scene, vertices, np.ascontiguousarray(self.mesh.faces, np.int32))
        # Build the BVH now (embreex commits on the first query): the one-off cost belongs to
        # setup, and no frame thread races another into the first commit.
        scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), query="OCCLUDED")
        self._scene = scene

    def rebuild(self, robust: bool) -> None:
        """Build the scene again, with or without Embree's robust flag, on the same path (one BVH at
        a time: the old one goes first). Not thread-safe against queries; not for a movable tracer."""
        if self.movable:
            raise ValueError("rebuild is not for a movable tracer (its vertices move: refit)")
        self.robust = robust
        if self._native is not None:
            from eden_pipe.render.embree_native import NativeScene

            library, lanes = self._native.library, self._native.lanes
            self._native.close()
            self._native = None
            self._native = NativeScene(library, self.mesh.vertices, self.mesh.faces, robust=robust, lanes=lanes)
        elif self._scene is not None:
            self._scene = None
            self._build_embreex()

    def refit(self) -> None:
        """Make the queries see the vertices written into :attr:`vertices` (a movable tracer): the
        native path refits its BVH; embreex's, which cannot refit, builds it again (slow)."""
        if self._native is not None:
            self._native.refit()
        elif self._scene is not None:
            self._build_embreex()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None
        if self._native is not None:
            self._native.close()
            self._native = None

    def __enter__(self) -> RayTracer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def map_chunks(self, fn, n: int):
        """``fn(start, stop)`` over chunks of ``n`` rays, on the thread pool where it pays: their results."""
        if self._pool is None or n < 2 * MIN_SPLIT:
            # One call: every return to Python between chunks must win the GIL back from the
            # other frame threads, which cost a frame thread ~20% of its time in waits.
            return [fn(0, n)]
        # Rays cost what their region of the image costs (a lawn's long grazing mirror rays several
        # times a fence's), so a batch is cut into several chunks per thread, which the pool hands
        # out as threads free up: 100,000 mirror rays in three full chunks and a short one kept one
        # core busy alone for a quarter of the batch (54 ms where eight chunks take 44 ms).
        size = min(CHUNK, max(MIN_SPLIT, -(-n // (CHUNKS_PER_THREAD * self.threads))))
        chunks = [(s, min(s + size, n)) for s in range(0, n, size)]
        return list(self._pool.map(lambda ab: fn(*ab), chunks))

    def intersect(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tmax: np.ndarray | None = None,
        *,
        image: tuple[int, int] | None = None,
        pixels: np.ndarray | None = None,
        settle_ties: bool = True,
        along: np.ndarray | None = None,
    ) -> Hits:
        """Closest hits. ``directions`` (N, 3), or (1, 3) for one shared by every ray (with
        ``settle_ties=False`` the native path packs those as :meth:`occluded` does). ``image`` (h, w):
        the rays are that image's pixels in row-major order, or with
        ``pixels`` (N,) the rays of those pixels; the native path then traces them as coherent packets
        (the hits are the same either way). ``settle_ties=False``: where another face lies at exactly
        the closest distance, a packet keeps the face it found instead of the one a single ray would
        report (docs/design.md, Ray tracing): for callers that count hits rather than label pixels.
        ``along`` (3,): the rays nearly share this direction (a sun's disc); the native path packs them
        as one shared direction's, by where they cross the plane across it (the same hits)."""
        origins, directions = _ray_buffer(origins), _ray_buffer(directions)
        n = len(origins)
        if self._native is not None and not self._empty and n:
            from eden_pipe.render.embree_native import trace

            limit = np.array([1e37], np.float32) if tmax is None else _ray_buffer(tmax, 1)  # embreex's default far end
            t, prim, ng = trace(
                self._native, 0, origins, directions, limit, self.map_chunks, image, pixels, settle_ties, along
            )
            return Hits(t, prim, unit_normals(ng))
        t = np.full(n, np.inf, np.float32)
        prim = np.full(n, -1, np.int64)
        normal = np.zeros((n, 3), np.float32)
        if self._empty or n == 0:
            return Hits(t, prim, normal)
        dists = None if tmax is None else _ray_buffer(np.broadcast_to(np.asarray(tmax, np.float32), (n,)), 1)
        if len(directions) == 1 and n > 1:  # one direction for every ray
            directions = np.ascontiguousarray(np.broadcast_to(directions, (n, 3)))

        scene = self._scene
        assert scene is not None  # not native, not empty: embreex's scene

        def run(a: int, b: int) -> None:
            kwargs = {} if dists is None else {"dists": dists[a:b].copy()}
            res = scene.run(origins[a:b], directions[a:b], output=1, **kwargs)
            p = res["primID"].astype(np.int64)
            hit = res["geomID"] >= 0
            p[~hit] = -1
            prim[a:b] = p
            t[a:b] = np.where(hit, res["tfar"], np.inf)
            ng = np.where(hit[:, None], res["Ng"], np.float32(0.0))  # stale on a miss: embreex reuses one ray record
            normal[a:b] = unit_normals(ng)

        self.map_chunks(run, n)
        return Hits(t, prim, normal)

    def occluded(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        tmax: np.ndarray | float | None = None,
        *,
        image: tuple[int, int] | None = None,
        pixels: np.ndarray | None = None,
        along: np.ndarray | None = None,
    ) -> np.ndarray:
        """(N,) bool: something lies along each ray before ``tmax`` (inf if None).

        ``directions`` is (N, 3), or (1, 3) for one direction shared by every ray (sun shadows: the
        native path packs those by where they cross the plane across it, ``embree_kernels.plane_order``).
        ``image``, ``pixels``: as :meth:`intersect`, for rays with directions of their own (flow occlusion).
        ``along``: as :meth:`intersect` (the sun's disc).
        """
        origins, directions = _ray_buffer(origins), _ray_buffer(directions)
        n = len(origins)
        out = np.zeros(n, bool)
        if self._empty or n == 0:
            return out
        limit = np.float32(3.0e37) if tmax is None else tmax
        if self._native is not None:
            from eden_pipe.render.embree_native import trace

            dists = _ray_buffer(np.asarray(limit, np.float32), 1)
            return trace(self._native, 1, origins, directions, dists, self.map_chunks, image, pixels, along=along)[0]
        dists = _ray_buffer(np.broadcast_to(np.asarray(limit, np.float32), (n,)), 1)

        shared = len(directions) == 1  # one direction for every ray (embreex reads row 0 for all)

        scene = self._scene
        assert scene is not None

        def run(a: int, b: int) -> None:
            # embreex only writes ``dists`` back for closest-hit queries, so no copy is needed here.
            res = scene.run(origins[a:b], directions if shared else directions[a:b], dists=dists[a:b], query="OCCLUDED")
            out[a:b] = np.asarray(res) >= 0

        self.map_chunks(run, n)
        return out
