"""pybullet as the collision engine of the scene and trajectory stages.

The terrain is a static concave triangle mesh in collision group 1; every
instance body is a static convex hull in group 2 (what those bodies are - a
tree's trunk base, a bush, the pieces the rig could touch - is decided in
:mod:`eden_pipe.scene.placement`).
Ground contact uses ray tests against group 1 only; overlap uses pybullet's
closest-point queries with a clearance margin.
"""

from __future__ import annotations

import numpy as np
import pybullet as pb

TERRAIN_GROUP, OBJECT_GROUP, PROBE_GROUP = 1, 2, 4
RAY_GROUP = 1  # the collision filter group pybullet gives its ray tests (Bullet's DefaultFilter)
MAX_PROXY_POINTS = 256


def proxy_points(vertices: np.ndarray, clip_height: float) -> np.ndarray:
    """Vertices of the part of a model below ``clip_height`` (model frame), thinned for a hull."""
    v = np.asarray(vertices, dtype=np.float64)
    if len(v) == 0:
        return np.zeros((0, 3))
    low = v[v[:, 2] <= v[:, 2].min() + clip_height]
    if len(low) < 4:
        low = v
    if len(low) > MAX_PROXY_POINTS:
        # Keep the extreme points in 8 horizontal directions and z, plus an even stride.
        dirs = np.array(
            [[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0, 2 * np.pi, 16, endpoint=False)]
            + [[0, 0, 1.0], [0, 0, -1.0]]
        )
        extremes = np.unique(np.argmax(low @ dirs.T, axis=0))
        stride = low[:: max(1, len(low) // (MAX_PROXY_POINTS - len(extremes)))]
        low = np.concatenate([low[extremes], stride])[:MAX_PROXY_POINTS]
    return low


class PhysicsWorld:
    """A private pybullet DIRECT client holding the terrain and instance proxies."""

    def __init__(self):
        self.client = pb.connect(pb.DIRECT)
        self.terrain_body: int | None = None
        self.bodies: list[int] = []

    def close(self) -> None:
        if self.client is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None

    def __enter__(self) -> PhysicsWorld:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def add_terrain(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        shape = pb.createCollisionShape(
            pb.GEOM_MESH,
            vertices=np.asarray(vertices, float).tolist(),
            indices=np.asarray(faces, int).ravel().tolist(),
            flags=pb.GEOM_FORCE_CONCAVE_TRIMESH,
            physicsClientId=self.client,
        )
        body = pb.createMultiBody(0, shape, physicsClientId=self.client)
        # The mask must admit group 1 too: pybullet's ray tests carry Bullet's default filter group (1), so
        # without it rayTestBatch never hits the terrain and every ground height comes back NaN.
        pb.setCollisionFilterGroupMask(
            body, -1, TERRAIN_GROUP, RAY_GROUP | OBJECT_GROUP | PROBE_GROUP, physicsClientId=self.client
        )
        self.terrain_body = body
        return body

    def add_proxy(self, points: np.ndarray, position=(0.0, 0.0, 0.0), yaw: float = 0.0) -> int:
        """A static convex hull of ``points`` (model frame) placed at position/yaw."""
        shape = pb.createCollisionShape(
            pb.GEOM_MESH, vertices=np.asarray(points, float).tolist(), physicsClientId=self.client
        )
        body = pb.createMultiBody(
            0,
            shape,
            basePosition=list(position),
            baseOrientation=pb.getQuaternionFromEuler([0, 0, yaw]),
            physicsClientId=self.client,
        )
        pb.setCollisionFilterGroupMask(body, -1, OBJECT_GROUP, OBJECT_GROUP | PROBE_GROUP, physicsClientId=self.client)
        self.bodies.append(body)
        return body

    def move(self, body: int, position, yaw: float = 0.0) -> None:
        pb.resetBasePositionAndOrientation(
            body, list(map(float, position)), pb.getQuaternionFromEuler([0, 0, yaw]), physicsClientId=self.client
        )

    def remove(self, body: int) -> None:
        pb.removeBody(body, physicsClientId=self.client)
        if body in self.bodies:
            self.bodies.remove(body)

    def ground_heights(self, xy: np.ndarray, top: float = 50.0, bottom: float = -50.0) -> np.ndarray:
        """Terrain height under each (x, y) by downward ray tests against the terrain only."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        starts = np.c_[xy, np.full(len(xy), top)]
        ends = np.c_[xy, np.full(len(xy), bottom)]
        out = np.full(len(xy), np.nan)
        for a in range(0, len(xy), 4096):  # pybullet's batch limit is large but finite
            res = pb.rayTestBatch(
                starts[a : a + 4096].tolist(),
                ends[a : a + 4096].tolist(),
                collisionFilterMask=TERRAIN_GROUP,
                physicsClientId=self.client,
            )
            out[a : a + len(res)] = [r[3][2] if r[0] == self.terrain_body else np.nan for r in res]
        return out

    def collides(self, body: int, others: list[int] | None = None, margin: float = 0.0) -> bool:
        """True if ``body`` comes within ``margin`` of any other object proxy."""
        candidates = self.bodies if others is None else others
        (lo, hi) = pb.getAABB(body, physicsClientId=self.client)
        lo = [c - margin for c in lo]
        hi = [c + margin for c in hi]
        near = pb.getOverlappingObjects(lo, hi, physicsClientId=self.client) or []
        near_ids = {b for b, _ in near}
        for other in candidates:
            if other == body or other not in near_ids:
                continue
            if pb.getClosestPoints(body, other, distance=margin, physicsClientId=self.client):
                return True
        return False
