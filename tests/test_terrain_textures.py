"""The compiled terrain textures (``render.textures``) are bit-identical to the numpy they replaced.

The numpy version below is the oracle, as it was: every terrain material (pebbles, gravel,
pavement, dirt, lawn soil) and the rows of other materials, at float32 hit points spread over
the garden and its 60 m skirt.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.models.mesh import MATERIALS
from eden_pipe.render import vec
from eden_pipe.render.textures import apply_terrain_textures


# ------------------------------------------------------------------ the numpy oracle
def _hash2(ix: np.ndarray, iy: np.ndarray, salt: int) -> np.ndarray:
    """Deterministic per-cell uniform numbers in [0, 1) from integer cell coordinates."""
    h = (ix.astype(np.int64) * 374761393 + iy.astype(np.int64) * 668265263 + salt * 2147483647) & 0xFFFFFFFF
    h = ((h ^ (h >> 13)) * 1274126177) & 0xFFFFFFFF
    h = h ^ (h >> 16)
    return (h & 0xFFFFFF).astype(np.float64) / float(1 << 24)


def cellular(x: np.ndarray, y: np.ndarray, cell: float, salt: int):
    """Worley noise: distances to the nearest and second feature points, the nearest's cell and offset."""
    gx, gy = x / cell, y / cell
    cx, cy = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
    f1 = np.full(x.shape, np.inf)
    f2 = np.full(x.shape, np.inf)
    best_x = np.zeros(x.shape, np.int64)
    best_y = np.zeros(x.shape, np.int64)
    off_x = np.zeros(x.shape)
    off_y = np.zeros(x.shape)
    for dx in (-1, 0, 1):
        for dy in (-1, 0, 1):
            nx, ny = cx + dx, cy + dy
            px = nx + _hash2(nx, ny, salt)
            py = ny + _hash2(nx, ny, salt + 1)
            ddx, ddy = gx - px, gy - py
            d = np.sqrt(ddx * ddx + ddy * ddy)
            closer = d < f1
            f2 = np.where(closer, f1, np.minimum(f2, d))
            f1 = np.where(closer, d, f1)
            best_x = np.where(closer, nx, best_x)
            best_y = np.where(closer, ny, best_y)
            off_x = np.where(closer, ddx, off_x)
            off_y = np.where(closer, ddy, off_y)
    return f1, f2, best_x, best_y, np.stack([off_x, off_y], axis=-1)


def _bump(normal: np.ndarray, slope_xy: np.ndarray) -> np.ndarray:
    n = normal.copy()
    n[:, :2] -= slope_xy
    return vec.normalize(n)


def _value(x, y, scale, salt):
    """Smooth value noise (bilinear over hashed lattice) in [0, 1)."""
    gx, gy = x / scale, y / scale
    ix, iy = np.floor(gx).astype(np.int64), np.floor(gy).astype(np.int64)
    fx, fy = gx - ix, gy - iy
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a, b = _hash2(ix, iy, salt), _hash2(ix + 1, iy, salt)
    c, d = _hash2(ix, iy + 1, salt), _hash2(ix + 1, iy + 1, salt)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


def _stones(x, y, normal, albedo, cell, palette, salt, gap_dark=0.35, dome=0.6, roundness=0.0):
    """Stones around Worley feature points: per-stone colour and tone, dark gaps, domed normals.

    ``roundness`` > 0 makes stones round (radius ``roundness`` cells, varying per stone) with
    soil between them, as loose pebbles; 0 packs them edge to edge, as gravel.
    """
    f1, f2, bx, by, off = cellular(x, y, cell, salt)
    pick = _hash2(bx, by, salt + 7)
    colours = np.asarray(palette)[np.minimum((pick * len(palette)).astype(int), len(palette) - 1)]
    shade = 0.75 + 0.5 * _hash2(bx, by, salt + 9)
    edge = np.clip((f2 - f1) / 0.12, 0.0, 1.0)  # 0 in the gaps between stones
    if roundness > 0:
        radius = roundness * (0.8 + 0.4 * _hash2(bx, by, salt + 5))
        edge = np.minimum(edge, np.clip((radius - f1) / 0.06, 0.0, 1.0))
        slope = dome * off / np.maximum(radius, 1e-6)[:, None] * edge[:, None]
    else:
        slope = dome * off * edge[:, None]  # the normal tilts away from the stone centre
    tone = (gap_dark + (1.0 - gap_dark) * edge) * shade
    # Keep the patch's tint (albedo relative to its mean) and take the stone's colour and tone.
    new_albedo = albedo / np.maximum(albedo.mean(axis=1, keepdims=True), 1e-6) * colours * tone[:, None]
    return new_albedo, _bump(normal, -slope)


