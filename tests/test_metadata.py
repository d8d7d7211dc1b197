"""Published metadata: TUM trajectories round-trip, the rig table and the instance table."""

from __future__ import annotations

import json

import numpy as np
import pytest

from eden_pipe import metadata
from eden_pipe.camera.rig import Rig
from eden_pipe.config import CameraConfig


def _ring_poses(frames: int = 5) -> np.ndarray:
    rig = Rig.from_config(CameraConfig())
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
    rig = Rig.from_config(CameraConfig())
    offsets = rig.poses(np.zeros(3), 0.0)
    meta = metadata.rig_metadata(
        np.array([[640, 0, 320], [0, 640, 240], [0, 0, 1.0]]),
        640,
        480,
        rig.baseline,
        offsets,
        poses,
        np.arange(3) / 10.0,
    )
    meta = json.loads(json.dumps(meta))  # plain JSON
    assert [c["camera"] for c in meta["cameras"]] == list(range(10))
    right = meta["cameras"][metadata.camera_index(2, 1)]
    assert right["pair"] == 2 and right["side"] == "right"
    np.testing.assert_allclose(right["poses"], poses[:, 2, 1], atol=1e-9)
    # The right camera sits one baseline along the left camera's own x axis.
    left = np.array(meta["cameras"][4]["rig_offset"])
    np.testing.assert_allclose(
        np.array(right["rig_offset"])[:3, 3] - left[:3, 3], rig.baseline * left[:3, 0], atol=1e-9
    )


def test_scene_metadata_maps_instance_ids_to_species():
    scene = {
        "garden_id": "g-s0",
        "seed": 0,
        "size_m": 10.0,
        "instances": [
            {
                "id": 1,
                "class": "tree",
                "semantic": 8,
                "pool": "trees",
                "type": "quaking_aspen",
                "model_seed": 5,
                "transform": np.eye(4).tolist(),
                "bbox_min": [0, 0, 0],
                "bbox_max": [1, 1, 3],
                "faces": 100,
            }
        ],
        "requested": {"trees": 1},
        "placed": {"trees": 1},
        "terrain_types": ["grass"],
        "lawn": {},
    }
    meta = metadata.scene_metadata(scene)
    assert meta["instances"][0] == {
        "id": 1,
        "class": "tree",
        "class_id": 8,
        "pool": "trees",
        "species": "quaking_aspen",
        "model_seed": 5,
        "transform": np.eye(4).tolist(),
        "bbox_min": [0, 0, 0],
        "bbox_max": [1, 1, 3],
        "faces": 100,
    }
    assert meta["fence_style"] is None
    fence_run = dict(scene["instances"][0], id=2, **{"class": "obstacle"}, semantic=7, pool="fence", type="panel")
    assert metadata.scene_metadata(dict(scene, instances=[fence_run, *scene["instances"]]))["fence_style"] == "panel"


# ------------------------------------------------------------------ end to end on the shared tiny dataset
def test_instance_id_from_a_mask_looks_up_to_its_species_in_plain_python(tmp_path_factory):
    import csv

    from PIL import Image

    from tests.tiny_dataset import tiny_root

    root = tiny_root(tmp_path_factory) / "dataset"
    row = next(csv.DictReader(open(root / "manifest.csv")))
    ids = np.unique(np.asarray(Image.open(root / row["instance"])))
    ids = [int(i) for i in ids if i]
    assert ids, "the first frame shows no instance"
    # What a user writes: the standard library and the published files only.
    scene = json.load(open(root / row["garden"] / "scene.json"))
    by_id = {inst["id"]: inst for inst in scene["instances"]}
    for i in ids:
        assert by_id[i]["species"] and by_id[i]["class"] in ("tree", "hedge", "topiary", "flower", "obstacle")
    assert scene["placed"] and scene["requested"]


def test_published_rig_and_tum_poses_agree_with_the_manifest(tmp_path_factory):
    import pandas as pd

    from eden_pipe.camera.rig import quaternion_to_rotation
    from tests.tiny_dataset import tiny_root

    root = tiny_root(tmp_path_factory) / "dataset"
    rows = pd.read_csv(root / "manifest.csv")
    job = root / rows.garden[0] / rows.lighting[0]
    rig = json.loads((job / "rig.json").read_text())
    lighting = json.loads((job / "lighting.json").read_text())
    assert lighting["scenario"] == rows.lighting[0] and lighting["exposure"] == pytest.approx(rows.exposure[0])
    described = json.loads((root / "dataset.json").read_text())
    assert described["columns"]["albedo"]["extension"] == "exr" and described["labels"][8]["name"] == "tree"
    assert f"{rows.garden[0]}/{rows.lighting[0]}" in described["jobs"]
    for _, r in rows.iterrows():
        pose = np.eye(4)
        pose[:3, :3] = quaternion_to_rotation([r.qw, r.qx, r.qy, r.qz])
        pose[:3, 3] = (r.tx, r.ty, r.tz)
        cam = metadata.camera_index(int(r.camera), 0)
        np.testing.assert_allclose(rig["cameras"][cam]["poses"][int(r.frame)], pose, atol=1e-6)
        times, tum = metadata.read_tum(job / "poses" / f"cam{cam:02d}.txt")
        np.testing.assert_allclose(tum[int(r.frame)], pose, atol=1e-6)
        assert times[int(r.frame)] == pytest.approx(r.timestamp)


def test_test_subsample_is_marked_listed_and_repeatable(tmp_path_factory):
    import pandas as pd

    from eden_pipe.pipeline import run_job
    from tests.conftest import TINY, make_cfg
    from tests.tiny_dataset import ALL_MODALITIES, tiny_root

    base = tiny_root(tmp_path_factory)  # reuse its stage cache: only the manifest and publishing rerun
    listed = []
    for name in ("a", "b"):
        cfg = make_cfg(
            base,
            TINY
            + [
                ALL_MODALITIES,
                f"paths.dataset={base}/sub_{name}",
                "split.test_subsample.count=7",
                "++split.overrides={small-s0: test}",
            ],
        )
        run_job(cfg, echo=lambda *_: None)
        rows = pd.read_csv(base / f"sub_{name}" / "manifest.csv")
        assert rows.test_subsample.sum() == 7 and set(rows.split) == {"test"}
        listed.append((base / f"sub_{name}" / "test_subsample.txt").read_text().split())
        chosen = rows[rows.test_subsample == 1]
        assert (
            sorted(
                f"{g}/{lt}/{f:05d}/cam{c}"
                for g, lt, f, c in zip(chosen.garden, chosen.lighting, chosen.frame, chosen.camera, strict=True)
            )
            == listed[-1]
        )
    assert listed[0] == listed[1]
