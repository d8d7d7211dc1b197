"""Parametric flowering plants: rose bushes, tulips, daisy-like composites, lavender, ground cover.

``build_flower(flower_type, seed)`` reads ``conf/species/flowers/<type>.yaml``
and returns one :class:`Mesh` (model frame: Z up, base centred at the origin,
z >= 0). Every face - blossoms, leaves and stems - carries the flower label
(``labels.FLOWER``, docs/design.md, Semantic labels). Materials: ``petal`` for blossoms,
``leaf`` for foliage, ``stem`` for stalks and canes.

A preset names its ``kind`` (the builder) and overrides the builder's
parameters; ``[lo, hi]`` values are drawn per (type, seed). Colours are sRGB;
``petal_colors`` is a palette from which each plant (or each blossom, with
``color_per_blossom``) picks one, then jittered in HSV - the colour variation
between seeds. All randomness comes from ``rng_for(seed, "flower", type, ...)``.

Blossoms are whorls of petals instanced with :func:`leaves.place_leaves`: a
petal at azimuth ``phi`` with opening angle ``theta`` from the flower axis has
its midrib along ``cos(theta) axis + sin(theta) radial`` and its inner face
towards the axis, so a positive curl cups it and a negative one reflexes it.
"""

from __future__ import annotations

import numpy as np

from eden_pipe.colour import jitter_colors
from eden_pipe.errors import ConfigError
from eden_pipe.geometry import UP, normalize, uniform_sphere
from eden_pipe.models.flower_parts import (
    _Builder,
    _curve_at,
    _curves,
    _disk,
    _stem_leaves,
    _whorl,
)
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.presets import draw_array, load_preset, preset_source
from eden_pipe.models.species import list_species


def flower_types() -> list[str]:
    return list_species("flowers")


