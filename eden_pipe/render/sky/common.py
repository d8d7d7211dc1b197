"""Small helpers shared by the sky modules: direction maths, smoothstep and the lat-long
sphere quadrature used to integrate the sky dome (luminance: :mod:`eden_pipe.colour`; the
sun's direction: ``geometry.spherical_direction``)."""

from __future__ import annotations

import math

import numpy as np

from eden_pipe.render import vec

SUN_ANGULAR_RADIUS = math.radians(0.53) / 2.0


def smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    """0 below ``e0``, 1 above ``e1``, the cubic 3t^2 - 2t^3 between."""
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def unit_vectors(v: np.ndarray) -> np.ndarray:
    """(N, 3) float64 unit vectors of one vector (3,) or rows (N, 3)."""
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    return vec.normalize(v, 1e-12)


def sphere_quadrature(n_up: int, n_down: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    """Lat-long midpoint quadrature: (M, 3) directions, (M,) solid angles.

    The horizon is a band edge, so the upper hemisphere integrates exactly the
    z >= 0 half (no band straddles the sky/ground seam). Below the horizon a
    quarter of the bands resolve the ~3 deg horizon-to-ground blend.
    """
    edges = [np.linspace(0.0, math.pi / 2, n_up + 1)]
    if n_down:
        fine = max(n_down // 4, 1)
        edges.append(
            np.concatenate(
                [
                    np.linspace(math.pi / 2, math.pi / 2 + 0.07, fine + 1),
                    np.linspace(math.pi / 2 + 0.07, math.pi, n_down - fine + 1)[1:],
                ]
            )
        )
    dirs, weights = [], []
    phi = (np.arange(n_phi) + 0.5) * (2 * math.pi / n_phi)
    for e in edges:
        t0, t1 = e[:-1], e[1:]
        tm = 0.5 * (t0 + t1)
        w = (np.cos(t0) - np.cos(t1)) * (2 * math.pi / n_phi)
        T, P = np.meshgrid(tm, phi, indexing="ij")
        st = np.sin(T)
        dirs.append(np.stack([st * np.cos(P), st * np.sin(P), np.cos(T)], -1).reshape(-1, 3))
        weights.append(np.repeat(w, n_phi))
    return np.concatenate(dirs), np.concatenate(weights)
