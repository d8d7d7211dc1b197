"""The bake's compiled bounce sums (:mod:`eden_pipe.render.visibility.bounce`): numba kernels that
do what its numpy code did, bit for bit, under the rules of :mod:`eden_pipe.render.visibility.kernels`
(the same float operations in the same order, sums in ``np.bincount``'s order)."""

from __future__ import annotations

import numba as nb
import numpy as np

from eden_pipe.render.prefetch import prefetch
from eden_pipe.render.visibility.kernels import kernel

# The faces a receiver's rays hit lie anywhere in tables of hundreds of MB: their rows are asked for
# (render/prefetch.py) AHEAD receivers before they are read, their probes' transfer rows half as
# far ahead, once the face rows have come (bounce_sums took 2.1 times as long without; the same values).
AHEAD = 8


@nb.njit(nogil=True, cache=True, inline="always")
def _fetch_hits_ahead(hit_face, i, stop, face_probe, exposure, translucency, transfer):
    """Ask for the rows the rays of receiver ``i + AHEAD`` (face rows) and ``i + AHEAD // 2``
    (their probes' transfer rows, 128 bytes each) will read."""
    rays = hit_face.shape[1]
    if i + AHEAD < stop:
        for r in range(rays):
            g = hit_face[i + AHEAD, r]
            if g >= 0:
                prefetch(face_probe.ctypes.data + g * face_probe.strides[0])
                prefetch(exposure.ctypes.data + g * exposure.strides[0])
                prefetch(translucency.ctypes.data + g * translucency.strides[0])
    if i + AHEAD // 2 < stop:
        for r in range(rays):
            g = hit_face[i + AHEAD // 2, r]
            if g >= 0:
                for side in range(2):
                    row = transfer.ctypes.data + face_probe[g, side] * transfer.strides[0]
                    prefetch(row)
                    prefetch(row + 64)


@kernel
def bounce_weights(hit_face, hit_back, start, stop, albedo, multi, face_probe):
    """The blocked rays of receivers ``start:stop`` in order: their albedo times the multi-bounce
    factor of the probe they hit (``bounce_transfer``'s ``weight_rgb``, float64 (N, 3))."""
    count = 0
    for i in range(start, stop):
        for r in range(hit_face.shape[1]):
            if hit_face[i, r] >= 0:
                count += 1
    out = np.empty((count, 3))
    j = 0
    for i in range(start, stop):
        for r in range(hit_face.shape[1]):
            f = hit_face[i, r]
            if f >= 0:
                near = face_probe[f, 1 if hit_back[i, r] else 0]
                for k in range(3):
                    out[j, k] = albedo[f, k] * multi[near, k]
                j += 1
    return out


@kernel
def add_hit_light(acc, weight, f, b, translucency, face_probe, transfer, exposure):
    """``acc`` (terms,) += ``weight`` times the light of side ``b`` of face ``f`` as a bounce ray
    meets it: its probe's transfer times its exposure, plus the light through it (the other side's
    times its translucency). The one formula of the probes' and the cameras' bounce sums."""
    near, far = face_probe[f, b], face_probe[f, 1 - b]
    through = translucency[f] * exposure[f, 1 - b]
    for k in range(acc.shape[0]):
        acc[k] += weight * (transfer[near, k] * exposure[f, b] + through * transfer[far, k])


@kernel
def bounce_sums(
    hit_face, hit_back, start, stop, weight_rgb, weight, translucency, face_probe, transfer, exposure, bounce, tint
):
    """``bounce_transfer``'s per-receiver sums over the blocked rays of receivers ``start:stop``
    (``weight_rgb``, ``weight``: theirs from :func:`bounce_weights` and its luma), ray by ray as
    ``np.bincount`` adds them: the hit side's light (its probe's transfer times its exposure, plus
    the light through it) times the weight, over every ray (float32 ``bounce``, as the float64
    mean cast), and the weights (``tint``, float64)."""
    j = 0
    n_terms = transfer.shape[1]
    rays = hit_face.shape[1]
    acc = np.zeros(n_terms)
    acc_rgb = np.zeros(3)
    for i in range(start, stop):
        _fetch_hits_ahead(hit_face, i, stop, face_probe, exposure, translucency, transfer)
        acc[:] = 0.0
        acc_rgb[:] = 0.0
        for r in range(rays):
            f = hit_face[i, r]
            if f < 0:
                continue
            add_hit_light(acc, weight[j], f, 1 if hit_back[i, r] else 0, translucency, face_probe, transfer, exposure)
            for k in range(3):
                acc_rgb[k] += weight_rgb[j, k]
            j += 1
        for k in range(n_terms):
            bounce[i, k] = np.float32(acc[k] / rays)
        tint[i, :] = acc_rgb


@kernel
def seen_bounce_blend(
    order, starts, first, last, probe_of, hit_face, hit_back, albedo, factor, luma, translucency, face_probe,
    transfer, exposure, samples, prior, rows, sun_rows, tint, done,
):  # fmt: skip
    """``bounce.camera_bounce``'s rows of the probes of runs ``first:last`` (run r: the rays
    ``order[starts[r]:starts[r + 1]]``, the rays sorted by probe, one probe a run), in place: ray
    ``order[i]`` from a point of a side of probe ``probe_of[.]`` met side ``hit_back[.]`` of face
    ``hit_face[.]``; its albedo times the hit probe's ``factor`` (luma by ``luma``) times that side's
    light (its probe's transfer times its exposure, plus the light through it), summed per probe in
    float64; then each probe with ``samples`` camera points becomes ``(sum + prior * row) /
    (samples + prior)``, rounded once to float32, and is marked ``done``. ``sun_rows`` (P, terms),
    not empty: the same with a factor of 1 (the sun's table), from the same pass over the hits. With
    ``tint`` (P, 3), not empty: each such probe's colour (luma 1) becomes that of those hits
    weighted by their light under an even sky (band 0 of it), shrunk toward its own by the prior
    alike. Runs are independent: threads may take disjoint ones (:func:`seen_bounce_unseen` after)."""
    n_terms = rows.shape[1]
    acc = np.zeros(n_terms)
    acc_sun = np.zeros(n_terms)
    rho = np.zeros(3)  # a hit's albedo times its probe's factor
    colour = np.zeros(3)
    light = np.zeros(1)  # a hit's band-0 light
    with_tint = tint.shape[0] > 0
    with_sun = sun_rows.shape[0] > 0
    for run in range(first, last):
        p = probe_of[order[starts[run]]]
        acc[:] = 0.0
        acc_sun[:] = 0.0
        colour[:] = 0.0
        lit = 0.0
        for i in range(starts[run], starts[run + 1]):
            j = order[i]
            f = hit_face[j]
            b = 1 if hit_back[j] else 0
            weight = 0.0
            for k in range(3):
                rho[k] = albedo[f, k] * factor[face_probe[f, b], k]
                weight += rho[k] * luma[k]
            add_hit_light(acc, weight, f, b, translucency, face_probe, transfer, exposure)
            if with_tint:
                light[0] = 0.0
                add_hit_light(light, 1.0, f, b, translucency, face_probe, transfer, exposure)
                lit += weight * light[0]
                for k in range(3):
                    colour[k] += rho[k] * light[0]
            if with_sun:
                weight = 0.0
                for k in range(3):
                    weight += (albedo[f, k] * 1.0) * luma[k]
                add_hit_light(acc_sun, weight, f, b, translucency, face_probe, transfer, exposure)
        for k in range(n_terms):
            rows[p, k] = np.float32((acc[k] + prior * np.float64(rows[p, k])) / (samples[p] + prior))
        if with_sun:
            for k in range(n_terms):
                sun_rows[p, k] = np.float32((acc_sun[k] + prior * np.float64(sun_rows[p, k])) / (samples[p] + prior))
        if with_tint and lit > 0.0:
            pseudo = prior * lit / samples[p]  # the prior's rays at these rays' mean light
            for k in range(3):
                tint[p, k] = (colour[k] + pseudo * tint[p, k]) / (lit + pseudo)
        done[p] = True


@kernel
def seen_bounce_unseen(samples, done, prior, rows):
    """After :func:`seen_bounce_blend`: the probes with camera points none of whose sky rays met a
    surface (all escaped) shrink their ``rows`` toward nothing by the prior alike."""
    n_terms = rows.shape[1]
    for p in range(rows.shape[0]):
        if samples[p] > 0 and not done[p]:
            for k in range(n_terms):
                rows[p, k] = np.float32(prior * np.float64(rows[p, k]) / (samples[p] + prior))
