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
    raw = formats.read_raw(tmp_path / "d.png")
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
    raw = formats.read_raw(tmp_path / "n.png")[..., ::-1]
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


# ------------------------------------------------------------- modality table
from eden_pipe import modalities  # noqa: E402
from eden_pipe.io import layout  # noqa: E402

# Today's literal lists, locked: the manifest bytes depend on PATH_COLUMNS' order.
PATH_COLUMNS_LOCKED = [
    "rgb_left",
    "rgb_right",
    "semantic",
    "instance",
    "depth",
    "depth_right",
    "normal",
    "flow_fwd",
    "flow_bwd",
    "occ_fwd",
    "occ_bwd",
    "albedo",
    "shading",
    "translucency",
    "glossy",
    "background",
    "rgb_linear",
    "dynamic",
    "motion_fwd",
    "motion_bwd",
]
DEFAULT_LOCKED = ("rgb", "semantic", "instance", "depth", "normal", "flow", "albedo", "shading", "translucency")
MODALITIES_LOCKED = DEFAULT_LOCKED + ("glossy", "background", "rgb_linear", "dynamic")
WIND_COLUMNS_LOCKED = ["dynamic", "motion_fwd", "motion_bwd"]  # in a manifest only when written


def sample_for(column: str, rng) -> np.ndarray:
    """An array that the column's format stores exactly."""
    shape = (5, 7)
    if column.startswith("rgb_") and column != "rgb_linear":
        return rng.integers(0, 256, shape + (3,), dtype=np.uint8)
    if column == "semantic":
        return rng.integers(0, 10, shape, dtype=np.uint8)
    if column == "instance":
        return rng.integers(0, 65536, shape, dtype=np.uint16)
    if column.startswith("depth"):
        return np.where(rng.random(shape) < 0.2, np.inf, rng.integers(1, 65535, shape) / 1000.0).astype(np.float32)
    if column == "normal":
        n = rng.normal(size=shape + (3,))
        return (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    if column.startswith("flow"):
        return rng.normal(size=shape + (2,)).astype(np.float32)
    if modalities.COLUMNS[column].values == "binary":  # occlusion and dynamic masks
        return rng.integers(0, 2, shape, dtype=np.uint8)
    if modalities.COLUMNS[column].values == "displacement":  # signed metres
        return rng.normal(0.0, 0.01, shape + (3,)).astype(np.float32)
    return rng.random(shape + (3,)).astype(np.float32)


@pytest.mark.parametrize("depth_format,storage", [("png16", "compact"), ("float", "exact"), ("png16", "exact")])
def test_every_modality_column_round_trips(tmp_path, depth_format, storage):
    rng = np.random.default_rng(4)
    options = modalities.WriteOptions(depth_format=depth_format, storage=storage, compression=3)
    files = layout.frame_files(0, 7, modalities.MODALITIES, options, has_next=True, has_prev=True)
    assert list(files) == modalities.PATH_COLUMNS
    for column, rel in files.items():
        data = sample_for(column, rng)
        modalities.write_column(tmp_path / rel, column, data, options)
        back = formats.read_modality(tmp_path / rel, column)
        assert back.shape == data.shape, column
        if column == "normal":
            assert np.allclose(back, data, atol=2e-5), column
        elif column.startswith("depth"):
            assert np.allclose(back, data, rtol=0, atol=1e-6) and np.array_equal(np.isinf(back), np.isinf(data)), column
        elif storage == "compact" and column.startswith("flow"):  # KITTI PNG: 1/64 px steps
            assert back.dtype == np.float32 and np.abs(back - data).max() <= 1 / 128 + 1e-6, column
        elif storage == "compact" and modalities.COLUMNS[column].chosen_by == "storage":  # half-float EXR
            assert back.dtype == np.float32 and np.all(np.abs(back - data) <= 2.0**-11 * np.abs(data) + 1e-7), column
        else:
            assert back.dtype == data.dtype and np.array_equal(back, data), column


def test_derived_lists_equal_the_former_literals():
    from eden_pipe import config
    from eden_pipe.stages import manifest

    assert tuple(modalities.MODALITIES) == MODALITIES_LOCKED == tuple(config.MODALITIES)
    assert tuple(modalities.DEFAULT_MODALITIES) == DEFAULT_LOCKED == tuple(config.DEFAULT_MODALITIES)
    assert modalities.PATH_COLUMNS == PATH_COLUMNS_LOCKED == manifest.PATH_COLUMNS
    still = [c for c in PATH_COLUMNS_LOCKED if c not in WIND_COLUMNS_LOCKED]
    assert manifest.columns() == manifest.INFO_COLUMNS + still
    assert manifest.columns(["motion_fwd"]) == manifest.INFO_COLUMNS + still + ["motion_fwd"]


def test_frame_files_layout_and_extensions():
    exact = modalities.WriteOptions(storage="exact")
    files = layout.frame_files(2, 13, {"rgb", "depth", "flow", "albedo"}, exact, has_next=True, has_prev=False)
    assert files == {
        "rgb_left": "cam2/rgb_left/00013.png",
        "rgb_right": "cam2/rgb_right/00013.png",
        "depth": "cam2/depth/00013.png",
        "depth_right": "cam2/depth_right/00013.png",
        "flow_fwd": "cam2/flow_fwd/00013.flo",
        "occ_fwd": "cam2/occ_fwd/00013.png",
        "albedo": "cam2/albedo/00013.npy",
    }
    compact = layout.frame_files(2, 13, {"flow", "albedo"}, modalities.WriteOptions(), has_next=True, has_prev=False)
    assert compact == {
        "flow_fwd": "cam2/flow_fwd/00013.png",
        "occ_fwd": "cam2/occ_fwd/00013.png",
        "albedo": "cam2/albedo/00013.exr",
    }
    floats = modalities.WriteOptions(depth_format="float")
    assert layout.frame_files(0, 0, {"depth"}, floats, False, False)["depth"] == "cam0/depth/00000.npy"
    assert modalities.camera_passes({"rgb", "depth", "semantic"}, "right") == {"rgb", "depth"}
    assert modalities.camera_passes({"semantic", "flow"}, "right") == set()


def test_unknown_column_is_a_clear_error(tmp_path):
    with pytest.raises(KeyError, match="unknown modality column"):
        formats.read_modality(tmp_path / "x.png", "colour")
