"""float32 to IEEE half floats and back, compiled: the EXR layers' conversion (:mod:`eden_pipe.io.exr`)
and the bake's float16 tables (:mod:`eden_pipe.render.visibility.store`).

numpy converts to float16 in software and raises the floating-point underflow flag for every
value that lands on a half subnormal (below 6.1e-5): a translucency layer, mostly faint light
through leaves, took 29 ms a frame for what takes 2.5 ms elsewhere. This kernel rounds the
same way (to nearest, ties to even; NaN keeps its top payload bits) without the flags, clips
finite values to the half range as the EXR writer does, and writes each channel as its own
contiguous plane, in one pass. ``tests/test_exr.py`` checks it against numpy.

Back to float32 (:func:`widen`), numpy is slow for the same values: a half subnormal takes its
scalar path, and the bake's tables are more than half subnormals (the default garden's 1.5 M
probes: 0.17-0.27 s a table against 0.02 s here). Every half is exactly a float32, so a table of
numpy's own conversion of all 65,536 bit patterns gives the same bits, NaN payloads included.
"""

from __future__ import annotations

import numpy as np
from numba import njit

HALF_MAX_BITS = 0x7BFF  # 65504, the largest finite half
HALF_INF_BITS = 0x7C00


@njit(inline="always")
def _half_bits(f):
    """The bits of the half nearest to the float32 with bits ``f`` (ties to even), finite values
    clipped to +-65504."""
    sign = (f >> 16) & 0x8000
    exponent = (f >> 23) & 0xFF
    mantissa = f & 0x7FFFFF
    if exponent == 0xFF:  # inf, or NaN (which keeps its top payload bits and stays a NaN)
        return sign | HALF_INF_BITS | (max(mantissa >> 13, 1) if mantissa else 0)
    if exponent >= 143:  # |x| >= 2^16: beyond the half range
        return sign | HALF_MAX_BITS
    if exponent < 102:  # |x| < 2^-25, half the smallest half subnormal: a signed zero
        return sign
    if exponent <= 112:  # a half subnormal: units of 2^-24
        significand = mantissa | 0x800000
        shift = 126 - exponent
        bits = significand >> shift
        rest = significand & ((1 << shift) - 1)
        tie = 1 << (shift - 1)
    else:  # a normal half: 10 of the 23 mantissa bits
        bits = ((exponent - 112) << 10) | (mantissa >> 13)
        rest = mantissa & 0x1FFF
        tie = 0x1000
    if rest > tie or (rest == tie and bits & 1):
        bits += 1  # a carry into the exponent is right (up to the smallest normal, or to inf)
    return sign | min(bits, HALF_MAX_BITS)


@njit(nogil=True, cache=True)
def _half_planes(bits, out):
    height, width, channels = bits.shape
    for y in range(height):
        for x in range(width):
            for c in range(channels):
                out[c, y, x] = _half_bits(bits[y, x, c])
    return out


def half_planes(array: np.ndarray) -> np.ndarray:
    """(C, H, W) float16 channel planes of a float32 (H, W, C) array (any strides): each value
    rounded to the nearest half, finite values clipped to +-65504, inf and NaN kept."""
    array = np.asarray(array, np.float32)
    out = np.empty((array.shape[2],) + array.shape[:2], np.uint16)
    return _half_planes(array.view(np.uint32), out).view(np.float16)


# numpy's own float32 of every half's bit pattern: :func:`widen` reads it, so its values are numpy's.
_WIDE = np.arange(1 << 16, dtype=np.uint16).view(np.float16).astype(np.float32)


@njit(nogil=True, cache=True)
def _widen(bits, table, out):
    for i in range(bits.size):
        out[i] = table[bits[i]]
    return out


def widen(array: np.ndarray) -> np.ndarray:
    """float32 of a float16 array (any shape and strides): the same bits as numpy's ``astype``."""
    bits = np.ascontiguousarray(array, np.float16).view(np.uint16)
    out = np.empty(bits.shape, np.float32)
    _widen(bits.reshape(-1), _WIDE, out.reshape(-1))
    return out
