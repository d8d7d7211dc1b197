"""Each point's own visible sky from the bake's outside-in bundles kept as depth maps
(``render.sky_visibility.shadow_maps``).

The bundles (``bake.sky_hits``) send, for each of ``directions`` sky directions, a grid of parallel
rays ``spacing_m`` apart into the garden, and the bake counts which face sides they hit first. Kept
as they are traced, each direction's first-hit distances are a depth map seen from the sky (a
shadow map, Williams 1978): a point is open to the sky along a direction when the ray of the map's
texel nearest to it along that direction meets nothing before the point, less a bias: the
texel's ray passes up to half a diagonal of a spacing beside the point and meets the point's own
surface a little before it, by that offset times the tangent of the angle between the surface's
normal and the direction (``BIAS_M`` plus ``SLOPE`` spacings times that tangent, chosen on the
realism protocol's tuning views). Over the directions, cosine-weighted, that is the point's own
visible sky, which changes from leaf to leaf and within a leaf, where the probes and faces of the
bake hold one value each (docs/realism.md, "Each pixel's own sky from the bundles' depth maps").

The distances are stored as 16-bit steps of the bundles' whole depth range (under half a
millimetre for a garden 20 m across; ``MISS``: the ray met nothing), two bytes a bundle ray.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

MISS = np.uint16(65535)  # the texel's ray met nothing: the sky along it is open to every point below
LAST_STEP = 65534  # distances are stored in steps 0..LAST_STEP of (0, 2 * radius]
BIAS_M = 0.003  # a point is open along a direction when its texel's hit lies at most this much before it
SLOPE = 0.3  # ... plus this many spacings times tan(n, w): the point's own surface, met beside it
MAX_TAN = 10.0  # the tangent's cap: a direction grazing the surface
BLOCK_BITS = 3
BLOCK = 1 << BLOCK_BITS  # maps are stored in tiles of BLOCK x BLOCK texels (_texel_address)
OPEN_SKY_BLOCK = 1024  # points _open_sky takes through every direction at a time


@njit(nogil=True, cache=True, inline="always")
def _texel_address(first, across_blocks, iu, iv):
    """Where texel (iu, iv) of a map beginning at ``first`` lies: maps are stored in BLOCK x BLOCK
    tiles, row by row of tiles (``across_blocks`` a row), each tile row-major, so that the texels
    of neighbouring points share cache lines whichever way the image runs across the map."""
    tile = (iv >> BLOCK_BITS) * across_blocks + (iu >> BLOCK_BITS)
    return first + (tile << (2 * BLOCK_BITS)) + ((iv & (BLOCK - 1)) << BLOCK_BITS) + (iu & (BLOCK - 1))


@njit(nogil=True, cache=True)
def quantise_depth(t, across, across_blocks, first_row, step, out, first):
    """Rows ``first_row`` on of the map at ``first`` (``across`` texels a row) <- the distances
    ``t`` (rows x across, inf: a miss) in steps of ``step``."""
    inv = 1.0 / step
    for i in range(t.shape[0]):
        d = t[i]
        q = MISS if d == np.inf else min(int(d * inv + 0.5), LAST_STEP)
        out[_texel_address(first, across_blocks, i % across, first_row + i // across)] = q


# Serial and nogil (frame threads call it side by side); no fastmath, as every kernel of the
# renderer (render/kernels.py): the same sums on every machine, so the same pixels.
@njit(nogil=True, cache=True)
def _open_sky(
    px, py, pz, nx, ny, nz, ranges, subset_of, frames, grids, starts, depth, radius, spacing, step, bias, slope, out
):
    """Per point i: the sum over the directions w of its subset of max(n.w, 0) where the point is
    open along w: its nearest texel's hit lies beyond it, less ``bias`` (a miss is stored past
    every point). Direction k belongs to subset ``subset_of[k]``, whose points are rows
    ``ranges[s]:ranges[s + 1]``. ``px``, ``py``, ``pz`` (N,) float32: the points less the maps'
    centre, one array a coordinate (so the loops vectorise); ``nx``, ``ny``, ``nz`` their normals;
    ``out`` (N,) float32, added to, each point's directions in their order.

    A subset's points go in blocks of OPEN_SKY_BLOCK rows (neighbouring pixels), each block through
    every direction of its subset before the next, so that the block's rows stay in the core's
    cache. Per direction and block, three loops: the texels and distances (vectorised), the reads
    of the map (a gather, alone), the open test and sum (vectorised); as one loop the reads kept
    the test from vectorising, and 3.2 times the time went (docs/realism.md)."""
    inv = 1.0 / spacing
    texel = np.empty(OPEN_SKY_BLOCK, np.uint32)  # unsigned: the map's reads need no wrap-around test
    # the point's distance along w from the bundle's starting plane, less the bias, in depth steps
    beyond = np.empty(OPEN_SKY_BLOCK, np.float32)
    weight = np.empty(OPEN_SKY_BLOCK, np.float32)
    hit = np.empty(OPEN_SKY_BLOCK, np.float32)  # the texels' first-hit depths, in steps
    zero, one = np.float32(0.0), np.float32(1.0)
    max_tan = np.float32(MAX_TAN)
    min_cos = np.float32(1.0 / np.sqrt(1.0 + MAX_TAN * MAX_TAN))
    far = np.float32((radius - bias) / step)
    per_step = np.float32(1.0 / step)
    tilt = np.float32(slope * spacing / step)  # the slope's share of the bias, in depth steps
    for s in range(ranges.shape[0] - 1):
        for block in range(ranges[s], ranges[s + 1], OPEN_SKY_BLOCK):
            end = min(block + OPEN_SKY_BLOCK, ranges[s + 1])
            size = end - block
            # The block's rows as slices read at j in range(size): an index numba knows is not
            # negative, so the loops vectorise without numpy's wrap-around test at every read.
            bpx, bpy, bpz = px[block:end], py[block:end], pz[block:end]
            bnx, bny, bnz = nx[block:end], ny[block:end], nz[block:end]
            added = out[block:end]
            for k in range(frames.shape[0]):
                if subset_of[k] != s:
                    continue
                wx, wy, wz = np.float32(frames[k, 0]), np.float32(frames[k, 1]), np.float32(frames[k, 2])
                ax, ay = np.float32(frames[k, 3] * inv), np.float32(frames[k, 4] * inv)
                az = np.float32(frames[k, 5] * inv)
                bx, by = np.float32(frames[k, 6] * inv), np.float32(frames[k, 7] * inv)
                bz = np.float32(frames[k, 8] * inv)
                # texel coordinates + 0.5: a truncation is then the nearest texel (clamped to the map)
                u0, v0 = np.float32(0.5 - grids[k, 0] * inv), np.float32(0.5 - grids[k, 1] * inv)
                across_blocks = np.int32((grids[k, 2] + BLOCK - 1) // BLOCK)
                last_u, last_v = np.float32(grids[k, 2] - 1.0), np.float32(grids[k, 3] - 1.0)
                first = np.int32(starts[k])
                for j in range(size):
                    x, y, z = bpx[j], bpy[j], bpz[j]
                    cos = max(bnx[j] * wx + bny[j] * wy + bnz[j] * wz, zero)
                    weight[j] = cos
                    # The texel's ray passes up to half a diagonal of a spacing beside the point: on
                    # its own plane it meets the surface that much times tan(n, w) nearer (capped).
                    tan = min(np.sqrt(max(one - cos * cos, zero)) / max(cos, min_cos), max_tan)
                    u = x * ax + y * ay + z * az + u0
                    v = x * bx + y * by + z * bz + v0
                    inside = (u >= zero) & (u <= last_u) & (v >= zero) & (v <= last_v)
                    iu, iv = np.int32(min(max(u, zero), last_u)), np.int32(min(max(v, zero), last_v))
                    texel[j] = _texel_address(first, across_blocks, iu, iv)
                    # Outside the bundle nothing of the garden lies that way: open.
                    beyond[j] = (far - (x * wx + y * wy + z * wz) * per_step - tilt * tan) * np.float32(inside)
                # The map's reads alone in one loop, so that the test beside them vectorises.
                for j in range(size):
                    hit[j] = depth[texel[j]]  # a step count, exact as float32
                for j in range(size):
                    # a select, not a branch: open or not is a coin toss the CPU cannot predict
                    added[j] += weight[j] if hit[j] >= beyond[j] else zero
    return out


@dataclass
class ShadowMaps:
    """The bundles' first-hit depth maps: per direction ``frame`` (D, 9) float64, the direction w
    toward the sky and the grid's axes e1, e2; ``grid`` (D, 4) float64, the first texel's
    coordinates along e1 and e2 (from ``params``' centre) and the texels across and down;
    ``start`` (D + 1,) int64, where each map begins in ``depth`` (T,) uint16, in tiles of its
    grid; ``params`` (6,) float64: the bundles' centre (3), the distance of their starting plane
    from it (radius), the spacing and the depth step. Empty: no maps (:meth:`none`)."""

    frame: np.ndarray
    grid: np.ndarray
    start: np.ndarray
    depth: np.ndarray
    params: np.ndarray

    FIELDS = ("frame", "grid", "start", "depth", "params")

    @classmethod
    def none(cls) -> ShadowMaps:
        return cls(np.zeros((0, 9)), np.zeros((0, 4)), np.zeros(1, np.int64), np.zeros(0, np.uint16), np.zeros(6))

    @classmethod
    def allocate(cls, centre, radius: float, spacing: float, frames: list, grids: list) -> ShadowMaps:
        """Maps for the bundles' directions (``frames`` rows w, e1, e2; ``grids`` rows u0, v0, nu,
        nv), their depths to be filled as the bundles are traced (:meth:`store`)."""
        grid = np.asarray(grids, np.float64).reshape(-1, 4)
        sizes = (-(-grid[:, 2] // BLOCK) * -(-grid[:, 3] // BLOCK) * BLOCK * BLOCK).astype(np.int64)  # whole tiles
        start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        step = 2.0 * radius / LAST_STEP
        params = np.array([*np.asarray(centre, np.float64), radius, spacing, step])
        depth = np.full(int(start[-1]), MISS, np.uint16)
        return cls(np.asarray(frames, np.float64).reshape(-1, 9), grid, start, depth, params)

    @property
    def present(self) -> bool:
        return len(self.frame) > 0

    def arrays(self) -> dict[str, Any]:
        """The bake file's entries (``shadow_map_*``): none without maps, so such a file is as before."""
        return {f"shadow_map_{k}": getattr(self, k) for k in self.FIELDS} if self.present else {}

    @classmethod
    def read(cls, data) -> ShadowMaps:
        """The maps from a bake file's entries (``np.load``'s), none where it has none."""
        if "shadow_map_depth" not in data.files:
            return cls.none()
        return cls(*(data[f"shadow_map_{k}"] for k in cls.FIELDS))

    def store(self, direction: int, first_row: int, t: np.ndarray) -> None:
        """The hit distances ``t`` (rows x nu, inf on a miss) of direction ``direction``'s rows from
        ``first_row`` on."""
        across = int(self.grid[direction, 2])
        quantise_depth(
            np.ascontiguousarray(t, np.float32),
            across,
            -(-across // BLOCK),
            first_row,
            float(self.params[5]),
            self.depth,
            int(self.start[direction]),
        )

    def visible_fraction(
        self, points: np.ndarray, normals: np.ndarray, phase: np.ndarray | None = None, subsets: int = 1
    ) -> np.ndarray:
        """(N,) float32 cosine-weighted visible sky of ``points`` (N, 3) on the side of their unit
        ``normals`` (N, 3): the maps' directions (equal solid angles) open at the point, weighted by
        n.w; directions below the horizon count as blocked (the ground). With ``subsets`` > 1 each
        point reads only the directions of its ``phase`` (N,) in 0..subsets-1 (:func:`subset_of`:
        an even share of every elevation): ``subsets`` times fewer reads, for a caller that pools
        neighbours of different phases (``pixel_sky.pooled_scale``)."""
        n = len(points)
        out = np.zeros(n, np.float32)
        if n == 0 or not self.present:
            return out
        p = self.params
        if phase is None or subsets == 1:
            order, ranges, subsets = None, np.array([0, n], np.int64), 1
            centred = np.array(points, np.float32)
            normals = np.asarray(normals, np.float32)
        else:
            # The points grouped by subset (each direction reads its subset's rows alone), back at the end.
            order = np.argsort(phase, kind="stable")
            ranges = np.searchsorted(np.take(phase, order), np.arange(subsets + 1)).astype(np.int64)
            centred = np.take(np.asarray(points, np.float32), order, axis=0)
            normals = np.take(np.asarray(normals, np.float32), order, axis=0)
        centred -= p[0:3].astype(np.float32)
        px, py, pz = (np.ascontiguousarray(centred[:, j]) for j in range(3))  # one array a coordinate
        nx, ny, nz = (np.ascontiguousarray(normals[:, j]) for j in range(3))
        _open_sky(
            px,
            py,
            pz,
            nx,
            ny,
            nz,
            ranges,
            subset_of(len(self.frame), subsets),
            self.frame,
            self.grid,
            self.start,
            self.depth,
            float(p[3]),
            float(p[4]),
            float(p[5]),
            BIAS_M,
            SLOPE,
            out,
        )
        out *= np.float32(2.0 * subsets / len(self.frame))
        np.minimum(out, np.float32(1.0), out=out)
        if order is None:
            return out
        result = np.empty_like(out)
        result[order] = out
        return result


def strata(count: int) -> tuple[int, int]:
    """(rows, cols): the bundles' ``count`` sky directions as rows of equal solid angle in cos theta
    by columns in azimuth (``bake.sky_directions``), exactly ``count`` of them (a partial row would
    bias the estimate), as near to twice as many columns as rows as ``count``'s divisors allow."""
    rows = min((r for r in range(1, count + 1) if count % r == 0), key=lambda r: abs(r - np.sqrt(count / 2)))
    return rows, count // rows


def subset_of(count: int, subsets: int) -> np.ndarray:
    """(count,) int64: which of ``subsets`` subsets each of the ``count`` directions belongs to: in
    every row of :func:`strata` an even share of the azimuths, turned by one column from row to
    row, so that each subset spans every elevation and many azimuths."""
    cols = strata(count)[1]
    k = np.arange(count)
    return ((k % cols + k // cols) % subsets).astype(np.int64)
