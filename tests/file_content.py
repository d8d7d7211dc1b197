"""What two jobs' files are compared by: an image's decoded array (its PNG or EXR bytes can differ for
the same pixels: ISA-L's deflate, docs/design.md, File formats), any other file's bytes."""

from __future__ import annotations

import hashlib
from pathlib import Path

from scripts.dataset_fingerprint import IMAGES, pixel_digest


def content_digest(path: Path) -> str:
    """``dataset_fingerprint.pixel_digest`` of an image, sha256 of another file's bytes."""
    return pixel_digest(path) if path.suffix in IMAGES else hashlib.sha256(path.read_bytes()).hexdigest()
