"""The validator's geometry check: the published scene mesh is the one the images were rendered from.

For sampled pixels of each row, the left depth, K and pose put the pixel's surface point in the world
(pixel centres at integer coordinates, depth along the optical axis, docs/design.md, Frames and units);
the pixel agrees when a face of the published ``<garden>/geometry.ply`` whose instance id is the pixel's
instance id lies within what the depth file resolves of that point: the depth format's error (png16:
+-0.5 mm) times the ray's length per unit depth, plus the float32 arithmetic of the renderer's hit point.
Exact, with no renderer: the faces near each point are found on a uniform grid over the sampled points
(every face listed in each cell its bounding box touches), then the exact point-triangle distance
decides. A shuffled instance id, a moved or missing face shows as pixels that do not agree.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eden_pipe import modalities

# Pixels sampled per row (among those with a finite depth) and the share that must agree.
SAMPLE_PIXELS = 256
AGREEMENT = 0.999
# float32 hit points and vertices: a few ulp (6e-8 each) of the distance; 4e-6 relative leaves a wide margin and
# stays far below the png16 depth's own 0.5 mm at garden distances.
ARITHMETIC_RELATIVE = 4e-6
ARITHMETIC_M = 1e-6
CELL_M = 0.1  # grid cell; faces are listed in every cell their box touches
CHUNK = 1 << 20  # faces (then face-point pairs) handled at once, to bound memory
LARGE_FACE_CELLS = 64


@dataclass
class Samples:
    """One garden's sampled pixels: world points, their tolerance (m), instance id and row."""

    points: list[np.ndarray] = field(default_factory=list)
    tolerance: list[np.ndarray] = field(default_factory=list)
    instance: list[np.ndarray] = field(default_factory=list)
    rows: list[str] = field(default_factory=list)

    def add(self, points, tolerance, instance, row: str) -> None:
        self.points.append(points)
        self.tolerance.append(tolerance)
        self.instance.append(instance)
        self.rows.append(row)


def sample_row(
    depth: np.ndarray,
    instance: np.ndarray,
    depth_format: modalities.FileFormat,
    K: np.ndarray,
    pose: np.ndarray,
    rng: np.random.Generator,
    n: int = SAMPLE_PIXELS,
    still: np.ndarray | None = None,
    depth_error=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(world points (m, 3), tolerance (m,), instance ids (m,)) of up to ``n`` random pixels with a depth;
    ``still`` (H, W) bool: only those pixels (wind: the published mesh is where nothing moved);
    ``depth_error``: the rendering backend's own z error (``Backend.depth_error``), None: none."""
    finite = np.flatnonzero((np.isfinite(depth) & (True if still is None else still)).ravel())
    pick = np.sort(rng.choice(finite, size=min(n, len(finite)), replace=False))
    v, u = np.divmod(pick, depth.shape[1])
    z = depth.ravel()[pick].astype(np.float64)
    ray = np.stack([(u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1], np.ones(len(pick))], axis=1)
    world = (ray * z[:, None]) @ pose[:3, :3].T + pose[:3, 3]
    length = np.linalg.norm(ray, axis=1)
    dz = depth_format.error_bound(depth.ravel()[pick]).astype(np.float64)
    if depth_error is not None:
        dz += depth_error(z)
    tol = dz * length + ARITHMETIC_RELATIVE * z * length + ARITHMETIC_M
    return world, tol, instance.ravel()[pick].astype(np.int64)


def point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Exact distance from each point to its triangle (rows of (n, 3) arrays): the closest point by the
    triangle's Voronoi regions (Ericson, Real-Time Collision Detection, 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v, w = vb / denom, vc / denom
        closest = a + ab * v[:, None] + ac * w[:, None]  # inside the face
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    regions = [
        ((d1 <= 0) & (d2 <= 0), a),
        ((d3 >= 0) & (d4 <= d3), b),
        ((d6 >= 0) & (d5 <= d6), c),
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), a + ab * t_ab[:, None]),
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), a + ac * t_ac[:, None]),
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), b + (c - b) * t_bc[:, None]),
    ]
    done = np.zeros(len(p), bool)
    for region, point in regions:  # the first region that holds wins, as in the branching original
        take = region & ~done
        closest[take] = point[take]
        done |= take
    # A zero-area face in no vertex or edge region keeps a NaN point: no distance, so never "within"
    # (no ray hits such a face; the faces it lies on decide).
    return np.linalg.norm(p - closest, axis=1)


def _cell_keys(cells: np.ndarray, origin: np.ndarray) -> np.ndarray:
    rel = cells - origin
    return (rel[:, 0] << 42) | (rel[:, 1] << 21) | rel[:, 2]


