"""python -m eden_pipe.tools.view: a recording of the tiny dataset, read back with Rerun's own reader."""

from __future__ import annotations

import collections
import json

import numpy as np
import pytest

from eden_pipe import labels, metadata, modalities
from eden_pipe.data.manifest_reader import load_manifest, row_pose
from eden_pipe.io.mesh_ply import read_mesh_ply
from eden_pipe.tools import view
from tests.tiny_dataset import tiny_root

rr = pytest.importorskip("rerun")


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tiny_root(tmp_path_factory) / "dataset"


@pytest.fixture(scope="module")
def recording(root, tmp_path_factory):
    """(facts, {entity: [chunk record batches]}, {entity: rows}) of a recording of the tiny dataset."""
    out = tmp_path_factory.mktemp("view") / "garden.rrd"
    facts = view.write_recording(root, out, depth_stride=3)
    batches, rows = collections.defaultdict(list), collections.Counter()
    (store,) = rr.chunk.RrdReader(out).recordings()
    assert store.application_id == "eden_pipe"
    for chunk in rr.chunk.RrdReader(out).stream():
        batches[chunk.entity_path].append(chunk.to_record_batch())
        rows[chunk.entity_path] += chunk.num_rows
    return facts, batches, rows


def _column(batches, name):
    return [value for batch in batches if name in batch.schema.names for value in batch.column(name).to_pylist()]


def test_entities_and_their_counts(root, recording):
    facts, _, rows = recording
    manifest = load_manifest(root)
    frames = manifest["frame"].nunique()
    expected = {"/": 1, "/world": 1, "/world/mesh": 1}
    for pair in sorted(manifest["camera"].unique()):
        job = manifest[manifest["camera"] == pair]
        for side, camera_side in enumerate(("left", "right")):
            camera = metadata.camera_index(int(pair), side)
            expected[f"/{view.camera_entity(camera)}"] = 1 + frames  # static Pinhole + a pose per frame
            expected[f"/{view.points_entity(camera)}"] = frames
            for column in modalities.COLUMNS.values():
                written = int((job[column.name].astype(str) != "").sum()) if column.name in job else 0
                if column.camera == camera_side and written:
                    # + the instance table, a static annotation context on each instance image
                    expected[f"/{view.camera_entity(camera)}/{column.name}"] = written + (column.loader == "ids")
    got = {entity: n for entity, n in rows.items() if not entity.startswith("/__")}  # "/__properties": Rerun's own
    assert got == expected
    assert facts["cameras"] == 10 and facts["frames"] == frames
    flows = [e for e in expected if e.endswith("/flow_fwd")]
    assert flows and all(expected[e] == frames - 1 for e in flows)  # no forward flow at the last frame


def test_mesh_class_table_cameras_and_points(root, recording):
    facts, batches, _ = recording
    mesh = read_mesh_ply(root / "small-s0" / metadata.GEOMETRY_FILE)
    (positions,) = _column(batches["/world/mesh"], "Mesh3D:vertex_positions")
    (triangles,) = _column(batches["/world/mesh"], "Mesh3D:triangle_indices")
    (class_ids,) = _column(batches["/world/mesh"], "Mesh3D:class_ids")
    assert len(positions) == len(mesh["vertices"]) and len(triangles) == len(mesh["faces"]) == facts["mesh_faces"]
    np.testing.assert_array_equal(np.asarray(triangles), mesh["faces"])
    # Each face's three vertices carry a class of the published faces (shared vertices take one of them).
    vertex_class = np.asarray(class_ids)
    assert set(np.unique(vertex_class)) == set(np.unique(mesh["class"]))

    ((context,),) = _column(batches["/"], "AnnotationContext:context")
    table = {c["class_id"]: c["class_description"]["info"]["label"] for c in context}
    assert table == dict(enumerate(labels.NAMES))
    scene = json.loads((root / "small-s0" / metadata.SCENE_FILE).read_text())
    ((context,),) = _column(batches[f"/{view.camera_entity(0)}/instance"], "AnnotationContext:context")
    table = {c["class_id"]: c["class_description"]["info"]["label"] for c in context}
    assert table == {0: "none", **{i["id"]: f"{i['id']} {i['class']} {i['species']}" for i in scene["instances"]}}

    manifest = load_manifest(root)
    first = manifest.sort_values(["frame", "camera"]).iloc[0]
    entity = f"/{view.camera_entity(metadata.camera_index(int(first['camera']), 0))}"
    (K,) = _column(batches[entity], "Pinhole:image_from_camera")
    want_K = np.array([[first["fx"], 0, first["cx"]], [0, first["fy"], first["cy"]], [0, 0, 1]], np.float32)
    np.testing.assert_array_equal(np.asarray(K).reshape(3, 3).T, want_K)  # Rerun stores it column-major
    translations = _column(batches[entity], "Transform3D:translation")
    np.testing.assert_allclose(translations[0][0], row_pose(first)[:3, 3], atol=1e-5)

    points = sum(
        len(p) for e, b in batches.items() if e.startswith("/world/points/") for p in _column(b, "Points3D:positions")
    )
    assert points == facts["depth_points"] > 0


def test_bad_arguments_fail_before_any_work(root, tmp_path):
    with pytest.raises(SystemExit, match="--garden 'nope' is not in"):
        view.write_recording(root, tmp_path / "x.rrd", garden="nope")
    with pytest.raises(SystemExit, match="--depth-stride must be >= 1, got 0"):
        view.write_recording(root, tmp_path / "x.rrd", depth_stride=0)
    assert not (tmp_path / "x.rrd").exists()


def test_command_line_writes_the_first_frames(root, tmp_path):
    out = tmp_path / "one.rrd"
    assert view.main([str(root), "--out", str(out), "--frames", "1", "--lighting", "clear"]) == 0
    frames = {
        value
        for chunk in rr.chunk.RrdReader(out).stream()
        if "frame" in chunk.to_record_batch().schema.names
        for value in chunk.to_record_batch().column("frame").to_pylist()
    }
    assert frames == {0}
