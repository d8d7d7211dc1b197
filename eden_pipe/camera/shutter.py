"""When each row of a view is exposed, and the camera pose it is seen from (docs/design.md, Camera effects).

A rolling shutter exposes row r of a view (height H) at ``frame time + (r / (H - 1) - 0.5) *
readout_s``; motion blur averages S sub-frame samples at ``((j + 0.5) / S - 0.5) * exposure_s`` around
that. The pose at a time between two frames of the trajectory interpolates the two frames' poses of
that camera: rotation by slerp, translation linearly. Before the first frame and after the last, the
first or last pair of frames is extrapolated (constant velocity); a one-frame trajectory keeps its one
pose. Everything here is a function of the published poses (``rig.json``), the frame rate and the
camera keys, so a user reproduces the exact poses the renderer used: :func:`exposure_poses`.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.camera.rig import rotation_to_quaternion


def row_offsets(height: int, readout_s: float) -> np.ndarray:
    """(H,) seconds from the frame time to each row's exposure; 0 for every row of a global shutter."""
    if height < 2 or readout_s == 0:
        return np.zeros(height)
    return (np.arange(height) / (height - 1) - 0.5) * float(readout_s)


def sample_offsets(exposure_s: float, samples: int) -> np.ndarray:
    """(S,) seconds from the frame time to each sub-frame sample of the exposure; [0.0] without blur."""
    if exposure_s == 0:
        return np.zeros(1)
    return ((np.arange(samples) + 0.5) / samples - 0.5) * float(exposure_s)


def _axis_angle(axes: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations by ``angles`` (T,) about unit ``axes`` (T, 3) (Rodrigues' formula)."""
    x, y, z = axes[:, 0], axes[:, 1], axes[:, 2]
    c, s = np.cos(angles), np.sin(angles)
    k = 1.0 - c
    return np.stack(
        [
            np.stack([c + x * x * k, x * y * k - z * s, x * z * k + y * s], -1),
            np.stack([y * x * k + z * s, c + y * y * k, y * z * k - x * s], -1),
            np.stack([z * x * k - y * s, z * y * k + x * s, c + z * z * k], -1),
        ],
        -2,
    )


def poses_at(camera_poses: np.ndarray, fps: float, frame: int, offsets: np.ndarray) -> np.ndarray:
    """(T, 4, 4) camera-to-world poses of one camera at ``frame``'s time plus ``offsets`` (T,) seconds.

    ``camera_poses``: (N, 4, 4), the camera's pose at every frame of the trajectory (rig.json). With
    an offset of 0 the pose is ``camera_poses[frame]`` exactly."""
    camera_poses = np.asarray(camera_poses, np.float64)
    offsets = np.asarray(offsets, np.float64)
    n = len(camera_poses)
    out = np.tile(camera_poses[frame], (len(offsets), 1, 1))
    if n < 2:
        return out
    where = frame + offsets * float(fps)  # in frames
    first = np.clip(np.floor(where).astype(np.int64), 0, n - 2)
    fraction = where - first  # < 0 or > 1 only past the trajectory's ends: extrapolated
    p0, p1 = camera_poses[first], camera_poses[first + 1]
    out[:, :3, 3] = (1.0 - fraction)[:, None] * p0[:, :3, 3] + fraction[:, None] * p1[:, :3, 3]
    # Slerp: R0 @ exp(fraction * log(R0^T R1)), the relative rotation taken the short way round; its
    # axis and angle once per pair of frames used (a view's rows span one or two).
    segments, which = np.unique(first, return_inverse=True)
    relative = [camera_poses[i, :3, :3].T @ camera_poses[i + 1, :3, :3] for i in segments]
    quats = np.array([rotation_to_quaternion(r) for r in relative])
    sin_half = np.linalg.norm(quats[:, 1:], axis=1)
    angles = 2.0 * np.arctan2(sin_half, quats[:, 0])
    axes = np.where(sin_half[:, None] > 0, quats[:, 1:] / np.maximum(sin_half, 1e-300)[:, None], [1.0, 0.0, 0.0])
    out[:, :3, :3] = p0[:, :3, :3] @ _axis_angle(axes[which], fraction * angles[which])
    # Exactly the published pose where a time falls on a frame (no rounding through the slerp).
    on_frame = fraction == 0.0
    out[on_frame] = p0[on_frame]
    on_next = fraction == 1.0
    out[on_next] = p1[on_next]
    return out


def exposure_poses(
    camera_poses: np.ndarray,
    fps: float,
    frame: int,
    height: int,
    readout_s: float,
    exposure_s: float = 0.0,
    samples: int = 1,
) -> np.ndarray:
    """(S, H, 4, 4): the pose of each row of one view at each sub-frame sample (S = 1 without blur).

    The one function the renderer takes its per-row poses from; ``camera_poses`` (N, 4, 4) are the
    camera's published poses (``rig.json``: ``cameras[c]["poses"]``), ``fps`` the trajectory's rate
    (``rig.json`` timestamps), the rest the ``camera.*`` keys recorded in ``camera.json``."""
    rows = row_offsets(height, readout_s)
    subs = sample_offsets(exposure_s, samples)
    offsets = (subs[:, None] + rows[None, :]).ravel()
    return poses_at(camera_poses, fps, frame, offsets).reshape(len(subs), height, 4, 4)
