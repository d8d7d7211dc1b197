"""Where a garden's instances go: the two collision bodies of a model and the seeded sampler.

Each instance has two bodies, both built from its model's vertices (model frame):

- the **base**: what must never share space with another instance's base - what a
  robot would hit and what cannot interpenetrate in a real garden: a tree's trunk
  near the ground, the whole of a bush, flower, rock, pot or bench below the rig's
  reach. A tree's crown (low branches of firs and pines included) is not part of its
  base, so canopies overlap other canopies, bushes and objects as in real gardens,
  instead of one low-branched fir blocking its whole neighbourhood. Bases are kept
  ``spacing_m`` apart (the family table).
- the **reach**: everything the rig could touch (model parts below rig height +
  0.4 m: trunks, pots, rocks, and low foliage), as convex pieces on a
  ``REACH_CELL_M`` grid. The trajectory stage keeps the rig clear of these pieces.
  One convex hull per model would close the gaps between a fir's low branches or
  an oak's drooping limbs and the trunk (a 5 m disc for a wide oak); per-cell hulls
  follow the geometry to half a metre, while still covering every face the rig could
  hit (a face goes to the cell of its centroid, with all its vertices).

:func:`place` places each request by its family's ``PlacementKind`` (the family table,
``eden_pipe.models.registry``), kind by kind: first the runs along the garden's edges
(:func:`place_along_edges`, a fence), then the scattered bases (:func:`place_scattered`),
which keep clear of the runs. The sampler places large bases first (the hardest to fit),
each instance from its own seeded generator: ``attempts`` uniform random draws, then, if
none was free, a systematic search over a seeded shuffle of candidate positions on a grid,
so an instance is only left out when no grid position is free. Those are returned as
:class:`Unplaced` with the reason; nothing is dropped silently.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from eden_pipe.models.mesh import MATERIALS
from eden_pipe.models.registry import PlacementKind, family
from eden_pipe.scene.physics import PhysicsWorld, proxy_points

TRUNK_HEIGHT_M = 0.5  # the trunk prism tested for placement reaches this far up
TRUNK_SLAB_M = 0.05  # the trunk's cross-section is read from its lowest bark (below any branch)
TRUNK_GAP_M = 0.15  # a radial gap this wide separates the trunk from branch tips resting on the ground
REACH_CELL_M = 0.5  # grid of the reach pieces
MAX_PIECE_POINTS = 64  # vertices kept per reach piece (extremes first)
CANDIDATE_STEP_M = 0.25  # grid of the systematic search
CANDIDATE_YAWS = 4  # yaws tried at each candidate position
VOLUME_PAD_M = 0.01  # every body gets a copy of its points shifted by this, so no hull is flat


def _with_volume(points: np.ndarray) -> np.ndarray:
    """``points`` plus a slightly shifted copy: a convex hull with volume even for a flat or tiny set."""
    return np.concatenate([points, points + VOLUME_PAD_M])


def trunk_points(mesh) -> np.ndarray:
    """A prism around a tree's trunk base, ``TRUNK_HEIGHT_M`` high (model frame; trees grow from the origin).

    The trunk's cross-section is the innermost radial cluster of its bark within ``TRUNK_SLAB_M`` of the
    ground: leaves hanging to the ground (a willow), low branches (a fir) and branch tips resting on the
    ground beyond a gap of ``TRUNK_GAP_M`` are left out. A model without bark uses all its vertices."""
    v = np.asarray(mesh.vertices, dtype=np.float64)
    z0 = float(v[:, 2].min())
    bark = np.unique(np.asarray(mesh.faces)[np.asarray(mesh.material) == MATERIALS["bark"]].ravel())
    wood = v[bark] if len(bark) else v
    slab = wood[wood[:, 2] <= wood[:, 2].min() + TRUNK_SLAB_M]
    dist = np.hypot(slab[:, 0], slab[:, 1])
    order = np.sort(dist)
    gaps = np.flatnonzero(np.diff(order) > TRUNK_GAP_M)
    radius = order[gaps[0]] if len(gaps) else order[-1]
    ring = slab[dist <= radius + 1e-9][:, :2]
    ring = proxy_points(np.c_[ring, np.zeros(len(ring))], np.inf)[:, :2]  # thinned, extremes kept
    bottom = np.c_[ring, np.full(len(ring), z0)]
    top = np.c_[ring, np.full(len(ring), z0 + TRUNK_HEIGHT_M)]
    return _with_volume(np.concatenate([bottom, top]))


def base_points(pool: str, mesh, clip: float) -> np.ndarray:
    """The base body of a model of ``pool`` (model frame): the trunk prism for trees, else the model below ``clip``."""
    if family(pool).base_is_trunk:
        return trunk_points(mesh)
    return _with_volume(proxy_points(mesh.vertices, clip))


def reach_pieces(vertices: np.ndarray, faces: np.ndarray, clip: float) -> list[np.ndarray]:
    """Convex pieces covering every face that reaches below ``clip`` above the model's lowest point (model frame)."""
    v = np.asarray(vertices, dtype=np.float64)
    f = np.asarray(faces, dtype=np.int64)
    if len(f) == 0:
        return []
    z0 = float(v[:, 2].min())
    f = f[v[f, 2].min(axis=1) <= z0 + clip]
    if len(f) == 0:
        return []
    cell = np.floor(v[f, :2].mean(axis=1) / REACH_CELL_M).astype(np.int64) + (1 << 20)
    _, group = np.unique(cell[:, 0] << 21 | cell[:, 1], return_inverse=True)
    # (piece, vertex) pairs, each once, sorted by piece: the vertices of every piece in one pass.
    pairs = np.unique((group.ravel()[:, None] * len(v) + f).ravel())
    piece, vertex = np.divmod(pairs, len(v))
    starts = np.flatnonzero(np.diff(piece)) + 1
    return [_with_volume(_thin(v[members], MAX_PIECE_POINTS)) for members in np.split(vertex, starts)]


