"""What two jobs' files are compared by: an image's decoded array (its PNG or EXR bytes can differ for
the same pixels: ISA-L's deflate, docs/design.md, File formats), any other file's bytes."""

from __future__ import annotations

import hashlib
from pathlib import Path

import cv2

from eden_pipe.io.exr import read_exr


def content_digest(path: Path) -> str:
    """sha256 of an image's decoded array with its dtype and shape, or of another file's bytes."""
    if path.suffix == ".exr":
        array = read_exr(path)
    elif path.suffix == ".png":
        array = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    else:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    return hashlib.sha256(f"{array.dtype} {array.shape}".encode() + array.tobytes()).hexdigest()
