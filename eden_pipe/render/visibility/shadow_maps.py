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
MOMENTS = 8  # direction_polynomials' count: with the constant, the span of the SH bands 0-2


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


def direction_polynomials(directions: np.ndarray) -> np.ndarray:
    """(D, MOMENTS) float32: x, y, z, xy, yz, xz, x^2 - y^2, z^2 of unit ``directions`` (D, 3): with
    the constant, the polynomials of order 2 at most on the sphere (the span of the spherical
    harmonics' bands 0-2), each within [-1, 1]."""
    x, y, z = (np.asarray(directions, np.float64)[:, i] for i in range(3))
    return np.stack([x, y, z, x * y, y * z, x * z, x * x - y * y, z * z], axis=1).astype(np.float32)


FIT_DIRECTIONS = 4096  # directions of the upper hemisphere a frame's sky is fitted over (hemisphere_fit)


def hemisphere_directions(count: int) -> np.ndarray:
    """(count, 3) float32 unit directions of the upper hemisphere, a Fibonacci lattice: equal areas,
    the same on every call."""
    golden = np.pi * (3.0 - np.sqrt(5.0))
    i = np.arange(count)
    z = (i + 0.5) / count
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(golden * i), r * np.sin(golden * i), z], axis=1).astype(np.float32)


def sky_basis(directions: np.ndarray) -> np.ndarray:
    """(D, 1 + MOMENTS) float64: the constant, then :func:`direction_polynomials` of ``directions``."""
    return np.concatenate([np.ones((len(directions), 1)), direction_polynomials(directions)], axis=1, dtype=np.float64)


def hemisphere_fit(radiance) -> np.ndarray:
    """(1 + MOMENTS, 3) float32: the least-squares fit of the sky's ``radiance`` (a function of (D, 3)
    unit directions -> (D, 3)) over the upper hemisphere (:func:`hemisphere_directions`) by
    :func:`sky_basis`: a face side's sky light over its visible fraction is then its moments' means
    (``face_sky.face_sky_table``) times it, with 1 for the constant (docs/realism.md)."""
    d = hemisphere_directions(FIT_DIRECTIONS)
    return np.linalg.lstsq(sky_basis(d), np.asarray(radiance(d), np.float64), rcond=None)[0].astype(np.float32)


