"""Compiled quantisers of the PNG writers: unit normals and KITTI flow to their uint16 codes, linear
RGB to the 8-bit sRGB of the rgb PNGs.

Each replaces a chain of numpy passes over the image (clip, add, scale, round, mask, cast: about
ten for the flow, whose writer spent three times its encoder's time there) by one pass, with the
same float operations in the same precision and order, so the codes are bit-identical to the
formulas in :mod:`eden_pipe.io.formats` and :mod:`eden_pipe.io.kitti` (``tests/test_encoders.py``
checks both against numpy). The sRGB codes are a step function of the float32 value, so they come
from a table of its 255 steps instead, found in :func:`eden_pipe.colour.srgb_to_uint8` itself
(:func:`srgb8_codes`). ``nogil``: the writer threads run them beside the render.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
from numba import njit

NORMAL_SCALE = np.float32(0.5 * 65535.0)  # exact in float32
ONE = np.float32(1.0)

log = logging.getLogger(__name__)


@njit(nogil=True, cache=True)
def _normal_codes(normal, out):
    height, width, _ = normal.shape
    for y in range(height):
        for x in range(width):
            if normal[y, x, 0] != 0 or normal[y, x, 1] != 0 or normal[y, x, 2] != 0:
                for c in range(3):
                    clipped = min(max(normal[y, x, c], -ONE), ONE)
                    out[y, x, c] = np.uint16(np.rint((clipped + ONE) * NORMAL_SCALE))
            else:  # sky
                for c in range(3):
                    out[y, x, c] = 0
    return out


def normal_codes(normal: np.ndarray) -> np.ndarray:
    """uint16 (H, W, 3) round((clip(n, -1, 1) + 1) * 65535 / 2) in float32, 0, 0, 0 where n is 0, 0, 0
    (sky); ``normal`` finite."""
    normal = np.asarray(normal, np.float32)
    return _normal_codes(normal, np.empty(normal.shape, np.uint16))


@njit(nogil=True, cache=True)
def _kitti_flow_codes(flow, valid, lowest, highest, scale, offset, out):
    height, width, _ = flow.shape
    for y in range(height):
        for x in range(width):
            u = flow[y, x, 0]
            v = flow[y, x, 1]
            # NaN fails every comparison and infinities are out of range: the numpy writer's isfinite.
            if valid[y, x] and lowest <= u <= highest and lowest <= v <= highest:
                out[y, x, 0] = np.uint16(np.rint(u * scale) + offset)
                out[y, x, 1] = np.uint16(np.rint(v * scale) + offset)
                out[y, x, 2] = 1
            else:  # written as zero flow, marked invalid
                out[y, x, 0] = np.uint16(offset)
                out[y, x, 1] = np.uint16(offset)
                out[y, x, 2] = 0
    return out


def kitti_flow_codes(
    flow: np.ndarray, valid: np.ndarray, lowest: float, highest: float, scale: float, offset: float
) -> np.ndarray:
    """uint16 (H, W, 3) [rint(u * scale) + offset, rint(v * scale) + offset, 1] where ``valid`` and both
    components lie in [lowest, highest], else [offset, offset, 0]. float32 flow is scaled in float32, any
    other in float64 (the scale a power of two and the codes integers below 2^16: exact either way)."""
    flow = flow if flow.dtype == np.float32 else np.asarray(flow, np.float64)
    dtype = flow.dtype.type
    out = np.empty(flow.shape[:2] + (3,), np.uint16)
    return _kitti_flow_codes(
        flow, np.asarray(valid, np.bool_), dtype(lowest), dtype(highest), dtype(scale), dtype(offset), out
    )


# ------------------------------------------------------------------ 8-bit sRGB
ONE_BITS = 0x3F800000  # the float32 1.0: the sRGB curve's input is clipped to [0, 1]
POSITIVE_INF_BITS = 0x7F800000
NEGATIVE_INF_BITS = 0xFF800000
BUCKET_SHIFT = 16  # a float32's bits >> 16 pick its bucket: 16,257 buckets over [0, 1]


@functools.cache
def srgb8_tables() -> tuple[np.ndarray, np.ndarray, int] | None:
    """(steps (257,) uint32, bucket codes (16,257,) uint8, NaN's code) of
    :func:`eden_pipe.colour.srgb_to_uint8` on float32 values, made from that function itself:
    ``steps[k]`` holds the bits of the least float32 in [0, 1] whose code is at least k (``steps[256]``
    above every float), found by bisection over the bits for all k at once; ``bucket codes`` the code at
    the start of each bucket. The codes rise with the value, at most one step within a bucket, so a
    value's code is its bucket's, plus one where it lies at or past the next step. None (logged) where
    this machine's formula does not behave so: :func:`srgb8_codes` then runs the formula itself."""
    from eden_pipe.colour import srgb_to_uint8  # the formula (colour imports nothing of the package)

    def codes(bits: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore"):  # NaN's cast to uint8
            return srgb_to_uint8(np.asarray(bits, np.uint32).view(np.float32)).astype(np.int64)

    levels = np.arange(1, 256)
    low, high = np.zeros(255, np.int64), np.full(255, ONE_BITS, np.int64)  # code(low) < k <= code(high)
    if codes(low[:1])[0] != 0 or codes(high[:1])[0] != 255:
        log.warning("srgb_to_uint8 does not map 0 to 0 and 1 to 255 here: the rgb PNGs use it directly")
        return None
    while np.any(high - low > 1):
        middle = (low + high) // 2
        above = codes(middle) >= levels
        high, low = np.where(above, middle, high), np.where(above, low, middle)
    steps = np.concatenate([[0], high, [0xFFFFFFFF]]).astype(np.uint32)
    starts = np.arange(0, ONE_BITS + 1, 1 << BUCKET_SHIFT, dtype=np.int64)
    bucket_codes = codes(starts)
    inside = np.searchsorted(steps[1:256], starts + (1 << BUCKET_SHIFT) - 1, "right") - np.searchsorted(
        steps[1:256], starts, "right"
    )
    rising = np.all(np.diff(steps[1:256].astype(np.int64)) > 0) and np.all(np.diff(bucket_codes) >= 0)
    if not rising or inside.max() > 1 or np.any(np.take(steps, bucket_codes) > starts):
        log.warning("srgb_to_uint8's codes do not rise one step at a time here: the rgb PNGs use it directly")
        return None
    return steps, bucket_codes.astype(np.uint8), int(codes(np.array([0x7FC00000]))[0])


@njit(nogil=True, cache=True)
def _srgb8_codes(bits, steps, bucket_codes, nan_code, out):
    for i in range(bits.shape[0]):
        b = bits[i]
        if b < POSITIVE_INF_BITS:  # 0 up to the largest float (clipped to 1)
            clipped = min(b, np.uint32(ONE_BITS))
            code = bucket_codes[clipped >> BUCKET_SHIFT]
            out[i] = code + (clipped >= steps[code + 1])
        elif b == POSITIVE_INF_BITS:
            out[i] = 255
        elif b < 0x80000000 or b > NEGATIVE_INF_BITS:  # NaN
            out[i] = nan_code
        else:  # negative values, -0 and -inf clip to 0
            out[i] = 0
    return out


def srgb8_codes(linear: np.ndarray) -> np.ndarray:
    """uint8 sRGB codes of linear RGB, as :func:`eden_pipe.colour.srgb_to_uint8` gives them (the
    same bytes: ``tests/test_encoders.py``; checked once over all 2^32 float32 bit patterns), in one
    pass for float32 input (0.75-0.78 against 10.3 ms for a render's image); other dtypes go
    through it."""
    tables = srgb8_tables() if linear.dtype == np.float32 else None
    if tables is None:
        from eden_pipe.colour import srgb_to_uint8

        return srgb_to_uint8(linear)
    values = np.ascontiguousarray(linear)
    out = np.empty(values.shape, np.uint8)
    _srgb8_codes(values.reshape(-1).view(np.uint32), *tables, out.reshape(-1))
    return out
