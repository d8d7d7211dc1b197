"""KITTI flow and disparity PNGs: round trips, invalid pixels, the devkit formula on independent decoders."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from PIL import Image

from eden_pipe.io.kitti import (
    FLOW_MAX,
    FLOW_MIN,
    depth_to_disparity,
    read_kitti_disparity,
    read_kitti_flow,
    write_kitti_disparity,
    write_kitti_flow,
)


def _flow(h=48, w=64, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-300, 300, (h, w, 2)).astype(np.float32)


def test_flow_round_trip_within_half_a_step(tmp_path):
    flow = _flow()
    write_kitti_flow(tmp_path / "f.png", flow)
    back, valid = read_kitti_flow(tmp_path / "f.png")
    assert back.dtype == np.float32 and back.shape == flow.shape and valid.dtype == bool and valid.all()
    assert np.abs(back - flow).max() <= 1 / 128 + 1e-6


def test_float32_flow_encodes_as_its_float64_values(tmp_path):
    """The renderer's float32 flow is encoded in float32 (rint(64 u) + 2^15): the stored levels are
    round(64 u + 2^15) of the values in float64, ties (odd multiples of 1/128 px, rounded half to
    even) and the range's ends included, and a float64 array of the same values gives the same file."""
    ties = (np.arange(-40, 40) * 2 + 1) / 128.0
    ends = [FLOW_MIN, FLOW_MAX, FLOW_MIN - 2**-14, FLOW_MAX + 2**-14, np.nan, np.inf, 0.0, -0.0]
    values = np.concatenate([ties, ends, np.random.default_rng(3).uniform(-600, 600, 912)]).astype(np.float32)
    flow = values.reshape(25, 20, 2)
    write_kitti_flow(tmp_path / "single.png", flow)
    write_kitti_flow(tmp_path / "double.png", flow.astype(np.float64))
    assert (tmp_path / "single.png").read_bytes() == (tmp_path / "double.png").read_bytes()
    wide = flow.astype(np.float64)
    ok = np.all(np.isfinite(wide) & (wide >= FLOW_MIN) & (wide <= FLOW_MAX), axis=-1)
    levels = np.round(np.where(ok[..., None], wide, 0.0) * 64 + 2**15)
    bgr = cv2.imread(str(tmp_path / "single.png"), cv2.IMREAD_UNCHANGED)
    assert np.array_equal(bgr[..., 0], ok) and np.array_equal(bgr[..., 2:0:-1], levels)


def test_flow_invalid_pixels(tmp_path):
    flow = _flow(8, 9)
    flow[0, 0] = np.nan
    flow[1, 1, 0] = np.inf
    mask = np.ones((8, 9), bool)
    mask[2:4, 5] = False
    write_kitti_flow(tmp_path / "f.png", flow, mask)
    back, valid = read_kitti_flow(tmp_path / "f.png")
    expect = mask.copy()
    expect[0, 0] = expect[1, 1] = False
    assert np.array_equal(valid, expect)
    assert np.all(back[~expect] == 0)
    assert np.abs(back[expect] - flow[expect]).max() <= 1 / 128 + 1e-6


def test_flow_beyond_representable_range_is_invalid_not_clipped(tmp_path):
    flow = np.array([[[1000.0, -1000.0], [511.98, -512.0], [FLOW_MAX, 3.0]]], np.float32)
    write_kitti_flow(tmp_path / "f.png", flow)
    back, valid = read_kitti_flow(tmp_path / "f.png")
    assert valid.tolist() == [[False, True, True]]
    assert back[0, 0].tolist() == [0.0, 0.0] and back[0, 1].tolist() == [512.0 - 1 / 64, -512.0]
    assert back[0, 2].tolist() == [FLOW_MAX, 3.0]


def test_flow_devkit_formula_on_pillow_and_raw_rgb(tmp_path):
    """Decode the file as RGB without OpenCV: R = u*64 + 2^15, G = v, B = valid (KITTI devkit order)."""
    flow = _flow(6, 7, seed=1)
    mask = np.random.default_rng(2).random((6, 7)) > 0.3
    write_kitti_flow(tmp_path / "f.png", flow, mask)
    with Image.open(tmp_path / "f.png") as img:
        assert img.size == (7, 6)
        # Pillow has no 3x16-bit mode: it converts to 8 bits, so check the layout on the high bytes ...
        rgb8 = np.asarray(img.convert("RGB")) if img.mode != "RGB" else np.asarray(img)
    # ... and decode the full 16-bit samples from the raw PNG data with zlib (no PNG library at all).
    rgb = _png_rgb16(tmp_path / "f.png")
    assert np.array_equal(rgb8, (rgb >> 8).astype(np.uint8))
    u = (rgb[..., 0].astype(np.float64) - 2**15) / 64
    v = (rgb[..., 1].astype(np.float64) - 2**15) / 64
    assert np.array_equal(rgb[..., 2] == 1, mask) and set(np.unique(rgb[..., 2])) <= {0, 1}
    assert np.abs(u[mask] - flow[..., 0][mask]).max() <= 1 / 128
    assert np.abs(v[mask] - flow[..., 1][mask]).max() <= 1 / 128


