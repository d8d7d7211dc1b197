"""Lightmaps of large faces: the sky they see, node by node, for the bake (``visibility.bake``).

One visible fraction per face side cannot hold a fence plank or a trunk: a
plank of 0.1 m^2 sees the open sky at its top and the lawn and hedges at its
foot, and a camera sees all of it. Measured on the benchmark's sunset pixels
of obstacles (fences, sheds, posts): the bake's per-face value is off the
pixel's own cosine-weighted visible sky (512 rays) by 0.033 (11 % of its
mean), the exact per-face mean by 15 %; this map's blend of the nodes around
the pixel by 0.021, most of it the 512 rays' own noise (``docs/realism.md``).

Faces wider than a cell (area above ``cell_m^2``) of the bake's box get a grid
of nodes over the rectangle that bounds them in their plane, along their
longest edge and across it, about ``cell_m`` apart (at most ``MAX_STEPS`` steps
a side: a 1.6 m rail gets 16 x 1, not the hundreds a grid in its barycentrics
would give it). A node outside the face is moved to the nearest point of it,
and every node is pulled a little toward the centroid (a node on an edge would
meet the plank or post beside it). Each node traces ``rays`` stratified cosine
rays per side; a pixel blends its cell's four nodes bilinearly
(``visible_at``). The underside of the ground (an opaque face of a terrain
material, on its side that faces down) is never traced: no camera, mirror or
bounce ray can reach it from above the ground, and no translucency reads it
(it holds 0: half the nodes of a default garden are terrain, a quarter of the
lightmaps' rays). The render reads it as the side's exposure (its amount of
sky; the probe still gives the sky's shape): ``SkyVisibility.lookup``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from functools import partial

import numpy as np

from eden_pipe.models.terrain import TERRAIN_MATERIALS
from eden_pipe.render import vec
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.kernels import lightmap_visible
from eden_pipe.render.visibility import kernels, ray_kernels

MAX_STEPS = 16  # grid steps a side at most
INSET = 0.97  # nodes pulled toward the centroid by this factor
EPS = 1e-3  # node offset along the side's normal
RAYS_PER_WAVE = 1 << 20


@dataclass
class Lightmaps:
    faces: np.ndarray  # (K,) int32 faces with a lightmap, ascending
    frame: np.ndarray  # (K, 9) float32 grid origin o, axes a, b in steps per metre: a point's node coordinates
    #                      are a.(p - o), b.(p - o)
    steps: np.ndarray  # (K, 2) int32 grid steps along a and b
    first: np.ndarray  # (K,) int32 each face's first node (row by row in b)
    visible: np.ndarray  # (N, 2) float32 each node's cosine-weighted visible sky, per face side

    FIELDS = ("faces", "frame", "steps", "first", "visible")

    @classmethod
    def none(cls) -> Lightmaps:
        return cls(
            np.zeros(0, np.int32),
            np.zeros((0, 9), np.float32),
            np.zeros((0, 2), np.int32),
            np.zeros(0, np.int32),
            np.zeros((0, 2), np.float32),
        )

    @functools.cached_property
    def _terms(self) -> tuple[np.ndarray, ...]:
        """Each face's grid origin, axes (K, 3 each), steps along a and b (K, float32 each), nodes
        across and first node (K, int32), each contiguous (``kernels.lightmap_visible`` reads them)."""
        frame = self.frame.astype(np.float32)
        steps = self.steps.astype(np.float32)
        return (
            np.ascontiguousarray(frame[:, 0:3]),
            np.ascontiguousarray(frame[:, 3:6]),
            np.ascontiguousarray(frame[:, 6:9]),
            np.ascontiguousarray(steps[:, 0]),
            np.ascontiguousarray(steps[:, 1]),
            (self.steps[:, 0] + 1).astype(np.int32),
            self.first.astype(np.int32),
        )

    def visible_at(self, slot: np.ndarray, back: np.ndarray, points: np.ndarray) -> np.ndarray:
        """(N,) float32 the visible sky at ``points`` (N, 3) on the faces of lightmap rows ``slot``
        (N,), side 1 where ``back``: the bilinear blend of the four nodes of the grid cell holding
        the point."""
        origin, axis_a, axis_b, steps_a, steps_b, across, first = self._terms
        return lightmap_visible(
            slot, back, points, origin, axis_a, axis_b, steps_a, steps_b, across, first, self.visible.ravel()
        )


def bake_lightmaps(
    mesh,
    tracer: RayTracer,
    rng: np.random.Generator,
    areas: np.ndarray,
    inside: np.ndarray,
    *,
    cell_m: float,
    rays: int,
) -> Lightmaps:
    """Lightmaps of the faces ``inside`` (F,) the bake's box with an area above ``cell_m^2``
    (``areas`` (F,); their unit normals are made for those faces alone): see the module doc."""
    if cell_m <= 0 or rays <= 0:
        return Lightmaps.none()
    faces = np.flatnonzero(inside & (areas > cell_m * cell_m)).astype(np.int32)
    if not len(faces):
        return Lightmaps.none()
    face_normals = kernels.face_normals(mesh.vertices, mesh.faces, faces)
    tri = mesh.vertices[mesh.faces[faces]].astype(np.float64)
    edges = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 1], tri[:, 0] - tri[:, 2]], axis=1)
    longest = np.take_along_axis(edges, np.argmax(np.linalg.norm(edges, axis=2), axis=1)[:, None, None], axis=1)[:, 0]
    a = vec.normalize(longest, 1e-30)
    b = vec.normalize(np.cross(face_normals, a), 1e-30)
    ca, cb = np.einsum("kvc,kc->kv", tri, a), np.einsum("kvc,kc->kv", tri, b)
    lo = np.stack([ca.min(axis=1), cb.min(axis=1)], axis=1)
    extent = np.stack([ca.max(axis=1), cb.max(axis=1)], axis=1) - lo
    steps = np.clip(np.ceil(extent / cell_m), 1, MAX_STEPS).astype(np.int32)
    per_step = steps / np.maximum(extent, 1e-9)  # node units per metre along a and b
    origin = tri[:, 0] + a * (lo[:, 0] - ca[:, 0])[:, None] + b * (lo[:, 1] - cb[:, 0])[:, None]
    count = (steps[:, 0] + 1) * (steps[:, 1] + 1)
    first = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int32)
    node_face = np.repeat(np.arange(len(faces)), count)
    local = np.arange(len(node_face)) - first[node_face]
    across = steps[node_face, 0] + 1
    i, j = local % across, local // across
    points = (
        origin[node_face]
        + a[node_face] * (i / per_step[node_face, 0])[:, None]
        + b[node_face] * (j / per_step[node_face, 1])[:, None]
    )
    points = nearest_on_triangle(points, tri[node_face])
    centroid = tri.mean(axis=1)[node_face]
    points = centroid + INSET * (points - centroid)
    visible = np.zeros((len(points), 2))
    node_normals = face_normals[node_face]
    ground = np.isin(mesh.material[faces], TERRAIN_MATERIALS) & (mesh.translucency[faces] <= 0)
    per_wave = max(1, RAYS_PER_WAVE // rays)
    for side, sign in enumerate((1.0, -1.0)):
        # The underside of the ground, whose rays are not traced (they count as blocked: 0 sky).
        under = (ground & (face_normals[:, 2] * sign < 0))[node_face]
        for w0 in range(0, len(points), per_wave):
            m = min(len(points), w0 + per_wave) - w0
            # Drawn for every node, traced or not: the other nodes' rays stay those of a full wave.
            u1, rc, rs = ray_kernels.stratified_disc(m, rays, rng, tracer.map_chunks)
            origins, directions = np.empty((m * rays, 3), np.float32), np.empty((m * rays, 3), np.float32)
            tracer.map_chunks(
                partial(
                    ray_kernels.node_rays, points, node_normals, sign, w0, m, rays, rc, rs, u1, EPS, origins, directions
                ),
                m,
            )
            traced = np.repeat(~under[w0 : w0 + m], rays)
            if traced.all():
                occluded = tracer.occluded(origins, directions)
            else:
                occluded = np.ones(m * rays, bool)
                occluded[traced] = tracer.occluded(origins[traced], directions[traced])
            ray_kernels.escaped_fraction(occluded, m, rays, visible, side, w0)
    frame = np.column_stack([origin, a * per_step[:, :1], b * per_step[:, 1:]]).astype(np.float32)
    return Lightmaps(faces, frame, steps, first, visible.astype(np.float32))


def nearest_on_triangle(points: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """(N, 3) the points of triangles ``tri`` (N, 3, 3) nearest ``points`` (N, 3) that lie in their
    planes: the point itself where it lies inside, else its projection on the nearest edge."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    q = points - tri[:, 0]
    d11, d12, d22 = vec.dot(e1, e1), vec.dot(e1, e2), vec.dot(e2, e2)
    det = np.maximum(d11 * d22 - d12 * d12, 1e-30)
    u = (d22 * vec.dot(e1, q) - d12 * vec.dot(e2, q)) / det
    v = (d11 * vec.dot(e2, q) - d12 * vec.dot(e1, q)) / det
    out = points.copy()
    outside = np.flatnonzero((u < 0) | (v < 0) | (u + v > 1))
    if len(outside):
        p, t = points[outside], tri[outside]
        best, nearest = np.full(len(outside), np.inf), np.zeros_like(p)
        for k in range(3):  # the three edges
            start, edge = t[:, k], t[:, (k + 1) % 3] - t[:, k]
            along = np.clip(vec.dot(p - start, edge) / np.maximum(vec.dot(edge, edge), 1e-30), 0.0, 1.0)
            candidate = start + edge * along[:, None]
            dist = vec.dot(p - candidate, p - candidate)
            closer = dist < best
            best[closer], nearest[closer] = dist[closer], candidate[closer]
        out[outside] = nearest
    return out
