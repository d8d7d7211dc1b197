"""The garden ground: an fBm-displaced heightfield split into 1 x 1 m patches.

Each patch is one terrain type (grass, pebbles, gravel, dirt, pavement) with its
semantic id and a procedural colour. Patch types form contiguous zones (nearest
of a few seeded zone centres), as garden beds, paths and lawns do, rather than a
checkerboard. Around the garden an outer skirt of ground (class background)
reaches the horizon region, so rays leaving the garden low still hit geometry.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.models.noise import Perlin
from eden_pipe.rng import rng_for

# Per terrain type: semantic id, material kind, base linear albedo, colour jitter.
TERRAIN_TYPES = {
    "grass": (labels.GRASS, "grass_soil", (0.055, 0.085, 0.025), 0.06),
    "pebbles": (labels.GROUND, "pebbles", (0.30, 0.27, 0.22), 0.05),
    "gravel": (labels.GROUND, "gravel", (0.36, 0.34, 0.31), 0.04),
    "dirt": (labels.GROUND, "dirt", (0.16, 0.10, 0.055), 0.05),
    "pavement": (labels.PAVEMENT, "pavement", (0.42, 0.40, 0.36), 0.04),
}
TERRAIN_MATERIALS = np.array(sorted({MATERIALS[kind] for _, kind, _, _ in TERRAIN_TYPES.values()}), np.uint8)
SKIRT_M = 60.0
SKIRT_ALBEDO = (0.09, 0.11, 0.05)


@dataclass
class Terrain:
    heights: np.ndarray  # (n+1, n+1) float64 vertex heights, index [iy, ix]
    size_m: float  # garden side length (metres)
    cells_per_m: int
    patch_types: list[str]  # type names, index = patch code
    patch_grid: np.ndarray  # (size, size) int patch code, index [py, px]
    patch_tint: np.ndarray  # (size, size, 3) per-patch albedo multiplier

    @property
    def cell(self) -> float:
        return 1.0 / self.cells_per_m

    def height_at(self, x, y) -> np.ndarray:
        """Exact height of the triangulated surface (same diagonal split as the mesh)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        n = self.heights.shape[0] - 1
        gx = np.clip(x / self.cell, 0.0, n - 1e-9)
        gy = np.clip(y / self.cell, 0.0, n - 1e-9)
        ix = np.floor(gx).astype(np.int64)
        iy = np.floor(gy).astype(np.int64)
        fx, fy = gx - ix, gy - iy
        h = self.heights
        z00, z10, z01, z11 = h[iy, ix], h[iy, ix + 1], h[iy + 1, ix], h[iy + 1, ix + 1]
        lower = fx >= fy
        return np.where(lower, z00 + fx * (z10 - z00) + fy * (z11 - z10), z00 + fy * (z01 - z00) + fx * (z11 - z01))

    def patches_of(self, type_name: str) -> list[tuple[int, int]]:
        """(px, py) of every patch of one type, in row-major order."""
        if type_name not in self.patch_types:
            return []
        code = self.patch_types.index(type_name)
        ys, xs = np.nonzero(self.patch_grid == code)
        return list(zip(xs.tolist(), ys.tolist(), strict=True))

    # ---------------------------------------------------------------- geometry
    def mesh(self) -> Mesh:
        n = self.heights.shape[0] - 1
        coords = np.arange(n + 1) * self.cell
        gx, gy = np.meshgrid(coords, coords)
        vertices = np.stack([gx, gy, self.heights], axis=-1).reshape(-1, 3)
        iy, ix = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
        v00 = (iy * (n + 1) + ix).ravel()
        v10, v01, v11 = v00 + 1, v00 + n + 1, v00 + n + 2
        # Diagonal v00-v11, matching height_at; counter-clockwise seen from above.
        faces = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
        cell_x = np.concatenate([ix.ravel(), ix.ravel()])
        cell_y = np.concatenate([iy.ravel(), iy.ravel()])
        px = np.minimum((cell_x * self.cell).astype(int), self.patch_grid.shape[1] - 1)
        py = np.minimum((cell_y * self.cell).astype(int), self.patch_grid.shape[0] - 1)
        codes = self.patch_grid[py, px]
        table_sem = np.array([TERRAIN_TYPES[t][0] for t in self.patch_types], np.uint8)
        table_mat = np.array([MATERIALS[TERRAIN_TYPES[t][1]] for t in self.patch_types], np.uint8)
        table_alb = np.array([TERRAIN_TYPES[t][2] for t in self.patch_types], np.float32)
        albedo = table_alb[codes] * self.patch_tint[py, px]
        specular = np.where(table_mat[codes] == MATERIALS["pavement"], 0.04, 0.0)
        ground = Mesh(vertices, faces, table_sem[codes], table_mat[codes], albedo, 0.0, specular)
        return Mesh.concatenate([ground, self._skirt()])

    def _skirt(self) -> Mesh:
        """A flat ring of land around the garden out to SKIRT_M, class background."""
        s, far = self.size_m, SKIRT_M
        z = float(np.mean(self.heights[[0, -1], :])) - 0.02
        inner = [(0, 0), (s, 0), (s, s), (0, s)]
        outer = [(-far, -far), (s + far, -far), (s + far, s + far), (-far, s + far)]
        vertices = [(x, y, z) for x, y in inner + outer]
        faces = []
        for k in range(4):
            a, b = k, (k + 1) % 4
            faces += [(4 + a, 4 + b, b), (4 + a, b, a)]
        return Mesh.from_arrays(vertices, faces, semantic=labels.BACKGROUND, material="grass_soil", albedo=SKIRT_ALBEDO)


