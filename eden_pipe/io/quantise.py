"""Compiled quantisers of the PNG writers: unit normals and KITTI flow to their uint16 codes.

Each replaces a chain of numpy passes over the image (clip, add, scale, round, mask, cast: about
ten for the flow, whose writer spent three times its encoder's time there) by one pass, with the
same float operations in the same precision and order, so the codes are bit-identical to the
formulas in :mod:`eden_pipe.io.formats` and :mod:`eden_pipe.io.kitti` (``tests/test_encoders.py``
checks both against numpy). ``nogil``: the writer threads run them beside the render.
"""

from __future__ import annotations

import numpy as np
from numba import njit

NORMAL_SCALE = np.float32(0.5 * 65535.0)  # exact in float32
ONE = np.float32(1.0)


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
