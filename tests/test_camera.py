"""Rig geometry, projection conventions and the random-walk planner."""

from __future__ import annotations

import dataclasses

import numpy as np

from eden_pipe.camera.random_walk import PathParams, plan_path
from eden_pipe.camera.rig import Intrinsics, Rig, quaternion_to_rotation, rotation_to_quaternion
from eden_pipe.config import CameraConfig

K640 = Intrinsics(640, 480, 640.0, 640.0, 320.0, 240.0)


def test_rig_pairs_baseline_and_yaw():
    rig = Rig(pairs=5, ring_radius=0.1, baseline=0.03, pitch=0.0)
    poses = rig.poses(np.array([5.0, 5.0, 1.0]), heading=0.3)
    assert poses.shape == (5, 2, 4, 4)
    for k in range(5):
        left, right = poses[k]
        R = left[:3, :3]
        assert np.allclose(R.T @ R, np.eye(3)) and np.isclose(np.linalg.det(R), 1.0)
        assert np.allclose(right[:3, 3] - left[:3, 3], 0.03 * R[:, 0])  # +baseline along own x
        forward = R[:, 2]
        assert np.isclose(np.arctan2(forward[1], forward[0]) % (2 * np.pi), (0.3 + k * 2 * np.pi / 5) % (2 * np.pi))
        assert np.isclose(np.linalg.norm(left[:2, 3] - 5.0), 0.1)  # on the ring
        assert np.allclose(R[:, 1] @ [0, 0, 1], -1.0)  # y points down (no pitch, no roll)


def test_pitch_looks_down():
    rig = dataclasses.replace(Rig.from_config(CameraConfig()), pitch=np.deg2rad(-10))
    R = rig.poses(np.zeros(3), 0.0)[0, 0, :3, :3]
    assert np.isclose(R[2, 2], np.sin(np.deg2rad(-10)))


def test_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(50):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        R = quaternion_to_rotation(q)
        q2 = rotation_to_quaternion(R)
        assert np.allclose(quaternion_to_rotation(q2), R)
        assert q2[0] >= 0


def test_pixel_centre_convention():
    u, v = K640.pixel_grid()
    rays = K640.camera_rays(u, v)
    pu, pv, z = K640.project(rays * 3.0)
    assert np.allclose(pu, u) and np.allclose(pv, v) and np.allclose(z, 3.0)
    assert np.allclose(rays[240, 320], [0, 0, 1])  # the principal point is pixel (320, 240)


def test_planner_avoids_obstacles_and_walls():
    obstacle, radius = np.array([5.0, 5.0]), 1.5

    def is_free(x, y):
        return np.hypot(x - obstacle[0], y - obstacle[1]) > radius

    params = PathParams(
        steps=400,
        step_m=0.05,
        run_steps=(10, 40),
        turn_deg=(30, 120),
        abrupt_turn_probability=0.3,
        gradual_turn_steps=(5, 15),
        spin_deg_per_step=(-2, 2),
        max_attempts=50,
    )
    xy, heading, travel = plan_path(params, is_free, (0.5, 0.5, 9.5, 9.5), np.random.default_rng(3))
    assert len(xy) == 400
    assert np.all(np.hypot(*(xy - obstacle).T) > radius)
    assert np.all((xy >= 0.5) & (xy <= 9.5))
    assert np.allclose(np.linalg.norm(np.diff(xy, axis=0), axis=1), 0.05)
    turns = np.abs(np.diff(np.unwrap(travel)))
    assert np.any(turns > np.deg2rad(25)) and np.any((turns > 1e-6) & (turns < np.deg2rad(25)))  # abrupt and gradual
    assert np.ptp(heading) > 0  # the ring rotates on itself
