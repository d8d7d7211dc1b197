"""Row-wise vector kernels for (N, 3) arrays, written along numpy's fast paths.

The renderer's per-pixel math is mostly dots, normalisations, gathers and
sign flips of (N, 3) rows. The obvious numpy spellings of these go through
slow generic loops: for 300K rows, ``a[idx]`` takes 2.1 ms where
``np.take(a, idx, axis=0)`` takes 0.5 ms, ``np.einsum("ij,ij->i")`` 1.6 ms
where ``(a * b) @ ones`` takes 0.2 ms, ``np.where(mask[:, None], a, -a)``
5.7 ms where a multiply by a sign column takes 0.8 ms (and ``x ** 60`` is a
general power, 29 ms, where repeated squaring is six multiplies: ``kernels._power``).
"""

from __future__ import annotations

import numpy as np

from eden_pipe.render.kernels import normalize_rows, take_items, take_rows3

_ONES = {np.dtype(np.float32): np.ones(3, np.float32), np.dtype(np.float64): np.ones(3, np.float64)}


def dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N,) row-wise dot products of two (N, 3) arrays (or one (3,) vector)."""
    prod = a * b
    return prod @ _ONES.get(prod.dtype, np.ones(3, prod.dtype))


def length(a: np.ndarray) -> np.ndarray:
    return np.sqrt(dot(a, a))


def normalize(a: np.ndarray, floor: float = 1e-30) -> np.ndarray:
    """Rows scaled to unit length (zero rows stay zero): each over the larger of its :func:`length`
    and ``floor``, in the rows' precision (one compiled pass, ``kernels.normalize_rows``)."""
    return normalize_rows(a, a.dtype.type(floor))


def orthonormal_basis(n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(t, b) (N, 3): unit vectors that complete the unit normals ``n`` (N, 3) to right-handed
    frames (t, b, n); t is perpendicular to n and to +X (to +Y where n is near the X axis)."""
    helper = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    t = np.cross(n, helper)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def facing(normals: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Normals flipped where needed to face against ``directions`` (toward the viewer)."""
    return facing_side(normals, directions)[0]


def facing_side(normals: np.ndarray, directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(:func:`facing`'s normals, (N,) bool where they were flipped: the viewer is behind them)."""
    behind = dot(normals, directions) > 0
    sign = np.where(behind, normals.dtype.type(-1.0), normals.dtype.type(1.0))
    return normals * sign[:, None], behind


def gather(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """Rows ``a[index]``, ``np.take(a, index, axis=0)`` (4x faster than fancy indexing for 2-D
    arrays); :func:`take`'s compiled copy where it has one."""
    return take(a, index)


def take(a: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``np.take(a, index, axis=0)``, the same values and errors. For a 1-D signed integer
    ``index`` into a contiguous numeric ``a`` that is 1-D, (P, 3) rows or rows of one machine word
    ((P, 2) int32, read as int64), a compiled copy (``kernels.take_items``, ``kernels.take_rows3``):
    numpy's take copies those through its generic chunk loop in 1.2-3.8x and 1.5-2x the time, and
    a view's gathers are a tenth of its arithmetic (docs/scale-out.md). numpy's own take for the
    rest."""
    index = np.asarray(index)
    if (
        index.ndim == 1
        and index.dtype.kind == "i"
        and isinstance(a, np.ndarray)
        and (a.dtype.kind in "biu" or a.dtype in (np.float32, np.float64))
        and a.flags.c_contiguous
    ):
        if a.ndim == 1:
            return take_items(a, index)
        if a.ndim == 2 and a.shape[1] == 3:
            return take_rows3(a, index)
        if a.ndim == 2 and (row := a.shape[1] * a.itemsize) in _WORDS:  # a row as one word: (P, 2) int32
            return take_items(a.view(_WORDS[row]).reshape(-1), index).view(a.dtype).reshape(-1, a.shape[1])
    return np.take(a, index, axis=0)


_WORDS = {1: np.uint8, 2: np.uint16, 4: np.uint32, 8: np.uint64}


class Scatter:
    """Expand per-hit rows back to every ray: ``expand(values)`` is ``out[index] = values`` on
    zeros, done as one fast ``take`` from the values plus a zero row."""

    def __init__(self, index: np.ndarray, n: int):
        self.n_values = len(index)
        self.source = np.full(n, self.n_values, np.int64)
        self.source[index] = np.arange(self.n_values)

    def expand(self, values: np.ndarray) -> np.ndarray:
        padded = np.concatenate([values, np.zeros((1,) + values.shape[1:], values.dtype)])
        return take(padded, self.source)


def select(mask: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rows of ``a`` where ``mask`` (N,) is true, else rows of ``b`` (a full-shape mask is 2x
    faster in ``np.where`` than a broadcast (N, 1) one)."""
    return np.where(np.repeat(mask[:, None], a.shape[1], axis=1), a, b)
