"""KITTI 2015 devkit PNG encodings (flow and disparity), numpy + OpenCV only.

Flow: 16-bit 3-channel PNG, R = u, G = v, B = valid;
``u = (R - 2**15) / 64``, ``v = (G - 2**15) / 64``, valid = B > 0 (OpenCV
stores BGR, so arrays are channel-reversed on write and read).
Disparity: 16-bit 1-channel PNG, ``disparity = value / 256``, 0 = invalid.
(eden_pipe.io.kitti may provide the same; the integrator dedupes.)
"""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

FLOW_SCALE = 64.0
FLOW_OFFSET = 2.0**15
DISP_SCALE = 256.0


def _write(path, array) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), array):
        raise IOError(f"cannot write {path}")


def encode_flow(flow: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """(H, W, 2) float flow (+ bool validity) -> (H, W, 3) uint16 in R, G, B order.

    Pixels whose flow is non-finite or beyond the encodable +-512 px become invalid.
    """
    flow = np.asarray(flow, np.float64)[..., :2]
    ok = np.all(np.isfinite(flow), axis=-1)
    if valid is not None:
        ok &= np.asarray(valid, bool)
    enc = np.round(np.where(np.isfinite(flow), flow, 0.0) * FLOW_SCALE + FLOW_OFFSET)
    ok &= np.all((enc >= 0) & (enc <= 65535), axis=-1)
    enc = np.where(ok[..., None], np.clip(enc, 0, 65535), 0.0)  # zeroed when invalid, as the devkit writes
    return np.dstack([enc, ok.astype(np.float64)]).astype(np.uint16)


def write_flow_png(path: str | os.PathLike, flow: np.ndarray, valid: np.ndarray | None = None) -> None:
    _write(path, encode_flow(flow, valid)[..., ::-1])


def read_flow_png(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """(H, W, 2) float32 flow in pixels and (H, W) bool validity."""
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 3:
        raise ValueError(f"{path}: not a KITTI 16-bit 3-channel flow PNG")
    rgb = raw[..., ::-1].astype(np.float64)
    flow = (rgb[..., :2] - FLOW_OFFSET) / FLOW_SCALE
    return flow.astype(np.float32), rgb[..., 2] > 0


def encode_disparity(disparity: np.ndarray) -> np.ndarray:
    """float disparity in pixels (non-finite / <= 0 = invalid) -> uint16, 0 = invalid."""
    d = np.asarray(disparity, np.float64)
    enc = np.where(np.isfinite(d) & (d > 0), np.round(d * DISP_SCALE), 0.0)
    enc = np.where(enc > 65535, 0.0, enc)  # beyond 256 px: not representable
    return enc.astype(np.uint16)


def write_disparity_png(path: str | os.PathLike, disparity: np.ndarray) -> None:
    _write(path, encode_disparity(disparity))


def read_disparity_png(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None or raw.dtype != np.uint16 or raw.ndim != 2:
        raise ValueError(f"{path}: not a KITTI 16-bit disparity PNG")
    return (raw.astype(np.float32) / DISP_SCALE), raw > 0