# ----------------------------------------------------------------- builders
def _rose(b: _Builder):
    r = b.rng("shape")
    height = float(b.get("height", [0.5, 0.9], r))
    spread = float(b.get("spread", [0.2, 0.35], r))
    n_canes = int(round(float(b.get("canes", [5, 8], r))))
    # canes: arching from a tight crown
    ang = r.uniform(0, 2 * np.pi, n_canes)
    lean = r.uniform(0.15, 0.5, n_canes)
    out = np.stack([np.cos(ang), np.sin(ang), np.zeros(n_canes)], 1)
    base = out * r.uniform(0.0, 0.04, n_canes)[:, None]
    dirs = normalize(UP + lean[:, None] * out)
    length = height * r.uniform(0.75, 1.1, n_canes) / dirs[:, 2]
    bend = out * (spread / height) * r.uniform(0.2, 0.6, n_canes)[:, None] - UP * r.uniform(0.05, 0.2, n_canes)[:, None]
    # side shoots from the upper half of the canes
    n_side = int(b.get("side_shoots", 2))
    ts = r.uniform(0.45, 0.85, (n_canes, n_side))
    sp, st = _curve_at(base, dirs, length, bend, ts)
    sp, st = sp.reshape(-1, 3), st.reshape(-1, 3)
    sdir = normalize(st + 0.9 * normalize(np.cross(st, uniform_sphere(len(sp), r))) + 0.3 * UP)
    slen = r.uniform(0.12, 0.25, len(sp)) * height
    sbend = -UP * r.uniform(0.0, 0.15, len(sp))[:, None]
    all_base = np.concatenate([base, sp])
    all_dir = np.concatenate([dirs, sdir])
    all_len = np.concatenate([length, slen])
    all_bend = np.concatenate([bend, sbend])
    k = 8
    pts, tans = _curves(all_base, all_dir, all_len, all_bend, k)
    radii = (
        np.concatenate([np.full(n_canes, 0.007), np.full(len(sp), 0.0035)])[:, None] * np.linspace(1.0, 0.5, k)[None]
    )
    pts[:, :, 2] = np.maximum(pts[:, :, 2], radii)
    ids = np.repeat(np.arange(len(all_base)), k)
    b.tubes(pts.reshape(-1, 3), radii.reshape(-1), ids, 5, b.get("stem_color", [0.28, 0.36, 0.16]))

    # leaves: pinnate, along canes and shoots
    lr = b.rng("leaves")
    n_leaf = int(b.get("leaves_per_stem", 8))
    lp, lt, side = _stem_leaves(all_base, all_dir, all_len, all_bend, n_leaf, (0.25, 0.95), lr)
    lt_dir = normalize(side + 0.5 * lt + 0.2 * UP)
    ln = normalize(UP + 0.5 * uniform_sphere(len(lp), lr) - 0.3 * side)
    lsize = draw_array(b.get("leaf_size", [0.08, 0.13]), lr, len(lp))
    b.leaves(
        "leaf",
        b.get("leaf_type", "pinnate"),
        lp,
        ln,
        lt_dir,
        lsize,
        lr,
        b.leaf_colors(len(lp)),
        curl=lr.uniform(-0.25, 0.0, len(lp)),
    )

    # blossoms at the tips (some as buds)
    fr = b.rng("blossoms")
    tips = pts[:, -1]
    axis = normalize(tans[:, -1] + 1.2 * UP + 0.3 * fr.normal(size=(len(tips), 3)))
    nb = len(tips)
    bud = fr.uniform(0, 1, nb) < float(b.get("bud_fraction", 0.25))
    bloom = float(b.get("bloom_size", [0.035, 0.05], fr))
    bsize = bloom * fr.uniform(0.85, 1.15, nb) * np.where(bud, 0.55, 1.0)
    colors = b.petal_palette(nb)
    rings = int(b.get("petal_rings", 5))
    per_ring = int(b.get("petals_per_ring", 5))
    pos_l, tan_l, nrm_l, size_l, curl_l, fold_l, col_l = [], [], [], [], [], [], []
    phase0 = fr.uniform(0, 2 * np.pi, nb)
    for i in range(rings):
        f = i / max(rings - 1, 1)  # 0 inner .. 1 outer
        theta = np.where(bud, np.radians(8 + 12 * f), np.radians(12 + 68 * f**1.3))
        theta = theta[:, None] + np.radians(fr.uniform(-6, 6, (nb, per_ring)))
        p, t, n = _whorl(tips, axis, per_ring, theta, bsize * 0.05, bsize * (0.12 - 0.08 * f), phase0 + i * 2.4)
        pos_l.append(p)
        tan_l.append(t)
        nrm_l.append(n)
        size_l.append(np.repeat(bsize * (0.55 + 0.45 * f), per_ring))
        curl_l.append(np.repeat(np.where(bud, 0.5, 0.45 - 0.7 * f), per_ring))
        fold_l.append(np.full(nb * per_ring, 0.25 - 0.1 * f))
        shade = 0.85 + 0.15 * f  # inner petals slightly darker
        col_l.append(np.repeat(colors * shade, per_ring, axis=0))
    b.leaves(
        "petal",
        b.get("petal_type", "petal_round"),
        np.concatenate(pos_l),
        np.concatenate(nrm_l),
        np.concatenate(tan_l),
        np.concatenate(size_l),
        fr,
        np.concatenate(col_l),
        fold=np.concatenate(fold_l),
        curl=np.concatenate(curl_l),
    )
    # green sepals under each blossom
    p, t, n = _whorl(tips, axis, 5, np.radians(fr.uniform(60, 110, (nb, 5))), bsize * 0.05, 0.0 * bsize, phase0)
    b.leaves("leaf", "lanceolate", p, n, t, np.repeat(bsize * 0.6, 5), fr, b.leaf_colors(len(p)), curl=-0.2)


