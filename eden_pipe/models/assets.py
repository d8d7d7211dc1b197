"""Garden assets (rocks, pots, planters, bench, bird bath, stone lantern) and fences.

Every asset type is a YAML preset under ``conf/species/assets/<name>.yaml``
whose ``family`` picks a builder here; sizes come from the preset's ranges
and colours from its linear-RGB ``color``/``colors`` with a per-instance
jitter (``color_var`` brightness, ``hue_var`` per channel) and a smaller
per-piece jitter (each board, facet or stone gets its own tone).

Model frame: Z up, base centred at the origin, resting on z = 0 (rocks are
partially sunk: their lowest point is slightly below 0). Fences run along +x
from x = 0 to x = length, centred on y = 0. Every face is semantic 7
(``labels.OBSTACLE``).

Randomness: ``build_asset(t, seed)`` draws from ``rng_for(seed, "asset", t)``
and ``build_fence(style, length, seed)`` from ``rng_for(seed, "fence", style)``,
so the same call is byte-identical in every process. The fence geometry is in
:mod:`eden_pipe.models.fences`, the colour and mesh helpers shared with it in
:mod:`eden_pipe.models.asset_surface`.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.errors import ConfigError
from eden_pipe.models import primitives as prim
from eden_pipe.models.asset_surface import OBSTACLE, _colour, _mesh, _piece_jitter
from eden_pipe.models.fences import _fence, _fence_asset, _fence_mesh, _fill, _picket_polygon  # noqa: F401  (moved; callers import it from here)
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.noise import Perlin
from eden_pipe.models.presets import draw_float, load_preset, preset_source
from eden_pipe.models.species import list_species
from eden_pipe.rng import rng_for

KIND = "assets"
DIRT = np.array([0.05, 0.035, 0.02])
MOSS = np.array([0.05, 0.08, 0.025])
FENCE_STYLES = ("picket", "panel", "post_and_rail", "slat")


# ------------------------------------------------------------------ helpers
def list_asset_types() -> list[str]:
    """Every asset preset name (fence presets included, as ``fence_<style>``)."""
    return list_species(KIND)


def list_fence_styles() -> list[str]:
    return [n[len("fence_") :] for n in list_asset_types() if n.startswith("fence_")]


def _centre_footprint_on_ground(mesh: Mesh) -> Mesh:
    """Centre the footprint on the origin and put the lowest point at z = 0."""
    lo, hi = mesh.bounds()
    m = np.eye(4)
    m[:3, 3] = [-(lo[0] + hi[0]) / 2, -(lo[1] + hi[1]) / 2, -lo[2]]
    return mesh.transformed(m)


# ------------------------------------------------------------------ rocks
def _rock(p: dict, rng: np.random.Generator) -> Mesh:
    size = draw_float(p["size_m"], rng)
    axes = (
        np.array([size, size * draw_float(p.get("aspect_y", 1.0), rng), size * draw_float(p.get("aspect_z", 0.7), rng)])
        / 2
    )
    style = p.get("style", "round")
    perlin = Perlin(rng)
    offset = rng.uniform(0.0, 64.0, 3)
    if style == "round":
        v, f = prim.icosphere(int(p.get("subdivisions", 3)))
        d = perlin.fbm(v * p.get("noise_freq", 1.5) + offset, int(p.get("octaves", 4)))
        v = v * (1.0 + p.get("noise_amp", 0.2) * d)[:, None]
    elif style == "faceted":
        n = int(p.get("points", 30))
        dirs = rng.normal(size=(n, 3))
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
        v, f = prim.convex_hull(dirs * rng.uniform(0.7, 1.0, (n, 1)))
        d = np.zeros(len(v))
    else:
        raise ValueError(f"unknown rock style {style!r}; allowed: round, faceted")
    v = v * axes
    yaw = rng.uniform(0, 2 * np.pi)
    v = v @ prim.rotation_z(yaw).T
    z = v[:, 2]
    lo, hi = z.min(), z.max()
    if p.get("flatten_bottom", 0.0) > 0:
        z = np.maximum(z, lo + p["flatten_bottom"] * (hi - lo))
    if p.get("flatten_top", 0.0) > 0:
        z = np.minimum(z, hi - p["flatten_top"] * (hi - lo))
    v[:, 2] = z
    height = z.max() - z.min()
    v[:, 2] -= z.min() + p.get("sink", 0.1) * height
    v[:, :2] -= 0.5 * (v[:, :2].min(0) + v[:, :2].max(0))

    # Colour: instance tone, darker crevices, per-facet jitter, moss on top.
    base = _colour(rng, p)
    df = d[f].mean(1)
    albedo = base[None, :] * np.clip(1.0 + 0.4 * df, 0.6, 1.3)[:, None]
    albedo = albedo * _piece_jitter(rng, len(f), p.get("facet_var", 0.05))
    cen = v[f].mean(1)
    nrm = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-20)
    moss = float(p.get("moss", 0.0))
    if moss > 0:
        m = perlin.fbm(cen / max(size, 1e-3) * 3.0 + offset[::-1], 3)
        cover = np.clip((nrm[:, 2] - 0.3) * 2.0, 0, 1) * np.clip((m + moss - 0.35) * 4.0, 0, 1) * rng.uniform(0.3, 1.0)
        albedo = albedo * (1 - cover[:, None]) + MOSS * cover[:, None]
    return _mesh(v, f, "rock", albedo, p.get("specular", 0.04))


# ------------------------------------------------------------------ pots
def _pot(p: dict, rng: np.random.Generator) -> Mesh:
    h = draw_float(p["height_m"], rng)
    rt = 0.5 * h * draw_float(p.get("top_ratio", 1.0), rng)  # outer radius under the rim
    rb = rt * draw_float(p.get("base_ratio", 0.72), rng)
    rim_h = h * draw_float(p.get("rim_height", 0.16), rng)
    rim_out = max(0.006, rt * draw_float(p.get("rim_out", 0.08), rng))
    wall = max(0.006, rt * p.get("wall", 0.07))
    soil = h * draw_float(p.get("soil_depth", 0.12), rng)
    belly = draw_float(p.get("belly", 0.0), rng)
    seg = int(p.get("segments", 32))
    body_top = h - rim_h
    t = np.linspace(0.0, 1.0, 7 if belly > 0 else 2)
    r_out = rb + (rt - rb) * t + belly * rt * np.sin(np.pi * t)
    z_out = body_top * t
    r_rim = rt + rim_out
    soil_z = h - soil
    r_in_top = rt - wall
    # Inner radius at soil level follows the taper of the outside wall.
    r_in_soil = max(0.3 * rt, np.interp(soil_z, z_out, r_out) - wall)
    radii = np.concatenate([r_out, [r_rim, r_rim, r_in_top, r_in_soil]])
    heights = np.concatenate([z_out, [body_top, h, h, soil_z]])
    v, f = prim.lathe(radii, heights, seg, cap_bottom=True, cap_top=True, phase=rng.uniform(0, 2 * np.pi))
    n_soil = seg  # the top cap (soil) is the last fan
    base = _colour(rng, p)
    zc = v[f].mean(1)[:, 2]
    # Terracotta darkens towards the damp base; glazed pots stay even.
    grad = 1.0 - p.get("base_darkening", 0.2) * np.clip(1.0 - zc / h, 0, 1) ** 2
    albedo = base[None, :] * grad[:, None]
    albedo[-n_soil:] = DIRT * np.exp(rng.normal(0, 0.1))
    mesh = Mesh(v, f, np.full(len(f), OBSTACLE), np.full(len(f), 0), np.clip(albedo, 0, 1))
    mat = np.full(len(f), _mat(p.get("material", "terracotta")), np.uint8)
    mat[-n_soil:] = _mat("dirt")
    spec = np.full(len(f), p.get("specular", 0.02), np.float32)
    spec[-n_soil:] = 0.0
    return mesh.with_attributes(material=mat, specular=spec)


def _mat(name: str) -> int:
    from eden_pipe.models.mesh import MATERIALS

    return MATERIALS[name]


# ------------------------------------------------------------------ planters
def _planter(p: dict, rng: np.random.Generator) -> Mesh:
    L, W, H = draw_float(p["length_m"], rng), draw_float(p["width_m"], rng), draw_float(p["height_m"], rng)
    t = p.get("board_thickness_m", 0.022)
    n_boards = max(1, int(round(H / p.get("board_height_m", 0.12))))
    bh = H / n_boards
    legs = draw_float(p.get("leg_height_m", 0.0), rng)
    z0 = legs + (t if legs > 0 else 0.0)
    zc = z0 + (np.arange(n_boards) + 0.5) * bh
    gap = 0.004
    # Long walls span the full length; short walls fit between them.
    cx = np.concatenate(
        [np.zeros(n_boards), np.zeros(n_boards), np.full(n_boards, -L / 2 + t / 2), np.full(n_boards, L / 2 - t / 2)]
    )
    cy = np.concatenate(
        [np.full(n_boards, -W / 2 + t / 2), np.full(n_boards, W / 2 - t / 2), np.zeros(n_boards), np.zeros(n_boards)]
    )
    cz = np.tile(zc, 4)
    sx = np.concatenate([np.full(2 * n_boards, L), np.full(2 * n_boards, t)])
    sy = np.concatenate([np.full(2 * n_boards, t), np.full(2 * n_boards, W - 2 * t - 0.002)])
    sz = np.full(4 * n_boards, bh - gap)
    boards = prim.box_batch(np.column_stack([cx, cy, cz]), np.column_stack([sx, sy, sz]))
    post = p.get("post_size_m", 0.045)
    px, py = L / 2 - t - post / 2 - 0.001, W / 2 - t - post / 2 - 0.001
    corners = np.array([[-px, -py], [px, -py], [-px, py], [px, py]])
    posts = prim.box_batch(np.column_stack([corners, np.full(4, z0 + H / 2)]), np.array([post, post, H]))
    parts = [boards, posts]
    if legs > 0:
        lx, ly = L / 2 - post / 2 - 0.01, W / 2 - post / 2 - 0.01
        leg_xy = np.array([[-lx, -ly], [lx, -ly], [-lx, ly], [lx, ly]])
        parts.append(prim.box_batch(np.column_stack([leg_xy, np.full(4, legs / 2)]), np.array([post, post, legs])))
        parts.append(prim.box_batch([[0, 0, legs + t / 2]], [[L, W, t]]))
    v_wood, f_wood = prim.merge(parts)
    base = _colour(rng, p)
    n_pieces = len(f_wood) // 12
    wood_alb = np.repeat(base[None, :] * _piece_jitter(rng, n_pieces, p.get("piece_var", 0.08)), 12, axis=0)
    wood = _mesh(v_wood, f_wood, "wood", wood_alb, p.get("specular", 0.02))
    soil_top = z0 + H - draw_float(p.get("soil_depth_m", 0.04), rng)
    sv, sf = prim.box_batch([[0, 0, (z0 + soil_top) / 2]], [[L - 2 * t - 0.004, W - 2 * t - 0.004, soil_top - z0]])
    soil = _mesh(sv, sf, "dirt", DIRT * np.exp(rng.normal(0, 0.1)))
    return _centre_footprint_on_ground(Mesh.concatenate([wood, soil]))


# ------------------------------------------------------------------ bench
def _bench(p: dict, rng: np.random.Generator) -> Mesh:
    L = draw_float(p["length_m"], rng)
    seat_h = draw_float(p.get("seat_height_m", 0.45), rng)
    depth = draw_float(p.get("depth_m", 0.45), rng)
    n_seat = int(p.get("seat_slats", 5))
    st = p.get("slat_thickness_m", 0.03)
    slat_w = depth / n_seat * 0.82
    ys = -depth / 2 + (np.arange(n_seat) + 0.5) * depth / n_seat
    seat = prim.box_batch(
        np.column_stack([np.zeros(n_seat), ys, np.full(n_seat, seat_h - st / 2)]), np.array([L, slat_w, st])
    )
    wood_parts = [seat]
    fx = L / 2 - p.get("frame_inset_m", 0.1)
    xs = np.array([-fx, fx] + ([0.0] if L > 1.5 else []))
    nf = len(xs)
    leg = p.get("leg_size_m", 0.045)
    rail_z = seat_h - st - 0.02
    metal = []
    back = bool(p.get("back", True))
    back_top = draw_float(p.get("back_height_m", 0.85), rng)
    yb0, yb1 = depth / 2 - leg / 2, depth / 2 + draw_float(p.get("back_lean_m", 0.1), rng)
    # Front legs and seat rails.
    metal.append(
        prim.box_batch(
            np.column_stack([xs, np.full(nf, -depth / 2 + leg / 2 + 0.02), np.full(nf, rail_z / 2)]),
            np.array([leg, leg, rail_z]),
        )
    )
    metal.append(
        prim.beam_batch(
            np.column_stack([xs, np.full(nf, -depth / 2), np.full(nf, rail_z - 0.015)]),
            np.column_stack([xs, np.full(nf, yb0), np.full(nf, rail_z - 0.015)]),
            leg * 0.8,
            0.03,
        )
    )
    if back:
        # Back legs run up to the backrest top, leaning back.
        top = np.column_stack([xs, np.full(nf, yb1), np.full(nf, back_top)])
        metal.append(
            prim.beam_batch(np.column_stack([xs, np.full(nf, yb0), np.zeros(nf)]), top, leg, leg, up=(1.0, 0.0, 0.0))
        )
        n_back = int(p.get("back_slats", 3))
        zb = np.linspace(seat_h + 0.1, back_top - 0.05, n_back)
        yz = yb0 + (yb1 - yb0) * zb / back_top - leg / 2 - 0.013
        tilt = np.array([0.0, yb1 - yb0, back_top])
        tilt /= np.linalg.norm(tilt)
        bw = min(0.09, (back_top - seat_h - 0.1) / n_back * 0.8)
        wood_parts.append(
            prim.beam_batch(
                np.column_stack([np.full(n_back, -L / 2 + 0.03), yz, zb]),
                np.column_stack([np.full(n_back, L / 2 - 0.03), yz, zb]),
                0.025,
                bw,
                up=tuple(tilt),
            )
        )
        if p.get("arms", True):
            arm_z = seat_h + 0.22
            ax = np.array([-fx, fx])
            ya = yb0 + (yb1 - yb0) * arm_z / back_top
            metal.append(
                prim.beam_batch(
                    np.column_stack([ax, np.full(2, -depth / 2 - 0.03), np.full(2, arm_z)]),
                    np.column_stack([ax, np.full(2, ya), np.full(2, arm_z)]),
                    0.05,
                    0.03,
                )
            )
            metal.append(
                prim.beam_batch(
                    np.column_stack([ax, np.full(2, -depth / 2 + 0.04), np.full(2, seat_h - st)]),
                    np.column_stack([ax, np.full(2, -depth / 2 + 0.0), np.full(2, arm_z - 0.015)]),
                    0.035,
                    0.035,
                    up=(1.0, 0.0, 0.0),
                )
            )
    else:
        metal.append(
            prim.box_batch(
                np.column_stack([xs, np.full(nf, depth / 2 - leg / 2 - 0.02), np.full(nf, rail_z / 2)]),
                np.array([leg, leg, rail_z]),
            )
        )
    v_w, f_w = prim.merge(wood_parts)
    wood_alb = np.repeat(
        _colour(rng, p)[None, :] * _piece_jitter(rng, len(f_w) // 12, p.get("piece_var", 0.06)), 12, axis=0
    )
    v_m, f_m = prim.merge(metal)
    mesh = Mesh.concatenate(
        [
            _mesh(v_w, f_w, "wood", wood_alb, 0.03),
            _mesh(v_m, f_m, "metal", _colour(rng, p, "frame_color"), p.get("frame_specular", 0.25)),
        ]
    )
    return _centre_footprint_on_ground(mesh)


# ------------------------------------------------------------- stone pieces
def _bird_bath(p: dict, rng: np.random.Generator) -> Mesh:
    s = draw_float(p.get("scale", 1.0), rng)
    H = draw_float(p["height_m"], rng) * s
    R = draw_float(p["bowl_radius_m"], rng) * s
    rb, rp = 0.6 * R, 0.22 * R
    zs = np.array([0.0, 0.06, 0.08, 0.12, 0.80, 0.88, 0.94, 1.0, 1.0, 0.97, 0.93]) * H
    rs = np.array([rb, rb, rb * 0.85, rp * 1.1, rp, rp * 1.6, R * 0.85, R, R - 0.025 * s, R * 0.75, R * 0.35])
    v, f = prim.lathe(rs, zs, int(p.get("segments", 32)), cap_bottom=True, cap_top=True)
    base = _colour(rng, p)
    zc = v[f].mean(1)[:, 2]
    alb = base[None, :] * (0.8 + 0.2 * np.clip(zc / H, 0, 1))[:, None] * _piece_jitter(rng, len(f), 0.03)
    return _mesh(v, f, "rock", alb, 0.03)


def _stone_lantern(p: dict, rng: np.random.Generator) -> Mesh:
    s = draw_float(p.get("scale", 1.0), rng)
    parts = [
        prim.lathe([0.20, 0.20, 0.16], [0.0, 0.07, 0.09], 6, True, True),  # hexagonal base
        prim.lathe([0.075, 0.065], [0.09, 0.50], 16, True, True),  # shaft
        prim.lathe([0.12, 0.18, 0.18], [0.50, 0.55, 0.59], 6, True, True),  # platform
        prim.lathe([0.13, 0.13], [0.59, 0.79], 4, True, True, phase=np.pi / 4),  # light box
        prim.lathe([0.26, 0.27, 0.07], [0.79, 0.82, 0.95], 6, True, True),  # roof
        prim.lathe([0.03, 0.05, 0.045, 0.015], [0.95, 0.97, 1.01, 1.05], 12, True, True),  # finial
    ]
    v, f = prim.merge(parts)
    v = v * s
    base = _colour(rng, p)
    zc = v[f].mean(1)[:, 2] / s
    alb = base[None, :] * (0.8 + 0.2 * zc)[:, None] * _piece_jitter(rng, len(f), 0.04)
    stone = _mesh(v, f, "rock", alb, 0.03)
    # Dark window openings on two sides of the light box.
    wv, wf = prim.box_batch(np.array([[0.0, 0.0, 0.69]]) * s, np.array([[0.19, 0.10, 0.10]]) * s)
    wv2, wf2 = prim.box_batch(np.array([[0.0, 0.0, 0.69]]) * s, np.array([[0.10, 0.19, 0.10]]) * s)
    wv3, wf3 = prim.merge([(wv, wf), (wv2, wf2)])
    window = _mesh(wv3, wf3, "generic", np.array([0.015, 0.013, 0.012]))
    return Mesh.concatenate([stone, window])


# ------------------------------------------------------------------ fences
# The builders are in eden_pipe.models.fences; the seeded entry point stays here, next to the presets.
def build_fence(style: str, length: float, seed: int) -> Mesh:
    """A fence of the given style along +x from x=0 to x=length, centred on
    y=0, standing on z=0. Styles: the ``fence_<style>`` asset presets."""
    if style not in list_fence_styles():
        raise KeyError(f"unknown fence style {style!r}; allowed: {', '.join(list_fence_styles())}")
    if not length > 0:
        raise ValueError(f"fence length must be > 0, got {length}")
    p = asset_preset(f"fence_{style}")
    return _fence(p, float(length), rng_for(seed, "fence", style))


# ------------------------------------------------------------------ entry
#: A preset's ``family`` -> the function that builds it from the preset and a generator.
ASSET_BUILDERS = {
    "rock": _rock,
    "pot": _pot,
    "planter": _planter,
    "bench": _bench,
    "bird_bath": _bird_bath,
    "stone_lantern": _stone_lantern,
    "fence": _fence_asset,
}


#: Keys every asset preset may use, then the keys each family reads.
COMMON_KEYS = {"name", "family", "color", "colors", "color_var", "hue_var", "piece_var", "specular"}
FAMILY_KEYS = {
    "rock": {
        "style",
        "size_m",
        "aspect_y",
        "aspect_z",
        "noise_amp",
        "noise_freq",
        "octaves",
        "subdivisions",
        "flatten_top",
        "flatten_bottom",
        "sink",
        "points",
        "facet_var",
        "moss",
    },
    "pot": {
        "material",
        "height_m",
        "top_ratio",
        "base_ratio",
        "rim_height",
        "rim_out",
        "belly",
        "wall",
        "soil_depth",
        "base_darkening",
        "segments",
    },
    "planter": {
        "length_m",
        "width_m",
        "height_m",
        "leg_height_m",
        "board_height_m",
        "board_thickness_m",
        "post_size_m",
        "soil_depth_m",
    },
    "bench": {
        "length_m",
        "seat_height_m",
        "depth_m",
        "seat_slats",
        "back_slats",
        "slat_thickness_m",
        "back_height_m",
        "back_lean_m",
        "back",
        "arms",
        "frame_inset_m",
        "leg_size_m",
        "frame_color",
        "frame_colors",
        "frame_specular",
    },
    "bird_bath": {"height_m", "bowl_radius_m", "segments", "scale"},
    "stone_lantern": {"scale"},
    "fence": {
        "style",
        "length_m",
        "height_m",
        "material",
        "post_size_m",
        "post_spacing_m",
        "post_height",
        "post_caps",
        "rails",
        "rail_thickness_m",
        "rail_height_m",
        "board_width_m",
        "board_thickness_m",
        "board_overlap_m",
        "gravel_board_m",
        "ground_gap_m",
        "picket_width_m",
        "picket_gap_m",
        "picket_thickness_m",
        "picket_top",
        "slat_height_m",
        "slat_gap_m",
        "slat_thickness_m",
    },
}


def preset_keys(preset: dict) -> set:
    """The keys an asset preset of its ``family`` may use (an unknown family is reported by :func:`asset_preset`)."""
    family = preset.get("family")
    return COMMON_KEYS | (FAMILY_KEYS[family] if family in FAMILY_KEYS else set(preset))


def asset_preset(asset_type) -> dict:
    """The checked preset (a name, or a path to a YAML file)."""
    p = load_preset(KIND, asset_type, preset_keys)
    if p.get("family") not in ASSET_BUILDERS:
        raise ConfigError(
            f"{preset_source(KIND, asset_type)}: unknown family {p.get('family')!r}; "
            f"allowed: {', '.join(ASSET_BUILDERS)}"
        )
    return p


def build_asset(asset_type: str, seed: int) -> Mesh:
    """One instance of an asset preset, deterministic in (asset_type, seed)."""
    p = asset_preset(asset_type)
    return ASSET_BUILDERS[p["family"]](p, rng_for(seed, "asset", asset_type))