def build_terrain(
    seed: int,
    size_m: float,
    cells_per_m: int,
    relief_m: float,
    relief_scale_m: float,
    patch_types: list[str],
    patch_weights: list[float],
    types_per_garden: tuple[int, int],
) -> Terrain:
    """Sample the garden's terrain: relief, the 2-4 terrain types in use and their zones."""
    unknown = [t for t in patch_types if t not in TERRAIN_TYPES]
    if unknown:
        raise ValueError(f"unknown terrain type {unknown[0]!r}; allowed: {', '.join(TERRAIN_TYPES)}")
    rng = rng_for(seed, "terrain")
    n = int(round(size_m * cells_per_m))
    coords = np.arange(n + 1) / cells_per_m
    gx, gy = np.meshgrid(coords, coords)
    perlin = Perlin(rng_for(seed, "terrain", "relief"))
    pts = np.stack([gx / relief_scale_m, gy / relief_scale_m, np.full(gx.shape, 0.41)], axis=-1)
    heights = relief_m * perlin.fbm(pts, octaves=4)
    heights -= heights.min()

    # The garden uses a few of the configured types (EDEN: 2-4 per pool), grass first if present.
    weights = np.asarray(patch_weights, dtype=np.float64)
    lo, hi = types_per_garden
    k = min(len(patch_types), int(rng.integers(lo, hi + 1)))
    chosen = list(rng.choice(len(patch_types), size=k, replace=False, p=weights / weights.sum()))
    used = [patch_types[i] for i in sorted(chosen)]
    used_weights = np.array([weights[patch_types.index(t)] for t in used])

    # Zones: nearest of a few seeded centres, each with a type drawn by weight.
    side = int(round(size_m))
    n_zones = int(rng.integers(5, 10))
    centres = rng.uniform(0, size_m, size=(n_zones, 2))
    zone_type = rng.choice(len(used), size=n_zones, p=used_weights / used_weights.sum())
    zone_type[: len(used)] = rng.permutation(len(used))[: min(len(used), n_zones)]  # every chosen type appears
    pc = np.stack(np.meshgrid(np.arange(side) + 0.5, np.arange(side) + 0.5), axis=-1)
    d2 = ((pc[:, :, None, :] - centres[None, None]) ** 2).sum(-1)
    patch_grid = zone_type[np.argmin(d2, axis=-1)].astype(np.int64)

    jitter = np.array([TERRAIN_TYPES[t][3] for t in used])[patch_grid]
    # Small per-patch tint only: large jumps show as seams between 1 m patches of one zone.
    tint = (
        1.0
        + jitter[..., None] * rng.uniform(-1, 1, size=(side, side, 1))
        + 0.015 * rng.uniform(-1, 1, size=(side, side, 3))
    )
    return Terrain(
        heights, float(size_m), int(cells_per_m), used, patch_grid, np.clip(tint, 0.5, 1.5).astype(np.float32)
    )
