"""The modality table carries each column's whole array contract, and everything reads it from there: a layer
added in a test is rendered, written, listed in the manifest and dataset.json, validated and loaded."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eden_pipe import modalities
from eden_pipe.io import layout
from tests.conftest import TINY, make_cfg

H, W = 9, 13


def contract_sample(column: modalities.Column, rng) -> np.ndarray:
    """Values inside the column's domain, continuous where the column is float (not exactly storable)."""
    shape = column.shape(H, W)
    if column.dtype != "float":
        top = {"class_id": 10, "binary": 2}.get(column.values, 256 if column.dtype == "uint8" else 65536)
        return rng.integers(0, top, shape).astype(np.dtype(column.dtype))
    if column.values == "depth":
        return np.where(rng.random(shape) < 0.2, np.inf, rng.uniform(0.1, 60.0, shape)).astype(np.float32)
    if column.values == "unit_vector":
        n = rng.normal(size=shape)
        return (n / np.linalg.norm(n, axis=-1, keepdims=True)).astype(np.float32)
    if column.values == "flow":
        return rng.normal(scale=40.0, size=shape).astype(np.float32)
    return rng.exponential(0.3, shape).astype(np.float32) * (rng.random(shape) < 0.9)


@pytest.mark.parametrize("depth_format,storage", [("png16", "compact"), ("float", "exact")])
def test_every_column_meets_its_contract_and_declared_precision(tmp_path, depth_format, storage):
    rng = np.random.default_rng(11)
    options = modalities.WriteOptions(depth_format=depth_format, storage=storage)
    files = layout.frame_files(0, 3, modalities.MODALITIES, options, has_next=True, has_prev=True)
    for name, rel in files.items():
        column = modalities.COLUMNS[name]
        data = contract_sample(column, rng)
        column.write(tmp_path / rel, data, options)
        back = column.read(tmp_path / rel)
        assert column.problem(back, H, W) is None, name
        if column.dtype == "float":
            bound = column.file_format(options).error_bound(data)
            finite = np.isfinite(data)
            assert np.all(np.abs(back[finite] - data[finite]) <= bound[finite]), name
            assert np.array_equal(np.isinf(back), np.isinf(data)), name
            fmt = column.file_format(options)
            if fmt.step > 0 or fmt.relative > modalities.FLOAT32_RELATIVE:
                # the bound is tight: a lossy format declaring more error than it makes would hide real errors
                assert np.abs(back[finite] - data[finite]).max() > 0.1 * bound[finite].max(), name
        else:
            assert np.array_equal(back, data), name
        # a wrong shape and a wrong dtype break the contract, by name
        assert column.problem(back[:-1], H, W)[0] == "shape"
        other = np.zeros(back.shape, np.int32 if column.dtype == "float" else np.float32)
        assert column.problem(other, H, W)[0] == "dtype"


def test_value_domains_name_what_is_wrong():
    assert modalities.COLUMNS["semantic"].problem(np.full((2, 2), 12, np.uint8), 2, 2)[0] == "range"
    assert modalities.COLUMNS["occ_fwd"].problem(np.full((2, 2), 2, np.uint8), 2, 2)[0] == "range"
    assert modalities.COLUMNS["albedo"].problem(-np.ones((2, 2, 3), np.float32), 2, 2)[0] == "range"
    n = np.zeros((2, 2, 3), np.float32)
    n[0, 0] = (0.5, 0.5, 0.5)
    assert modalities.COLUMNS["normal"].problem(n, 2, 2)[0] == "range"
    assert modalities.COLUMNS["depth"].problem(np.full((2, 2), np.inf, np.float32), 2, 2) is None


def test_the_identity_and_the_shading_layers_come_from_the_roles():
    assert modalities.formation_identity() == (
        "rgb_linear = albedo*shading + translucency + glossy + background; rgb_left = sRGB(exposure * composite)"
    )
    from eden_pipe.render import shading

    assert set(shading.LAYERS) == {"albedo", "shading", "translucency", "glossy", "background"}


def test_a_contract_outside_the_domains_is_refused():
    bad = modalities.float_layer("toy_bad", "emission")
    with pytest.raises(ValueError, match="role='emission'; allowed: reflectance"):
        modalities.register(bad)
    with pytest.raises(ValueError, match="duplicate modality 'albedo'"):
        modalities.register(modalities.float_layer("albedo", "reflectance"))
    assert "toy_bad" not in modalities.MODALITIES