def _tulip(b: _Builder):
    r = b.rng("shape")
    n = int(round(float(b.get("plants", [3, 7], r))))
    clump = float(b.get("clump_radius", [0.06, 0.15], r))
    rad = clump * np.sqrt(r.uniform(0, 1, n))
    ang = r.uniform(0, 2 * np.pi, n)
    base = np.stack([rad * np.cos(ang), rad * np.sin(ang), np.zeros(n)], 1)
    dirs = normalize(UP + 0.12 * r.normal(size=(n, 3)) * [1, 1, 0])
    length = draw_array(b.get("stem_length", [0.3, 0.5]), r, n)
    bend = 0.08 * r.normal(size=(n, 3)) * [1, 1, 0]
    k = 7
    pts, tans = _curves(base, dirs, length, bend, k)
    radius = float(b.get("stem_radius", 0.0035))
    b.tubes(
        pts.reshape(-1, 3),
        np.full(n * k, radius),
        np.repeat(np.arange(n), k),
        6,
        b.get("stem_color", [0.35, 0.5, 0.25]),
    )
    # broad basal leaves arching out
    lr = b.rng("leaves")
    nl = int(b.get("leaves_per_plant", 3))
    az = lr.uniform(0, 2 * np.pi, (n, nl))
    out = np.stack([np.cos(az), np.sin(az), np.zeros_like(az)], -1).reshape(-1, 3)
    tilt = np.radians(lr.uniform(20, 45, n * nl))
    lt = normalize(np.cos(tilt)[:, None] * UP + np.sin(tilt)[:, None] * out)
    ln = normalize(np.cos(tilt)[:, None] * -out + np.sin(tilt)[:, None] * UP)  # inner face up/in
    lp = np.repeat(base, nl, axis=0) + out * 0.008 + UP * lr.uniform(0.0, 0.04, n * nl)[:, None]
    lsize = np.repeat(length, nl) * lr.uniform(0.5, 0.8, n * nl)
    b.leaves(
        "leaf",
        b.get("leaf_type", "strap"),
        lp,
        ln,
        lt,
        lsize,
        lr,
        b.leaf_colors(len(lp)),
        fold=lr.uniform(0.3, 0.6, len(lp)),
        curl=lr.uniform(-0.7, -0.3, len(lp)),
    )
    # cup of six tepals in two whorls of three
    fr = b.rng("blossoms")
    tips = pts[:, -1]
    axis = normalize(tans[:, -1] + 0.5 * UP)
    size = draw_array(b.get("bloom_size", [0.045, 0.065]), fr, n)
    colors = b.petal_palette(n)
    phase = fr.uniform(0, 2 * np.pi, n)
    open_deg = float(b.get("opening_deg", [10, 22], fr))
    pos_l, tan_l, nrm_l = [], [], []
    for i in range(2):
        p, t, nn = _whorl(
            tips,
            axis,
            3,
            np.radians(open_deg + 6 * i + fr.uniform(-4, 4, (n, 3))),
            size * 0.08,
            -size * 0.05,
            phase + i * np.pi / 3,
        )
        pos_l.append(p)
        tan_l.append(t)
        nrm_l.append(nn)
    b.leaves(
        "petal",
        b.get("petal_type", "tepal"),
        np.concatenate(pos_l),
        np.concatenate(nrm_l),
        np.concatenate(tan_l),
        np.tile(np.repeat(size, 3), 2) * fr.uniform(0.92, 1.05, 6 * n),
        fr,
        np.tile(np.repeat(colors, 3, axis=0), (2, 1)),
        fold=0.4,
        curl=fr.uniform(0.15, 0.3, 6 * n),
    )