def test_disparity_round_trip_and_invalid(tmp_path):
    rng = np.random.default_rng(3)
    d = rng.uniform(0.01, 250, (20, 30))
    d[0, :5] = [0.0, -1.0, np.nan, np.inf, 1e-4]
    mask = np.ones(d.shape, bool)
    mask[5, 5] = False
    write_kitti_disparity(tmp_path / "d.png", d, mask)
    back, valid = read_kitti_disparity(tmp_path / "d.png")
    expect = mask & np.isfinite(d) & (d > 0)
    assert np.array_equal(valid, expect)
    assert np.all(back[~valid] == 0)
    assert back[0, 4] == 1 / 256  # tiny positive disparity stays valid at the smallest step
    ok = expect.copy()
    ok[0, 4] = False
    assert np.abs(back[ok] - d[ok]).max() <= 1 / 512 + 1e-9
    with Image.open(tmp_path / "d.png") as img:  # independent decode: Pillow, devkit formula d = I / 256
        raw = np.asarray(img).astype(np.int64)
    assert np.array_equal(raw, np.round(back * 256).astype(np.int64)) and np.array_equal(raw > 0, expect)


def test_disparity_clipped_and_from_depth(tmp_path):
    write_kitti_disparity(tmp_path / "d.png", np.array([[300.0, 255.99]]))
    back, _ = read_kitti_disparity(tmp_path / "d.png")
    assert back.tolist() == [[65535 / 256, 65533 / 256]]
    disp = depth_to_disparity(np.array([[1.0, 19.2, np.inf, 0.0]]), fx=640, baseline=0.03)
    assert disp[0].tolist() == pytest.approx([19.2, 1.0, 0.0, 0.0])


def test_bad_inputs(tmp_path):
    with pytest.raises(ValueError):
        write_kitti_flow(tmp_path / "f.png", np.zeros((4, 4, 3)))
    with pytest.raises(ValueError):
        write_kitti_flow(tmp_path / "f.png", np.zeros((4, 4, 2)), np.ones((3, 4), bool))
    write_kitti_disparity(tmp_path / "d.png", np.ones((4, 4)))
    with pytest.raises(ValueError, match="3 channel"):
        read_kitti_flow(tmp_path / "d.png")
    (tmp_path / "t.png").write_bytes((tmp_path / "d.png").read_bytes()[:20])
    with pytest.raises(ValueError, match="cannot decode"):
        read_kitti_disparity(tmp_path / "t.png")
    with pytest.raises(FileNotFoundError):
        read_kitti_flow(tmp_path / "missing.png")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []


def _png_rgb16(path) -> np.ndarray:
    """Decode a non-interlaced 16-bit RGB PNG from its chunks (zlib + the five PNG filters)."""
    import struct
    import zlib

    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat = 8, b""
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos : pos + 4])
        kind, body = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + n]
        if kind == b"IHDR":
            w, h, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
            assert (depth, ctype, interlace) == (16, 2, 0)
        elif kind == b"IDAT":
            idat += body
        pos += 12 + n
    raw = zlib.decompress(idat)
    bpp, stride = 6, w * 6
    out = np.zeros((h, stride), np.int64)
    for y in range(h):
        ftype = raw[y * (stride + 1)]
        line = np.frombuffer(raw, np.uint8, stride, y * (stride + 1) + 1).astype(np.int64)
        prev = out[y - 1] if y else np.zeros(stride, np.int64)
        cur = np.zeros(stride, np.int64)
        for i in range(stride):
            a = cur[i - bpp] if i >= bpp else 0
            b, c = prev[i], (prev[i - bpp] if i >= bpp else 0)
            if ftype == 0:
                pred = 0
            elif ftype == 1:
                pred = a
            elif ftype == 2:
                pred = b
            elif ftype == 3:
                pred = (a + b) // 2
            else:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
            cur[i] = (line[i] + pred) % 256
        out[y] = cur
    samples = (out[:, 0::2] << 8) | out[:, 1::2]
    return samples.reshape(h, w, 3).astype(np.uint16)