def _inverse_depth(view: dict) -> np.ndarray:
    depth = view["depth"]
    return np.where(np.isfinite(depth), 1.0 / depth, 0.0).astype(np.float32)


TOY = modalities.float_layer(
    "inverse_depth", None, default=False, channels=1, units="1/metres", derive=_inverse_depth, inputs=("depth",)
)


def test_a_layer_added_in_the_test_is_written_validated_and_loaded(tmp_path):
    from eden_pipe.pipeline import run_job
    from eden_pipe.tools import validate

    with modalities.registered(TOY):
        assert "inverse_depth" in modalities.MODALITIES and "inverse_depth" in modalities.PATH_COLUMNS
        cfg = make_cfg(
            tmp_path, TINY + ["camera.trajectory.frames=[2,2]", "render.modalities=[rgb,depth,inverse_depth]"]
        )
        run_job(cfg, echo=lambda *_: None)
        root = tmp_path / "dataset"
        rows = validate.read_manifest(root)
        assert len(rows) == 10 and all(rows.inverse_depth.str.endswith(".exr"))
        described = json.loads((root / "dataset.json").read_text())["columns"]["inverse_depth"]
        assert described["channels"] == 1 and described["units"] == "1/metres"

        # written: the file is the derived pass of the depth written beside it
        inv = modalities.read_modality(root / rows.inverse_depth[0], "inverse_depth")
        depth = modalities.read_modality(root / rows.depth[0], "depth")
        finite = np.isfinite(depth)
        assert inv.shape == (72, 96) and np.allclose(inv[finite], 1 / depth[finite], rtol=2e-3, atol=1e-6)

        # validated: its contract is checked, and a broken file is named
        report = validate.check_dataset(root)
        assert report.ok, report.lines()
        assert report.checks["file"] == 10 * 5  # rgb_left, rgb_right, depth, depth_right and the toy layer
        modalities.write_column(root / rows.inverse_depth[1], "inverse_depth", -np.ones((72, 96), np.float32))
        bad = validate.check_dataset(root)
        assert {(p, c) for p, c, _ in bad.failures} == {(rows.inverse_depth[1], "range")}, bad.lines()

        # loaded: the loader offers it under its name, as a (1, H, W) float tensor (the loader is torch's)
        pytest.importorskip("torch", reason="the loader is a torch Dataset: pip install -e '.[test,test-torch]'")
        from eden_pipe.data.dataset import EdenDataset

        item = EdenDataset(root, modalities=("inverse_depth", "depth"))[0]
        assert tuple(item["inverse_depth"].shape) == (1, 72, 96)
    assert "inverse_depth" not in modalities.MODALITIES and "inverse_depth" not in modalities.PATH_COLUMNS


def test_absent_layers_and_checks_not_run_are_reported(tmp_path_factory, tmp_path):
    from eden_pipe.tools import validate
    from tests.tools_dataset import copy_dataset, manifest, tiny_dataset

    root = copy_dataset(tiny_dataset(tmp_path_factory), tmp_path / "ds")
    rows = manifest(root)
    rows["glossy"] = ""
    rows.to_csv(root / "manifest.csv", index=False)
    report = validate.check_dataset(root)
    assert report.ok, report.lines()
    assert report.absent == ["glossy"]
    assert report.not_run == {("compose", "glossy not readable or not written"): 20}
    assert report.checks["rgb"] == 20  # the composite column is there: the PNG is still checked
    lines = report.lines()
    assert "not written: glossy (render.modalities; their checks cannot run)" in lines
    assert "not run: compose on 20 rows: glossy not readable or not written" in lines

    rows["rgb_linear"] = ""
    rows.to_csv(root / "manifest.csv", index=False)
    report = validate.check_dataset(root)
    assert report.ok, report.lines()
    assert report.absent == ["glossy", "rgb_linear"] and report.checks["rgb"] == 20
    assert (
        report.not_run[
            (
                "rgb upper bound",
                "glossy not written: they only add light, so the PNG is checked from below where they may be non-zero",
            )
        ]
        == 20
    )

    # from below, the layers still catch a wrong one: shading of another frame
    from eden_pipe.modalities import read_modality, write_column

    victim = rows.shading[3]
    write_column(root / victim, "shading", read_modality(root / rows.shading[8], "shading"))
    bad = validate.check_dataset(root)
    assert {(p, c) for p, c, _ in bad.failures} == {(rows.rgb_left[3], "rgb-srgb")}, bad.lines()
