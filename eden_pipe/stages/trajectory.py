"""Trajectory stage: collision-free rig poses for every frame.

The rig (a ring of stereo pairs) is a vertical cylinder of radius
ring_radius + clearance for pybullet, from just above the ground to above the
cameras. Output under ``stages/trajectory/<key>/``: ``poses.npy``
(frames, pairs, 2, 4, 4) camera-to-world (index 0 left, 1 right) and
``trajectory.json`` (centres, headings, timestamps, fps, speed).
Input: the typed ``CameraConfig`` (rig and ``trajectory`` settings) and the
lighting's name. As in EDEN, each lighting of a garden gets its own random walk
and length (``trajectory.frames``), seeded from the garden's seed and the
lighting's name, so the lighting is part of the key; with
``trajectory.share_across_lightings`` one walk, seeded from the garden alone,
serves every lighting (paired views) and the key leaves the lighting out.
The rig's obstacles are the scene's reach pieces (``proxies.npz``: trunks,
pots, rocks and low foliage, everything the rig could touch).
"""

from __future__ import annotations

import json
from itertools import pairwise
from pathlib import Path
from typing import cast

import numpy as np
import pybullet as pb

from eden_pipe.camera.random_walk import PathParams, plan_path
from eden_pipe.camera.rig import Rig
from eden_pipe.config import CameraConfig, to_plain
from eden_pipe.rng import rng_for
from eden_pipe.scene.description import read_scene
from eden_pipe.scene.physics import PhysicsWorld
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash
from eden_pipe.stages.model import load_terrain

EDGE_MARGIN_M = 0.9  # keep the rig off the garden edge (fences), as a robot keeps off walls


def walk_names(camera_cfg: CameraConfig, lighting: str) -> tuple[str, ...]:
    """The names the walk's generators are derived from (after the garden seed): the lighting's
    name unless one walk is shared by every lighting."""
    return () if camera_cfg.trajectory.share_across_lightings else (str(lighting),)


def frame_count(camera_cfg: CameraConfig, garden_seed: int, lighting: str) -> int:
    """The length of the garden's trajectory under ``lighting``, drawn from ``trajectory.frames``."""
    lo, hi = camera_cfg.trajectory.frame_range()
    return int(rng_for(garden_seed, "trajectory", "frames", *walk_names(camera_cfg, lighting)).integers(lo, hi + 1))


def run_trajectory_stage(
    camera_cfg: CameraConfig, scene_art: Artifact, model_art: Artifact, cache: StageCache, lighting: str
) -> Artifact:
    cam = to_plain(camera_cfg)
    rig_slice = {k: cam[k] for k in ("pairs", "ring_radius_m", "baseline_m", "height_m", "pitch_deg")}
    names = walk_names(camera_cfg, lighting)
    key = config_hash(scene_art.key, rig_slice, cam["trajectory"], *names, code_fingerprint(__name__))

    def builder(folder: Path) -> dict:
        return build_trajectory(folder, camera_cfg, scene_art, model_art, lighting)

    return cache.build("trajectory", key, builder)


def build_trajectory(
    folder: Path, camera_cfg: CameraConfig, scene_art: Artifact, model_art: Artifact, lighting: str
) -> dict:
    seed = read_scene(scene_art).seed
    names = walk_names(camera_cfg, lighting)
    tcfg = camera_cfg.trajectory
    terrain = load_terrain(model_art)
    size = terrain.size_m
    radius = float(camera_cfg.ring_radius_m + tcfg.clearance_m)
    height = float(camera_cfg.height_m)
    with np.load(scene_art.path / "proxies.npz") as data:
        points, offsets = data["points"], data["offsets"]

    with PhysicsWorld() as world:
        for a, b in pairwise(offsets):
            if b - a >= 4:
                world.add_proxy(points[a:b])
        probe_shape = pb.createCollisionShape(
            pb.GEOM_CYLINDER, radius=radius, height=height + 0.2, physicsClientId=world.client
        )
        probe = pb.createMultiBody(0, probe_shape, physicsClientId=world.client)

        def is_free(x: float, y: float) -> bool:
            z = float(terrain.height_at(x, y)) + 0.1 + (height + 0.2) / 2.0
            world.move(probe, (x, y, z))
            return not world.collides(probe, margin=0.0)

        params = PathParams(
            steps=frame_count(camera_cfg, seed, lighting),
            step_m=float(tcfg.speed_mps / tcfg.fps),
            # Pairs: the config check (an Interval domain) holds each of these to two numbers.
            run_steps=cast("tuple[int, int]", tuple(tcfg.run_steps)),
            turn_deg=cast("tuple[float, float]", tuple(tcfg.turn_deg)),
            abrupt_turn_probability=float(tcfg.abrupt_turn_probability),
            gradual_turn_steps=cast("tuple[int, int]", tuple(tcfg.gradual_turn_steps)),
            spin_deg_per_step=cast("tuple[float, float]", tuple(tcfg.spin_deg_per_step)),
            max_attempts=int(tcfg.max_attempts),
        )
        margin = max(radius + 0.1, EDGE_MARGIN_M)
        xy, headings, travel = plan_path(
            params, is_free, (margin, margin, size - margin, size - margin), rng_for(seed, "trajectory", *names)
        )
    rig = Rig.from_config(camera_cfg)
    z = terrain.height_at(xy[:, 0], xy[:, 1]) + height
    centres = np.c_[xy, z]
    poses = np.stack([rig.poses(c, h) for c, h in zip(centres, headings, strict=True)])  # plan_path: n of each
    np.save(folder / "poses.npy", poses)
    info = {
        "frames": len(poses),
        "lighting": names[0] if names else None,
        "fps": float(tcfg.fps),
        "speed_mps": float(tcfg.speed_mps),
        "timestamps": (np.arange(len(poses)) / tcfg.fps).round(6).tolist(),
        "centres": np.round(centres, 9).tolist(),
        "headings": np.round(headings, 9).tolist(),
        "travel_directions": np.round(travel, 9).tolist(),
    }
    (folder / "trajectory.json").write_text(json.dumps(info, indent=1))
    return {"frames": len(poses)}


def load_poses(traj_art: Artifact) -> np.ndarray:
    return np.load(traj_art.path / "poses.npy")
