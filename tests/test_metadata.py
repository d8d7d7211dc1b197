"""Published metadata: TUM trajectories round-trip, the rig table and the instance table."""

from __future__ import annotations

import json

import numpy as np

from eden_pipe import metadata
from eden_pipe.camera.rig import Rig


def _ring_poses(frames: int = 5) -> np.ndarray:
    rig = Rig()
    return np.stack([rig.poses(np.array([2.0 + 0.05 * f, 3.0, 0.8]), 0.1 * f) for f in range(frames)])


def test_tum_round_trip_is_exact_to_print_precision(tmp_path):
    poses = _ring_poses()[:, 1, 0]
    times = np.arange(len(poses)) / 10.0
    path = tmp_path / "cam02.txt"
    path.write_text(metadata.tum_lines(times, poses))
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    assert len(lines) == len(poses) and all(len(line.split()) == 8 for line in lines)
    t2, p2 = metadata.read_tum(path)
    np.testing.assert_allclose(t2, times)
    np.testing.assert_allclose(p2, poses, atol=1e-8)


def test_rig_metadata_lists_ten_cameras_with_offsets_and_poses():
    poses = _ring_poses(3)
    rig = Rig()
    offsets = rig.poses(np.zeros(3), 0.0)
    meta = metadata.rig_metadata(np.array([[640, 0, 320], [0, 640, 240], [0, 0, 1.0]]), 640, 480, rig.baseline,
                                 offsets, poses, np.arange(3) / 10.0)
    meta = json.loads(json.dumps(meta))  # plain JSON
    assert [c["camera"] for c in meta["cameras"]] == list(range(10))
    right = meta["cameras"][metadata.camera_index(2, 1)]
    assert right["pair"] == 2 and right["side"] == "right"
    np.testing.assert_allclose(right["poses"], poses[:, 2, 1], atol=1e-9)
    # The right camera sits one baseline along the left camera's own x axis.
    left = np.array(meta["cameras"][4]["rig_offset"])
    np.testing.assert_allclose(np.array(right["rig_offset"])[:3, 3] - left[:3, 3], rig.baseline * left[:3, 0], atol=1e-9)


def test_scene_metadata_maps_instance_ids_to_species():
    scene = {"garden_id": "g-s0", "seed": 0, "size_m": 10.0, "instances": [
        {"id": 1, "class": "tree", "semantic": 8, "pool": "trees", "type": "quaking_aspen", "model_seed": 5,
         "transform": np.eye(4).tolist(), "bbox_min": [0, 0, 0], "bbox_max": [1, 1, 3], "faces": 100}],
        "requested": {"trees": 1}, "placed": {"trees": 1}, "terrain_types": ["grass"], "lawn": {}, "fence": None}
    meta = metadata.scene_metadata(scene)
    assert meta["instances"][0] == {"id": 1, "class": "tree", "class_id": 8, "pool": "trees", "species": "quaking_aspen",
                                    "model_seed": 5, "transform": np.eye(4).tolist(), "bbox_min": [0, 0, 0],
                                    "bbox_max": [1, 1, 3], "faces": 100}
    assert meta["fence_style"] is None
