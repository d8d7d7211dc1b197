"""scripts/dataset_fingerprint.py: a byte comparison says which differing images kept their pixels."""

from __future__ import annotations

import zlib

import cv2
import numpy as np

from eden_pipe.io.encoders import png_encode
from scripts.dataset_fingerprint import annotate, compare, content_digest


def test_a_new_deflate_stream_of_the_same_pixels_is_told_apart(tmp_path):
    rng = np.random.default_rng(3)
    image = rng.integers(0, 65535, (24, 32, 3), dtype=np.uint16)
    same = tmp_path / "same.png"
    same.write_bytes(png_encode(image, 1))
    # The same rows deflated at another level: other bytes, the same decoded array.
    restream = tmp_path / "restream.png"
    restream.write_bytes(png_encode(image, 6))
    changed = tmp_path / "changed.png"
    other = image.copy()
    other[5, 7, 1] += 1
    changed.write_bytes(png_encode(other, 1))
    assert same.read_bytes() != restream.read_bytes()
    assert np.array_equal(cv2.imread(str(restream), cv2.IMREAD_UNCHANGED), cv2.imread(str(same), cv2.IMREAD_UNCHANGED))

    def byte_digest(path):
        return zlib.crc32(path.read_bytes())

    before = {"job": {"a/normal/0.png": byte_digest(same), "b/normal/0.png": byte_digest(same), "x.csv": 1}}
    after = {"job": {"a/normal/0.png": byte_digest(restream), "b/normal/0.png": byte_digest(changed), "x.csv": 2}}
    decoded = {
        "job": (
            {"a/normal/0.png": content_digest(same), "b/normal/0.png": content_digest(same)},
            {"a/normal/0.png": content_digest(restream), "b/normal/0.png": content_digest(changed)},
        )
    }
    lines = [annotate(line, decoded) for line in compare(before, after)]
    assert lines == [
        "job: differs a/normal/0.png (its pixels the same: another deflate stream)",
        "job: differs b/normal/0.png (its pixels too)",
        "job: differs x.csv",
    ]
    # A record made before the pixel digests existed: the lines stay as they were.
    assert annotate(lines[2], {"job": (None, None)}) == lines[2]
    assert annotate("job: differs a/normal/0.png", {}) == "job: differs a/normal/0.png"
