"""The PNG and OpenEXR encoders behind every compact file (docs/design.md, File formats).

Both formats are deflate streams over a cheap, exactly invertible transform: PNG over rows each led
by a filter byte, OpenEXR's ZIP over blocks of 16 scanlines split into their low and high bytes and
delta-coded. OpenCV's PNG writer and the OpenEXR library deflate with zlib (level 1: about 100 MB/s
here) and libdeflate (OpenEXR's fixed level), which made encoding a camera pair about 160 ms of CPU.
These writers do the transforms with numpy and deflate with ISA-L (``isal``, 4-5x faster than zlib
at the same level and within a few per cent of its size), so the files are standard PNG and
scanline ZIP OpenEXR that any reader decodes to the same arrays; only the compressed bytes differ.
Without ``isal`` installed the standard library's zlib deflates (the same files, slower).

``deflate(data, level)``: level 0 stores (no compression), 1-3 are ISA-L's levels 1-3 (zlib's where
ISA-L is missing), 4-9 zlib's (smaller, several times slower).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Sequence

import numpy as np

_fast_compress: Callable[..., bytes] | None
try:
    from isal import isal_zlib

    _fast_compress = isal_zlib.compress
except ImportError:  # the same streams from the standard library, slower
    _fast_compress = None

FAST_LEVELS = (1, 2, 3)  # ISA-L's levels; 0 is stored, 4-9 go to zlib
# Inputs under this many bytes go to zlib. Two identical jobs once wrote ISA-L streams of the same
# 7 KB rows (a 96 x 72 label PNG) that differed, 599 against 596 bytes, both valid, while 14-21 KB
# inputs of the same runs matched; no rerun in one process reproduced it. zlib's stream is a
# function of its input alone, and at this size its speed does not matter: the smallest input of
# a 640 x 480 dataset is an EXR block of 61 KB (docs/design.md, File formats).
SMALL_INPUT_BYTES = 16384


def deflate(data, level: int) -> bytes:
    """A zlib stream of ``data`` (bytes-like) at ``level`` 0-9 (0: stored)."""
    level = int(level)
    if not 0 <= level <= 9:
        raise ValueError(f"deflate level {level} not in 0..9")
    if level in FAST_LEVELS and _fast_compress is not None and memoryview(data).nbytes >= SMALL_INPUT_BYTES:
        return _fast_compress(data, level)
    return zlib.compress(data, level)


# ------------------------------------------------------------------------ PNG
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
FILTER_NONE, FILTER_SUB, FILTER_UP = 0, 1, 2  # PNG filter types (one for every row)
_COLOUR_TYPES = {1: 0, 2: 4, 3: 2, 4: 6}  # channels -> grey, grey+alpha, RGB, RGBA


def _chunk(kind: bytes, data) -> bytes:
    crc = zlib.crc32(data, zlib.crc32(kind))
    return struct.pack(">I", len(data)) + kind + bytes(data) + struct.pack(">I", crc)


def filtered_rows(array: np.ndarray, row_filter: int) -> np.ndarray:
    """(H, 1 + row bytes) uint8: each row of ``array`` (uint8 or big-endian uint16 samples) led by its
    filter type and filtered by it (PNG specification, Filtering: differences modulo 256)."""
    height = array.shape[0]
    samples = array.astype(">u2", copy=False) if array.dtype == np.uint16 else array
    rows = np.ascontiguousarray(samples).view(np.uint8).reshape(height, -1)
    pixel_bytes = (array.shape[2] if array.ndim == 3 else 1) * array.dtype.itemsize
    out = np.empty((height, rows.shape[1] + 1), np.uint8)
    out[:, 0] = row_filter
    if row_filter == FILTER_NONE:
        out[:, 1:] = rows
    elif row_filter == FILTER_SUB:  # each byte less the same byte of the pixel to its left
        out[:, 1 : 1 + pixel_bytes] = rows[:, :pixel_bytes]
        np.subtract(rows[:, pixel_bytes:], rows[:, :-pixel_bytes], out=out[:, 1 + pixel_bytes :])
    elif row_filter == FILTER_UP:  # each byte less the byte above it
        out[0, 1:] = rows[0]
        np.subtract(rows[1:], rows[:-1], out=out[1:, 1:])
    else:
        raise ValueError(f"row filter {row_filter} not supported (0 none, 1 sub, 2 up)")
    return out


def png_encode(array: np.ndarray, level: int, row_filter: int = FILTER_NONE, palette=None) -> bytes:
    """A PNG of a uint8 or uint16 (H, W) or (H, W, C) array, channels in the file's order (R, G, B(, A));
    with ``palette`` ((N, 3) uint8) an indexed PNG of a uint8 (H, W) array."""
    a = np.asarray(array)
    if a.dtype not in (np.uint8, np.uint16) or a.ndim not in (2, 3) or 0 in a.shape[:2]:
        raise ValueError(f"expected a uint8/uint16 (H, W[, C]) image, got {a.dtype} {a.shape}")
    channels = a.shape[2] if a.ndim == 3 else 1
    if palette is not None:
        if a.dtype != np.uint8 or channels != 1:
            raise ValueError("an indexed PNG needs a uint8 (H, W) array")
        colour_type = 3
    elif channels in _COLOUR_TYPES:
        colour_type = _COLOUR_TYPES[channels]
    else:
        raise ValueError(f"a PNG holds 1-4 channels, got {channels}")
    header = struct.pack(">IIBBBBB", a.shape[1], a.shape[0], 8 * a.dtype.itemsize, colour_type, 0, 0, 0)
    parts = [PNG_SIGNATURE, _chunk(b"IHDR", header)]
    if palette is not None:
        parts.append(_chunk(b"PLTE", np.asarray(palette, np.uint8).reshape(-1, 3).tobytes()))
    parts += [_chunk(b"IDAT", deflate(filtered_rows(a, row_filter), level)), _chunk(b"IEND", b"")]
    return b"".join(parts)


# ------------------------------------------------------------------- OpenEXR
EXR_MAGIC = 20000630
EXR_HALF, EXR_FLOAT = 1, 2  # pixel types
EXR_NO_COMPRESSION, EXR_ZIPS, EXR_ZIP = 0, 2, 3
_ZIP_LINES = {EXR_NO_COMPRESSION: 1, EXR_ZIPS: 1, EXR_ZIP: 16}  # scanlines per block


def _attribute(name: str, kind: str, value: bytes) -> bytes:
    return name.encode() + b"\0" + kind.encode() + b"\0" + struct.pack("<i", len(value)) + value


def _zip_predict(blocks: np.ndarray) -> np.ndarray:
    """OpenEXR's ZIP transform of each row of ``blocks`` (uint8): the even bytes, then the odd ones,
    then each byte less its predecessor plus 128 (modulo 256), the first byte kept."""
    split = np.concatenate([blocks[:, 0::2], blocks[:, 1::2]], axis=1)
    out = np.empty_like(split)
    out[:, 0] = split[:, 0]
    np.subtract(split[:, 1:], split[:, :-1], out=out[:, 1:])
    out[:, 1:] += np.uint8(128)
    return out


def exr_encode(planes: np.ndarray, names: Sequence[str], compression: int = EXR_ZIP, level: int = 1) -> bytes:
    """A single-part scanline OpenEXR of (C, H, W) float16 or float32 ``planes`` named ``names``,
    NO, ZIPS or ZIP compressed (the ZIP blocks deflated at ``level``)."""
    planes = np.asarray(planes)
    if planes.dtype not in (np.float16, np.float32) or planes.ndim != 3 or len(names) != planes.shape[0]:
        raise ValueError(f"expected (C, H, W) float16/float32 planes and C names, got {planes.dtype} {planes.shape}")
    if compression not in _ZIP_LINES:
        raise ValueError(f"EXR compression {compression} not supported (0 none, 2 zips, 3 zip)")
    order = sorted(range(len(names)), key=lambda i: names[i])  # the file's channel order: by name
    pixel_type = EXR_HALF if planes.dtype == np.float16 else EXR_FLOAT
    _, height, width = planes.shape
    channels = b"".join(names[i].encode() + b"\0" + struct.pack("<iB3xii", pixel_type, 0, 1, 1) for i in order)
    window = struct.pack("<4i", 0, 0, width - 1, height - 1)
    header = b"".join(
        (
            struct.pack("<ii", EXR_MAGIC, 2),
            _attribute("channels", "chlist", channels + b"\0"),
            _attribute("compression", "compression", bytes([compression])),
            _attribute("dataWindow", "box2i", window),
            _attribute("displayWindow", "box2i", window),
            _attribute("lineOrder", "lineOrder", b"\0"),
            _attribute("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
            _attribute("screenWindowCenter", "v2f", struct.pack("<2f", 0.0, 0.0)),
            _attribute("screenWindowWidth", "float", struct.pack("<f", 1.0)),
            b"\0",
        )
    )
    # Scanline by scanline, each channel's row in turn (little-endian, as numpy holds them here).
    lines = np.ascontiguousarray(planes[order].transpose(1, 0, 2)).astype(planes.dtype.newbyteorder("<"), copy=False)
    line_bytes = lines.view(np.uint8).reshape(height, -1)
    per_block = _ZIP_LINES[compression]
    starts = range(0, height, per_block)
    chunks = []
    full = height // per_block
    raw_blocks = [line_bytes[y : y + per_block].reshape(1, -1) for y in starts]
    if compression == EXR_NO_COMPRESSION:
        chunks = [b.tobytes() for b in raw_blocks]
    else:
        predicted = list(_zip_predict(line_bytes[: full * per_block].reshape(full, -1))) if full else []
        if full < len(raw_blocks):
            predicted.append(_zip_predict(raw_blocks[-1])[0])
        for raw, ready in zip(raw_blocks, predicted, strict=True):
            packed = deflate(ready, level)
            chunks.append(packed if len(packed) < raw.size else raw.tobytes())  # stored when deflate does not help
    offsets = np.cumsum([len(header) + 8 * len(chunks)] + [8 + len(c) for c in chunks[:-1]]).astype("<u8")
    body = b"".join(struct.pack("<ii", y, len(c)) + c for y, c in zip(starts, chunks, strict=True))
    return header + offsets.tobytes() + body
