"""Pinhole cameras (OpenCV axes) and the EDEN ring of stereo pairs.

Conventions (docs/design.md, Frames and units): camera x right, y down, z forward; poses are
camera-to-world 4x4 matrices; pixel (u, v) has its centre at coordinates
(u, v), so ``K @ X`` of a point seen at pixel centre (u, v) gives (u, v, 1)*z.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @classmethod
    def from_config(cls, cam) -> Intrinsics:
        return cls(int(cam.width), int(cam.height), float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy))

    def pixel_grid(self, offset: tuple[float, float] | np.ndarray = (0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
        """(H, W) u and v pixel coordinates (centres, plus an optional sub-pixel offset)."""
        u, v = np.meshgrid(np.arange(self.width, dtype=np.float64), np.arange(self.height, dtype=np.float64))
        off = np.asarray(offset, dtype=np.float64)
        return u + off[..., 0], v + off[..., 1]

    def camera_rays(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Camera-frame directions with z = 1 (so a ray's t is its z-depth)."""
        return np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], axis=-1)

    def project(self, points_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Camera-frame points -> (u, v, z); u, v are nan where z <= 0."""
        z = points_cam[..., 2]
        safe = np.where(z > 1e-9, z, np.nan)
        return self.fx * points_cam[..., 0] / safe + self.cx, self.fy * points_cam[..., 1] / safe + self.cy, z


def look_rotation(yaw: float, pitch: float) -> np.ndarray:
    """Camera-to-world rotation for a camera looking at (yaw, pitch), world Z up, no roll."""
    forward = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    return np.stack([right, down, forward], axis=1)


@dataclass(frozen=True)
class Rig:
    """A ring of ``pairs`` stereo pairs; pair k looks outward at yaw heading + k*2pi/pairs. Built from the
    camera config (``Rig.from_config``), which holds the defaults (``config.CameraConfig``)."""

    pairs: int
    ring_radius: float
    baseline: float
    pitch: float

    @classmethod
    def from_config(cls, cam) -> Rig:
        return cls(int(cam.pairs), float(cam.ring_radius_m), float(cam.baseline_m), float(np.deg2rad(cam.pitch_deg)))

    def poses(self, centre: np.ndarray, heading: float) -> np.ndarray:
        """(pairs, 2, 4, 4) camera-to-world poses: [k, 0] left, [k, 1] right camera."""
        out = np.tile(np.eye(4), (self.pairs, 2, 1, 1))
        for k in range(self.pairs):
            yaw = heading + 2.0 * np.pi * k / self.pairs
            rot = look_rotation(yaw, self.pitch)
            left = np.asarray(centre, dtype=np.float64) + self.ring_radius * np.array([np.cos(yaw), np.sin(yaw), 0.0])
            out[k, :, :3, :3] = rot
            out[k, 0, :3, 3] = left
            out[k, 1, :3, 3] = left + self.baseline * rot[:, 0]  # +baseline along the camera's own x
        return out


def rotation_to_quaternion(rot: np.ndarray) -> np.ndarray:
    """3x3 rotation -> unit quaternion (w, x, y, z) with w >= 0."""
    m = np.asarray(rot, dtype=np.float64)
    tr = np.trace(m)
    if tr > 0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(m)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + m[i, i] - m[j, j] - m[k, k])
        q = [0.0] * 4
        q[0] = (m[k, j] - m[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (m[j, i] + m[i, j]) / s
        q[1 + k] = (m[k, i] + m[i, k]) / s
    quat = np.asarray(q)
    quat /= np.linalg.norm(quat)
    return quat if quat[0] >= 0 else -quat


def quaternion_to_rotation(q: npt.ArrayLike) -> np.ndarray:
    w, x, y, z = np.asarray(q, dtype=np.float64) / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )
