"""Writers and readers for the modality files (docs/design.md, File formats).

| modality | file | encoding |
|---|---|---|
| rgb | PNG uint8 sRGB | |
| semantic | PNG palette uint8 | index = class id, palette = ``labels.COLORS`` |
| instance | PNG uint16 | 0 = none |
| depth | PNG uint16 mm (0 = sky / beyond 65.535 m) or ``.npy`` float32 m (inf = sky) | |
| normal | PNG uint16 x3 (R,G,B = x,y,z) | (n+1)/2*65535, camera frame; 0,0,0 = sky |
| flow (``render.storage=exact``) | Middlebury ``.flo`` | 'PIEH', width, height, float32 (u, v) |
| occlusion | PNG uint8 | 1 = occluded or leaves the image |
| float layers (``render.storage=exact``) | ``.npy`` float32 (H, W, 3) | linear, lossless |

The compact storage's codecs live beside these: KITTI flow PNGs in :mod:`eden_pipe.io.kitti`,
half-float OpenEXR layers in :mod:`eden_pipe.io.exr`.
Which column uses which writer and reader is the modality table's business
(:mod:`eden_pipe.modalities`). Every writer goes through a temporary file and a rename, so an interrupted job
never leaves a truncated image under its final name.
"""

from __future__ import annotations

import io
from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from eden_pipe import labels
from eden_pipe.io.atomic import write_bytes_atomic

FLO_TAG = 202021.25  # b'PIEH' read as little-endian float32


# PNG row filters (one for every row, not libpng's per-row choice among all five, which encoded
# 1.6-1.9x slower at the same size). By content, measured on five default-garden views at level 1
# (docs/design.md, File formats): rendered colour, normals, ids and masks change from pixel to
# pixel, so no filter (NONE) encodes fastest and smallest (rgb 298 against 348 kB with SUB,
# normals 337 against 496 kB, in 0.7-0.8 of the time); depth is smooth along rows (SUB: 192 kB,
# NONE 216 kB); KITTI flow likewise (io.kitti).
PNG_NO_FILTER = cv2.IMWRITE_PNG_FILTER_NONE
PNG_ROW_FILTER = cv2.IMWRITE_PNG_FILTER_SUB


def png_bytes(array: np.ndarray, compression: int, row_filter: int = PNG_ROW_FILTER) -> memoryview:
    """An array's PNG encoding (OpenCV's channel order) at zlib level ``compression`` with one row filter."""
    params = [cv2.IMWRITE_PNG_COMPRESSION, int(compression), cv2.IMWRITE_PNG_FILTER, int(row_filter)]
    ok, buf = cv2.imencode(".png", array, params)
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.data  # written as is: no copy into a bytes object


