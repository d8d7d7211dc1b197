"""OpenEXR layers (the format Cycles writes, and EDEN's intrinsic layers).

``write_exr(path, array, half=True)`` writes a scanline EXR with lossless ZIP
compression (deflate over blocks of 16 scanlines, encoded by
:mod:`eden_pipe.io.encoders` at ``formats.EXR_DEFLATE_LEVEL``; read with the
OpenEXR library). Channels are named by the array's channel count:

| C | channels |
|---|---|
| 1 (or a 2-D array) | ``Y`` |
| 3 | ``R``, ``G``, ``B`` |
| 4 | ``R``, ``G``, ``B``, ``A`` |

or explicitly with ``channels=("u", "v")`` (any names, one per channel).

Precision: ``half=True`` stores IEEE half floats (11 significant bits): the
relative error of a normal value (|x| >= 6.1e-5) is at most 2**-11 = 4.9e-4,
values below that are subnormal (absolute error <= 3e-8), and a value that is
already representable as a half is stored bit-exactly (ZIP is lossless).
Finite values beyond the half range (|x| > 65504) are clipped to +-65504
rather than turning into inf; inf and NaN are kept. ``half=False`` stores
float32 exactly.

``read_exr(path)`` returns float32 (H, W, C) in the order above (a ``Y`` file
gives C = 1). A truncated or corrupt file raises ``ExrError`` (an ``OSError``)
naming the file; a missing file raises ``FileNotFoundError``.

Writes are atomic (temporary file in the same folder, then ``os.replace``).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import OpenEXR

from eden_pipe.io.atomic import write_bytes_atomic
from eden_pipe.io.encoders import EXR_ZIP, exr_encode
from eden_pipe.io.formats import EXR_DEFLATE_LEVEL
from eden_pipe.io.half_float import half_planes, widen

HALF_MAX = 65504.0

_DEFAULT_NAMES = {1: ("Y",), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}


class ExrError(OSError):
    """An EXR file that cannot be read: truncated, corrupt, or not the expected layout."""


def _channel_names(count: int, channels: Sequence[str] | None) -> tuple[str, ...]:
    if channels is not None:
        names = tuple(str(c) for c in channels)
        if len(names) != count or len(set(names)) != count:
            raise ValueError(f"need {count} distinct channel names, got {names}")
        return names
    if count not in _DEFAULT_NAMES:
        raise ValueError(f"an array with {count} channels needs explicit channel names (default layouts: 1, 3, 4)")
    return _DEFAULT_NAMES[count]


def write_exr(path, array: np.ndarray, half: bool = True, channels: Sequence[str] | None = None) -> None:
    """Write a float (H, W, C) or (H, W) array as a ZIP-compressed scanline EXR (half floats unless ``half=False``)."""
    a = np.asarray(array)
    if a.ndim == 2:
        a = a[..., None]
    if a.ndim != 3 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ValueError(f"expected an (H, W, C) or (H, W) array, got shape {np.shape(array)}")
    if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer) or a.dtype == bool):
        raise TypeError(f"expected a numeric array, got {a.dtype}")
    names = _channel_names(a.shape[2], channels)
    if half:
        planes = half_planes(a.astype(np.float32, copy=False))  # finite values clipped to the half range
    else:
        planes = np.moveaxis(a.astype(np.float32, copy=False), 2, 0)
    write_bytes_atomic(path, exr_encode(planes, names, EXR_ZIP, EXR_DEFLATE_LEVEL))


def _order(names: Sequence[str]) -> tuple[str, ...]:
    present = set(names)
    for layout in (("R", "G", "B", "A"), ("R", "G", "B"), ("Y",)):
        if present == set(layout):
            return layout
    return tuple(sorted(names))


def read_exr(path, channels: Sequence[str] | None = None) -> np.ndarray:
    """float32 (H, W, C): channels Y, or R,G,B(,A), or those named in ``channels`` in that order (others sorted)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no EXR file {path}")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as exr:
            found = {name: ch.pixels for name, ch in exr.channels().items()}
    except (RuntimeError, ValueError, TypeError, KeyError, IndexError) as err:
        raise ExrError(f"{path}: truncated or corrupt EXR file ({err})") from err
    if not found:
        raise ExrError(f"{path}: EXR file has no channels (truncated?)")
    names = tuple(channels) if channels is not None else _order(list(found))
    missing = [n for n in names if n not in found]
    if missing:
        raise ExrError(f"{path}: missing channels {missing}; the file has {sorted(found)}")
    planes = [np.asarray(found[n]) for n in names]
    if any(p.ndim != 2 or p.shape != planes[0].shape for p in planes):
        raise ExrError(f"{path}: channels of unequal or subsampled shapes are not supported")
    stacked = np.stack(planes, axis=-1)
    return widen(stacked) if stacked.dtype == np.float16 else stacked.astype(np.float32)
