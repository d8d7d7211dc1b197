"""OpenEXR layers: round trips, half precision, lossless ZIP, size, truncation, an independent decoder."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from eden_pipe.io.exr import HALF_MAX, ExrError, read_exr, write_exr


def _smooth_layer(h=480, w=640, seed=0) -> np.ndarray:
    """Shading/albedo-like linear layer: smooth gradients and blobs, values ~1e-3..50, a little noise."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    out = np.empty((h, w, 3), np.float32)
    for c in range(3):
        field = np.zeros((h, w), np.float32)
        for _ in range(6):
            cx, cy, s = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(40, 200)
            field += rng.uniform(-5, 5) * np.exp(-((x - cx) ** 2 + (y - cy) ** 2) / (2 * s * s))
        field += 0.002 * x - 0.001 * y * (c + 1) / 3
        out[..., c] = np.exp(np.clip(field, -6.9, 3.9))  # e^-6.9 = 1e-3 .. e^3.9 = 50
    out *= 1.0 + rng.normal(0, 0.002, out.shape).astype(np.float32)  # render noise
    return out


def test_round_trip_float32_exact(tmp_path):
    a = np.random.default_rng(1).normal(0, 100, (13, 17, 3)).astype(np.float32)
    write_exr(tmp_path / "f.exr", a, half=False)
    back = read_exr(tmp_path / "f.exr")
    assert back.dtype == np.float32 and back.shape == a.shape and np.array_equal(back, a)


def test_half_relative_error_on_realistic_layer(tmp_path):
    a = _smooth_layer(96, 128)
    assert 1e-3 <= a.min() and a.max() <= 51
    write_exr(tmp_path / "s.exr", a)
    back = read_exr(tmp_path / "s.exr")
    rel = np.abs(back - a) / a
    assert rel.max() <= 1e-3
    assert rel.max() <= 2.0**-11 * 1.0001  # round to nearest half: at most half an ulp


def test_half_representable_round_trips_bit_exactly(tmp_path):
    rng = np.random.default_rng(2)
    bits = rng.integers(0, 2**16, (31, 29, 3), dtype=np.uint16)
    h = bits.view(np.float16)
    h = np.where(np.isfinite(h), h, np.float16(1.5))  # inf/NaN patterns aside
    write_exr(tmp_path / "h.exr", h)
    back = read_exr(tmp_path / "h.exr")
    assert np.array_equal(back.astype(np.float16).view(np.uint16), h.view(np.uint16))  # -0.0 included


def test_one_channel_is_y_and_two_d_input(tmp_path):
    a = np.linspace(0.5, 4, 6 * 5, dtype=np.float32).reshape(6, 5)
    write_exr(tmp_path / "y.exr", a, half=False)
    back = read_exr(tmp_path / "y.exr")
    assert back.shape == (6, 5, 1) and np.array_equal(back[..., 0], a)
    assert _decode_exr((tmp_path / "y.exr").read_bytes())[1] == ["Y"]


def test_rgba_and_named_channels(tmp_path):
    a = np.arange(4 * 3 * 4, dtype=np.float32).reshape(4, 3, 4)
    write_exr(tmp_path / "a.exr", a)
    assert np.array_equal(read_exr(tmp_path / "a.exr"), a)
    write_exr(tmp_path / "uv.exr", a[..., :2], channels=("u", "v"))
    assert np.array_equal(read_exr(tmp_path / "uv.exr"), a[..., :2])
    assert np.array_equal(read_exr(tmp_path / "uv.exr", channels=("v",))[..., 0], a[..., 1])
    with pytest.raises(ValueError):
        write_exr(tmp_path / "bad.exr", a[..., :2])  # two channels need names
    with pytest.raises(ExrError, match="missing"):
        read_exr(tmp_path / "uv.exr", channels=("R",))


def test_half_overflow_is_clipped_and_non_finite_kept(tmp_path):
    a = np.array([[[1e6, -1e6, np.inf]], [[np.nan, -np.inf, 65504.0]]], np.float32)
    write_exr(tmp_path / "o.exr", a)
    back = read_exr(tmp_path / "o.exr")
    assert back[0, 0, 0] == HALF_MAX and back[0, 0, 1] == -HALF_MAX and back[0, 0, 2] == np.inf
    assert np.isnan(back[1, 0, 0]) and back[1, 0, 1] == -np.inf and back[1, 0, 2] == HALF_MAX