def read_raw(path) -> np.ndarray:
    """An image file's array as stored: OpenCV's channel order (BGR) and the file's dtype."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileNotFoundError(f"cannot read image {path}")
    return img


# ------------------------------------------------------------------ RGB (uint8)
def write_rgb(path, rgb: np.ndarray, compression: int = 1) -> None:
    write_bytes_atomic(path, png_bytes(np.ascontiguousarray(rgb[..., ::-1]), compression, PNG_NO_FILTER))


def read_rgb(path) -> np.ndarray:
    return np.ascontiguousarray(read_raw(path)[..., ::-1])


# ------------------------------------------------------------ semantic palette
def write_semantic(path, ids: np.ndarray, compression: int = 1) -> None:
    img = Image.fromarray(np.asarray(ids, np.uint8), mode="P")
    img.putpalette(labels.palette_rgb().ravel().tolist())
    buf = io.BytesIO()
    img.save(buf, format="PNG", compress_level=int(compression))
    write_bytes_atomic(path, buf.getvalue())


def read_semantic(path) -> np.ndarray:
    with Image.open(path) as img:
        if img.mode != "P":
            raise ValueError(f"{path}: expected a palette PNG, got mode {img.mode}")
        return np.asarray(img, dtype=np.uint8)


def read_palette(path) -> np.ndarray:
    """(N, 3) uint8 palette stored in an indexed PNG."""
    with Image.open(path) as img:
        return np.asarray(img.getpalette(), dtype=np.uint8).reshape(-1, 3)


# --------------------------------------------------------------------- uint16
def write_instance(path, ids: np.ndarray, compression: int = 1) -> None:
    write_bytes_atomic(path, png_bytes(np.asarray(ids, np.uint16), compression, PNG_NO_FILTER))


def read_instance(path) -> np.ndarray:
    return read_raw(path).astype(np.uint16)


def write_depth(path, depth: np.ndarray, fmt: str = "png16", compression: int = 1) -> None:
    """z-depth in metres; non-finite = sky."""
    depth = np.asarray(depth, np.float64)
    if fmt == "float":
        write_bytes_atomic(path, _npy_writer(np.where(np.isfinite(depth), depth, np.inf).astype(np.float32)))
        return
    mm = np.where(np.isfinite(depth), np.round(depth * 1000.0), 0.0)
    mm = np.where(mm > 65535, 0, mm)  # beyond the encodable range counts as invalid
    write_bytes_atomic(path, png_bytes(mm.astype(np.uint16), compression))


def read_depth(path) -> np.ndarray:
    """Metres as float32; sky / invalid as inf (both formats)."""
    path = Path(path)
    if path.suffix == ".npy":
        return np.load(path).astype(np.float32)
    mm = read_raw(path).astype(np.float32)
    return np.where(mm > 0, mm / 1000.0, np.inf).astype(np.float32)


def write_normal(path, normal: np.ndarray, compression: int = 1) -> None:
    n = np.asarray(normal, np.float32)[..., ::-1]  # OpenCV writes BGR
    valid = (n[..., 0] != 0) | (n[..., 1] != 0) | (n[..., 2] != 0)
    enc = np.round((np.clip(n, -1, 1) + np.float32(1.0)) * np.float32(0.5 * 65535.0)) * valid[..., None]
    write_bytes_atomic(path, png_bytes(enc.astype(np.uint16), compression, PNG_NO_FILTER))


def read_normal(path) -> np.ndarray:
    """Unit normals (H, W, 3) float32 in the camera frame; zeros where the file has 0,0,0 (sky)."""
    enc = read_raw(path)[..., ::-1].astype(np.float32)
    n = enc / 65535.0 * 2.0 - 1.0
    return np.where(np.any(enc > 0, axis=-1, keepdims=True), n, 0.0).astype(np.float32)


# ----------------------------------------------------------------------- flow
def write_flo(path, flow: np.ndarray) -> None:
    flow = np.asarray(flow, np.float32)
    h, w = flow.shape[:2]
    header = np.array([FLO_TAG], np.float32).tobytes() + np.array([w, h], np.int32).tobytes()
    write_bytes_atomic(path, lambda fh: (fh.write(header), fh.write(np.ascontiguousarray(flow[..., :2]).data)))


def read_flo(path) -> np.ndarray:
    with open(path, "rb") as fh:
        tag = np.frombuffer(fh.read(4), np.float32)[0]
        if tag != np.float32(FLO_TAG):
            raise ValueError(f"{path}: not a Middlebury .flo file (bad tag)")
        w, h = np.frombuffer(fh.read(8), np.int32)
        data = np.frombuffer(fh.read(), np.float32)
    return data.reshape(int(h), int(w), 2).copy()


def write_mask(path, mask: np.ndarray, compression: int = 1) -> None:
    write_bytes_atomic(path, png_bytes(np.asarray(mask, np.uint8), compression, PNG_NO_FILTER))


def read_mask(path) -> np.ndarray:
    return read_raw(path).astype(np.uint8)


# ---------------------------------------------------------------- float layers
def _npy_writer(array: np.ndarray):
    # Contiguous first: ndarray.tofile (np.save's path for files) writes a strided view one
    # element at a time, which made the float layers a sixth of a frame's time.
    array = np.ascontiguousarray(array)
    return lambda fh: np.save(fh, array, allow_pickle=False)


def write_float(path, array: np.ndarray) -> None:
    write_bytes_atomic(path, _npy_writer(np.asarray(array, np.float32)))


def read_float(path) -> np.ndarray:
    return np.load(path, allow_pickle=False)


def read_modality(path, column: str) -> np.ndarray:
    """Read any manifest path column's file (the reader comes from the modality table,
    :mod:`eden_pipe.modalities`)."""
    from eden_pipe.modalities import read_modality

    return read_modality(path, column)
