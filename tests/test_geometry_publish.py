"""The published scene mesh (<garden>/geometry.ply): read back by trimesh, equal to the scene stage's arrays,
checked by the validator against the rendered masks, and the source of the 3DRMS point cloud."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
import trimesh

from eden_pipe import metadata
from eden_pipe.io.mesh_ply import bytes_per_face, bytes_per_vertex, mesh_ply_bytes, read_mesh_ply
from eden_pipe.tools import export as ex
from eden_pipe.tools import geometry_check, validate
from tests.tiny_dataset import tiny_root
from tests.tools_dataset import copy_dataset

GARDEN = "small-s0"


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return tiny_root(tmp_path_factory)


@pytest.fixture(scope="module")
def root(base):
    return base / "dataset"


@pytest.fixture(scope="module")
def scene_npz(base):
    (path,) = (base / "stages" / "scene").glob("*/geometry.npz")
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def test_published_beside_scene_json_and_named_by_the_metadata(root, base):
    ply = root / GARDEN / metadata.GEOMETRY_FILE
    assert ply.is_file()
    assert json.loads((root / GARDEN / metadata.SCENE_FILE).read_text())["geometry"] == metadata.GEOMETRY_FILE
    files = json.loads((root / metadata.DATASET_FILE).read_text())["metadata_files"]
    assert files["geometry"] == f"<garden>/{metadata.GEOMETRY_FILE}"
    # The scene stage's own file, linked as the images are.
    (stage_ply,) = (base / "stages" / "scene").glob(f"*/{metadata.GEOMETRY_FILE}")
    assert os.path.samefile(ply, stage_ply)


def test_trimesh_reads_the_scene_arrays_exactly(root, scene_npz):
    mesh = trimesh.load(root / GARDEN / metadata.GEOMETRY_FILE, process=False)
    assert isinstance(mesh, trimesh.Trimesh)
    np.testing.assert_array_equal(mesh.vertices.astype(np.float32), scene_npz["vertices"])
    np.testing.assert_array_equal(mesh.faces, scene_npz["faces"])
    face = mesh.metadata["_ply_raw"]["face"]["data"]
    np.testing.assert_array_equal(face["instance"], scene_npz["instance"])
    np.testing.assert_array_equal(face["class"], scene_npz["semantic"])
    np.testing.assert_array_equal(face["material"], scene_npz["material"])
    albedo = np.stack([face["albedo_r"], face["albedo_g"], face["albedo_b"]], axis=1)
    np.testing.assert_array_equal(albedo, scene_npz["albedo"])
    np.testing.assert_array_equal(face["translucency"], scene_npz["translucency"])
    np.testing.assert_array_equal(face["specular"], scene_npz["specular"])
    # Every instance of scene.json owns faces, and no face names an instance it does not list.
    scene = json.loads((root / GARDEN / metadata.SCENE_FILE).read_text())
    faces_per_id = np.bincount(face["instance"])
    assert {i["id"]: i["faces"] for i in scene["instances"]} == {
        int(i): int(faces_per_id[i]) for i in np.flatnonzero(faces_per_id) if i != 0
    }


def test_size_is_the_formats_and_rewrites_are_byte_identical(root, scene_npz):
    ply = root / GARDEN / metadata.GEOMETRY_FILE
    data = ply.read_bytes()
    header = data.split(b"end_header\n", 1)[0] + b"end_header\n"
    v, f = len(scene_npz["vertices"]), len(scene_npz["faces"])
    assert (bytes_per_vertex(), bytes_per_face()) == (12, 37)
    assert len(data) == len(header) + 12 * v + 37 * f
    back = read_mesh_ply(ply)
    comments = tuple(line[len("comment ") :] for line in header.decode().splitlines() if line.startswith("comment "))
    assert mesh_ply_bytes(back, comments) == data  # the same arrays give the same bytes


def test_validator_agrees_with_the_masks(root):
    report = validate.check_dataset(root, sample=6, progress=False)
    assert report.ok, report.lines()
    assert report.checks["geometry"] == 6
    (note,) = [n for n in report.notes if n.startswith(f"geometry {GARDEN}")]
    n = 6 * geometry_check.SAMPLE_PIXELS
    assert note.startswith(f"geometry {GARDEN}: {n} of {n} sampled px (100.000%)")


def test_validator_catches_shuffled_instance_ids(root, tmp_path):
    bad = copy_dataset(root, tmp_path / "bad")
    ply = bad / GARDEN / metadata.GEOMETRY_FILE
    arrays = read_mesh_ply(ply)
    arrays["instance"] = np.random.default_rng(0).permutation(arrays["instance"])
    ply.write_bytes(mesh_ply_bytes(arrays))
    report = validate.check_dataset(bad, sample=4, progress=False)
    failed = [(path, check) for path, check, _ in report.failures]
    assert len(failed) == 4 and {check for _, check in failed} == {"geometry"}
    assert all(path.endswith(".png") and "/instance/" in path for path, _ in failed)
    # Without the file the check says why it did not run.
    ply.unlink()
    report = validate.check_dataset(bad, sample=4, progress=False)
    assert report.ok and (("geometry", f"no published scene mesh ({GARDEN}/geometry.ply)") in report.not_run)


def test_point_triangle_distance_matches_trimesh():
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(500, 3, 3))
    tri[:5, 2] = tri[:5, 0]  # a few degenerate (zero-area) faces
    p = rng.normal(size=(500, 3)) * 2
    got = geometry_check.point_triangle_distance(p, tri[:, 0], tri[:, 1], tri[:, 2])
    want = np.linalg.norm(p - trimesh.triangles.closest_point(tri, p), axis=1)
    ok = np.isfinite(got)
    assert ok[5:].all()
    np.testing.assert_allclose(got[ok], want[ok], atol=1e-9)


def test_3drms_point_cloud_without_stages(root, rows_fixture, tmp_path):
    facts = ex.export_3drms(root, tmp_path / "3drms", rows_fixture, stages=None, points=20000)
    (ply,) = facts["ply"]
    cloud = trimesh.load(ply, process=False)
    label = cloud.metadata["_ply_raw"]["vertex"]["data"]["label"]
    mesh = read_mesh_ply(root / GARDEN / metadata.GEOMETRY_FILE)
    v = mesh["vertices"].astype(np.float64)
    a, b, c = (v[mesh["faces"][:, i]] for i in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    expected = np.bincount(mesh["class"], weights=area, minlength=10) / area.sum()
    np.testing.assert_allclose(np.bincount(label, minlength=10) / len(label), expected, atol=0.02)


@pytest.fixture(scope="module")
def rows_fixture(root):
    return ex.select_rows(root)