def _composite(b: _Builder):
    """Daisy-like plants: basal rosette, stems, heads of ray petals around a disk."""
    r = b.rng("shape")
    n = int(round(float(b.get("stems", [6, 14], r))))
    crown = float(b.get("crown_radius", [0.03, 0.08], r))
    rad = crown * np.sqrt(r.uniform(0, 1, n))
    ang = r.uniform(0, 2 * np.pi, n)
    out = np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], 1)
    base = out * rad[:, None]
    dirs = normalize(UP + r.uniform(0.05, 0.4, n)[:, None] * out)
    length = draw_array(b.get("stem_length", [0.25, 0.5]), r, n)
    bend = out * r.uniform(0.0, 0.15, n)[:, None] - UP * r.uniform(0.0, 0.1, n)[:, None]
    k = 6
    pts, tans = _curves(base, dirs, length, bend, k)
    b.tubes(
        pts.reshape(-1, 3),
        np.full(n * k, float(b.get("stem_radius", 0.0018))),
        np.repeat(np.arange(n), k),
        4,
        b.get("stem_color", [0.32, 0.45, 0.2]),
    )
    # basal rosette + a few stem leaves
    lr = b.rng("leaves")
    nr_ = int(b.get("rosette_leaves", 14))
    az = lr.uniform(0, 2 * np.pi, nr_)
    o = np.stack([np.cos(az), np.sin(az), np.zeros(nr_)], 1)
    tilt = np.radians(lr.uniform(45, 80, nr_))
    lt = normalize(np.cos(tilt)[:, None] * UP + np.sin(tilt)[:, None] * o)
    ln = normalize(np.cos(tilt)[:, None] * -o + np.sin(tilt)[:, None] * UP)
    lsize = draw_array(b.get("leaf_size", [0.06, 0.11]), lr, nr_)
    lp = o * 0.01 + UP * 0.005
    b.leaves("leaf", b.get("leaf_type", "spatulate"), lp, ln, lt, lsize, lr, b.leaf_colors(nr_), curl=-0.2)
    sp, st, side = _stem_leaves(base, dirs, length, bend, int(b.get("stem_leaves", 2)), (0.15, 0.6), lr)
    b.leaves(
        "leaf",
        "lanceolate",
        sp,
        normalize(UP - 0.4 * side),
        normalize(side + 0.6 * st),
        lr.uniform(0.03, 0.05, len(sp)),
        lr,
        b.leaf_colors(len(sp)),
        curl=-0.15,
    )
    # heads
    fr = b.rng("blossoms")
    tips = pts[:, -1]
    axis = normalize(tans[:, -1] + float(b.get("face_up", 1.0)) * UP + 0.25 * fr.normal(size=(n, 3)))
    head = draw_array(b.get("head_radius", [0.02, 0.035]), fr, n)
    disk_r = head * float(b.get("disk_fraction", 0.32))
    colors = b.petal_palette(n)
    nray = int(b.get("rays", 21))
    theta = np.radians(float(b.get("ray_angle_deg", 88)) + fr.uniform(-8, 8, (n, nray)))
    p, t, nn = _whorl(tips, axis, nray, theta, disk_r * 0.8, disk_r * 0.1, fr.uniform(0, 2 * np.pi, n))
    ray_len = np.repeat(head - disk_r * 0.8, nray) * fr.uniform(0.9, 1.1, n * nray)
    b.leaves(
        "petal",
        b.get("petal_type", "petal_ray"),
        p,
        nn,
        t,
        ray_len,
        fr,
        np.repeat(colors, nray, axis=0),
        fold=0.1,
        curl=float(b.get("ray_curl", -0.1)),
    )
    dv, df = _disk(tips, axis, disk_r, disk_r * float(b.get("disk_height", 0.35)), 10)
    dcol = jitter_colors(b.p.get("disk_color", [0.85, 0.65, 0.08]), n, b.col_rng, 0.02, 0.05, 0.1)
    b.raw(dv, df, "petal", np.repeat(dcol, 10, axis=0), translucency=0.08)


