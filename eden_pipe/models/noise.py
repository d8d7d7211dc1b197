"""Improved Perlin noise (Perlin 2002) and fBm, vectorised over point arrays.

The permutation table comes from a seeded generator, so every noise field is
reproducible from the job seed. Quintic fade 6t^5-15t^4+10t^3; gradients are
the 12 cube-edge directions selected by the hashed lattice corner.

The lattice sum runs in one compiled pass (:func:`_lattice_noise`): numpy's version made
eight gathers and a dozen (N,) temporaries per corner, and noise is evaluated per blade (lawn
colour), per terrain vertex, per cloud-table sample and per background pixel (the scenery's
texture). It does the same float64 operations in the same order, so every value is the same bits.
"""

from __future__ import annotations

import numpy as np
from numba import njit

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

    def noise(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        flat = np.ascontiguousarray(p.reshape(-1, 3))
        return _lattice_noise(flat, self.perm, _GRADIENTS).reshape(p.shape[:-1])

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


@njit(inline="always")
def _fade(t: float) -> float:
    """Perlin's quintic fade 6t^5 - 15t^4 + 10t^3."""
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


@njit(nogil=True, cache=True)
def _lattice_noise(points: np.ndarray, perm: np.ndarray, gradients: np.ndarray) -> np.ndarray:
    """(N,) noise at (N, 3) float64 ``points``: the 8 lattice corners' gradient dot products, summed
    with trilinear quintic-fade weights, corner by corner in the order x, then y, then z."""
    out = np.empty(len(points))
    for n in range(len(points)):
        f0, f1, f2 = points[n, 0], points[n, 1], points[n, 2]
        c0, c1, c2 = np.floor(f0), np.floor(f1), np.floor(f2)
        f0, f1, f2 = f0 - c0, f1 - c1, f2 - c2
        xi, yi, zi = np.int64(c0) & 255, np.int64(c1) & 255, np.int64(c2) & 255
        u0, u1, u2 = _fade(f0), _fade(f1), _fade(f2)
        result = 0.0
        for dx in range(2):
            wx = u0 if dx else 1.0 - u0
            a = perm[xi + dx]
            d0 = f0 - dx
            for dy in range(2):
                wy = u1 if dy else 1.0 - u1
                b = perm[a + yi + dy]
                d1 = f1 - dy
                for dz in range(2):
                    wz = u2 if dz else 1.0 - u2
                    g = perm[b + zi + dz] & 15
                    d2 = f2 - dz
                    # One gradient component is 0 and the others +-1: the products are exact and
                    # the sum the same in any order.
                    dot = gradients[g, 0] * d0 + gradients[g, 1] * d1 + gradients[g, 2] * d2
                    result = result + wx * wy * wz * dot
        out[n] = result
    return out


def fbm2(perlin: Perlin, x: np.ndarray, y: np.ndarray, octaves: int = 4, z: float = 0.37) -> np.ndarray:
    """fBm over a 2-D field (a fixed z slice that avoids the lattice plane)."""
    x = np.asarray(x, dtype=np.float64)
    pts = np.stack([x, np.broadcast_to(y, x.shape), np.full(x.shape, z)], axis=-1)
    return perlin.fbm(pts, octaves)
