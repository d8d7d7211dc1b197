"""The bounce transfer: the light a receiver (a probe, a ground-map node) gets from what its rays hit.

Shared by the bake's probes (:mod:`eden_pipe.render.visibility.bake`) and the
ground map's nodes (:mod:`eden_pipe.render.visibility.ground_map`).
"""

from __future__ import annotations

import numpy as np

from eden_pipe.colour import LUMA
from eden_pipe.render import sh
from eden_pipe.render.visibility import RAYS_PER_WAVE

LUMA_F32 = LUMA.astype(np.float32)  # the bake sums with float32 weights (float64 ones change its last bits)


def bounce_transfer(
    mesh,
    hit_face: np.ndarray,
    hit_back: np.ndarray,
    multi: np.ndarray,
    face_probe: np.ndarray,
    transfer: np.ndarray,
    exposure: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """(bounce (R, 16), tint (R, 3)) of R receivers from what their cosine rays hit (``hit_face``
    (R, rays), -1 where a ray escaped; ``hit_back`` the side of the hit face facing the receiver):
    the hit face side's light as seen from the receiver (see the module doc); ``multi`` (P, 3) is each
    probe's multi-bounce factor, applied where it is hit. In waves of bounded memory."""
    n_recv, rays = hit_face.shape
    bounce = np.zeros((n_recv, sh.COUNT))
    tint = np.zeros((n_recv, 3))
    per_wave = max(1, RAYS_PER_WAVE // max(rays, 1))
    for p0 in range(0, n_recv if rays else 0, per_wave):
        p1 = min(n_recv, p0 + per_wave)
        f = hit_face[p0:p1].ravel()
        rows = np.repeat(np.arange(p1 - p0), rays)
        blocked = f >= 0
        f, b, rows = f[blocked], hit_back[p0:p1].ravel()[blocked].astype(np.int64), rows[blocked]
        near, far = face_probe[f, b], face_probe[f, 1 - b]
        weight_rgb = mesh.albedo[f] * multi[near]
        light = (
            transfer[near] * exposure[f, b][:, None]
            + (mesh.translucency[f] * exposure[f, 1 - b])[:, None] * transfer[far]
        )
        weight = weight_rgb @ LUMA_F32
        for k in range(sh.COUNT):
            bounce[p0:p1, k] = np.bincount(rows, weights=weight * light[:, k], minlength=p1 - p0)
        for k in range(3):
            tint[p0:p1, k] = np.bincount(rows, weights=weight_rgb[:, k], minlength=p1 - p0)
    bounce /= max(rays, 1)
    tint_luma = tint @ LUMA_F32
    tint = np.where(tint_luma[:, None] > 1e-9, tint / np.maximum(tint_luma, 1e-9)[:, None], 1.0)
    return bounce, tint
