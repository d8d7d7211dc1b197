"""The bounce transfer: the light a receiver (a probe, a ground-map node) gets from what its rays hit.

Shared by the bake's probes (:mod:`eden_pipe.render.visibility.bake`) and the
ground map's nodes (:mod:`eden_pipe.render.visibility.ground_map`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe.colour import LUMA
from eden_pipe.render import sh
from eden_pipe.render.visibility import bounce_kernels

LUMA_F32 = LUMA.astype(np.float32)  # the bake sums with float32 weights (float64 ones change its last bits)


def bounce_transfer(
    mesh,
    hit_face: np.ndarray,
    hit_back: np.ndarray,
    multi: np.ndarray,
    face_probe: np.ndarray,
    transfer: np.ndarray,
    exposure: np.ndarray,
    map_chunks=None,
    sun_multi: bool = False,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bounce (R, 16) float32, sun's bounce (R, 16) float32, tint (R, 3)) of R receivers from what
    their cosine rays hit (``hit_face`` (R, rays), -1 where a ray escaped; ``hit_back`` the side of
    the hit face facing the receiver): the hit face side's light as seen from the receiver (see the
    module doc). ``multi`` (P, 3) is each probe's multi-bounce factor, applied where it is hit, in
    the bounce of sky light; the sun's bounce leaves it out (the surfaces around a sunlit one are not
    all sunlit, docs/realism.md) unless ``sun_multi`` (then it is the same table). Both take the same
    tint. Receivers in blocks (``map_chunks``: ``RayTracer.map_chunks``, every core; None: one
    block), each summed over its blocked rays in ray order (:mod:`eden_pipe.render.visibility.bounce_kernels`)."""
    n_recv, rays = hit_face.shape
    bounce = np.zeros((n_recv, sh.COUNT), np.float32)  # the mean over the rays, cast as the bake's tables are
    sun_bounce = bounce if sun_multi else np.zeros((n_recv, sh.COUNT), np.float32)
    tint = np.zeros((n_recv, 3))
    tables = [(multi, bounce, tint)]
    if not sun_multi:  # the sun's colour sums are dropped: both bounces take the tint of the first
        tables.append((np.ones_like(multi), sun_bounce, np.zeros((n_recv, 3))))

    def block(a: int, b: int) -> None:
        for factor, out, out_tint in tables:
            weight_rgb = bounce_kernels.bounce_weights(hit_face, hit_back, a, b, mesh.albedo, factor, face_probe)
            weight = weight_rgb @ LUMA_F32  # BLAS's sums, as over every receiver at once
            bounce_kernels.bounce_sums(
                hit_face,
                hit_back,
                a,
                b,
                weight_rgb,
                weight,
                mesh.translucency,
                face_probe,
                transfer,
                exposure,
                out,
                out_tint,
            )

    if rays:
        (map_chunks or (lambda fn, n: fn(0, n)))(block, n_recv)
    tint_luma = tint @ LUMA_F32
    tint = np.where(tint_luma[:, None] > 1e-9, tint / np.maximum(tint_luma, 1e-9)[:, None], 1.0)
    return bounce, sun_bounce, tint


@dataclass
class SeenRays:
    """The camera gain's sky rays that met a surface (``bake.camera_gain``), kept for
    :func:`camera_bounce`: the probe of the side each started from, the face it met and that face's
    side facing it (1 along the winding normal); and per probe, its camera points (every sky ray)."""

    probe: np.ndarray  # (B,) int32
    hit_face: np.ndarray  # (B,) int32
    hit_back: np.ndarray  # (B,) bool
    samples: np.ndarray  # (P,) float64


def camera_bounce(
    mesh,
    seen: SeenRays,
    multi: np.ndarray,
    face_probe: np.ndarray,
    transfer: np.ndarray,
    exposure: np.ndarray,
    bounce: np.ndarray,
    sun_bounce: np.ndarray,
    prior_rays: float,
    tint: np.ndarray | None = None,
    map_chunks=None,
) -> None:
    """The bounce of the points cameras see, in place of each probe's (``bounce`` and the sun's
    ``sun_bounce``, (P, 16) float32): its camera points' one sky ray each (what a blocked one met, lit
    as :func:`bounce_transfer` lights it; an escaped one adds nothing), shrunk toward the probe's own
    rays' value by ``prior_rays`` pseudo-rays. A camera sees the open side of a hedge or a leaf,
    whose neighbours are the lit ones, while a probe's rays leave every side of its cell, the shaded
    insides too: at the cameras' points the reference's bounce was about twice the probe's
    (docs/realism.md, Bounce). The sun's table leaves the multi-bounce factor out; ``sun_bounce is
    bounce`` (``sun_multi``) keeps them one table. Rewritten probe by probe: no (P, 16) temporaries
    (the bake's peak memory, docs/scale-out.md).

    ``tint`` (P, 3), the probes' colours (luma 1, :func:`bounce_transfer`'s), in place: a probe the
    cameras' rays light takes the colour of what they meet, each hit weighted by its light under an
    even sky (shrunk toward its own alike). The tables are luma; a probe's own colour is the mean
    albedo of every surface its rays meet, lit or not, which under-counts a lit neighbour whose
    colour is not the leaves' (docs/realism.md, The bounce of the points cameras see)."""
    order = np.argsort(seen.probe, kind="stable")
    luma = LUMA_F32.astype(np.float64)
    # One run of rays a probe; runs are independent, so the cores take disjoint ones. The sun's
    # table (a factor of 1) is summed in the same pass over the hits as the first.
    ordered = np.take(seen.probe, order)
    starts = np.flatnonzero(np.r_[True, ordered[1:] != ordered[:-1], True]).astype(np.int64)
    sun_rows = np.zeros((0, bounce.shape[1]), np.float32) if sun_bounce is bounce else sun_bounce
    no_tint = np.zeros((0, 3))
    done = np.zeros(len(bounce), np.bool_)

    def block(first: int, last: int) -> None:
        bounce_kernels.seen_bounce_blend(
            order, starts, first, last, seen.probe, seen.hit_face, seen.hit_back, mesh.albedo, multi, luma,
            mesh.translucency, face_probe, transfer, exposure, seen.samples, np.float64(prior_rays), bounce,
            sun_rows, tint if tint is not None else no_tint, done,
        )  # fmt: skip

    runs = len(starts) - 1 if len(order) else 0
    (map_chunks or (lambda fn, n: fn(0, n)))(block, runs)
    for rows in [bounce] if sun_bounce is bounce else [bounce, sun_bounce]:
        bounce_kernels.seen_bounce_unseen(seen.samples, done, np.float64(prior_rays), rows)
