"""Ray casting with Intel Embree (embreex): the default, all-modality backend.

One Embree scene per garden holds the flattened world triangle soup (Embree 4
via embreex has no instancing). Queries are split into chunks across a thread
pool: embreex releases the GIL inside ``rtcIntersect1``/``rtcOccluded1``.

Directions need not be unit length: ``t`` comes back in units of the
direction's length, which the camera code uses to read z-depth directly.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from eden_pipe.models.mesh import Mesh

CHUNK = 32768


@dataclass
class Hits:
    t: np.ndarray        # (N,) float32 ray parameter, inf on a miss
    prim: np.ndarray     # (N,) int64 face index, -1 on a miss
    normal: np.ndarray   # (N, 3) float32 unit geometric normal (as wound), zeros on a miss

    @property
    def hit(self) -> np.ndarray:
        return self.prim >= 0


class RayTracer:
    """Closest-hit and occlusion queries against one static triangle mesh."""

    def __init__(self, mesh: Mesh, threads: int = 0):
        self.mesh = mesh
        self.threads = threads or os.cpu_count() or 1
        self._scene = rtcs.EmbreeScene()
        if mesh.n_faces:
            TriangleMesh(self._scene, np.ascontiguousarray(mesh.vertices, np.float32), np.ascontiguousarray(mesh.faces, np.int32))
        self._pool = ThreadPoolExecutor(max_workers=self.threads) if self.threads > 1 else None
        self._empty = mesh.n_faces == 0

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None

    def __enter__(self) -> "RayTracer":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _map(self, fn, n: int):
        chunks = [(s, min(s + CHUNK, n)) for s in range(0, n, CHUNK)]
        if self._pool is None or len(chunks) == 1:
            return [fn(a, b) for a, b in chunks]
        return list(self._pool.map(lambda ab: fn(*ab), chunks))

    def intersect(self, origins: np.ndarray, directions: np.ndarray, tmax: np.ndarray | None = None) -> Hits:
        origins = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
        directions = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
        n = len(origins)
        t = np.full(n, np.inf, np.float32)
        prim = np.full(n, -1, np.int64)
        normal = np.zeros((n, 3), np.float32)
        if self._empty or n == 0:
            return Hits(t, prim, normal)
        dists = None if tmax is None else np.ascontiguousarray(np.broadcast_to(tmax, (n,)), np.float32)

        def run(a: int, b: int) -> None:
            kwargs = {} if dists is None else {"dists": dists[a:b].copy()}
            res = self._scene.run(origins[a:b], directions[a:b], output=1, **kwargs)
            p = res["primID"].astype(np.int64)
            hit = res["geomID"] >= 0
            p[~hit] = -1
            prim[a:b] = p
            t[a:b] = np.where(hit, res["tfar"], np.inf)
            ng = res["Ng"].astype(np.float32)
            length = np.linalg.norm(ng, axis=1, keepdims=True)
            normal[a:b] = np.where(hit[:, None], ng / np.maximum(length, 1e-30), 0.0)

        self._map(run, n)
        return Hits(t, prim, normal)

    def occluded(self, origins: np.ndarray, directions: np.ndarray, tmax: np.ndarray | float | None = None) -> np.ndarray:
        """(N,) bool: something lies along each ray before ``tmax`` (inf if None)."""
        origins = np.ascontiguousarray(origins, np.float32).reshape(-1, 3)
        directions = np.ascontiguousarray(directions, np.float32).reshape(-1, 3)
        n = len(origins)
        out = np.zeros(n, bool)
        if self._empty or n == 0:
            return out
        limit = np.float32(3.0e37) if tmax is None else tmax
        dists = np.ascontiguousarray(np.broadcast_to(np.asarray(limit, np.float32), (n,)), np.float32)

        def run(a: int, b: int) -> None:
            res = self._scene.run(origins[a:b], directions[a:b], dists=dists[a:b].copy(), query="OCCLUDED")
            out[a:b] = np.asarray(res) >= 0

        self._map(run, n)
        return out
