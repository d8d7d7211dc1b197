"""Real spherical harmonics of order 4 (bands 0-3, sixteen functions) for low-frequency lighting.

Sky visibility is baked as a transfer vector T (Sloan et al. 2002, precomputed
radiance transfer): ``T_i = int V(w) max(n.w, 0)/pi Y_i(w) dw``, so a sky whose
radiance projects to ``L_i = int L(w) Y_i(w) dw`` gives the occluded sky
irradiance/pi as the dot product ``T . L``. The product integral is exact
whenever either factor is band-limited to the order. Order 3 (bands 0-2) holds
the clamped cosine to within a few per cent (Ramamoorthi and Hanrahan 2001),
but not a partly hidden sky whose light sits low: under a sunset's bright
horizon, order 3 from the exact visibility of each pixel was 18-22 % too dark on
the hedges' and trees' sides and 4 % too bright on open ground; band 3 takes
that to 2-4 % (``docs/realism.md``). The clamped cosine has nothing in band 3,
so the open sky's transfer is the same as order 3's.
"""

from __future__ import annotations

import numpy as np

BAND = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3])
COUNT = len(BAND)
# Clamped-cosine convolution per band, divided by pi: int max(n.w, 0)/pi Y_lm(w) dw = COSINE[l] Y_lm(n)
# (zero for odd bands above 1).
COSINE = np.array([1.0, 2.0 / 3.0, 0.25, 0.0])[BAND].astype(np.float32)


def basis(directions: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions -> (N, 16) float32 values of the sixteen real SH functions, band by
    band, m from -l to l (bands 0-2 as Sloan's "Stupid SH tricks"; band 3 the same convention).
    Column-major (the transpose of a (16, N) array): each function is written as one contiguous
    row from contiguous coordinates, five times faster than sixteen strided columns."""
    x, y, z = np.asarray(directions, np.float32).T.copy()
    out = np.empty((COUNT, len(x)), np.float32)
    out[0] = 0.282095
    np.multiply(0.488603, y, out=out[1])
    np.multiply(0.488603, z, out=out[2])
    np.multiply(0.488603, x, out=out[3])
    out[4] = 1.092548 * x * y
    out[5] = 1.092548 * y * z
    out[6] = 0.315392 * (3.0 * z * z - 1.0)
    out[7] = 1.092548 * x * z
    out[8] = 0.546274 * (x * x - y * y)
    xx, yy, zz = x * x, y * y, z * z
    out[9] = 0.590044 * y * (3.0 * xx - yy)
    out[10] = 2.890611 * x * y * z
    out[11] = 0.457046 * y * (5.0 * zz - 1.0)
    out[12] = 0.373176 * z * (5.0 * zz - 3.0)
    out[13] = 0.457046 * x * (5.0 * zz - 1.0)
    out[14] = 1.445306 * z * (xx - yy)
    out[15] = 0.590044 * x * (xx - 3.0 * yy)
    return out.T


def open_transfer(normals: np.ndarray) -> np.ndarray:
    """(N, 16) transfer of points that see the whole hemisphere about each normal (no occluder)."""
    return basis(normals) * COSINE


def project_latlong(table: np.ndarray, block: int = 4) -> np.ndarray:
    """(16, C) SH coefficients of a lat-long table (H, W, C): rows from the zenith down, columns
    over azimuth from -pi (``shading.EnvironmentMap``'s layout). Averaged in ``block`` x ``block``
    texels first: sixteen coefficients need no finer grid."""
    h, w, c = table.shape
    coarse = table[: h - h % block, : w - w % block].reshape(h // block, block, w // block, block, c).mean(axis=(1, 3))
    hb, wb = coarse.shape[:2]
    theta = (np.arange(hb) + 0.5) / hb * np.pi
    phi = (np.arange(wb) + 0.5) / wb * 2.0 * np.pi - np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    edges = np.arange(hb + 1) / hb * np.pi
    band = (np.cos(edges[:-1]) - np.cos(edges[1:])) * (2.0 * np.pi / wb)  # exact solid angle of a texel row
    solid = np.repeat(band, wb)
    return (basis(dirs).astype(np.float64) * solid[:, None]).T @ coarse.reshape(-1, c).astype(np.float64)
