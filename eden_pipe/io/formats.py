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

from pathlib import Path

import cv2
import numpy as np
from PIL import Image

from eden_pipe import labels
from eden_pipe.io.atomic import write_bytes_atomic
from eden_pipe.io.encoders import FILTER_NONE, FILTER_SUB, FILTER_UP, png_encode
from eden_pipe.io.quantise import normal_codes

FLO_TAG = 202021.25  # b'PIEH' read as little-endian float32


# The encoder settings of every file kind, in one table (docs/design.md, File formats): the PNG row
# filter (one for every row: libpng's per-row choice among all five encoded 1.6-1.9x slower at the same
# size) and the OpenEXR layers' ZIP deflate level; the PNGs' level is ``render.png_compression``.
# Chosen by benchmarks/encode_settings.py on default-garden frames (the cheapest CPU time, files
# within the row budget): rendered colour, normals, ids and masks change from pixel to pixel, so no
# filter encodes fastest and smallest (rgb 293 kB in 3.0 ms against 300 kB in 3.2 ms with SUB);
# depth is smooth down columns as much as along rows (UP: 98 kB, SUB 101 kB); KITTI flow along rows
# (SUB 229 kB, NONE 499 kB). ISA-L's level 2 deflates the EXR blocks as fast as its level 1, a little
# smaller (598 against 599 kB for albedo, in 4.2 against 4.7 ms).
ROW_FILTERS = {
    "rgb": FILTER_NONE,
    "semantic": FILTER_NONE,
    "instance": FILTER_NONE,
    "depth": FILTER_UP,
    "normal": FILTER_NONE,
    "kitti_flow": FILTER_SUB,
    "kitti_disparity": FILTER_SUB,
    "mask": FILTER_NONE,
}
EXR_DEFLATE_LEVEL = 2


def write_png(path, array: np.ndarray, compression: int, kind: str, palette=None) -> None:
    """``array`` (channels in the file's order: R, G, B) as a PNG at deflate level ``compression``,
    filtered as ``ROW_FILTERS[kind]`` says (:func:`eden_pipe.io.encoders.png_encode`), written atomically."""
    write_bytes_atomic(path, png_encode(array, compression, ROW_FILTERS[kind], palette=palette))


def read_raw(path) -> np.ndarray:
    """An image file's array as stored: OpenCV's channel order (BGR) and the file's dtype."""
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileNotFoundError(f"cannot read image {path}")
    return img


# ------------------------------------------------------------------ RGB (uint8)
def write_rgb(path, rgb: np.ndarray, compression: int = 1) -> None:
    write_png(path, np.asarray(rgb, np.uint8), compression, "rgb")


def read_rgb(path) -> np.ndarray:
    return np.ascontiguousarray(read_raw(path)[..., ::-1])


# ------------------------------------------------------------ semantic palette
def write_semantic(path, ids: np.ndarray, compression: int = 1) -> None:
    ids = np.asarray(ids, np.uint8)
    write_png(path, ids, compression, "semantic", palette=labels.palette_rgb())


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
    write_png(path, np.asarray(ids, np.uint16), compression, "instance")


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
    write_png(path, mm.astype(np.uint16), compression, "depth")


def read_depth(path) -> np.ndarray:
    """Metres as float32; sky / invalid as inf (both formats)."""
    path = Path(path)
    if path.suffix == ".npy":
        return np.load(path).astype(np.float32)
    mm = read_raw(path).astype(np.float32)
    return np.where(mm > 0, mm / 1000.0, np.inf).astype(np.float32)


def write_normal(path, normal: np.ndarray, compression: int = 1) -> None:
    # round((clip(n, -1, 1) + 1) * 65535 / 2) in float32, 0, 0, 0 on sky: one compiled pass
    codes = normal_codes(np.asarray(normal, np.float32))
    write_png(path, codes, compression, "normal")


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
    write_png(path, np.asarray(mask, np.uint8), compression, "mask")


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
