"""The PNG and OpenEXR encoders (io.encoders): every setting decodes, through readers that share no code
with them (OpenCV's libpng, Pillow, the OpenEXR library), to exactly the encoded array."""

from __future__ import annotations

import io

import cv2
import numpy as np
import OpenEXR
import pytest
from PIL import Image

from eden_pipe.io import encoders, formats, kitti
from eden_pipe.io.exr import read_exr, write_exr


def _image(rng, shape, dtype):
    """Noise, runs and smooth ramps: content for each filter's and deflate's paths."""
    top = np.iinfo(dtype).max
    a = rng.integers(0, top + 1, shape, dtype=dtype)
    a[: shape[0] // 3] = 0  # a long run (sky)
    ramp = np.linspace(0, top, shape[1]).astype(dtype)
    a[shape[0] // 3 : 2 * shape[0] // 3] = ramp[None, :, None] if a.ndim == 3 else ramp[None, :]
    return a


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
@pytest.mark.parametrize("channels", [1, 3, 4])
def test_png_settings_decode_exactly(dtype, channels):
    rng = np.random.default_rng(channels)
    shape = (37, 53) if channels == 1 else (37, 53, channels)
    a = _image(rng, shape, dtype)
    in_bgr = a if channels == 1 else a[..., [2, 1, 0, 3][:channels]]
    for row_filter in (encoders.FILTER_NONE, encoders.FILTER_SUB, encoders.FILTER_UP):
        for level in range(10):
            data = encoders.png_encode(a, level, row_filter)
            by_opencv = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
            assert by_opencv.dtype == dtype and np.array_equal(by_opencv, in_bgr), (row_filter, level)
            if dtype == np.uint8:
                assert np.array_equal(np.asarray(Image.open(io.BytesIO(data))), a), (row_filter, level)


def test_png_palette_and_bad_inputs():
    rng = np.random.default_rng(1)
    palette = rng.integers(0, 256, (256, 3), dtype=np.uint8)
    ids = rng.integers(0, 12, (30, 41), dtype=np.uint8)
    with Image.open(io.BytesIO(encoders.png_encode(ids, 1, encoders.FILTER_NONE, palette=palette))) as img:
        assert img.mode == "P"
        assert np.array_equal(np.asarray(img), ids)
        assert np.array_equal(np.asarray(img.getpalette(), np.uint8).reshape(-1, 3), palette)
    with pytest.raises(ValueError):
        encoders.png_encode(ids.astype(np.float32), 1)
    with pytest.raises(ValueError):
        encoders.png_encode(ids, 1, row_filter=4)
    with pytest.raises(ValueError):
        encoders.deflate(b"x", 10)


def test_deflate_levels_are_zlib_streams(monkeypatch):
    """ISA-L's levels and zlib's, and zlib's alone where ``isal`` is missing."""
    import zlib

    data = np.random.default_rng(2).integers(0, 4, 100_000, dtype=np.uint8).tobytes()
    for level in range(10):
        assert zlib.decompress(encoders.deflate(data, level)) == data
    monkeypatch.setattr(encoders, "_fast_compress", None)
    assert encoders.deflate(data, 1) == zlib.compress(data, 1)


def test_small_inputs_are_deflated_by_zlib_and_large_ones_by_isal():
    """Under ``SMALL_INPUT_BYTES`` the stream is zlib's, a function of the input alone (also for a
    numpy array's buffer); from it on, ISA-L's where it is installed."""
    import zlib

    isal_zlib = pytest.importorskip("isal.isal_zlib")
    rows = np.random.default_rng(3).integers(0, 4, (72, 97), dtype=np.uint8)  # a 96 x 72 label PNG's rows
    assert rows.nbytes < encoders.SMALL_INPUT_BYTES
    for level in (1, 2, 3):
        assert encoders.deflate(rows, level) == zlib.compress(rows.tobytes(), level)
    big = np.random.default_rng(4).integers(0, 4, encoders.SMALL_INPUT_BYTES, dtype=np.uint8)
    assert encoders.deflate(big, 1) == isal_zlib.compress(big.tobytes(), 1)


def _library_planes(path):
    with OpenEXR.File(str(path), separate_channels=True) as exr:
        return exr.header()["compression"], {n: c.pixels for n, c in exr.channels().items()}


@pytest.mark.parametrize("height", [1, 15, 16, 33, 48])
def test_exr_settings_decode_exactly(tmp_path, height):
    """Every compression and level, half and float, blocks that deflate helps and blocks stored raw."""
    rng = np.random.default_rng(height)
    for dtype in (np.float16, np.float32):
        planes = rng.standard_normal((3, height, 29)).astype(dtype)
        planes[:, : height // 2] = 0  # compressible rows beside incompressible noise
        for compression in (encoders.EXR_NO_COMPRESSION, encoders.EXR_ZIPS, encoders.EXR_ZIP):
            for level in (0, 1, 3, 6):
                path = tmp_path / "x.exr"
                path.write_bytes(encoders.exr_encode(planes, ("R", "G", "B"), compression, level))
                stored, got = _library_planes(path)
                assert stored == OpenEXR.Compression(compression)
                for i, name in enumerate("RGB"):
                    assert got[name].dtype == dtype
                    assert np.array_equal(got[name].view(np.uint8), planes[i].view(np.uint8)), (dtype, compression)


def test_exr_channel_names_sorted_in_the_file(tmp_path):
    planes = np.arange(2 * 5 * 7, dtype=np.float32).reshape(2, 5, 7).astype(np.float16)
    (tmp_path / "uv.exr").write_bytes(encoders.exr_encode(planes, ("v", "u")))
    _, got = _library_planes(tmp_path / "uv.exr")
    assert np.array_equal(got["v"], planes[0]) and np.array_equal(got["u"], planes[1])


def test_writers_store_what_the_former_encoders_stored(tmp_path):
    """Each column writer's file decodes to the array OpenCV's and OpenEXR's encoders were given
    before (the same pixels; only the compressed bytes differ)."""
    rng = np.random.default_rng(5)
    rgb = _image(rng, (24, 40, 3), np.uint8)
    formats.write_rgb(tmp_path / "rgb.png", rgb)
    assert np.array_equal(formats.read_raw(tmp_path / "rgb.png"), rgb[..., ::-1])
    normal = rng.standard_normal((24, 40, 3)).astype(np.float32)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    normal[:4] = 0
    formats.write_normal(tmp_path / "n.png", normal)
    enc = np.round((np.clip(normal[..., ::-1], -1, 1) + np.float32(1)) * np.float32(0.5 * 65535)) * np.any(
        normal != 0, axis=-1, keepdims=True
    )
    assert np.array_equal(formats.read_raw(tmp_path / "n.png"), enc.astype(np.uint16))
    flow = rng.uniform(-600, 600, (24, 40, 2)).astype(np.float32)
    kitti.write_kitti_flow(tmp_path / "f.png", flow)
    raw = cv2.imread(str(tmp_path / "f.png"), cv2.IMREAD_UNCHANGED)  # BGR: valid, v, u
    ok = np.all((flow >= kitti.FLOW_MIN) & (flow <= kitti.FLOW_MAX), axis=-1)
    assert np.array_equal(raw[..., 0] == 1, ok)
    assert np.array_equal(raw[..., 2][ok], (np.rint(flow[..., 0] * 64) + 2**15)[ok].astype(np.uint16))
    layer = np.abs(rng.standard_normal((24, 40, 3))).astype(np.float32)
    write_exr(tmp_path / "l.exr", layer)
    assert np.array_equal(read_exr(tmp_path / "l.exr"), layer.astype(np.float16).astype(np.float32))


def test_quantisers_equal_the_numpy_formulas():
    """The compiled normal and KITTI flow quantisers against the numpy formulas they replaced, on
    rounding ties, range edges, signed zeros, sky pixels and non-finite flow."""
    from eden_pipe.io.quantise import kitti_flow_codes, normal_codes

    rng = np.random.default_rng(7)
    n = rng.uniform(-1.2, 1.2, (64, 80, 3)).astype(np.float32)
    ties = (np.arange(-200, 200, dtype=np.float32) + np.float32(0.5)) / np.float32(32767.5) - np.float32(1.0)
    n.reshape(-1)[: ties.size] = np.clip(ties, -1, 1)
    n[0, :4] = [[0, 0, 0], [-0.0, 0, 0], [0, 0, 1], [1, -1, 0]]
    n[1, :4] = [[1.0000001, -1.0000001, 0.5], [-0.0, -0.0, -0.0], [1e-30, 0, 0], [0.99999994, -0.99999994, 0]]
    valid = (n[..., 0] != 0) | (n[..., 1] != 0) | (n[..., 2] != 0)
    expected = np.round((np.clip(n, -1, 1) + np.float32(1.0)) * np.float32(0.5 * 65535.0)) * valid[..., None]
    assert np.array_equal(normal_codes(n), expected.astype(np.uint16))
    assert np.array_equal(normal_codes(n[:, ::-1]), expected[:, ::-1].astype(np.uint16))  # any strides

    flow = rng.uniform(-600, 600, (64, 80, 2)).astype(np.float32)
    flow.reshape(-1)[:2000] = (np.arange(-1000, 1000, dtype=np.float32) + np.float32(0.5)) / np.float32(64)
    flow[0, :8, 0] = [np.nan, np.inf, -np.inf, -512.0, 511.984375, 511.99, -512.01, -0.0]
    mask = rng.random((64, 80)) < 0.9
    pixels = np.rint(np.nan_to_num(flow[..., ::-1], posinf=0, neginf=0) * 4).astype(np.int32)  # integer flow
    for f in (flow, flow.astype(np.float64), pixels):
        g = f if f.dtype == np.float32 else f.astype(np.float64)
        ok = mask & np.all(np.isfinite(g) & (g >= kitti.FLOW_MIN) & (g <= kitti.FLOW_MAX), axis=-1)
        enc = np.rint(np.where(ok[..., None], g, 0) * kitti.FLOW_SCALE) + kitti.FLOW_OFFSET
        expected = np.stack([enc[..., 0], enc[..., 1], ok], -1).astype(np.uint16)
        got = kitti_flow_codes(f, mask, kitti.FLOW_MIN, kitti.FLOW_MAX, kitti.FLOW_SCALE, kitti.FLOW_OFFSET)
        assert np.array_equal(got, expected), f.dtype


def test_srgb_codes_equal_the_colour_formula(monkeypatch):
    """The rgb PNG's 8-bit sRGB codes from the table of the formula's steps against the formula
    (``colour.srgb_to_uint8``) itself: random float32 bit patterns of every class, every step and
    the three floats either side of it, the ends of [0, 1], zeros, infinities and NaN, an image
    with strides, and float64 input (the formula's own path). Checked once over all 2^32 float32
    bit patterns too."""
    from eden_pipe.colour import linear_to_srgb, srgb_to_uint8
    from eden_pipe.io.quantise import srgb8_codes, srgb8_tables

    steps, buckets, nan_code = srgb8_tables()
    assert steps.shape == (257,) and buckets.shape == (16257,) and steps[0] == 0
    around = steps[1:256].astype(np.int64)[:, None] + np.arange(-3, 4)
    # Each step is where the code first reaches its level, by the formula, in float32.
    below, at = around[:, 2].astype(np.uint32).view(np.float32), steps[1:256].view(np.float32)
    assert np.array_equal(srgb_to_uint8(at).astype(int), np.arange(1, 256))
    assert np.array_equal(srgb_to_uint8(below).astype(int), np.arange(0, 255))
    assert 0.0031308 > at[7] and np.float32(1.0) >= at[-1] > np.float32(0.99)  # the linear toe, the top
    assert 255 * linear_to_srgb(np.float32(at[99])) >= np.float32(99.5) > 255 * linear_to_srgb(below[99])

    rng = np.random.default_rng(11)
    bits = np.concatenate(
        [
            rng.integers(0, 2**32, 400_000, dtype=np.uint64).astype(np.uint32),
            rng.integers(0, 0x3F800001, 400_000, dtype=np.uint64).astype(np.uint32),  # [0, 1]
            around.reshape(-1).astype(np.uint32),
            np.array([0, 1, 0x3F7FFFFF, 0x3F800000, 0x3F800001, 0x7F7FFFFF, 0x7F800000, 0x7F800001], np.uint32),
            np.array([0x7FC00000, 0x7FFFFFFF, 0x80000000, 0x80000001, 0xBF800000, 0xFF800000, 0xFFC00000], np.uint32),
        ]
    )
    values = bits.view(np.float32)
    with np.errstate(invalid="ignore"):
        expected = srgb_to_uint8(values)
    assert np.array_equal(srgb8_codes(values), expected)
    assert srgb8_codes(np.array([np.nan], np.float32))[0] == nan_code

    image = rng.uniform(-0.1, 1.3, (48, 64, 3)).astype(np.float32) ** 3
    assert np.array_equal(srgb8_codes(image[::-1, ::2]), srgb_to_uint8(image[::-1, ::2]))  # any strides
    wide = image.astype(np.float64) * 1.0000001
    assert np.array_equal(srgb8_codes(wide), srgb_to_uint8(wide))

    # Where the tables cannot be made (a formula that does not rise one step at a time), the formula.
    from eden_pipe.io import quantise

    monkeypatch.setattr(quantise, "srgb8_tables", lambda: None)
    assert np.array_equal(srgb8_codes(image), srgb_to_uint8(image))