def _lavender(b: _Builder):
    r = b.rng("shape")
    n = int(round(float(b.get("spikes", [35, 60], r))))
    mound = float(b.get("mound_radius", [0.2, 0.35], r))
    ang = r.uniform(0, 2 * np.pi, n)
    out = np.stack([np.cos(ang), np.sin(ang), np.zeros(n)], 1)
    base = out * r.uniform(0, 0.05, n)[:, None]
    spread = r.uniform(0.0, 1.0, n) ** 0.7
    dirs = normalize(UP + spread[:, None] * (mound / 0.5) * out)
    length = draw_array(b.get("stem_length", [0.35, 0.55]), r, n)
    bend = out * 0.1 * r.uniform(0, 1, n)[:, None]
    k = 7
    pts, _ = _curves(base, dirs, length, bend, k)
    b.tubes(
        pts.reshape(-1, 3),
        np.full(n * k, 0.0014),
        np.repeat(np.arange(n), k),
        3,
        b.get("stem_color", [0.45, 0.52, 0.38]),
    )
    # grey-green linear foliage on the lower stems
    lr = b.rng("leaves")
    per = int(b.get("leaves_per_stem", 6))
    lp, lt, side = _stem_leaves(base, dirs, length, bend, per, (0.02, 0.45), lr)
    ltan = normalize(lt + 0.9 * side)
    b.leaves(
        "leaf",
        b.get("leaf_type", "linear"),
        lp,
        normalize(UP - side),
        ltan,
        lr.uniform(0.04, 0.065, len(lp)),
        lr,
        b.leaf_colors(len(lp)),
        curl=lr.uniform(-0.2, 0.1, len(lp)),
    )
    # spikes: whorls of tiny florets over the top of each stem
    fr = b.rng("blossoms")
    whorls = int(b.get("whorls", 10))
    per_w = int(b.get("florets_per_whorl", 5))
    spike = float(b.get("spike_fraction", 0.22))
    t = 1.0 - spike * (np.arange(whorls) / max(whorls - 1, 1))[None].repeat(n, 0)
    wp, wt = _curve_at(base, dirs, length, bend, t)
    wp, wt = wp.reshape(-1, 3), wt.reshape(-1, 3)
    colors = b.petal_palette(n)
    p, tt, nn = _whorl(
        wp,
        wt,
        per_w,
        np.radians(fr.uniform(30, 60, (len(wp), per_w))),
        np.full(len(wp), 0.0015),
        np.zeros(len(wp)),
        fr.uniform(0, 2 * np.pi, len(wp)),
    )
    taper = np.repeat((1.0 - 0.5 * np.arange(whorls) / whorls)[None].repeat(n, 0).reshape(-1), per_w)
    fsize = draw_array(b.get("floret_size", [0.007, 0.01]), fr, len(p)) * taper
    b.leaves(
        "petal",
        b.get("petal_type", "floret"),
        p,
        nn,
        tt,
        fsize,
        fr,
        np.repeat(np.repeat(colors, whorls, axis=0), per_w, axis=0),
        fold=0.3,
        curl=0.3,
    )


def _groundcover(b: _Builder):
    r = b.rng("shape")
    R = float(b.get("radius", [0.3, 0.5], r))
    H = float(b.get("height", [0.05, 0.1], r))
    squash = r.uniform(0.75, 1.0)

    def dome(x, y):
        q = (x / R) ** 2 + (y / (R * squash)) ** 2
        return H * np.sqrt(np.clip(1.0 - q, 0.0, 1.0))

    # foliage: layered small leaves over a dome
    lr = b.rng("leaves")
    leaf_type = b.get("leaf_type", "ovate")
    from eden_pipe.models.leaves import leaf_template

    lsz = b.get("leaf_size", [0.015, 0.025])
    mean_area = leaf_template(leaf_type).area() * np.mean(lsz) ** 2
    area = np.pi * R * R * squash
    nl = int(float(b.get("coverage", 1.6)) * area / mean_area)
    rr = np.sqrt(lr.uniform(0, 1, nl))
    a = lr.uniform(0, 2 * np.pi, nl)
    x, y = R * rr * np.cos(a), R * squash * rr * np.sin(a)
    z = dome(x, y) * lr.uniform(0.35, 1.0, nl)
    lp = np.stack([x, y, z], 1)
    ln = normalize(UP + 0.6 * uniform_sphere(nl, lr))
    lt = uniform_sphere(nl, lr)
    b.leaves("leaf", leaf_type, lp, ln, lt, draw_array(lsz, lr, nl), lr, b.leaf_colors(nl))
    # runners between the leaves
    ns = int(b.get("runners", 24))
    a = lr.uniform(0, 2 * np.pi, ns)
    o = np.stack([np.cos(a), np.sin(a) * squash, np.zeros(ns)], 1)
    sp, _ = _curves(
        np.zeros((ns, 3)) + [0, 0, 0.004], o, np.full(ns, R * 0.9), 0.1 * lr.normal(size=(ns, 3)) * [1, 1, 0], 6
    )
    sp[:, :, 2] = np.maximum(dome(sp[:, :, 0], sp[:, :, 1]) * 0.5, 0.003)
    b.tubes(
        sp.reshape(-1, 3),
        np.full(ns * 6, 0.0015),
        np.repeat(np.arange(ns), 6),
        3,
        b.get("stem_color", [0.4, 0.35, 0.2]),
    )
    # small five-petal blossoms scattered over the top
    fr = b.rng("blossoms")
    nb = int(float(b.get("blossom_density", 900)) * area)
    rr = np.sqrt(fr.uniform(0, 0.95, nb))
    a = fr.uniform(0, 2 * np.pi, nb)
    x, y = R * rr * np.cos(a), R * squash * rr * np.sin(a)
    c = np.stack([x, y, dome(x, y) + 0.004], 1)
    axis = normalize(UP + 0.35 * fr.normal(size=(nb, 3)))
    bs = draw_array(b.get("bloom_size", [0.008, 0.012]), fr, nb)
    colors = b.petal_palette(nb)
    npet = int(b.get("petals", 5))
    p, t, nn = _whorl(
        c, axis, npet, np.radians(fr.uniform(70, 90, (nb, npet))), bs * 0.1, np.zeros(nb), fr.uniform(0, 2 * np.pi, nb)
    )
    b.leaves(
        "petal",
        b.get("petal_type", "petal_notched"),
        p,
        nn,
        t,
        np.repeat(bs, npet),
        fr,
        np.repeat(colors, npet, axis=0),
        fold=0.1,
        curl=0.1,
    )


