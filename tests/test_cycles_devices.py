"""benchmarks/cycles_devices.py's ``record``: what the ``render=cycles`` worker is sent for frame 0 of a
garden, written by the pipeline's own stages (no bpy needed; ``run`` is tested in test_cycles.py)."""

from __future__ import annotations

import json

import numpy as np

from benchmarks.cycles_devices import INTRINSICS, MESH_KEYS, record
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.config import make_cfg, to_config
from eden_pipe.pipeline import run_stages
from eden_pipe.stages.cache import StageCache
from eden_pipe.stages.scene import load_scene
from eden_pipe.stages.trajectory import load_poses
from tests.conftest import TINY


def test_record_writes_the_gardens_mesh_sky_and_left_cameras(tmp_path):
    overrides = [*TINY, "lighting=sunset", "render.cycles.map_width=64"]
    job = tmp_path / "job.npz"
    record(job, overrides, tmp_path)
    cfg = to_config(make_cfg(tmp_path, ["progress=false", *overrides]))
    arts = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="trajectory")  # cached: the same
    _, arrays = load_scene(arts["scene"])
    with np.load(job) as f:
        data = {k: f[k] for k in f.files}
    for key in MESH_KEYS:
        np.testing.assert_array_equal(data[f"mesh_{key}"], getattr(arrays.mesh, key))
    np.testing.assert_array_equal(data["poses"], load_poses(arts["trajectory"])[0, :, 0])
    assert data["poses"].shape == (5, 4, 4)
    intr = Intrinsics.from_config(cfg.camera)
    assert dict(zip(INTRINSICS, data["intrinsics"], strict=True)) == {k: getattr(intr, k) for k in INTRINSICS}
    assert data["world_light_map"].shape == data["world_camera_map"].shape == (32, 64, 3)
    assert np.all(data["world_light_map"] >= 0) and data["world_light_map"].max() > 0
    sun = data["world_sun_direction"]
    assert abs(np.linalg.norm(sun) - 1.0) < 1e-6 and sun[2] > 0  # a sunset's sun, above the horizon
    meta = json.loads(str(data["meta"]))
    assert meta == {"garden": "small", "seed": int(cfg.garden.seed), "lighting": "sunset", "faces": arrays.mesh.n_faces}
