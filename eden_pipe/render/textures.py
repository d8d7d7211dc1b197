"""Procedural terrain materials evaluated at hit points in world space.

Pebbles, gravel, paving tiles with joints, dirt and the soil under the lawn get
their pattern here, per hit point, from world x, y, so the pattern is fixed to
the ground (it never swims with the camera) and costs nothing in triangles.
Each returns a new albedo (the Dcol pass, so the albedo layer shows the
texture) and a shading normal with small bumps. The geometric normal stays
untouched for the normal ground truth.

Compiled (numba, one pass per hit; see :mod:`eden_pipe.render.kernels` for why):
the arithmetic is numpy's, operation for operation, in the precision numpy gave
each step (float32 where a step read float32 coordinates, float64 for the noise),
so the patterns are bit-identical to the numpy version, which
``tests/test_render_kernels.py`` keeps as the oracle.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from eden_pipe.models.mesh import MATERIALS
from eden_pipe.render.kernels import KERNEL, _clip, _maximum, _minimum

ONE = np.float32(1.0)
# (cell size m, palette (linear RGB), salt, gap darkness, dome, roundness): pebbles are round and loose
# on soil, gravel packed edge to edge (``_stone``).
PEBBLES = (
    0.045,
    np.array([(0.34, 0.32, 0.29), (0.42, 0.38, 0.32), (0.24, 0.23, 0.22), (0.40, 0.30, 0.22), (0.50, 0.48, 0.45)]),
    11,
    0.25,
    0.9,
    0.48,
)
GRAVEL = (
    0.014,
    np.array([(0.45, 0.44, 0.42), (0.36, 0.35, 0.33), (0.52, 0.49, 0.45), (0.30, 0.29, 0.28)]),
    23,
    0.5,
    0.4,
    0.0,
)
SOILS = ((MATERIALS["dirt"], 0.08, 0.35), (MATERIALS["grass_soil"], 0.05, 0.3))  # (material, noise scale m, amplitude)


@njit(inline="always")
def _hash2(ix, iy, salt):
    """A deterministic uniform number in [0, 1) from integer cell coordinates."""
    h = (ix * 374761393 + iy * 668265263 + salt * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return np.float64(h & 0xFFFFFF) / float(1 << 24)


@njit(inline="always")
def _value(x, y, scale, salt):
    """Smooth value noise (bilinear over hashed lattice) in [0, 1) at float32 ``x``, ``y``."""
    gx, gy = x / np.float32(scale), y / np.float32(scale)
    ix, iy = np.int64(np.floor(gx)), np.int64(np.floor(gy))
    fx, fy = np.float64(gx) - ix, np.float64(gy) - iy
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a, b = _hash2(ix, iy, salt), _hash2(ix + 1, iy, salt)
    c, d = _hash2(ix, iy + 1, salt), _hash2(ix + 1, iy + 1, salt)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


@njit(inline="always")
def _bump(normal, k, sx, sy):
    """The unit normal of row ``k`` of ``normal`` tilted by the slope (``sx``, ``sy``), in place."""
    n0 = np.float32(normal[k, 0] - sx)
    n1 = np.float32(normal[k, 1] - sy)
    n2 = normal[k, 2]
    length = _maximum(np.sqrt((n0 * n0 + n1 * n1) + n2 * n2), np.float32(1e-30))
    normal[k, 0], normal[k, 1], normal[k, 2] = n0 / length, n1 / length, n2 / length


@njit(inline="always")
def _stone(k, x, y, normal, albedo, cell, palette, salt, gap_dark, dome, roundness):
    """Stones around Worley feature points: per-stone colour and tone, dark gaps, domed normals.
    ``roundness`` > 0 makes stones round (radius ``roundness`` cells, varying per stone) with
    soil between them, as loose pebbles; 0 packs them edge to edge, as gravel."""
    gx, gy = x / np.float32(cell), y / np.float32(cell)
    cx, cy = np.int64(np.floor(gx)), np.int64(np.floor(gy))
    f1 = f2 = np.inf
    bx = by = 0
    off_x = off_y = 0.0
    for dx in (-1, 0, 1):  # the nearest and second nearest feature points of the 3 x 3 cells
        for dy in (-1, 0, 1):
            nx, ny = cx + dx, cy + dy
            ddx = np.float64(gx) - (nx + _hash2(nx, ny, salt))
            ddy = np.float64(gy) - (ny + _hash2(nx, ny, salt + 1))
            d = np.sqrt(ddx * ddx + ddy * ddy)
            if d < f1:
                f2, f1, bx, by, off_x, off_y = f1, d, nx, ny, ddx, ddy
            else:
                f2 = _minimum(f2, d)
    count = palette.shape[0]
    pick = min(np.int64(_hash2(bx, by, salt + 7) * count), count - 1)
    shade = 0.75 + 0.5 * _hash2(bx, by, salt + 9)
    edge = _clip((f2 - f1) / 0.12, 0.0, 1.0)  # 0 in the gaps between stones
    if roundness > 0:
        radius = roundness * (0.8 + 0.4 * _hash2(bx, by, salt + 5))
        edge = _minimum(edge, _clip((radius - f1) / 0.06, 0.0, 1.0))
        reach = _maximum(radius, 1e-6)
        slope_x, slope_y = dome * off_x / reach * edge, dome * off_y / reach * edge
    else:
        slope_x, slope_y = dome * off_x * edge, dome * off_y * edge  # the normal tilts away from the stone centre
    tone = (gap_dark + (1.0 - gap_dark) * edge) * shade
    # Keep the patch's tint (albedo relative to its mean) and take the stone's colour and tone.
    mean = _maximum((albedo[k, 0] + albedo[k, 1] + albedo[k, 2]) / np.float32(3), np.float32(1e-6))
    for j in range(3):
        albedo[k, j] = albedo[k, j] / mean * palette[pick, j] * tone
    _bump(normal, k, -slope_x, -slope_y)


@njit(inline="always")
def _paving(k, x, y, normal, albedo):
    """Running-bond tiles (every other row shifted by half a tile) with dark, bevelled joints."""
    tile = np.float32(0.5)
    row = np.floor(y / tile)
    x_shift = x + np.float32(0.5 * 0.5) * (row % np.float32(2))
    col = np.floor(x_shift / tile)
    ux, uy = x_shift / tile - col, y / tile - row
    across_x, across_y = _minimum(ux, ONE - ux), _minimum(uy, ONE - uy)
    joint = _minimum(across_x, across_y) * tile
    if joint < np.float32(0.006):
        factor = 0.45
    else:
        factor = (0.88 + 0.24 * _hash2(np.int64(col), np.int64(row), 31)) * (0.9 + 0.2 * _value(x, y, 0.03, 37))
    for j in range(3):
        albedo[k, j] = albedo[k, j] * factor
    bevel = _clip(ONE - joint / np.float32(0.012), np.float32(0.0), ONE)
    gx = (1.0 if ux < np.float32(0.5) else -1.0) * (across_x < across_y)
    gy = (1.0 if uy < np.float32(0.5) else -1.0) * (across_y <= across_x)
    lean = np.float32(-0.5) * bevel
    _bump(normal, k, lean * gx, lean * gy)


@njit(inline="always")
def _soil(k, x, y, normal, albedo, scale, amp):
    """Dirt and the soil under the lawn: two octaves of value noise and clumps, gently bumped."""
    v = 0.6 * _value(x, y, scale, 41) + 0.4 * _value(x, y, scale / 4.0, 43)
    clumps = _value(x, y, 0.012, 47)
    factor = (1.0 - amp + 2.0 * amp * v) * (0.85 + 0.3 * clumps)
    for j in range(3):
        albedo[k, j] = albedo[k, j] * factor
    eps = scale / 4.0
    step = np.float32(eps)
    gx = (_value(x + step, y, scale / 4.0, 43) - _value(x - step, y, scale / 4.0, 43)) / (2 * eps)
    gy = (_value(x, y + step, scale / 4.0, 43) - _value(x, y - step, scale / 4.0, 43)) / (2 * eps)
    _bump(normal, k, 0.01 * gx, 0.01 * gy)


@njit(**KERNEL)
def _textures(material, points, albedo, normal, codes, pebbles, gravel, soils):
    for k in range(material.shape[0]):
        m = material[k]
        x, y = points[k, 0], points[k, 1]
        if m == codes[0]:
            _stone(k, x, y, normal, albedo, pebbles[0], pebbles[1], pebbles[2], pebbles[3], pebbles[4], pebbles[5])
        elif m == codes[1]:
            _stone(k, x, y, normal, albedo, gravel[0], gravel[1], gravel[2], gravel[3], gravel[4], gravel[5])
        elif m == codes[2]:
            _paving(k, x, y, normal, albedo)
        else:
            for code, scale, amp in soils:
                if m == code:
                    _soil(k, x, y, normal, albedo, scale, amp)
        for j in range(3):
            albedo[k, j] = _clip(albedo[k, j], np.float32(0.0), ONE)


def apply_terrain_textures(material: np.ndarray, points: np.ndarray, albedo: np.ndarray, normal: np.ndarray):
    """(albedo, shading normal) (N, 3) float32 for hit points (float32); only terrain materials change,
    and every albedo is clipped to [0, 1]."""
    albedo = np.array(albedo, np.float32)
    normal = np.array(normal, np.float32)
    codes = np.array([MATERIALS["pebbles"], MATERIALS["gravel"], MATERIALS["pavement"]], np.int64)
    _textures(material, np.asarray(points, np.float32), albedo, normal, codes, PEBBLES, GRAVEL, SOILS)
    return albedo, normal