BUILDERS = {"rose": _rose, "tulip": _tulip, "composite": _composite, "lavender": _lavender, "groundcover": _groundcover}


#: Keys every flower preset may use, then the keys each builder reads.
COMMON_KEYS = {
    "kind",
    "name",
    "material",
    "color_per_blossom",
    "leaf_color",
    "leaf_hsv",
    "petal_colors",
    "petal_hsv",
    "stem_color",
}
KIND_KEYS = {
    "rose": {
        "bloom_size",
        "bud_fraction",
        "canes",
        "height",
        "leaf_size",
        "leaf_type",
        "leaves_per_stem",
        "petal_rings",
        "petal_type",
        "petals_per_ring",
        "side_shoots",
        "spread",
    },
    "tulip": {
        "bloom_size",
        "clump_radius",
        "leaf_type",
        "leaves_per_plant",
        "opening_deg",
        "petal_type",
        "plants",
        "stem_length",
        "stem_radius",
    },
    "composite": {
        "crown_radius",
        "disk_color",
        "disk_fraction",
        "disk_height",
        "face_up",
        "head_radius",
        "leaf_size",
        "leaf_type",
        "petal_type",
        "ray_angle_deg",
        "ray_curl",
        "rays",
        "rosette_leaves",
        "stem_leaves",
        "stem_length",
        "stem_radius",
        "stems",
    },
    "lavender": {
        "floret_size",
        "florets_per_whorl",
        "leaf_type",
        "leaves_per_stem",
        "mound_radius",
        "petal_type",
        "spike_fraction",
        "spikes",
        "stem_length",
        "whorls",
    },
    "groundcover": {
        "bloom_size",
        "blossom_density",
        "coverage",
        "height",
        "leaf_size",
        "leaf_type",
        "petal_type",
        "petals",
        "radius",
        "runners",
    },
}
MATERIAL_KEYS = {"petal_translucency", "leaf_translucency"}


def preset_keys(preset: dict) -> dict:
    """The keys a flower preset of its ``kind`` may use (an unknown kind is reported by :func:`build_flower`)."""
    kind = preset.get("kind")
    kind_keys = KIND_KEYS[kind] if isinstance(kind, str) and kind in KIND_KEYS else set(preset)
    return {None: COMMON_KEYS | kind_keys, "material": MATERIAL_KEYS}


def load_flower_preset(flower_type) -> dict:
    """The checked preset (a name, or a path to a YAML file)."""
    preset = load_preset("flowers", flower_type, preset_keys)
    kind = preset.get("kind")
    if kind not in BUILDERS:
        raise ConfigError(
            f"{preset_source('flowers', flower_type)}: unknown flower kind {kind!r}; allowed: {', '.join(BUILDERS)}"
        )
    return preset


def build_flower(flower_type: str, seed: int) -> Mesh:
    """The flowering plant preset ``flower_type`` for ``seed`` (deterministic)."""
    preset = load_flower_preset(flower_type)
    b = _Builder(preset, seed, flower_type)
    BUILDERS[preset["kind"]](b)
    return b.mesh()
