"""Round trips through every writer and reader, with exact values."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.io import formats


def test_rgb_round_trip(tmp_path):
    rgb = np.random.default_rng(0).integers(0, 256, (7, 9, 3), dtype=np.uint8)
    formats.write_rgb(tmp_path / "a.png", rgb)
    assert np.array_equal(formats.read_rgb(tmp_path / "a.png"), rgb)


def test_semantic_palette_round_trip(tmp_path):
    ids = np.arange(10, dtype=np.uint8).repeat(3).reshape(5, 6)
    formats.write_semantic(tmp_path / "s.png", ids)
    assert np.array_equal(formats.read_semantic(tmp_path / "s.png"), ids)
    assert np.array_equal(formats.read_palette(tmp_path / "s.png")[:10], labels.COLORS)


def test_instance_uint16_round_trip(tmp_path):
    ids = np.array([[0, 1, 65535], [300, 2, 7]], np.uint16)
    formats.write_instance(tmp_path / "i.png", ids)
    out = formats.read_instance(tmp_path / "i.png")
    assert out.dtype == np.uint16 and np.array_equal(out, ids)


def test_depth_png16_is_millimetres_and_sky_is_zero(tmp_path):
    depth = np.array([[1.2344, np.inf], [65.535, 70.0]])
    formats.write_depth(tmp_path / "d.png", depth)
    raw = formats._imread(tmp_path / "d.png")
    assert raw.dtype == np.uint16 and raw.tolist() == [[1234, 0], [65535, 0]]
    back = formats.read_depth(tmp_path / "d.png")
    assert back[0, 0] == pytest.approx(1.234) and np.isinf(back[0, 1]) and np.isinf(back[1, 1])


def test_depth_float_round_trip(tmp_path):
    depth = np.array([[1.2344, np.inf]], np.float32)
    formats.write_depth(tmp_path / "d.npy", depth, fmt="float")
    assert np.array_equal(formats.read_depth(tmp_path / "d.npy"), depth)


def test_normal_encoding(tmp_path):
    n = np.array([[[0.0, 0.0, -1.0], [0.6, -0.8, 0.0], [0.0, 0.0, 0.0]]])
    formats.write_normal(tmp_path / "n.png", n)
    raw = formats._imread(tmp_path / "n.png")[..., ::-1]
    assert raw[0, 0].tolist() == [32768, 32768, 0]  # (n+1)/2*65535 rounded, RGB = xyz
    assert raw[0, 2].tolist() == [0, 0, 0]
    back = formats.read_normal(tmp_path / "n.png")
    assert np.allclose(back[0, :2], n[0, :2], atol=2e-5) and np.all(back[0, 2] == 0)


def test_flo_round_trip_and_header(tmp_path):
    flow = np.random.default_rng(1).normal(size=(4, 5, 2)).astype(np.float32)
    formats.write_flo(tmp_path / "f.flo", flow)
    raw = (tmp_path / "f.flo").read_bytes()
    assert raw[:4] == b"PIEH" and np.frombuffer(raw[4:12], np.int32).tolist() == [5, 4]
    assert np.array_equal(formats.read_flo(tmp_path / "f.flo"), flow)


def test_float_layers_are_lossless(tmp_path):
    a = np.random.default_rng(2).random((3, 4, 3)).astype(np.float32)
    formats.write_float(tmp_path / "a.npy", a)
    assert np.array_equal(formats.read_modality(tmp_path / "a.npy", "albedo"), a)


def test_no_temporary_files_left(tmp_path):
    formats.write_mask(tmp_path / "m.png", np.ones((2, 2), np.uint8))
    assert [p.name for p in tmp_path.iterdir()] == ["m.png"]
