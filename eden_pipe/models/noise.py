"""Improved Perlin noise (Perlin 2002) and fBm, vectorised over point arrays.

The permutation table comes from a seeded generator, so every noise field is
reproducible from the job seed. Quintic fade 6t^5-15t^4+10t^3; gradients are
the 12 cube-edge directions selected by the hashed lattice corner.
"""

from __future__ import annotations

import numpy as np

_GRADIENTS = np.array(
    [
        [1, 1, 0],
        [-1, 1, 0],
        [1, -1, 0],
        [-1, -1, 0],
        [1, 0, 1],
        [-1, 0, 1],
        [1, 0, -1],
        [-1, 0, -1],
        [0, 1, 1],
        [0, -1, 1],
        [0, 1, -1],
        [0, -1, -1],
        [1, 1, 0],
        [0, -1, 1],
        [-1, 1, 0],
        [0, -1, -1],
    ],
    dtype=np.float64,
)


class Perlin:
    """3-D gradient noise in about [-1, 1]; ``noise(points)`` takes (..., 3) arrays."""

    def __init__(self, rng: np.random.Generator):
        perm = rng.permutation(256)
        self.perm = np.concatenate([perm, perm]).astype(np.int64)  # 512 entries

    @staticmethod
    def _fade(t: np.ndarray) -> np.ndarray:
        return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)

    def noise(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        cell = np.floor(p)
        f = p - cell
        i = cell.astype(np.int64) & 255
        u = self._fade(f)
        perm = self.perm
        xi, yi, zi = i[..., 0], i[..., 1], i[..., 2]
        result = np.zeros(p.shape[:-1])
        # Sum the 8 lattice corners' contributions with trilinear fade weights.
        for dx in (0, 1):
            wx = u[..., 0] if dx else 1.0 - u[..., 0]
            a = perm[xi + dx]
            for dy in (0, 1):
                wy = u[..., 1] if dy else 1.0 - u[..., 1]
                b = perm[a + yi + dy]
                for dz in (0, 1):
                    wz = u[..., 2] if dz else 1.0 - u[..., 2]
                    h = perm[b + zi + dz] & 15
                    g = _GRADIENTS[h]
                    d = f - np.array([dx, dy, dz], dtype=np.float64)
                    result = result + wx * wy * wz * np.sum(g * d, axis=-1)
        return result

    def fbm(self, points: np.ndarray, octaves: int = 4, lacunarity: float = 2.0, gain: float = 0.5) -> np.ndarray:
        """Fractal sum of octaves with halving amplitude, normalised to about [-1, 1]."""
        p = np.asarray(points, dtype=np.float64)
        total = np.zeros(p.shape[:-1])
        amplitude, norm = 1.0, 0.0
        for octave in range(octaves):
            # Offset each octave so lattice zeros do not line up across octaves.
            total += amplitude * self.noise(p * lacunarity**octave + 17.31 * octave)
            norm += amplitude
            amplitude *= gain
        return total / norm


def fbm2(perlin: Perlin, x: np.ndarray, y: np.ndarray, octaves: int = 4, z: float = 0.37) -> np.ndarray:
    """fBm over a 2-D field (a fixed z slice that avoids the lattice plane)."""
    x = np.asarray(x, dtype=np.float64)
    pts = np.stack([x, np.broadcast_to(y, x.shape), np.full(x.shape, z)], axis=-1)
    return perlin.fbm(pts, octaves)