@dataclass
class ModelBodies:
    """A model's placement base and rig-reach pieces (model frame, unscaled)."""

    base: np.ndarray
    pieces: list[np.ndarray]
    reach_radius: float  # horizontal extent of the pieces around the model's origin

    @classmethod
    def of(cls, pool: str, mesh, clip: float) -> ModelBodies:
        """``clip``: the rig's reach above the model's lowest point, in model units."""
        pieces = reach_pieces(mesh.vertices, mesh.faces, clip)
        radius = max((float(np.max(np.hypot(p[:, 0], p[:, 1]))) for p in pieces), default=0.0)
        return cls(base_points(pool, mesh, clip), pieces, radius)


def _thin(points: np.ndarray, limit: int) -> np.ndarray:
    if len(points) <= limit:
        return points
    dirs = np.array(
        [[np.cos(a), np.sin(a), 0.0] for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)]
        + [[0, 0, 1.0], [0, 0, -1.0]]
    )
    extremes = np.unique(np.argmax(points @ dirs.T, axis=0))
    stride = points[:: max(1, len(points) // (limit - len(extremes)))]
    return np.concatenate([points[extremes], stride])[:limit]


@dataclass
class PlacementRequest:
    """One instance to place: its base body (model frame, scaled), clearance, generator and placement kind."""

    key: int  # caller's index of the request
    base: np.ndarray  # (N, 3) base points, model frame times the instance scale
    reach_radius: float  # horizontal extent of what the rig could touch (for the edge inset)
    spacing_m: float
    rng: np.random.Generator
    placement: PlacementKind = PlacementKind.SCATTERED

    @property
    def extent(self) -> float:
        """How far from the edge the instance's origin must stay: its base, and what the rig could touch up
        to ``MAX_EDGE_INSET_M`` (a crown may overhang the edge, as over a real fence). The sampler places the
        largest extents first: they have the least room to go."""
        base = float(np.max(np.hypot(self.base[:, 0], self.base[:, 1]))) if len(self.base) else 0.0
        return max(base, min(self.reach_radius, MAX_EDGE_INSET_M))


@dataclass
class Placement:
    key: int
    position: tuple[float, float, float]
    yaw: float


@dataclass
class Unplaced:
    key: int
    reason: str


EDGE_MARGIN_M = 0.35  # bases stay this far inside the garden edge
MAX_EDGE_INSET_M = 1.25  # what the rig could touch may reach this far toward the edge, no further
EDGE_RUN_INSET_M = 0.05  # a run along an edge stands this far inside it
EDGE_RUN_GROUND_SAMPLES = 21  # ground heights read along a run: it is sunk to the lowest


def place(
    world: PhysicsWorld, requests: list[PlacementRequest], size: float, attempts: int, sink_m: float
) -> tuple[list[Placement], list[Unplaced]]:
    """Place ``requests`` kind by kind (``PlacementKind`` order); the world keeps every placed body, so a
    kind placed later keeps clear of those placed before. An edge-placed request gives one placement per
    run, in edge order."""
    placed, unplaced = [], []
    for kind in PlacementKind:
        done, missing = PLACERS[kind](world, [r for r in requests if r.placement is kind], size, attempts, sink_m)
        placed += done
        unplaced += missing
    return placed, unplaced


def edge_runs(size: float) -> list[tuple[tuple[float, float], float]]:
    """((x, y), yaw) of a run along each edge of a ``size`` garden, counter-clockwise from the origin: a model
    that runs along its +x axis from its origin (a fence as long as the garden's side), put there and turned
    by ``yaw``, lies along the edge with its +y side facing inward. The runs meet at the corners."""
    inset = EDGE_RUN_INSET_M
    return [
        ((0.0, inset), 0.0),
        ((size - inset, 0.0), np.pi / 2),
        ((size, size - inset), np.pi),
        ((inset, size), 1.5 * np.pi),
    ]


def place_along_edges(
    world: PhysicsWorld, requests: list[PlacementRequest], size: float, attempts: int, sink_m: float
) -> tuple[list[Placement], list[Unplaced]]:
    """Each request's model laid along every edge (:func:`edge_runs`), each run sunk ``sink_m`` below the
    lowest ground under it; nothing is left out (``attempts`` is unused: nothing is drawn)."""
    placed = []
    for req in requests:
        for (x, y), yaw in edge_runs(size):
            along = np.array([np.cos(yaw), np.sin(yaw)])
            xy = np.array([x, y]) + np.linspace(0, size, EDGE_RUN_GROUND_SAMPLES)[:, None] * along
            z = float(np.nanmin(world.ground_heights(xy))) - sink_m
            world.add_proxy(req.base, (x, y, z), yaw)
            placed.append(Placement(req.key, (x, y, z), yaw))
    return placed, []


def place_scattered(
    world: PhysicsWorld, requests: list[PlacementRequest], size: float, attempts: int, sink_m: float
) -> tuple[list[Placement], list[Unplaced]]:
    """Place ``requests`` (largest base first) without base overlap, ``spacing_m`` clear of every body in the world."""
    placed, unplaced = [], []
    for req in sorted(requests, key=lambda r: (-r.extent, r.key)):
        inset = EDGE_MARGIN_M + min(req.extent, size / 4)
        lo, hi = inset, size - inset
        footprint = req.base[:: max(1, len(req.base) // 16), :2]
        body = None

        # footprint and req bound as defaults: this request's, though free_at only runs in this iteration.
        def free_at(
            x: float, y: float, yaw: float, footprint: np.ndarray = footprint, req: PlacementRequest = req
        ) -> tuple[float, float, float] | None:
            nonlocal body
            c, s = np.cos(yaw), np.sin(yaw)
            foot = footprint @ np.array([[c, s], [-s, c]]) + [x, y]
            z = float(np.nanmin(world.ground_heights(foot))) - sink_m
            if body is None:
                body = world.add_proxy(req.base, (x, y, z), yaw)
            else:
                world.move(body, (x, y, z), yaw)
            return None if world.collides(body, margin=req.spacing_m) else (float(x), float(y), z)

        spot = _first_free(free_at, req.rng, lo, hi, attempts)
        if spot is None:
            if body is not None:
                world.remove(body)
            n = len(_candidates(req.rng, lo, hi, dry=True))
            unplaced.append(
                Unplaced(
                    req.key,
                    f"no free spot for its base: {attempts} random draws and {n} grid "
                    f"candidates all overlap placed bases (spacing {req.spacing_m} m)",
                )
            )
        else:
            (x, y, z), yaw = spot
            placed.append(Placement(req.key, (x, y, z), yaw))
    return placed, unplaced


PLACERS: dict[PlacementKind, Callable[..., tuple[list[Placement], list[Unplaced]]]] = {
    PlacementKind.ALONG_EDGES: place_along_edges,
    PlacementKind.SCATTERED: place_scattered,
}


def _first_free(free_at: Callable, rng: np.random.Generator, lo: float, hi: float, attempts: int):
    for _ in range(attempts):
        x, y = rng.uniform(lo, hi, size=2)
        yaw = float(rng.uniform(0, 2 * np.pi))
        at = free_at(x, y, yaw)
        if at is not None:
            return at, yaw
    for x, y, yaw in _candidates(rng, lo, hi):
        at = free_at(x, y, yaw)
        if at is not None:
            return at, yaw
    return None


def _candidates(rng: np.random.Generator, lo: float, hi: float, dry: bool = False) -> np.ndarray:
    """(x, y, yaw) rows on a grid over [lo, hi]^2 in a seeded random order (``dry``: the grid only, no draw)."""
    axis = np.arange(lo, hi + 1e-9, CANDIDATE_STEP_M) if hi > lo else np.array([(lo + hi) / 2])
    gx, gy, gk = np.meshgrid(axis, axis, np.arange(CANDIDATE_YAWS), indexing="ij")
    grid = np.c_[gx.ravel(), gy.ravel(), gk.ravel().astype(np.float64)]
    if dry:
        return grid
    grid[:, 2] = (grid[:, 2] + rng.uniform()) * (2 * np.pi / CANDIDATE_YAWS)
    return grid[rng.permutation(len(grid))]


def smallest_gap(
    bodies: list[np.ndarray], skip: Callable[[int, int], bool] = lambda i, j: False, reach: float = 1.0
) -> float:
    """The smallest distance between two of the convex ``bodies`` (world points each; < 0 = overlap),
    over the pairs ``skip`` does not exclude; ``inf`` when no pair is within ``reach`` metres.
    Checks placement independently of the sampler (benchmark and tests)."""
    import pybullet as pb

    gap = np.inf
    with PhysicsWorld() as world:
        ids = [world.add_proxy(points) for points in bodies]
        for i in range(len(ids)):
            for j in range(i + 1, len(ids)):
                if skip(i, j):
                    continue
                for contact in pb.getClosestPoints(ids[i], ids[j], distance=reach, physicsClientId=world.client) or []:
                    gap = min(gap, contact[8])
    return float(gap)


def scene_base_gap(scene_folder) -> float:
    """:func:`smallest_gap` over a scene artifact's instance bases (``proxies.npz``); the runs of an edge-placed
    family meet at the garden's corners by design, so pairs of its runs are left out."""
    from pathlib import Path

    from eden_pipe.scene.description import SceneDescription

    pools = {i.id: i.pool for i in SceneDescription.load(scene_folder).instances}
    with np.load(Path(scene_folder) / "proxies.npz") as data:
        points, offsets, ids = data["base_points"], data["base_offsets"], data["base_ids"]
    bodies = [points[a:b] for a, b in pairwise(offsets)]

    def runs_of_one_family(i: int, j: int) -> bool:
        pool = pools[ids[i]]
        return pool == pools[ids[j]] and family(pool).placement is PlacementKind.ALONG_EDGES

    return smallest_gap(bodies, runs_of_one_family)