def numpy_terrain_textures(material: np.ndarray, points: np.ndarray, albedo: np.ndarray, normal: np.ndarray):
    """(albedo, shading normal) for hit points; only terrain materials change."""
    albedo = albedo.copy()
    normal = normal.copy()
    x, y = points[:, 0], points[:, 1]
    m = MATERIALS
    # Each material works on its own rows: index arrays with take/put are several times
    # faster than boolean masks on (N, 3) arrays.

    sel = np.nonzero(material == m["pebbles"])[0]
    if len(sel):
        pal = [(0.34, 0.32, 0.29), (0.42, 0.38, 0.32), (0.24, 0.23, 0.22), (0.40, 0.30, 0.22), (0.50, 0.48, 0.45)]
        albedo[sel], normal[sel] = _stones(
            x[sel],
            y[sel],
            vec.gather(normal, sel),
            vec.gather(albedo, sel),
            0.045,
            pal,
            11,
            gap_dark=0.25,
            dome=0.9,
            roundness=0.48,
        )
    sel = np.nonzero(material == m["gravel"])[0]
    if len(sel):
        pal = [(0.45, 0.44, 0.42), (0.36, 0.35, 0.33), (0.52, 0.49, 0.45), (0.30, 0.29, 0.28)]
        albedo[sel], normal[sel] = _stones(
            x[sel], y[sel], vec.gather(normal, sel), vec.gather(albedo, sel), 0.014, pal, 23, gap_dark=0.5, dome=0.4
        )
    sel = np.nonzero(material == m["pavement"])[0]
    if len(sel):
        xs, ys = x[sel], y[sel]
        tile = 0.5
        # Running bond: every other row shifted by half a tile.
        row = np.floor(ys / tile)
        xs_shift = xs + 0.5 * tile * (row % 2)
        col = np.floor(xs_shift / tile)
        ux, uy = xs_shift / tile - col, ys / tile - row
        joint = np.minimum(np.minimum(ux, 1 - ux), np.minimum(uy, 1 - uy)) * tile
        in_joint = joint < 0.006
        tint = 0.88 + 0.24 * _hash2(col.astype(np.int64), row.astype(np.int64), 31)
        grain = 0.9 + 0.2 * _value(xs, ys, 0.03, 37)
        factor = np.where(in_joint, 0.45, tint * grain)
        albedo[sel] = vec.gather(albedo, sel) * factor[:, None]
        bevel = np.clip(1.0 - joint / 0.012, 0.0, 1.0)
        gxs = np.where(ux < 0.5, 1.0, -1.0) * (np.minimum(ux, 1 - ux) < np.minimum(uy, 1 - uy))
        gys = np.where(uy < 0.5, 1.0, -1.0) * (np.minimum(uy, 1 - uy) <= np.minimum(ux, 1 - ux))
        normal[sel] = _bump(vec.gather(normal, sel), -0.5 * bevel[:, None] * np.stack([gxs, gys], axis=1))
    for name, scale, amp in (("dirt", 0.08, 0.35), ("grass_soil", 0.05, 0.3)):
        sel = np.nonzero(material == m[name])[0]
        if len(sel):
            xs, ys = x[sel], y[sel]
            v = 0.6 * _value(xs, ys, scale, 41) + 0.4 * _value(xs, ys, scale / 4.0, 43)
            clumps = _value(xs, ys, 0.012, 47)
            albedo[sel] = vec.gather(albedo, sel) * ((1.0 - amp + 2.0 * amp * v) * (0.85 + 0.3 * clumps))[:, None]
            eps = scale / 4.0
            gx = (_value(xs + eps, ys, scale / 4.0, 43) - _value(xs - eps, ys, scale / 4.0, 43)) / (2 * eps)
            gy = (_value(xs, ys + eps, scale / 4.0, 43) - _value(xs, ys - eps, scale / 4.0, 43)) / (2 * eps)
            normal[sel] = _bump(vec.gather(normal, sel), 0.01 * np.stack([gx, gy], axis=1))
    return np.clip(albedo, 0.0, 1.0), normal


# ------------------------------------------------------------------ the kernel against it
@pytest.mark.parametrize("spread_m", [3.0, 60.0])
def test_terrain_textures_are_bit_identical_to_numpy(spread_m):
    rng = np.random.default_rng(21)
    n = 60_000
    kinds = [MATERIALS[k] for k in ("pebbles", "gravel", "pavement", "dirt", "grass_soil", "grass", "bark")]
    material = rng.choice(np.array(kinds, np.uint8), n)
    points = np.column_stack([rng.uniform(-spread_m, spread_m, (n, 2)), rng.uniform(-0.2, 0.3, n)]).astype(np.float32)
    points[:50, :2] = np.round(points[:50, :2] * 4) / 4  # on tile joints and cell corners
    albedo = rng.uniform(0.0, 1.2, (n, 3)).astype(np.float32)
    albedo[::97] = 0.0  # a black patch: its mean is floored
    normal = vec.normalize(rng.normal(size=(n, 3)) * [0.2, 0.2, 1.0]).astype(np.float32)
    expected = numpy_terrain_textures(material, points, albedo, normal)
    got = apply_terrain_textures(material, points, albedo, normal)
    for g, e in zip(got, expected, strict=True):
        assert g.dtype == e.dtype == np.float32 and np.array_equal(g.view(np.uint32), e.view(np.uint32))
    changed = np.any(got[1] != normal, axis=1)
    assert changed[np.isin(material, kinds[:5])].mean() > 0.5 and not changed[np.isin(material, kinds[5:])].any()
