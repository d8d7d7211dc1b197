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


def test_a_job_cut_short_ends_its_sequence_and_validates(tmp_path_factory, tmp_path):
    """``render.max_frames=2``: the sequence ends at frame 1, which has no forward flow (its partner
    image is not in the dataset), and the dataset validates. Every file it does write is the full
    job's, byte for byte; the space estimate counts the same files."""
    from eden_pipe.config import to_config
    from eden_pipe.pipeline import run_job
    from eden_pipe.preflight import job_progress, row_bytes
    from tests.conftest import TINY, make_cfg
    from tests.tiny_dataset import ALL_MODALITIES, tiny_root

    root = tiny_root(tmp_path_factory)  # its stages: the same scene, trajectory and bake
    cfg = make_cfg(root, [*TINY, ALL_MODALITIES, "render.max_frames=2", f"paths.dataset={tmp_path / 'short'}"])
    frames, todo, _ = job_progress(to_config(cfg))
    assert frames == 2 and todo == [0, 1]
    run_job(cfg, echo=lambda *_: None)
    short, full = manifest(tmp_path / "short"), manifest(root / "dataset")
    assert sorted(set(short.frame)) == [0, 1] and len(short) == 10
    assert (short[short.frame == 1].flow_fwd == "").all() and (short[short.frame == 1].occ_fwd == "").all()
    assert (short[short.frame == 0].flow_fwd != "").all() and (short[short.frame == 1].flow_bwd != "").all()
    assert (full[full.frame == 1].flow_fwd != "").all()
    report = validate.check_dataset(tmp_path / "short")
    assert report.ok, report.lines()
    assert report.checks["flow"] == 10  # frame 0 forward, frame 1 backward, 5 cameras
    written = [rel for col in short.columns for rel in short[col] if isinstance(rel, str) and "/" in rel]
    assert len(written) > 100
    for rel in written:
        assert (tmp_path / "short" / rel).read_bytes() == (root / "dataset" / rel).read_bytes(), rel
    # The bytes the preflight reserves per row follow the same rule (no forward flow at the end).
    assert row_bytes(to_config(cfg), has_next=False) < row_bytes(to_config(cfg))


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
    ok = subprocess.run(
        [sys.executable, "-m", "eden_pipe.tools.validate", str(copy), "--sample", "5", "--seed", "3"],
        capture_output=True,
        text=True,
    )
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert "5 rows" in ok.stdout and ok.stdout.strip().endswith("OK")
    rel = manifest(copy).semantic[0]
    (copy / rel).write_bytes((copy / rel).read_bytes()[:100])
    bad = subprocess.run(
        [sys.executable, "-m", "eden_pipe.tools.validate", str(copy), "--no-progress"], capture_output=True, text=True
    )
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


def test_flow_shifted_by_a_tenth_of_a_pixel_is_named(copy):
    from eden_pipe.modalities import read_modality, write_column

    rows = manifest(copy)
    rel = rows[(rows.frame == 1) & (rows.camera == 2)].flow_fwd.iloc[0]
    flow = read_modality(copy / rel, "flow_fwd")
    write_column(copy / rel, "flow_fwd", flow + np.float32(0.1))
    report = validate.check_dataset(copy)
    assert failures(report) == {(rel, "flow-reprojection")}, report.lines()


def test_flow_one_frame_late_is_named(copy):
    rows = manifest(copy)
    cam = rows[rows.camera == 4]
    late, right = cam[cam.frame == 2].flow_fwd.iloc[0], cam[cam.frame == 1].flow_fwd.iloc[0]
    (copy / right).write_bytes((copy / late).read_bytes())
    report = validate.check_dataset(copy)
    assert failures(report) == {(right, "flow-reprojection")}, report.lines()


def _close_up(offset_px: float = 0.0):
    """A camera 0.46-0.6 m from a slanted wall moving 6 cm: ~100 px of flow, written as KITTI PNG
    stores it, with the depth as png16 stores it (1 mm steps)."""
    from eden_pipe.modalities import COLUMNS

    h, w, f = 480, 640, 640.0
    K = np.array([[f, 0, w / 2], [0, f, h / 2], [0, 0, 1.0]])
    v, u = np.mgrid[0:h, 0:w]
    depth = (0.46 + 0.14 * u / w + 0.02 * v / h).astype(np.float32)
    pose0, pose1 = np.eye(4), np.eye(4)
    pose1[:3, 3] = (0.05, 0.01, 0.03)
    true_flow = validate.reprojection_flow(depth.astype(np.float64), K, pose0, pose1)
    written = np.round((true_flow + offset_px) * 64) / 64  # KITTI's 1/64 px steps
    stored_depth = np.round(depth * 1000) / 1000
    fmts = (COLUMNS["depth"].file_format(), COLUMNS["flow_fwd"].file_format())
    return written.astype(np.float32), stored_depth.astype(np.float32), K, pose0, pose1, fmts


def test_close_up_flow_is_judged_by_what_the_files_resolve():
    flow, depth, K, pose0, pose1, fmts = _close_up()
    expected = validate.reprojection_flow(depth, K, pose0, pose1)
    err = np.hypot(*np.moveaxis(flow - expected, -1, 0))
    assert np.median(err) > 0.01  # what a fixed 0.01 px median limit called a failure: millimetre depth
    report = validate.Report()
    validate._check_flow(report, "f.png", flow, None, depth, K, pose0, pose1, fmts)
    assert report.ok and report.checks == {"flow": 1}, report.lines()
    bound = validate.flow_tolerance(depth, fmts[0], flow, fmts[1], K, pose0, pose1, expected)
    assert 0.011 < float(np.median(bound)) < 0.1  # 1/64 px steps plus 0.5 mm of depth at half a metre


@pytest.mark.parametrize("offset", [0.1, -0.1])
def test_close_up_flow_off_by_a_tenth_of_a_pixel_fails(offset):
    flow, depth, K, pose0, pose1, fmts = _close_up(offset)
    report = validate.Report()
    validate._check_flow(report, "f.png", flow, None, depth, K, pose0, pose1, fmts)
    ((_path, check, detail),) = report.failures
    assert check == "flow-reprojection" and float(detail.split("%")[0]) > 90, detail
