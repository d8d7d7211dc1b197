"""The strip primitive of the lawn: blades and weed leaves as strips along a bent centreline.

A strip has k segments and a width profile; it is two triangles a segment and
one triangle at a pointed tip (a pointed strip of k segments has 2k-1
triangles, a blunt one 2k). :func:`build_strips` builds any number of strips
with one segment count at once (no Python loop per blade); width profiles come
from the one leaf table (:data:`eden_pipe.models.leaves.STRIP_PROFILES`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import MATERIALS, Mesh

MAX_THETA = np.radians(88.0)  # leaves never droop below horizontal
MIN_WIDTH_FRACTION = 0.06  # of the maximal width, except at a pointed tip


def strip_triangles(segments: int, shape: dict) -> int:
    return 2 * segments - 1 if shape["tip"] <= 0 else 2 * segments


def width_profile(
    s: np.ndarray, shape: dict, petiole: float = 0.0, lobes: int = 0, lobe_depth: float = 0.0
) -> np.ndarray:
    """Relative width (max 1) at arc-length fractions ``s`` in [0, 1]."""
    s = np.asarray(s, dtype=np.float64)
    u = np.clip((s - petiole) / max(1e-9, 1.0 - petiole), 0.0, 1.0)
    base, peak, tip, sharp = shape["base"], max(1e-3, shape["peak"]), shape["tip"], shape["sharp"]
    rise = base + (1.0 - base) * np.sin(0.5 * np.pi * np.minimum(u / peak, 1.0))
    fall_t = np.clip((u - peak) / max(1e-3, 1.0 - peak), 0.0, 1.0)
    fall = tip + (1.0 - tip) * np.cos(0.5 * np.pi * fall_t) ** sharp
    w = np.where(u < peak, rise, fall)
    if lobes and lobe_depth > 0:
        # Runcinate lobes (dandelion): teeth widen towards the tip, then notch back.
        t = np.mod(u * lobes, 1.0)
        w = w * (1.0 - lobe_depth * (1.0 - t) * (u < 0.92))
    if petiole > 0:
        w = np.where(s < petiole, 0.1, w)
    w = np.maximum(w, MIN_WIDTH_FRACTION)
    if tip <= 0:
        w = np.where(s >= 1.0 - 1e-9, 0.0, w)
    return w


@lru_cache(maxsize=64)
def _strip_template(k: int, pointed: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """Local faces of one strip, the segment index of each face, vertices per strip."""
    faces, seg = [], []
    quads = k - 1 if pointed else k
    for j in range(quads):
        a, b, c, d = 2 * j, 2 * j + 1, 2 * j + 2, 2 * j + 3
        faces += [(a, c, b), (b, c, d)]
        seg += [j, j]
    if pointed:
        a, b, t = 2 * (k - 1), 2 * (k - 1) + 1, 2 * k
        faces.append((a, t, b))
        seg.append(k - 1)
        nv = 2 * k + 1
    else:
        nv = 2 * k + 2
    return np.array(faces, np.int64), np.array(seg, np.int64), nv


@dataclass
class Strips:
    """A batch of strips with equal segment count, before meshing."""

    vertices: np.ndarray  # (N, nv, 3)
    centre: np.ndarray  # (N, k+1, 3)
    faces: np.ndarray  # (nf, 3) local template
    face_seg: np.ndarray  # (nf,) segment index per template face
    k: int

    @property
    def n(self) -> int:
        return len(self.vertices)


def build_strips(root, phi, theta0, curvature, twist, length, widths, pointed: bool) -> Strips:
    """Vectorised strips: N centrelines leaning at ``theta0`` from vertical
    towards azimuth ``phi``, bending by a further ``curvature`` (radians) from
    root to tip, twisting by ``twist`` about the centreline; ``widths`` (N, k+1)
    are absolute full widths at the k+1 stations (the last ignored if pointed)."""
    root = np.asarray(root, np.float64)
    widths = np.asarray(widths, np.float64)
    n, k1 = widths.shape
    k = k1 - 1
    s = np.linspace(0.0, 1.0, k1)
    smid = (np.arange(k) + 0.5) / k
    th_mid = np.clip(theta0[:, None] + curvature[:, None] * smid, 0.0, MAX_THETA)
    seg_len = (length / k)[:, None]
    cph, sph = np.cos(phi)[:, None], np.sin(phi)[:, None]
    horiz = np.sin(th_mid) * seg_len
    steps = np.stack([horiz * cph, horiz * sph, np.cos(th_mid) * seg_len], axis=-1)  # (N,k,3)
    centre = np.empty((n, k1, 3))
    centre[:, 0] = root
    np.cumsum(steps, axis=1, out=centre[:, 1:])
    centre[:, 1:] += root[:, None, :]
    th = np.clip(theta0[:, None] + curvature[:, None] * s, 0.0, MAX_THETA)
    alpha = twist[:, None] * s
    ca, sa, ct, st = np.cos(alpha), np.sin(alpha), np.cos(th), np.sin(th)
    # side = cos(a) * side0 + sin(a) * (side0 x tangent), side0 = (-sin phi, cos phi, 0)
    side = np.stack([-ca * sph + sa * cph * ct, ca * cph + sa * sph * ct, -sa * st], axis=-1)
    half = (0.5 * widths)[..., None] * side
    left, right = centre - half, centre + half
    faces, face_seg, nv = _strip_template(k, pointed)
    verts = np.empty((n, nv, 3))
    m = k if pointed else k1
    verts[:, 0 : 2 * m : 2] = left[:, :m]
    verts[:, 1 : 2 * m : 2] = right[:, :m]
    if pointed:
        verts[:, 2 * k] = centre[:, k]
    return Strips(verts, centre, faces, face_seg, k)


def strips_mesh(
    strips: Strips, colour: np.ndarray, translucency: np.ndarray, specular: np.ndarray, base_shade: np.ndarray
) -> Mesh:
    """Mesh of a strip batch; per-strip colour darkened towards the base."""
    n, nv = strips.vertices.shape[:2]
    nf = len(strips.faces)
    faces = strips.faces[None, :, :] + (np.arange(n) * nv)[:, None, None]
    t = (strips.face_seg + 0.5) / strips.k
    shade = base_shade[:, None] + (1.0 - base_shade[:, None]) * np.sqrt(t)[None, :]  # (N, nf)
    albedo = np.clip(colour[:, None, :] * shade[..., None], 0.0, 1.0)
    return Mesh(
        strips.vertices.reshape(-1, 3),
        faces.reshape(-1, 3),
        np.full(n * nf, labels.GRASS, np.uint8),
        np.full(n * nf, MATERIALS["grass"], np.uint8),
        albedo.reshape(-1, 3),
        np.repeat(translucency, nf),
        np.repeat(specular, nf),
    )
