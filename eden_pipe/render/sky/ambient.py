"""Ambient irradiance of a sky: the cosine-weighted integral of its radiance, for any normal.

* ``AmbientTable`` (what the renderer looks up): the exact convolution of the sky's
  radiance with the clamped cosine, tabulated on a grid of normals (33 polar rows,
  poles included, x 64 azimuth columns) and interpolated bilinearly. Used by every
  sky, the model skies and the HDR environment maps alike.
* 9-coefficient spherical harmonics (Ramamoorthi & Hanrahan 2001, "An efficient
  representation for irradiance environment maps"): the radiance projected on the real
  SH basis up to l = 2 and convolved with the clamped cosine (band weights pi, 2 pi / 3,
  pi / 4). Exact for the l <= 1 part of any sky (the clamped cosine has no odd band
  above 1), and the compact description of a job's ambient light published in
  lighting.json. Not what the renderer uses: for high-contrast skies (a bright sunset
  horizon over a dark ground) the missing l >= 4 bands err by ~1-3 % on upward normals
  and up to ~15 % on downward ones (measured, tests/test_environment.py), where the
  table is exact to its interpolation.
"""

from __future__ import annotations

import math

import numpy as np

from eden_pipe.render import lut
from eden_pipe.render.sky.equirect import pixel_directions, pixel_solid_angles


class AmbientTable:
    """Irradiance E(n) = sum L(d) max(n.d, 0) dw over quadrature directions, tabulated over normals."""

    ROWS, COLS = 33, 64

    def __init__(self, directions: np.ndarray, solid_angles: np.ndarray, radiance: np.ndarray):
        lw = np.asarray(radiance, np.float64) * np.asarray(solid_angles, np.float64)[:, None]
        dirs = np.asarray(directions, np.float64)
        th = np.linspace(0.0, math.pi, self.ROWS)
        ph = np.arange(self.COLS) * (2.0 * math.pi / self.COLS)
        t, p = np.meshgrid(th, ph, indexing="ij")
        normals = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
        out = np.empty((len(normals), 3))
        for i in range(0, len(normals), 256):
            cos = np.clip(normals[i : i + 256] @ dirs.T, 0.0, None)
            out[i : i + 256] = cos @ lw
        self._table = lut.wrap_columns(out.reshape(self.ROWS, self.COLS, 3))

    def scaled(self, factor: float) -> AmbientTable:
        """The table of the radiance times ``factor`` (irradiance is linear in radiance)."""
        out = object.__new__(AmbientTable)
        out._table = (self._table * np.float32(factor)).astype(np.float32)
        return out

    def irradiance(self, normals: np.ndarray) -> np.ndarray:
        """(N, 3) unit normals -> (N, 3) float32 (bilinear in the (theta, phi) table)."""
        # This runs for every shaded pixel of every view.
        n = np.asarray(normals, dtype=np.float32).reshape(-1, 3)
        rows = np.arccos(np.clip(n[:, 2], -1.0, 1.0)) * np.float32((self.ROWS - 1) / math.pi)
        cols = lut.periodic(np.arctan2(n[:, 1], n[:, 0]) * np.float32(self.COLS / (2.0 * math.pi)), self.COLS)
        return lut.sample(self._table, cols, rows)


# Real SH basis up to l = 2, in the order (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2).
_SH_C0, _SH_C1, _SH_C2, _SH_C20, _SH_C22 = 0.282095, 0.488603, 1.092548, 0.315392, 0.546274
# Clamped-cosine convolution per band (Ramamoorthi & Hanrahan 2001): A0 = pi, A1 = 2 pi / 3, A2 = pi / 4.
SH_COSINE_WEIGHTS = np.array([math.pi] + [2.0 * math.pi / 3.0] * 3 + [math.pi / 4.0] * 5)


def sh9_basis(directions: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions -> (N, 9) real spherical harmonics up to l = 2."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    return np.stack(
        [
            np.full(len(d), _SH_C0),
            _SH_C1 * y,
            _SH_C1 * z,
            _SH_C1 * x,
            _SH_C2 * x * y,
            _SH_C2 * y * z,
            _SH_C20 * (3.0 * z * z - 1.0),
            _SH_C2 * x * z,
            _SH_C22 * (x * x - y * y),
        ],
        axis=-1,
    )


def sh9_project_panorama(image: np.ndarray, rotation: float = 0.0, rows_per_block: int = 128) -> np.ndarray:
    """(9, 3) SH coefficients of an equirectangular map's radiance (world frame after ``rotation``)."""
    h, w = image.shape[:2]
    coeffs = np.zeros((9, 3))
    solid = pixel_solid_angles(h, w).reshape(h, w)
    for r0 in range(0, h, rows_per_block):  # blocks of rows: (pixels, 9) float64 stays small
        rows = slice(r0, min(h, r0 + rows_per_block))
        weighted = image[rows, :, :3].reshape(-1, 3).astype(np.float64) * solid[rows].reshape(-1, 1)
        coeffs += sh9_basis(pixel_directions(h, w, rotation, rows)).T @ weighted
    return coeffs


def sh9_irradiance(coeffs: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 3) cosine-weighted irradiance for unit normals from (9, 3) radiance coefficients (>= 0)."""
    return np.maximum(sh9_basis(normals) @ (SH_COSINE_WEIGHTS[:, None] * coeffs), 0.0)


def sh9_project(directions: np.ndarray, solid_angles: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """(9, 3) SH coefficients of radiance given at quadrature directions with solid angles."""
    weighted = np.asarray(radiance, np.float64) * np.asarray(solid_angles, np.float64)[:, None]
    return sh9_basis(directions).T @ weighted
