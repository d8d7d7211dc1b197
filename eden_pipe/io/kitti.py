"""KITTI 2015 ground-truth PNGs: optical flow and disparity (16-bit).

Flow (``flow_occ``/``flow_noc`` layout): a 3-channel uint16 PNG whose
channels, in the file's R, G, B order, are

    R = u * 64 + 2**15,   G = v * 64 + 2**15,   B = 1 if valid else 0

(u, v) in pixels, so u = (R - 2**15) / 64. The writer encodes [u, v, valid]
in that order (:mod:`eden_pipe.io.encoders`); OpenCV, which the readers use,
decodes it as BGR [valid, v, u]. The KITTI devkit (which reads R as u) and
Pillow-style RGB decoders see the layout above. Encoded
values are rounded to the nearest 1/64 px (error <= 1/128 px) and clipped to
the representable range [-512, 511.984375] px. Invalid pixels (mask False, or
non-finite flow) are written as zero flow with B = 0 and read back as zero
flow with ``valid`` False.

Disparity: a 1-channel uint16 PNG, value = round(d * 256), 0 = invalid.
Valid disparities are clipped to [1/256, 65535/256] px so a valid pixel never
encodes as 0; d <= 0, non-finite d or mask False are invalid.
``depth_to_disparity`` converts z-depth (metres) for a rectified pair:
d = fx * baseline / z.

Readers return ``(values float32, valid bool)``; invalid values are 0. Writes
are atomic (temporary file + ``os.replace``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from eden_pipe.io.formats import write_png
from eden_pipe.io.quantise import kitti_flow_codes

FLOW_SCALE = 64.0
FLOW_OFFSET = 2.0**15
FLOW_MIN = -FLOW_OFFSET / FLOW_SCALE  # -512 px
FLOW_MAX = (65535 - FLOW_OFFSET) / FLOW_SCALE  # 511.984375 px
DISP_SCALE = 256.0
DISP_MAX = 65535 / DISP_SCALE  # 255.99609375 px


def _read_png16(path, channels: int) -> np.ndarray:
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no PNG file {path}")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise ValueError(f"{path}: cannot decode the PNG (truncated or corrupt?)")
    if img.dtype != np.uint16:
        raise ValueError(f"{path}: expected a 16-bit PNG, got {img.dtype}")
    got = 1 if img.ndim == 2 else img.shape[2]
    if got != channels:
        raise ValueError(f"{path}: expected {channels} channel(s), got {got}")
    return img


def _mask(valid, shape) -> np.ndarray:
    if valid is None:
        return np.ones(shape, bool)
    valid = np.asarray(valid)
    if valid.shape != shape:
        raise ValueError(f"valid mask shape {valid.shape} != image shape {shape}")
    return valid.astype(bool)


def write_kitti_flow(path, flow: np.ndarray, valid: np.ndarray | None = None, compression: int = 3) -> None:
    """Write (H, W, 2) flow in pixels; ``valid`` (H, W) bool or None (= every pixel with finite flow).

    Flow outside KITTI's range (-512 .. 511.98 px) cannot be stored: such pixels are written invalid,
    never clipped, so a valid pixel's flow is always right to 1/128 px."""
    flow = np.asarray(flow)
    if flow.ndim != 3 or flow.shape[2] != 2:
        raise ValueError(f"expected (H, W, 2) flow, got shape {flow.shape}")
    # float32 flow (the renderer's) is encoded in float32: 64 u is exact, and rint(64 u) + 2^15 is
    # round(64 u + 2^15) (the offset is even: round-half-even's ties land alike), as in float64.
    # One compiled pass (io.quantise) over the pixels.
    rgb = kitti_flow_codes(flow, _mask(valid, flow.shape[:2]), FLOW_MIN, FLOW_MAX, FLOW_SCALE, FLOW_OFFSET)
    write_png(path, rgb, compression, "kitti_flow")


def read_kitti_flow(path) -> tuple[np.ndarray, np.ndarray]:
    """(flow float32 (H, W, 2) in pixels, valid bool (H, W)); invalid pixels hold zero flow."""
    bgr = _read_png16(path, 3)
    valid = bgr[..., 0] > 0
    flow = (bgr[..., 2:0:-1].astype(np.float32) - np.float32(FLOW_OFFSET)) / np.float32(FLOW_SCALE)
    flow[~valid] = 0.0
    return flow, valid


def write_kitti_disparity(path, disparity: np.ndarray, valid: np.ndarray | None = None, compression: int = 3) -> None:
    """Write (H, W) disparity in pixels as uint16 d*256 (0 = invalid: d <= 0, non-finite, or ``valid`` False)."""
    d = np.asarray(disparity, np.float64)
    if d.ndim == 3 and d.shape[2] == 1:
        d = d[..., 0]
    if d.ndim != 2:
        raise ValueError(f"expected (H, W) disparity, got shape {d.shape}")
    ok = _mask(valid, d.shape) & np.isfinite(d) & (d > 0)
    enc = np.where(ok, np.clip(np.round(np.where(ok, d, 0.0) * DISP_SCALE), 1, 65535), 0).astype(np.uint16)
    write_png(path, enc, compression, "kitti_disparity")


def read_kitti_disparity(path) -> tuple[np.ndarray, np.ndarray]:
    """(disparity float32 (H, W) in pixels, valid bool (H, W)); invalid pixels are 0."""
    enc = _read_png16(path, 1)
    return (enc.astype(np.float32) / np.float32(DISP_SCALE)), enc > 0


def depth_to_disparity(depth: np.ndarray, fx: float, baseline: float) -> np.ndarray:
    """Disparity (px) of a rectified stereo pair from z-depth (m): fx * baseline / z; 0 where z is not finite
    and > 0."""
    z = np.asarray(depth, np.float64)
    ok = np.isfinite(z) & (z > 0)
    return np.where(ok, float(fx) * float(baseline) / np.where(ok, z, 1.0), 0.0).astype(np.float32)


def read_kitti_flow_nan(path) -> np.ndarray:
    """Flow (H, W, 2) float32 with NaN where the file marks a pixel invalid (the manifest reader's form)."""
    flow, valid = read_kitti_flow(path)
    flow[~valid] = np.nan
    return flow
