"""Small vectorised vector helpers shared by every model: unit vectors, perpendiculars,
random directions and rotation matrices.

All functions work on stacks of vectors (``(..., 3)``) or per-row matrices
(``(N, 3, 3)``); none loops in Python per vector. They are kept bit-for-bit
stable because the models that use them promise byte-identical output for a
given seed: change the arithmetic here and every dataset changes.
"""

from __future__ import annotations

import math

import numpy as np

UP = np.array([0.0, 0.0, 1.0])


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis; zero vectors stay (near) zero instead of dividing by 0."""
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.maximum(n, 1e-12)


def any_perpendicular(n: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to each of ``n`` (N, 3), built from +Z (or +X near the poles)."""
    ref = np.where(np.abs(n[..., 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    return normalize(np.cross(n, ref))


def spherical_direction(elevation: float, azimuth: float) -> np.ndarray:
    """(3,) world unit vector ``elevation`` radians above the XY plane, ``azimuth`` radians from
    +X toward +Y (the sun's direction from its elevation and azimuth)."""
    ce = math.cos(elevation)
    return np.array([ce * math.cos(azimuth), ce * math.sin(azimuth), math.sin(elevation)])


def uniform_sphere(n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` directions uniform on the unit sphere (draws z then azimuth, in that order)."""
    z = rng.uniform(-1.0, 1.0, n)
    phi = rng.uniform(0.0, 2 * np.pi, n)
    s = np.sqrt(1.0 - z * z)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], 1)


def axis_angle_matrices(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """(N,3,3) rotation matrices about unit axes (N,3) by angles (N,) (Rodrigues, element by element)."""
    axis = np.asarray(axis, dtype=np.float64)
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    x, y, z = axis[:, 0], axis[:, 1], axis[:, 2]
    t = 1.0 - c
    m = np.empty((len(angle), 3, 3))
    m[:, 0, 0] = c + x * x * t
    m[:, 0, 1] = x * y * t - z * s
    m[:, 0, 2] = x * z * t + y * s
    m[:, 1, 0] = y * x * t + z * s
    m[:, 1, 1] = c + y * y * t
    m[:, 1, 2] = y * z * t - x * s
    m[:, 2, 0] = z * x * t - y * s
    m[:, 2, 1] = z * y * t + x * s
    m[:, 2, 2] = c + z * z * t
    return m


def local_axis_matrices(axis_index: int, angle: np.ndarray) -> np.ndarray:
    """(N,3,3) rotations about the local x (0), y (1) or z (2) axis; right-multiply a frame to turn it."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    m = np.zeros((len(angle), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis_index]
    m[:, axis_index, axis_index] = 1.0
    m[:, i, i] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    m[:, j, j] = c
    return m


def rotate_vectors(v: np.ndarray, axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotate rows of ``v`` (N,3) about unit ``axis`` rows by ``angle`` (N,) (Rodrigues' formula)."""
    c = np.cos(angle)[:, None]
    s = np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * np.sum(axis * v, axis=1, keepdims=True) * (1.0 - c)
