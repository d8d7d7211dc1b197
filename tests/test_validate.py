"""eden_pipe.tools.validate on a fresh tiny dataset and on corrupted copies of it."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from eden_pipe.tools import validate
from tests.tools_dataset import copy_dataset, manifest, tiny_dataset, write_metadata


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return tiny_dataset(tmp_path_factory)


@pytest.fixture
def copy(dataset, tmp_path):
    return copy_dataset(dataset, tmp_path / "ds")


def failures(report):
    return {(path, check) for path, check, _ in report.failures}


def test_fresh_dataset_passes_every_check(copy):
    report = validate.check_dataset(copy)
    assert report.ok, report.lines()
    assert report.rows == 20 and not report.warnings
    for check in ("file", "instance", "flow", "compose", "rgb"):
        assert report.checks.get(check, 0) > 0, check
    assert report.checks["flow"] == 30  # 3 forward + 3 backward per camera


def test_fresh_dataset_passes_against_its_published_metadata(dataset):
    report = validate.check_dataset(dataset)
    assert report.ok, report.lines()
    assert report.checks.get("instance") and report.checks.get("flow") and report.checks.get("file")


def test_missing_metadata_skips_the_instance_check_with_a_warning(copy):
    for scene in copy.glob("*/scene.json"):
        scene.unlink()
    report = validate.check_dataset(copy)
    assert report.ok, report.lines()
    assert any("no metadata" in w for w in report.warnings)
    assert "instance" not in report.checks


def test_load_instance_classes(copy, tmp_path):
    rows = manifest(copy)
    garden, lighting = rows.garden[0], rows.lighting[0]
    classes = validate.load_instance_classes(copy, garden, lighting)
    assert classes and all(isinstance(k, int) and 0 <= v < 10 for k, v in classes.items())
    assert validate.load_instance_classes(tmp_path, garden, lighting) is None


def test_cli_exit_status_and_summary(copy):
    ok = subprocess.run([sys.executable, "-m", "eden_pipe.tools.validate", str(copy), "--sample", "5", "--seed", "3"],
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert "5 rows" in ok.stdout and ok.stdout.strip().endswith("OK")
    rel = manifest(copy).semantic[0]
    (copy / rel).write_bytes((copy / rel).read_bytes()[:100])
    bad = subprocess.run([sys.executable, "-m", "eden_pipe.tools.validate", str(copy), "--no-progress"],
                         capture_output=True, text=True)
    assert bad.returncode == 1
    fail_lines = [line for line in bad.stdout.splitlines() if line.startswith("FAIL ")]
    assert fail_lines == [f"FAIL {rel}: decode: " + fail_lines[0].split(": decode: ")[1]]
    assert bad.stdout.strip().endswith("FAILED")


@pytest.mark.parametrize("column", ["rgb_left", "semantic", "instance", "depth", "normal", "occ_fwd"])
def test_truncated_png_is_named(copy, column):
    rel = manifest(copy)[column][5]
    data = (copy / rel).read_bytes()
    (copy / rel).write_bytes(data[: len(data) // 2])
    report = validate.check_dataset(copy)
    assert (rel, "decode") in failures(report), report.lines()
    assert {p for p, _ in failures(report)} == {rel}


def test_swapped_flow_files_are_named(copy):
    rows = manifest(copy)
    a = rows[(rows.frame == 0) & (rows.camera == 2)].flow_fwd.iloc[0]
    b = rows[(rows.frame == 1) & (rows.camera == 2)].flow_fwd.iloc[0]
    da, db = (copy / a).read_bytes(), (copy / b).read_bytes()
    (copy / a).write_bytes(db)
    (copy / b).write_bytes(da)
    report = validate.check_dataset(copy)
    assert failures(report) == {(a, "flow-reprojection"), (b, "flow-reprojection")}, report.lines()


def test_flow_of_another_camera_is_named(copy):
    rows = manifest(copy)
    a = rows[(rows.frame == 1) & (rows.camera == 0)].flow_bwd.iloc[0]
    b = rows[(rows.frame == 1) & (rows.camera == 3)].flow_bwd.iloc[0]
    (copy / a).write_bytes((copy / b).read_bytes())
    report = validate.check_dataset(copy)
    assert (a, "flow-reprojection") in failures(report), report.lines()


def test_instance_id_missing_from_metadata_is_named(copy):
    rows = manifest(copy)
    classes = write_metadata(copy)
    # An id seen in some but not all instance images.
    from eden_pipe.io.formats import read_modality

    seen = {rel: set(np.unique(read_modality(copy / rel, "instance")).tolist()) - {0} for rel in rows.instance}
    victim = max(classes, key=lambda i: sum(i in s for s in seen.values()))
    write_metadata(copy, drop=(victim,))
    report = validate.check_dataset(copy)
    expected = {(rel, "instance-metadata") for rel, ids in seen.items() if victim in ids}
    assert expected and failures(report) == expected, report.lines()
    assert all(f"[{victim}]" in detail for _, _, detail in report.failures)


def test_instance_of_the_wrong_class_is_named(copy):
    from eden_pipe.io.formats import read_modality

    classes = write_metadata(copy)
    seen = set().union(*(np.unique(read_modality(copy / rel, "instance")).tolist() for rel in manifest(copy).instance))
    victim = sorted(seen & set(classes))[0]  # an instance the images show
    write_metadata(copy, override={victim: (classes[victim] + 1) % 10})
    report = validate.check_dataset(copy)
    assert report.failures and {c for _, c in failures(report)} == {"instance-class"}, report.lines()


@pytest.mark.parametrize("column", ["albedo", "shading", "rgb_linear"])
def test_half_written_float_layer_is_named(copy, column):
    rel = manifest(copy)[column][7]
    data = (copy / rel).read_bytes()
    (copy / rel).write_bytes(data[: len(data) // 2])
    report = validate.check_dataset(copy)
    assert failures(report) == {(rel, "decode")}, report.lines()


def test_half_written_exr_layer_is_named(copy):
    exr = sorted(p for p in copy.rglob("*.exr"))
    if not exr:
        pytest.skip("this dataset writes no OpenEXR layers yet")
    rel = str(exr[0].relative_to(copy))
    data = exr[0].read_bytes()
    exr[0].write_bytes(data[: len(data) // 2])
    report = validate.check_dataset(copy)
    assert {p for p, _ in failures(report)} == {rel}, report.lines()


def test_broken_composition_and_values_are_named(copy):
    rows = manifest(copy)
    glossy, normal = rows.glossy[3], rows.normal[4]
    from eden_pipe.io.formats import read_modality
    from eden_pipe.modalities import write_column

    g = read_modality(copy / glossy, "glossy")
    g[10:20, 10:20] += 0.5
    write_column(copy / glossy, "glossy", g)
    import cv2

    n = cv2.imread(str(copy / normal), cv2.IMREAD_UNCHANGED)
    n[0:5, 0:5] = 40000  # (0.22, 0.22, 0.22): not unit length
    cv2.imwrite(str(copy / normal), n)
    report = validate.check_dataset(copy)
    assert failures(report) == {(rows.rgb_linear[3], "image-formation"), (normal, "range")}, report.lines()


def test_missing_file_and_wrong_shape_are_named(copy):
    rows = manifest(copy)
    (copy / rows.occ_bwd[6]).unlink()
    import cv2

    depth = rows.depth[2]
    img = cv2.imread(str(copy / depth), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(copy / depth), img[:-1])
    report = validate.check_dataset(copy)
    assert failures(report) == {(rows.occ_bwd[6], "exists"), (depth, "shape")}, report.lines()


def test_sample_checks_n_rows(copy):
    report = validate.check_dataset(copy, sample=4, seed=1)
    assert report.ok and report.rows == 4


def test_occlusion_mask_that_misses_out_of_view_pixels_is_named(copy):
    rows = manifest(copy)
    row = rows[(rows.frame == 1) & (rows.camera == 1)].iloc[0]
    import cv2

    cv2.imwrite(str(copy / row.occ_fwd), np.zeros((72, 96), np.uint8))
    report = validate.check_dataset(copy)
    assert failures(report) == {(row.flow_fwd, "occlusion")}, report.lines()
    assert row.occ_fwd in report.failures[0][2]
