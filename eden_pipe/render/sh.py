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
from numba import njit

BAND = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3])
COUNT = len(BAND)
BLOCK = 64  # rows a block of :func:`along`'s kernel
# Clamped-cosine convolution per band, divided by pi: int max(n.w, 0)/pi Y_lm(w) dw = COSINE[l] Y_lm(n)
# (zero for odd bands above 1).
COSINE = np.array([1.0, 2.0 / 3.0, 0.25, 0.0])[BAND].astype(np.float32)


def basis(directions: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions -> (N, 16) float32 values of the sixteen real SH functions, band by
    band, m from -l to l (bands 0-2 as Sloan's "Stupid SH tricks"; band 3 the same convention).
    Column-major (the transpose of a (16, N) array), the layout callers' sums over it were measured
    with; one compiled pass over the directions."""
    directions = _rows(directions)
    out = np.empty((COUNT, len(directions)), np.float32)
    _basis_columns(directions, out)
    return out.T


def along(coefficients: np.ndarray, rows: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """(N,) float32: the functions of ``coefficients`` (P, 16) float32 rows ``rows`` (N,) evaluated
    at unit ``directions`` (N, 3), ``np.einsum("ij,ij->i", coefficients[rows], basis(directions))``
    to the bit (each product rounded, then summed in band order from zero, as einsum does for more
    than one row) without the (N, 16) gathers."""
    if coefficients.dtype != np.float32 or coefficients.shape[1:] != (COUNT,):
        raise ValueError(f"SH coefficients must be float32 (P, {COUNT}), got {coefficients.dtype} {coefficients.shape}")
    rows, directions = np.asarray(rows), _rows(directions)
    if len(rows) == 1:  # einsum sums a lone row along its bands with its vector loop: another order
        return np.einsum("ij,ij->i", np.take(coefficients, rows, axis=0), basis(directions))
    out = np.empty(len(rows), np.float32)
    _along(coefficients, rows, directions, out)
    return out


def _rows(directions) -> np.ndarray:
    directions = np.asarray(directions)
    if directions.dtype not in (np.float32, np.float64):
        directions = directions.astype(np.float64)
    return directions.reshape(-1, 3)


@njit(inline="always")
def _functions(direction, values):
    """``values`` (16,) float32: the functions at one direction, each the float32 operations of numpy's
    whole-array form in the same order (a weakly typed constant such as ``0.488603 * y`` rounds
    to float32 first), so the values are numpy's to the bit."""
    f = np.float32
    x, y, z = f(direction[0]), f(direction[1]), f(direction[2])
    xx, yy, zz = x * x, y * y, z * z
    values[0] = f(0.282095)
    values[1] = f(0.488603) * y
    values[2] = f(0.488603) * z
    values[3] = f(0.488603) * x
    values[4] = f(1.092548) * x * y
    values[5] = f(1.092548) * y * z
    values[6] = f(0.315392) * (f(3.0) * z * z - f(1.0))
    values[7] = f(1.092548) * x * z
    values[8] = f(0.546274) * (xx - yy)
    values[9] = f(0.590044) * y * (f(3.0) * xx - yy)
    values[10] = f(2.890611) * x * y * z
    values[11] = f(0.457046) * y * (f(5.0) * zz - f(1.0))
    values[12] = f(0.373176) * z * (f(5.0) * zz - f(3.0))
    values[13] = f(0.457046) * x * (f(5.0) * zz - f(1.0))
    values[14] = f(1.445306) * z * (xx - yy)
    values[15] = f(0.590044) * x * (xx - f(3.0) * yy)


@njit(nogil=True, cache=True)
def _basis_columns(directions, out):
    values = np.empty(COUNT, np.float32)
    for i in range(directions.shape[0]):
        _functions(directions[i], values)
        for k in range(COUNT):
            out[k, i] = values[k]


@njit(nogil=True, cache=True)
def _along(coefficients, rows, directions, out):
    # Rows go in blocks, band by band across a block's rows: each row's sum keeps its band order,
    # and the block's rows are independent sums the CPU overlaps (one row at a time waits on each
    # add before the next, and on each row's load from the table).
    n = directions.shape[0]
    values = np.empty((BLOCK, COUNT), np.float32)
    total = np.empty(BLOCK, np.float32)
    for start in range(0, n, BLOCK):
        m = min(BLOCK, n - start)
        for r in range(m):
            _functions(directions[start + r], values[r])
            total[r] = np.float32(0.0)
        for k in range(COUNT):
            for r in range(m):
                total[r] = total[r] + coefficients[rows[start + r], k] * values[r, k]
        out[start : start + m] = total[:m]


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