def test_size_far_below_float32_npy(tmp_path):
    a = _smooth_layer()
    write_exr(tmp_path / "s.exr", a)
    np.save(tmp_path / "s.npy", a)
    exr, npy = (tmp_path / "s.exr").stat().st_size, (tmp_path / "s.npy").stat().st_size
    assert npy > 3.6e6
    assert exr * 3 < npy, (exr, npy)  # measured about 6x on this layer


def test_atomic_write_leaves_no_temporary_and_replaces(tmp_path):
    write_exr(tmp_path / "sub" / "x.exr", np.ones((4, 4, 3)))
    write_exr(tmp_path / "sub" / "x.exr", np.full((4, 4, 3), 2.0))
    assert [p.name for p in (tmp_path / "sub").iterdir()] == ["x.exr"]
    assert np.all(read_exr(tmp_path / "sub" / "x.exr") == 2.0)


def test_truncated_file_raises_clear_error(tmp_path):
    a = _smooth_layer(64, 80)
    write_exr(tmp_path / "full.exr", a)
    data = (tmp_path / "full.exr").read_bytes()
    for cut in (0, 3, 50, 300, len(data) // 3, len(data) // 2, len(data) - 100, len(data) - 1):
        (tmp_path / "cut.exr").write_bytes(data[:cut])
        with pytest.raises(ExrError, match=r"cut\.exr"):
            read_exr(tmp_path / "cut.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr at all" * 10)
    with pytest.raises(ExrError):
        read_exr(tmp_path / "junk.exr")
    with pytest.raises(FileNotFoundError):
        read_exr(tmp_path / "missing.exr")


def test_independent_decoders_agree(tmp_path):
    """A from-the-spec decoder (zlib + EXR ZIP predictor) and OpenEXR's legacy InputFile API read the same pixels."""
    import cv2

    a = _smooth_layer(40, 56, seed=3)
    write_exr(tmp_path / "s.exr", a)
    data = (tmp_path / "s.exr").read_bytes()
    header, names, planes = _decode_exr(data)
    assert header["compression"] == 3  # ZIP_COMPRESSION
    assert names == ["B", "G", "R"] and all(p.dtype == np.float16 for p in planes.values())
    ours = np.stack([planes[c] for c in "RGB"], -1)
    assert np.array_equal(ours.astype(np.float32), read_exr(tmp_path / "s.exr"))

    import OpenEXR

    legacy = OpenEXR.InputFile(str(tmp_path / "s.exr"))
    try:
        r = np.frombuffer(legacy.channel("R"), np.float16).reshape(40, 56)
    finally:
        legacy.close()
    assert np.array_equal(r, ours[..., 0])

    if cv2.haveImageReader(str(tmp_path / "s.exr")):  # only with OPENCV_IO_ENABLE_OPENEXR=1 and a build with the codec
        bgr = cv2.imread(str(tmp_path / "s.exr"), cv2.IMREAD_ANYDEPTH | cv2.IMREAD_UNCHANGED)
        assert np.array_equal(bgr[..., ::-1], ours.astype(np.float32))


# ------------------------------------------------------------ spec decoder
def _decode_exr(data: bytes):
    """Minimal single-part scanline EXR decoder (NO or ZIP compression), written from the file-layout spec."""
    assert data[:4] == b"\x76\x2f\x31\x01", "bad magic"
    pos, header = 8, {}
    while data[pos] != 0:
        end = data.index(b"\0", pos)
        name = data[pos:end].decode()
        tend = data.index(b"\0", end + 1)
        (size,) = struct.unpack_from("<i", data, tend + 1)
        header[name] = data[tend + 5 : tend + 5 + size]
        pos = tend + 5 + size
    pos += 1
    chans, q, raw = [], 0, header["channels"]
    while raw[q] != 0:
        end = raw.index(b"\0", q)
        (ptype,) = struct.unpack_from("<i", raw, end + 1)
        chans.append((raw[q:end].decode(), {0: "<u4", 1: "<f2", 2: "<f4"}[ptype]))
        q = end + 1 + 16
    x0, y0, x1, y1 = struct.unpack("<4i", header["dataWindow"])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    comp = header["compression"][0]
    lines = {0: 1, 3: 16}[comp]
    nchunks = -(-h // lines)
    offsets = struct.unpack_from(f"<{nchunks}Q", data, pos)
    planes = {n: np.empty((h, w), dt) for n, dt in chans}
    line_bytes = sum(w * np.dtype(dt).itemsize for _, dt in chans)
    for off in offsets:
        y, size = struct.unpack_from("<2i", data, off)
        block = data[off + 8 : off + 8 + size]
        rows = min(lines, y1 + 1 - y)
        if size < rows * line_bytes:  # compressed (stored raw when zlib does not help)
            t = np.frombuffer(zlib.decompress(block), np.uint8).astype(np.int64)
            d = t - 128
            d[0] = t[0]
            t = (np.cumsum(d) % 256).astype(np.uint8)  # undo the delta predictor
            half = (len(t) + 1) // 2
            block = np.empty_like(t)
            block[0::2], block[1::2] = t[:half], t[half:]  # re-interleave the two byte streams
            block = block.tobytes()
        p = 0
        for r in range(rows):
            for n, dt in chans:
                nb = w * np.dtype(dt).itemsize
                planes[n][y - y0 + r] = np.frombuffer(block[p : p + nb], dt)
                p += nb
    header["compression"] = comp
    return header, [n for n, _ in chans], planes


def test_half_planes_round_as_numpy_does_and_clip_finite_values():
    """The compiled float32 -> half conversion against numpy's (clip finite values, then round to
    nearest, ties to even), on every class of float32: subnormal halves and the ties between them,
    the normal range's ties and overflow, zeros, inf and NaN payloads. (Checked once over all 2^32
    float32 bit patterns too.)"""
    from eden_pipe.io.half_float import half_planes

    rng = np.random.default_rng(8)
    bits = np.concatenate(
        [
            rng.integers(0, 2**32, 200_000, dtype=np.uint64).astype(np.uint32),
            np.arange(0x32F00000, 0x33100000, 37, dtype=np.uint32),  # around 2^-25 (half the least subnormal)
            np.arange(0x387F0000, 0x38810000, 7, dtype=np.uint32),  # around the least normal half
            np.arange(0x477FE000, 0x47802000, 1, dtype=np.uint32),  # 65504 .. 65536
            np.array([0, 0x80000000, 0x7F800000, 0xFF800000, 0x7F800001, 0x7FC00000, 0xFFFFFFFF], np.uint32),
        ]
    )
    bits = np.concatenate([bits, bits | np.uint32(0x80000000)])[: 3 * (len(bits) * 2 // 3)]
    values = bits.view(np.float32).reshape(-1, 1, 3)  # (H, 1, 3): three channel planes
    with np.errstate(all="ignore"):
        expected = np.where(np.isfinite(values), np.clip(values, -HALF_MAX, HALF_MAX), values).astype(np.float16)
    got = half_planes(values)
    assert got.shape == (3, len(values), 1) and got.dtype == np.float16
    assert np.array_equal(np.moveaxis(got, 0, 2).view(np.uint16), expected.view(np.uint16))


def test_halves_widen_to_numpys_float32_bits():
    """The compiled half -> float32 conversion gives numpy's bits for every one of the 65,536 half
    bit patterns (subnormals, zeros, inf and NaN payloads), in any shape and stride (``read_exr``
    and the bake's tables read halves through it)."""
    from eden_pipe.io.half_float import widen

    halves = np.arange(1 << 16, dtype=np.uint16).view(np.float16)
    with np.errstate(all="ignore"):
        expected = halves.astype(np.float32)
    got = widen(halves)
    assert got.dtype == np.float32 and np.array_equal(got.view(np.uint32), expected.view(np.uint32))
    grid = halves.reshape(256, 16, 16)[:, ::2, 1:]  # strided
    assert np.array_equal(widen(grid).view(np.uint32), expected.reshape(256, 16, 16)[:, ::2, 1:].view(np.uint32))
    assert widen(np.zeros((0, 3), np.float16)).shape == (0, 3)
