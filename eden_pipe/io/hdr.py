"""Equirectangular panoramas: HDR environment maps and scenery images, read as linear RGB.

``read_panorama(path)`` returns float32 (H, W, 3) linear RGB, or (H, W, 4) with
an alpha channel where the file has one:

| extension | reader | values |
|---|---|---|
| ``.hdr``, ``.pic`` (Radiance RGBE) | ``cv2.imread(path, cv2.IMREAD_UNCHANGED)`` | linear, as stored |
| ``.exr`` (OpenEXR: Y, RGB or RGBA) | :func:`eden_pipe.io.exr.read_exr` | linear, as stored (Y is grey) |
| ``.png``, ``.jpg``, ``.jpeg``, ``.tif``, ``.tiff`` (8 or 16 bit) | ``cv2.imread`` | sRGB decoded to linear, 0..1 |

Only the HDR kinds (``HDR_EXTENSIONS``) can light a garden (``lighting.environment``);
a scenery panorama (``lighting.scenery``) may be any of them. A panorama must be
equirectangular: width = 2 x height (one pixel of slack for odd heights). A file that
is missing, unreadable, of another shape or with non-finite or negative values raises
:class:`PanoramaError` (an ``OSError``) with one line naming the file and the problem.

Reads are cached by (path, size, modification time): the config check, the sky and the
gallery read a map once. :func:`write_hdr` writes Radiance ``.hdr`` files (tests and
generated maps); OpenEXR files are written with :func:`eden_pipe.io.exr.write_exr`.
"""

from __future__ import annotations

import hashlib
import os
from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np

from eden_pipe.colour import srgb_to_linear
from eden_pipe.io.atomic import atomic_path

HDR_EXTENSIONS = (".hdr", ".pic", ".exr")
LDR_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff")
PANORAMA_EXTENSIONS = HDR_EXTENSIONS + LDR_EXTENSIONS


class PanoramaError(OSError):
    """A panorama that cannot be used: missing, unreadable, not 2:1, or with invalid values."""


def read_panorama(path) -> np.ndarray:
    """(H, W, 3 or 4) float32 linear RGB(A) of an equirectangular image; read-only (cached)."""
    p = Path(path)
    try:
        st = p.stat()
    except OSError as exc:
        raise PanoramaError(f"cannot read {p}: {exc.strerror or exc}") from None
    if not p.is_file():
        raise PanoramaError(f"{p} is not a file")
    return _read_cached(str(p.resolve()), st.st_size, st.st_mtime_ns)


@lru_cache(maxsize=4)
def _read_cached(path: str, size: int, mtime_ns: int) -> np.ndarray:
    image = _decode(Path(path))
    h, w = image.shape[:2]
    if abs(w - 2 * h) > 1 or h < 2:
        raise PanoramaError(f"{path} is {w}x{h}: an equirectangular panorama is twice as wide as it is high")
    if not np.all(np.isfinite(image)) or image.min() < 0:
        raise PanoramaError(f"{path} has negative or non-finite values")
    image.setflags(write=False)
    return image


def _decode(path: Path) -> np.ndarray:
    ext = path.suffix.lower()
    if ext not in PANORAMA_EXTENSIONS:
        raise PanoramaError(f"{path}: unknown image type {ext!r} (allowed: {', '.join(PANORAMA_EXTENSIONS)})")
    if ext == ".exr":
        from eden_pipe.io.exr import read_exr

        try:
            image = read_exr(path)
        except (OSError, ValueError) as exc:
            raise PanoramaError(f"cannot read {path}: {exc}") from None
        if image.shape[2] == 1:
            image = np.repeat(image, 3, axis=2)
        elif image.shape[2] not in (3, 4):
            raise PanoramaError(f"{path} has {image.shape[2]} channels (allowed: Y, RGB, RGBA)")
        return np.ascontiguousarray(image, dtype=np.float32)
    raw = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if raw is None:
        raise PanoramaError(f"cannot read {path}: not a valid {ext} image")
    if raw.ndim == 2:
        raw = raw[..., None]
    channels = raw.shape[2]
    if channels == 1:
        raw = np.repeat(raw, 3, axis=2)
    elif channels == 2:  # grey + alpha
        raw = np.concatenate([np.repeat(raw[..., :1], 3, axis=2), raw[..., 1:]], axis=2)
    else:
        order = [2, 1, 0, 3][: raw.shape[2]]  # OpenCV's BGR(A) -> RGB(A)
        raw = raw[..., order]
    if raw.dtype in (np.uint8, np.uint16):
        scale = np.float32(1.0 / (255 if raw.dtype == np.uint8 else 65535))  # the integer type's full scale
        image = raw.astype(np.float32) * scale
        image[..., :3] = srgb_to_linear(image[..., :3])
        return np.ascontiguousarray(image, dtype=np.float32)
    return np.ascontiguousarray(raw, dtype=np.float32)  # Radiance RGBE (and float TIFF): linear already


def write_hdr(path, rgb: np.ndarray) -> None:
    """Write (H, W, 3) linear RGB as a Radiance ``.hdr`` (RGBE: ~1 % precision per pixel)."""
    a = np.asarray(rgb, np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"expected an (H, W, 3) array, got shape {a.shape}")
    with atomic_path(path, suffix=".tmp.hdr") as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(a[..., ::-1])):
            raise OSError(f"cannot write {path}")


def file_sha256(path) -> str:
    """Hex SHA-256 of a file's bytes (what the render cache key and lighting.json record)."""
    digest = hashlib.sha256()
    with open(os.fspath(path), "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()