class _PointGrid:
    """The sampled points bucketed in cubes of CELL_M: which points lie in the cells a box touches."""

    def __init__(self, points: np.ndarray):
        cells = np.floor(points / CELL_M).astype(np.int64)
        self.origin, self.top = cells.min(axis=0) - 1, cells.max(axis=0) + 1
        if np.any(self.top - self.origin >= 1 << 21):
            raise ValueError("the sampled points span more than 2^21 grid cells along an axis")
        keys = _cell_keys(cells, self.origin)
        self.order = np.argsort(keys, kind="stable")
        self.keys, self.start = np.unique(keys[self.order], return_index=True)
        self.end = np.append(self.start[1:], len(points))

    def pairs(self, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(box, point) index pairs: every point in a cell of box b's cell range [lo[b], hi[b]]."""
        lo, hi = np.maximum(lo, self.origin), np.minimum(hi, self.top)
        dims = np.maximum(hi - lo + 1, 0)
        count = dims.prod(axis=1)
        box = np.repeat(np.arange(len(lo)), count)
        k = np.arange(len(box)) - np.repeat(np.cumsum(count) - count, count)
        d = dims[box]
        offset = np.stack([k // (d[:, 1] * d[:, 2]), (k // d[:, 2]) % d[:, 1], k % d[:, 2]], axis=1)
        keys = _cell_keys(lo[box] + offset, self.origin)
        slot = np.clip(np.searchsorted(self.keys, keys), 0, len(self.keys) - 1)
        hit = self.keys[slot] == keys
        box, slot = box[hit], slot[hit]
        per = self.end[slot] - self.start[slot]
        start = np.repeat(self.start[slot], per)
        point = self.order[start + np.arange(int(per.sum())) - np.repeat(np.cumsum(per) - per, per)]
        return np.repeat(box, per), point


def agreement(
    vertices: np.ndarray, faces: np.ndarray, face_instance: np.ndarray, points, tolerance, instance
) -> tuple[np.ndarray, np.ndarray]:
    """(on a face of the point's instance, on any face) per point, both within the point's tolerance."""
    points, tolerance, instance = np.asarray(points, np.float64), np.asarray(tolerance), np.asarray(instance)
    n = len(points)
    match, near = np.zeros(n, bool), np.zeros(n, bool)
    if n == 0 or len(faces) == 0:
        return match, near
    grid = _PointGrid(points)
    reach = float(tolerance.max())
    for first in range(0, len(faces), CHUNK):
        face = np.arange(first, min(first + CHUNK, len(faces)))
        tri = vertices[faces[face]].astype(np.float64)
        box_lo, box_hi = tri.min(axis=1) - reach, tri.max(axis=1) + reach
        lo, hi = np.floor(box_lo / CELL_M).astype(np.int64), np.floor(box_hi / CELL_M).astype(np.int64)
        # Faces over a few cells (the terrain's skirt, fence panels) are tested against every point of
        # their box directly: listing them in each cell they touch would cost more than the rest.
        large = (hi - lo + 1).prod(axis=1) > LARGE_FACE_CELLS
        small = np.flatnonzero(~large)
        box, point = grid.pairs(lo[small], hi[small])
        pair_faces, pair_points = [small[box]], [point]
        big = np.flatnonzero(large)
        step = max(1, CHUNK // max(n, 1))
        for first_big in range(0, len(big), step):  # the few large faces, against every point at once
            b = big[first_big : first_big + step]
            inside = ((box_lo[b, None] <= points[None]) & (points[None] <= box_hi[b, None])).all(axis=2)
            which, point = np.nonzero(inside)
            pair_faces.append(b[which])
            pair_points.append(point)
        local, point = np.concatenate(pair_faces), np.concatenate(pair_points)
        for lo_pair in range(0, len(local), CHUNK):
            pf, pp = local[lo_pair : lo_pair + CHUNK], point[lo_pair : lo_pair + CHUNK]
            # The face's box, grown by the point's tolerance, must hold the point: a cheap first cut.
            grown = (tolerance[pp] - reach)[:, None]
            keep = ((box_lo[pf] - grown <= points[pp]) & (points[pp] <= box_hi[pf] + grown)).all(axis=1)
            pf, pp = pf[keep], pp[keep]
            t = tri[pf]
            close = point_triangle_distance(points[pp], t[:, 0], t[:, 1], t[:, 2]) <= tolerance[pp]
            near[pp[close]] = True
            match[pp[close & (face_instance[face[pf]] == instance[pp])]] = True
    return match, near


@dataclass
class GardenResult:
    """The check of one garden: per row (its instance file) the sampled pixels that agree, of how many."""

    rows: dict[str, tuple[int, int]]
    agree: int
    near: int
    checked: int
    faces: int


def check_garden(path, samples: Samples) -> GardenResult:
    """Test one garden's sampled pixels against its published mesh (``read_mesh_ply``'s errors propagate)."""
    from eden_pipe.io.mesh_ply import read_mesh_ply

    mesh = read_mesh_ply(path)
    points = np.concatenate(samples.points) if samples.points else np.zeros((0, 3))
    tolerance = np.concatenate(samples.tolerance) if samples.tolerance else np.zeros(0)
    instance = np.concatenate(samples.instance) if samples.instance else np.zeros(0, np.int64)
    match, near = agreement(
        mesh["vertices"], mesh["faces"], mesh["instance"].astype(np.int64), points, tolerance, instance
    )
    rows: dict[str, tuple[int, int]] = {}
    start = 0
    for rel, chunk in zip(samples.rows, samples.points, strict=True):
        ok = match[start : start + len(chunk)]
        rows[rel] = (int(ok.sum()), len(ok))
        start += len(chunk)
    return GardenResult(rows, int(match.sum()), int(near.sum()), len(match), len(mesh["faces"]))