# Serial and nogil (frame threads call it side by side); no fastmath, as every kernel of the
# renderer (render/kernels.py): the same sums on every machine, so the same pixels.
@njit(nogil=True, cache=True)
def _open_sky(
    px, py, pz, nx, ny, nz, ranges, subset_of, frames, grids, starts, depth, radius, spacing, step, bias, slope, out,
    back, poly, moments, moments_back,
):  # fmt: skip
    """Per point i: the sum over the directions w of its subset of max(n.w, 0) where the point is
    open along w: its nearest texel's hit lies beyond it, less ``bias`` (a miss is stored past
    every point). Direction k belongs to subset ``subset_of[k]``, whose points are rows
    ``ranges[s]:ranges[s + 1]``. ``px``, ``py``, ``pz`` (N,) float32: the points less the maps'
    centre, one array a coordinate (so the loops vectorise); ``nx``, ``ny``, ``nz`` their normals;
    ``out`` (N,) float32, added to, each point's directions in their order; ``back`` (N,) float32 or
    empty: the same for the other side of each point (normal -n), from the same reads.
    ``moments`` (MOMENTS, N) float32 or (MOMENTS, 0): added to, the same sums times each direction's
    polynomials ``poly`` (D, MOMENTS) (:func:`direction_polynomials`); ``moments_back`` the same
    for ``back``.

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
    two_sided = back.shape[0] > 0
    with_moments = moments.shape[1] > 0
    acc = np.empty((MOMENTS, OPEN_SKY_BLOCK if with_moments else 0), np.float32)  # a block's moments
    acc_back = np.empty_like(acc)
    opened = np.empty(OPEN_SKY_BLOCK, np.float32)  # the block's weights where open
    depth_along = np.empty(OPEN_SKY_BLOCK, np.float32)  # the other side's ``beyond``
    # per point, for the other side's test: n.w, the distance along w and whether inside the bundle
    facing = np.empty(OPEN_SKY_BLOCK, np.float32)
    along = np.empty(OPEN_SKY_BLOCK, np.float32)
    inside = np.empty(OPEN_SKY_BLOCK, np.float32)
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
            added_back = back[block:end] if two_sided else back
            if with_moments:
                acc[:] = zero
                acc_back[:] = zero
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
                    facing[j] = bnx[j] * wx + bny[j] * wy + bnz[j] * wz
                    cos = max(facing[j], zero)
                    weight[j] = cos
                    # The texel's ray passes up to half a diagonal of a spacing beside the point: on
                    # its own plane it meets the surface that much times tan(n, w) nearer (capped).
                    tan = min(np.sqrt(max(one - cos * cos, zero)) / max(cos, min_cos), max_tan)
                    u = x * ax + y * ay + z * az + u0
                    v = x * bx + y * by + z * bz + v0
                    # Outside the bundle nothing of the garden lies that way: open.
                    inside[j] = np.float32((u >= zero) & (u <= last_u) & (v >= zero) & (v <= last_v))
                    iu, iv = np.int32(min(max(u, zero), last_u)), np.int32(min(max(v, zero), last_v))
                    texel[j] = _texel_address(first, across_blocks, iu, iv)
                    along[j] = x * wx + y * wy + z * wz
                    beyond[j] = (far - along[j] * per_step - tilt * tan) * inside[j]
                # The map's reads alone in one loop, so that the test beside them vectorises.
                for j in range(size):
                    hit[j] = depth[texel[j]]  # a step count, exact as float32
                for j in range(size):
                    # a select, not a branch: open or not is a coin toss the CPU cannot predict
                    added[j] += weight[j] if hit[j] >= beyond[j] else zero
                if with_moments:
                    _add_moments(poly[k], weight, hit, beyond, size, opened, acc)
                if two_sided:
                    # The other side (normal -n) of the same points: the same texels, its own weight and slope.
                    for j in range(size):
                        cos = max(-facing[j], zero)
                        weight[j] = cos
                        tan = min(np.sqrt(max(one - cos * cos, zero)) / max(cos, min_cos), max_tan)
                        depth_along[j] = (far - along[j] * per_step - tilt * tan) * inside[j]
                    for j in range(size):
                        added_back[j] += weight[j] if hit[j] >= depth_along[j] else zero
                    if with_moments:
                        _add_moments(poly[k], weight, hit, depth_along, size, opened, acc_back)
            if with_moments:  # the block's sums, kept in the core's cache until now
                for c in range(MOMENTS):
                    moments[c, block:end] += acc[c, :size]
                    if two_sided:
                        moments_back[c, block:end] += acc_back[c, :size]
    return out


@njit(nogil=True, cache=True, inline="always")
def _add_moments(p, weight, hit, beyond, size, opened, acc):
    """``acc`` (MOMENTS, OPEN_SKY_BLOCK) += each open point's weight times the direction's
    polynomials ``p``, over the block's first ``size`` points (``opened`` a buffer)."""
    zero = np.float32(0.0)
    for j in range(size):
        opened[j] = weight[j] if hit[j] >= beyond[j] else zero
    for c in range(MOMENTS):
        pc = np.float32(p[c])
        row = acc[c]
        for j in range(size):
            row[j] += opened[j] * pc


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
        return self._estimate(points, normals, phase, subsets, two_sided=False)[0]

    def both_sides(self, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(N,) float32 twice: :meth:`visible_fraction` of ``points`` on the side of ``normals`` and
        on the other side (the same values as with ``-normals``), from one pass over the maps."""
        front, back = self._estimate(points, normals, None, 1, two_sided=True)
        assert back is not None
        return front, back

    def both_sides_moments(self, points: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`both_sides` with the directions' polynomials: ((2, N) float32 the two sides'
        visible fractions before they are kept within 1, (2, MOMENTS, N) float32 the same sums
        times each direction's :func:`direction_polynomials`), from one pass over the maps. A
        side's moments over its fraction are the polynomials' cosine-weighted means over the
        directions it sees the sky in."""
        n = len(points)
        moments = np.zeros((2, MOMENTS, n), np.float32)
        front, back = self._estimate(points, normals, None, 1, two_sided=True, moments=moments)
        assert back is not None
        return np.stack([front, back]), moments

    def _estimate(
        self,
        points: np.ndarray,
        normals: np.ndarray,
        phase: np.ndarray | None,
        subsets: int,
        two_sided: bool,
        moments: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray | None]:
        """The fractions (kept within 1) of ``points`` (and their other sides); with ``moments``
        ((2, MOMENTS, N) float32 zeros, every direction, two-sided) the fractions are not kept within
        1 and ``moments`` receives their sums times the directions' polynomials, in the same scale."""
        n = len(points)
        out = np.zeros(n, np.float32)
        back = np.zeros(n if two_sided else 0, np.float32)
        if n == 0 or not self.present:
            return out, back if two_sided else None
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
        none = np.zeros((MOMENTS, 0), np.float32)
        assert moments is None or (order is None and two_sided), "moments: every direction, both sides"
        nx, ny, nz = (np.ascontiguousarray(normals[:, j]) for j in range(3))
        _open_sky(
            px, py, pz, nx, ny, nz, ranges, subset_of(len(self.frame), subsets), self.frame, self.grid,
            self.start, self.depth, float(p[3]), float(p[4]), float(p[5]), BIAS_M, SLOPE, out, back,
            direction_polynomials(self.frame[:, 0:3]), *(moments if moments is not None else (none, none)),
        )  # fmt: skip
        scale = np.float32(2.0 * subsets / len(self.frame))
        if moments is not None:
            moments *= scale
        results = []
        for sums in (out, back) if two_sided else (out,):
            sums *= scale
            if moments is None:
                np.minimum(sums, np.float32(1.0), out=sums)
            if order is not None:
                result = np.empty_like(sums)
                result[order] = sums
                sums = result
            results.append(sums)
        return results[0], results[1] if two_sided else None


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
