"""Fences: picket, panel, post-and-rail and slat, built from a ``fence_<style>`` preset.

A fence runs along +x from x = 0 to x = length, centred on y = 0, standing on
z = 0: posts at ``post_spacing_m``, then rails and the style's boards between
them; every board or post gets its own colour jitter. The presets and the
seeded entry point (``build_fence``) live in :mod:`eden_pipe.models.assets`.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.models import primitives as prim
from eden_pipe.models.asset_surface import _colour, _mesh, _piece_jitter
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.presets import draw_float


def _picket_polygon(w: float, h: float, top: str) -> np.ndarray:
    if top == "point":
        return np.array([[-w / 2, 0], [w / 2, 0], [w / 2, h - 0.6 * w], [0, h], [-w / 2, h - 0.6 * w]])
    if top == "dogear":
        c = 0.3 * w
        return np.array([[-w / 2, 0], [w / 2, 0], [w / 2, h - c], [w / 2 - c, h], [-w / 2 + c, h], [-w / 2, h - c]])
    return np.array([[-w / 2, 0], [w / 2, 0], [w / 2, h], [-w / 2, h]])


def _fence(p: dict, length: float, rng: np.random.Generator) -> Mesh:
    style = p["style"]
    p = dict(p, length=length)
    H = draw_float(p["height_m"], rng)
    post = min(p.get("post_size_m", 0.09), length)
    spacing = draw_float(p.get("post_spacing_m", 2.0), rng)
    n_sec = max(1, int(np.ceil((length - post) / spacing))) if length > 2 * post else 0
    px = np.linspace(post / 2, length - post / 2, n_sec + 1) if n_sec else np.array([length / 2])
    post_h = H * p.get("post_height", 1.0)
    pieces = []  # (V, F, pieces_count, faces_per_piece)

    def add(vf, count, fpp=12):
        pieces.append((vf[0], vf[1], count, fpp))

    add(
        prim.box_batch(
            np.column_stack([px, np.zeros(len(px)), np.full(len(px), post_h / 2)]), np.array([post, post, post_h])
        ),
        len(px),
    )
    if p.get("post_caps", False):
        cap = post / np.sqrt(2.0)  # a 4-sided lathe at 45 deg: flush with the post
        for_caps = [
            prim.lathe([cap, cap, 0.25 * cap], [post_h, post_h + 0.015, post_h + 0.04], 4, True, True, phase=np.pi / 4)
        ]
        cv, cf = for_caps[0]
        n = len(px)
        cvv = (cv[None] + np.column_stack([px, np.zeros(n), np.zeros(n)])[:, None, :]).reshape(-1, 3)
        cff = (cf[None] + (np.arange(n) * len(cv))[:, None, None]).reshape(-1, 3)
        add((cvv, cff), n, len(cf))
    if n_sec == 0:
        return _fence_mesh(pieces, p, rng)
    x0s, x1s = px[:-1] + post / 2, px[1:] - post / 2
    rail_t, rail_h = p.get("rail_thickness_m", 0.035), p.get("rail_height_m", 0.08)
    rails = np.asarray(p.get("rails", [0.25, 0.75]), np.float64)
    front = 0.0
    if style == "post_and_rail":
        # Rails nailed to the post fronts, butt-jointed at post centres.
        y = -(post / 2 + rail_t / 2)
        xa, xb = np.repeat(px[:-1], len(rails)), np.repeat(px[1:], len(rails))
        xa[np.isclose(xa, px[0])] = 0.0
        xb[np.isclose(xb, px[-1])] = length
        z = np.tile(rails * H, n_sec)
        sag = rng.normal(0, 0.008, (2, len(z)))
        add(
            prim.beam_batch(
                np.column_stack([xa + 0.001, np.full(len(z), y), z + sag[0]]),
                np.column_stack([xb - 0.001, np.full(len(z), y), z + sag[1]]),
                rail_t,
                rail_h,
            ),
            len(z),
        )
        return _fence_mesh(pieces, p, rng)
    # Rails between posts (mortised, centred on y=0).
    xa, xb = np.repeat(x0s, len(rails)), np.repeat(x1s, len(rails))
    z = np.tile(rails * H, n_sec)
    if len(z):
        add(
            prim.beam_batch(
                np.column_stack([xa, np.zeros(len(z)), z]), np.column_stack([xb, np.zeros(len(z)), z]), rail_t, rail_h
            ),
            len(z),
        )
    front = -(rail_t / 2)
    if style == "picket":
        w, gap, th = (
            p.get("picket_width_m", 0.08),
            draw_float(p.get("picket_gap_m", 0.06), rng),
            p.get("picket_thickness_m", 0.02),
        )
        ground = p.get("ground_gap_m", 0.05)
        pitch = w + gap
        xs = _fill(x0s, x1s, w, pitch)
        n = len(xs)
        hp = H - ground
        shape = _picket_polygon(w, hp, p.get("picket_top", "point"))
        poly = np.repeat(shape[None], n, axis=0)
        poly[:, :, 1] *= (1.0 + rng.normal(0, 0.005, n))[:, None]  # hand-cut heights
        origins = np.column_stack([xs, np.full(n, front - th / 2 - 0.001), np.full(n, ground)])
        k = len(shape)
        add(prim.prism_batch(poly, th, origins), n, 2 * (k - 2) + 2 * k)
    elif style == "panel":
        bw, th, overlap = (
            p.get("board_width_m", 0.1),
            p.get("board_thickness_m", 0.014),
            p.get("board_overlap_m", 0.015),
        )
        gravel = p.get("gravel_board_m", 0.15)
        cap_h = 0.025
        xs = _fill(x0s, x1s, bw, bw - overlap)
        n = len(xs)
        alt = np.where(np.arange(n) % 2 == 0, 0.0, -th * 0.6)
        zb0, zb1 = gravel, H - cap_h
        add(
            prim.box_batch(
                np.column_stack([xs, front - th / 2 - 0.001 + alt, np.full(n, (zb0 + zb1) / 2)]),
                np.column_stack([np.full(n, bw), np.full(n, th), np.full(n, zb1 - zb0)]),
            ),
            n,
        )
        span = x1s - x0s
        gb = np.column_stack([(x0s + x1s) / 2, np.full(n_sec, front - 0.015), np.full(n_sec, gravel / 2)])
        add(prim.box_batch(gb, np.column_stack([span, np.full(n_sec, 0.03), np.full(n_sec, gravel)])), n_sec)
        cap = np.column_stack([(x0s + x1s) / 2, np.full(n_sec, front - 0.6 * th), np.full(n_sec, H - cap_h / 2)])
        add(prim.box_batch(cap, np.column_stack([span, np.full(n_sec, 0.06), np.full(n_sec, cap_h)])), n_sec)
    elif style == "slat":
        sh, sg, th = (
            p.get("slat_height_m", 0.07),
            draw_float(p.get("slat_gap_m", 0.015), rng),
            p.get("slat_thickness_m", 0.018),
        )
        ground = p.get("ground_gap_m", 0.05)
        n_rows = max(1, int((H - ground) // (sh + sg)))
        zc = ground + (np.arange(n_rows) + 0.5) * (sh + sg)
        xa, xb = np.repeat(x0s, n_rows), np.repeat(x1s, n_rows)
        z = np.tile(zc, n_sec)
        add(
            prim.box_batch(
                np.column_stack([(xa + xb) / 2, np.full(len(z), front - th / 2 - 0.001), z]),
                np.column_stack([xb - xa, np.full(len(z), th), np.full(len(z), sh)]),
            ),
            len(z),
        )
    else:
        raise ValueError(f"unknown fence style {style!r}")
    return _fence_mesh(pieces, p, rng)


def _fill(x0s: np.ndarray, x1s: np.ndarray, w: float, pitch: float) -> np.ndarray:
    """Centres of width-``w`` pieces at ``pitch`` filling each [x0, x1] span, centred."""
    counts = np.maximum(0, np.floor((x1s - x0s - w) / pitch).astype(np.int64) + 1)
    counts = np.where(x1s - x0s >= w, counts, 0)
    if counts.sum() == 0:
        return np.zeros(0)
    sec = np.repeat(np.arange(len(x0s)), counts)
    k = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    used = (counts - 1) * pitch + w
    start = x0s + (x1s - x0s - used) / 2 + w / 2
    return start[sec] + k * pitch


def _fence_mesh(pieces, p: dict, rng: np.random.Generator) -> Mesh:
    base = _colour(rng, p)
    meshes = []
    for v, f, count, fpp in pieces:
        alb = np.repeat(base[None, :] * _piece_jitter(rng, count, p.get("piece_var", 0.06)), fpp, axis=0)
        meshes.append(_mesh(v, f, p.get("material", "wood"), alb, p.get("specular", 0.02)))
    mesh = Mesh.concatenate(meshes)
    if "length" in p:  # tilted rails may poke out of [0, length] by a hair
        mesh.vertices[:, 0] = np.clip(mesh.vertices[:, 0], 0.0, p["length"])
    lo = mesh.bounds()[0]
    if lo[2] < 0:  # tilted pieces may dip below ground by a hair
        mesh = mesh.transformed(np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -lo[2]], [0, 0, 0, 1]], float))
    return mesh


def _fence_asset(p: dict, rng: np.random.Generator) -> Mesh:
    return _fence(p, draw_float(p.get("length_m", 2.0), rng), rng)
