"""The four kinds of lawn plant as vectorised strip builders, and where their roots go.

A lawn patch (:func:`eden_pipe.models.grass.build_lawn_patch`) calls one builder
per species, by its preset's ``kind``: ``blade`` (grass blades), ``rosette``
(leaves spiralling from one crown), ``trifoliate`` (petioles topped by
leaflets) and ``creeper`` (stems with opposite leaf pairs). Each places its
roots with :func:`place_points` (clumps plus uniform scatter, wrapped into the
patch so neighbouring patches tile), sets them on ``height_at(x, y)`` and
builds every strip of the species in one batch; no Python loop runs per blade.
The mowing-stripe pattern (:data:`STRIPE_WIDTH`) is shared with the lawn colouring.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from eden_pipe.models.lawn_strips import build_strips, width_profile
from eden_pipe.models.presets import draw_array

STRIPE_WIDTH = 0.5


# ----------------------------------------------------------------- placement
def place_points(
    rng: np.random.Generator,
    n: int,
    x0: float,
    y0: float,
    size: float,
    clumping: float,
    clump_radius: float,
    clump_size: float,
) -> np.ndarray:
    """``n`` (x, y) points in the square, a ``clumping`` fraction of them in
    Gaussian clumps; wrapped into the square so adjacent patches tile."""
    n_clumped = int(round(n * float(np.clip(clumping, 0.0, 1.0))))
    n_clumps = max(1, int(np.ceil(n_clumped / max(1.0, clump_size))))
    centres = rng.random((n_clumps, 2)) * size
    which = rng.integers(0, n_clumps, n_clumped)
    clumped = centres[which] + rng.normal(0.0, clump_radius, (n_clumped, 2))
    uniform = rng.random((n - n_clumped, 2)) * size
    pts = np.mod(np.concatenate([clumped, uniform]), size)
    pts = np.minimum(pts, np.nextafter(size, 0.0))
    return pts + np.array([x0, y0])


def _clip_to(xy: np.ndarray, x0: float, y0: float, size: float) -> np.ndarray:
    lo = np.array([x0, y0])
    return np.clip(xy, lo, lo + np.nextafter(size, 0.0))


def _deg(x) -> float:
    return float(np.radians(x))


def _jitter(rng, n, mean, var):
    return mean + rng.normal(0.0, 1.0, n) * var


def _lengths(rng, n, preset, scale, key="length_m"):
    return draw_array(preset[key], rng, n) * scale


# ---------------------------------------------------------------- kinds
# Each builder returns ([(strips, unit_index, role, dead)], ground_strips)
# with geometry in world coordinates (roots on the terrain); the ground batch
# is always the first part.
def _stripe_sign(y: np.ndarray) -> np.ndarray:
    return np.where(np.mod(np.floor(y / STRIPE_WIDTH), 2) == 0, 1.0, -1.0)


def _build_blades(rng, n, p, x0, y0, size, trim, width_gain, params, height_at):
    xy = place_points(rng, n, x0, y0, size, p["clumping"], p["clump_radius_m"], p["clump_size"])
    root = np.column_stack([xy, _height(height_at, xy)])
    k = int(p["segments"])
    length = _lengths(rng, n, p, trim)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    theta0 = np.abs(_jitter(rng, n, _deg(p["bend_deg"]), _deg(p["bend_var_deg"])))
    curv = _jitter(rng, n, _deg(p["curvature_deg"]), _deg(p["curvature_var_deg"]))
    twist = rng.normal(0.0, _deg(p["twist_deg"]), n)
    width = p["width_m"] * width_gain * np.exp(rng.normal(0.0, p["width_var"], n))
    stripe_jitter = rng.normal(0.0, 0.45, n)  # drawn always: params never shift later draws
    if params.stripes:
        sign = _stripe_sign(xy[:, 1])
        phi = np.where(sign > 0, 0.0, np.pi) + stripe_jitter
        theta0 = theta0 + 0.25
        curv = np.abs(curv)
    dead = rng.random(n) < params.brownness
    theta0 = np.where(dead, theta0 + 0.35, theta0)
    prof = width_profile(np.linspace(0, 1, k + 1), p["shape"])
    strips = build_strips(
        root, phi, theta0, curv, twist, length, width[:, None] * prof[None, :], p["shape"]["tip"] <= 0
    )
    return [(strips, np.arange(n), "blade", dead)], strips


def _build_rosettes(rng, n, p, x0, y0, size, trim, width_gain, params, height_at):
    xy = place_points(rng, n, x0, y0, size, p["clumping"], p["clump_radius_m"], p["clump_size"])
    L, k = int(p["leaves"]), int(p["segments"])
    plant = np.repeat(np.arange(n), L)
    m = n * L
    # Leaves spiral around the crown by the golden angle, with jitter.
    phi = (rng.uniform(0, 2 * np.pi, n)[plant] + np.tile(np.arange(L), n) * 2.39996) + rng.normal(0, 0.15, m)
    r = rng.uniform(0.0, p["plant_radius_m"], m)
    lxy = xy[plant] + np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    lxy = _clip_to(lxy, x0, y0, size)
    root = np.column_stack([lxy, _height(height_at, lxy)])
    # Inner (younger) leaves are shorter and more upright.
    order = np.tile(np.arange(L), n) / max(1, L - 1)
    length = _lengths(rng, n, p, trim)[plant] * (1.0 - 0.35 * order) * np.exp(rng.normal(0, 0.12, m))
    theta0 = np.abs(_jitter(rng, m, _deg(p["bend_deg"]), _deg(p["bend_var_deg"]))) * (1.0 - 0.2 * order)
    curv = _jitter(rng, m, _deg(p["curvature_deg"]), _deg(p["curvature_var_deg"]))
    twist = rng.normal(0.0, _deg(p["twist_deg"]), m)
    width = p["width_m"] * np.exp(rng.normal(0.0, p["width_var"], m)) * (1.0 - 0.25 * order)
    prof = width_profile(np.linspace(0, 1, k + 1), p["shape"], p["petiole"], int(p["lobes"]), p["lobe_depth"])
    strips = build_strips(
        root, phi, theta0, curv, twist, length, width[:, None] * prof[None, :], p["shape"]["tip"] <= 0
    )
    dead = np.repeat(rng.random(n) < params.brownness, L)
    return [(strips, plant, "leaf", dead)], strips


def _build_trifoliate(rng, n, p, x0, y0, size, trim, width_gain, params, height_at):
    xy = place_points(rng, n, x0, y0, size, p["clumping"], p["clump_radius_m"], p["clump_size"])
    L, k, F, kl = int(p["leaves"]), int(p["segments"]), int(p["leaflets"]), int(p["leaflet_segments"])
    plant = np.repeat(np.arange(n), L)
    m = n * L
    ang = rng.uniform(0, 2 * np.pi, m)
    r = p["plant_radius_m"] * np.sqrt(rng.random(m))
    lxy = xy[plant] + np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    lxy = _clip_to(lxy, x0, y0, size)
    root = np.column_stack([lxy, _height(height_at, lxy)])
    length = _lengths(rng, m, p, trim)
    phi = rng.uniform(0, 2 * np.pi, m)
    theta0 = np.abs(_jitter(rng, m, _deg(p["bend_deg"]), _deg(p["bend_var_deg"])))
    curv = _jitter(rng, m, _deg(p["curvature_deg"]), _deg(p["curvature_var_deg"]))
    pw = np.full((m, k + 1), p["petiole_width_m"]) * np.linspace(1.0, 0.7, k + 1)[None, :]
    pet = build_strips(root, phi, theta0, curv, np.zeros(m), length, pw, False)
    # Leaflets radiate from the petiole tip, nearly horizontal.
    top = np.repeat(pet.centre[:, -1], F, axis=0)
    lphi = (
        np.repeat(rng.uniform(0, 2 * np.pi, m), F)
        + np.tile(np.arange(F) * 2 * np.pi / F, m)
        + rng.normal(0, 0.12, m * F)
    )
    lsize = np.repeat(_lengths(rng, m, p, np.sqrt(trim), "leaflet_length_m"), F) * np.exp(rng.normal(0, 0.08, m * F))
    ltheta = np.abs(_jitter(rng, m * F, _deg(p["leaflet_bend_deg"]), _deg(8.0)))
    lcurv = rng.normal(0.0, _deg(10.0), m * F)
    lprof = width_profile(np.linspace(0, 1, kl + 1), p["leaflet_shape"])
    lwidth = lsize * p["leaflet_aspect"]
    leaflets = build_strips(
        top,
        lphi,
        ltheta,
        lcurv,
        rng.normal(0, 0.15, m * F),
        lsize,
        lwidth[:, None] * lprof[None, :],
        p["leaflet_shape"]["tip"] <= 0,
    )
    dead = np.repeat(rng.random(n) < params.brownness, L)
    return [(pet, plant, "stem", dead), (leaflets, np.repeat(plant, F), "leaf", np.repeat(dead, F))], pet


def _build_creepers(rng, n, p, x0, y0, size, trim, width_gain, params, height_at):
    xy = place_points(rng, n, x0, y0, size, p["clumping"], p["clump_radius_m"], p["clump_size"])
    S, k, kl = int(p["stems"]), int(p["segments"]), int(p["leaf_segments"])
    plant = np.repeat(np.arange(n), S)
    m = n * S
    phi = rng.uniform(0, 2 * np.pi, n)[plant] + np.tile(np.arange(S) * 2 * np.pi / S, n) + rng.normal(0, 0.4, m)
    r = rng.uniform(0.0, p["plant_radius_m"], m)
    sxy = xy[plant] + np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    sxy = _clip_to(sxy, x0, y0, size)
    root = np.column_stack([sxy, _height(height_at, sxy)])
    length = _lengths(rng, m, p, trim)
    theta0 = np.abs(_jitter(rng, m, _deg(p["bend_deg"]), _deg(p["bend_var_deg"])))
    curv = _jitter(rng, m, _deg(p["curvature_deg"]), _deg(p["curvature_var_deg"]))
    sw = np.full((m, k + 1), p["stem_width_m"])
    stems = build_strips(root, phi, theta0, curv, np.zeros(m), length, sw, False)
    # Opposite leaf pairs at stem nodes 1..k, leaves shrink towards the stem tip.
    nodes = stems.centre[:, 1:]  # (m, k, 3)
    base = np.repeat(nodes.reshape(-1, 3), 2, axis=0)  # (m*k*2, 3)
    q = m * k * 2
    side = np.tile(np.array([0.5 * np.pi, -0.5 * np.pi]), m * k)
    lphi = np.repeat(phi, 2 * k) + side + rng.normal(0, 0.25, q)
    node_t = np.tile(np.repeat(np.arange(1, k + 1) / k, 2), m)
    lsize = _lengths(rng, q, p, np.sqrt(trim), "leaf_length_m") * (1.0 - 0.35 * node_t)
    ltheta = np.abs(_jitter(rng, q, _deg(p["leaf_bend_deg"]), _deg(10.0)))
    lprof = width_profile(np.linspace(0, 1, kl + 1), p["leaf_shape"], p.get("leaf_petiole", 0.0))
    lwidth = lsize * p["leaf_aspect"]
    leaves = build_strips(
        base,
        lphi,
        ltheta,
        rng.normal(0, _deg(10.0), q),
        rng.normal(0, 0.2, q),
        lsize,
        lwidth[:, None] * lprof[None, :],
        p["leaf_shape"]["tip"] <= 0,
    )
    dead = np.repeat(rng.random(n) < params.brownness, S)
    return [(stems, plant, "stem", dead), (leaves, np.repeat(plant, 2 * k), "leaf", np.repeat(dead, 2 * k))], stems


_BUILDERS = {
    "blade": _build_blades,
    "rosette": _build_rosettes,
    "trifoliate": _build_trifoliate,
    "creeper": _build_creepers,
}


def _height(height_at: Callable, xy: np.ndarray) -> np.ndarray:
    z = np.asarray(height_at(xy[:, 0].copy(), xy[:, 1].copy()), np.float64)
    return np.array(np.broadcast_to(z, (len(xy),)), np.float64)
