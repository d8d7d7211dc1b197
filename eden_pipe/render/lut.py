"""Table lookups at scattered coordinates through OpenCV's remap.

The renderer looks tables up (ambient irradiance by normal, the sky by
direction) for every shaded pixel of every view. ``cv2.remap`` does the
gather and the bilinear blend in one multithreaded C++ pass that releases the
GIL: 5x faster than the same lookup written as numpy gathers, and a frame
thread can trace rays meanwhile.
"""

from __future__ import annotations

import cv2
import numpy as np

ROW = 1024  # remap wants 2-D maps with sides below 32767: lay points out in rows of this length


def wrap_columns(table: np.ndarray) -> np.ndarray:
    """Append column 0 after the last one, so bilinear blends across the seam of a periodic axis."""
    table = np.asarray(table, np.float32)
    return np.ascontiguousarray(np.concatenate([table, table[:, :1]], axis=1))


def periodic(x: np.ndarray, period: float) -> np.ndarray:
    """``x % period`` for float32 ``x`` (N,), the same bits as numpy's remainder (in [0, period),
    +0 for either zero), at a fifth of its cost where every ``|x| < period`` (table coordinates
    from an angle), numpy's own otherwise: its floating remainder also divides, for a quotient
    nobody reads."""
    x = np.asarray(x, np.float32)
    p = np.float32(period)
    if len(x) and bool(np.all(np.abs(x) < p)):  # False for NaN: numpy's remainder
        # remainder = fmod(x, p) = x here, moved by p where its sign is not p's; -0 + 0 is +0.
        return x + np.where(x < 0, p, np.float32(0.0))
    return x % p


def sample(table: np.ndarray, x: np.ndarray, y: np.ndarray, *, nearest: bool = False) -> np.ndarray:
    """Values of ``table`` (H, W, C) float32 at texel coordinates (x = column, y = row; N each).

    Texel centres sit at integer coordinates; outside the table the edge texel is
    repeated. Returns (N, C) float32. Bilinear weights are OpenCV's, quantised to
    1/32 of a texel: far below the variation between neighbouring texels of any
    table looked up here.
    """
    n = len(x)
    channels = table.shape[2]
    if n == 0:
        return np.zeros((0, channels), np.float32)
    rows = -(-n // ROW)
    pad = rows * ROW - n
    map_x = np.pad(np.asarray(x, np.float32), (0, pad)).reshape(rows, ROW)
    map_y = np.pad(np.asarray(y, np.float32), (0, pad)).reshape(rows, ROW)
    out = np.empty((rows, ROW, channels), np.float32)
    interpolation = cv2.INTER_NEAREST if nearest else cv2.INTER_LINEAR
    if channels <= 4 and rows <= 32000:  # one call, written in place (a copy of its result took half the time)
        res = cv2.remap(
            np.ascontiguousarray(table), map_x, map_y, interpolation, dst=out, borderMode=cv2.BORDER_REPLICATE
        )
        return res.reshape(-1, channels)[:n]  # ``out`` itself where OpenCV could write there
    # remap handles at most 4 channels per call and rows below 32767.
    for start in range(0, rows, 32000):
        stop = min(rows, start + 32000)
        for c in range(0, channels, 4):
            block = np.ascontiguousarray(table[:, :, c : c + 4])
            res = cv2.remap(
                block,
                map_x[start:stop],
                map_y[start:stop],
                interpolation,
                borderMode=cv2.BORDER_REPLICATE,
            )
            out[start:stop, :, c : c + 4] = res.reshape(stop - start, ROW, -1)
    return out.reshape(-1, channels)[:n]
