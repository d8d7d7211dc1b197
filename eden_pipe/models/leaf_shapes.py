"""The leaf shape library: every named leaf, petal, card and strip shape, as data.

Split from :mod:`eden_pipe.models.leaves` (which meshes and places leaves and
re-exports these names): the fine leaf and petal outlines (``LEAF_TYPES``,
``PETAL_TYPES``; their kinds ``profile``, ``outline`` and ``compound`` are
described there), the coarse card leaves of trees (``CARD_LEAVES``), the lawn
strip width profiles (``STRIP_PROFILES``), their union ``LEAF_SHAPES``, and the
look-ups that turn a preset's shape word into one of them (docs/architecture.md).
"""

from __future__ import annotations

import numpy as np

from eden_pipe.errors import ConfigError

# --------------------------------------------------------------------------- data
# size: typical blade length range in metres (tip-to-base extent along the midrib).
# fold/curl: default per-leaf ranges, in units of the leaf length.
# Outline points are (x, y) or (x, y, 1) for a sharp corner; the first and last
# points lie on the midrib (x = 0).
LEAF_TYPES: dict[str, dict] = {
    # ---- simple, profile-defined blades
    "elliptic": dict(kind="profile", aspect=0.48, a=1.0, b=0.6, stations=3, size=(0.03, 0.08)),
    "ovate": dict(kind="profile", aspect=0.58, a=0.68, b=0.6, stations=3, size=(0.03, 0.09)),
    "obovate": dict(kind="profile", aspect=0.52, a=1.55, b=0.6, stations=3, size=(0.03, 0.08)),
    "lanceolate": dict(kind="profile", aspect=0.22, a=0.75, b=0.85, stations=4, size=(0.05, 0.12)),
    "linear": dict(kind="profile", aspect=0.08, a=1.0, b=0.22, stations=4, size=(0.06, 0.25), curl=(0.05, 0.3)),
    "strap": dict(kind="profile", aspect=0.26, a=0.85, b=0.7, stations=7, size=(0.1, 0.3), curl=(-0.6, -0.1)),
    "oblong": dict(kind="profile", aspect=0.40, a=1.0, b=0.3, stations=4, size=(0.03, 0.08)),
    "orbicular": dict(kind="profile", aspect=0.95, a=1.0, b=0.5, stations=4, size=(0.02, 0.06)),
    "serrated_elliptic": dict(kind="profile", aspect=0.50, a=0.9, b=0.6, stations=11, teeth=0.14, size=(0.04, 0.10)),
    "needle": dict(
        kind="outline",
        size=(0.012, 0.03),
        fold=(0.0, 0.0),
        curl=(0.0, 0.15),
        points=[(0, 0), (0.035, 0.06, 1), (0.03, 0.85, 1), (0, 1)],
        smooth=0,
    ),
    # ---- simple, outline-defined blades
    "acuminate": dict(
        kind="outline",
        size=(0.04, 0.10),
        points=[
            (0, 0),
            (0.14, 0.04),
            (0.26, 0.2),
            (0.27, 0.42),
            (0.2, 0.6),
            (0.1, 0.76),
            (0.04, 0.88),
            (0.012, 0.96),
            (0, 1),
        ],
        smooth=0,
    ),
    "spatulate": dict(
        kind="outline",
        size=(0.03, 0.08),
        points=[(0, 0), (0.05, 0.08), (0.07, 0.35), (0.14, 0.55), (0.22, 0.72), (0.22, 0.86), (0.15, 0.96), (0, 1)],
        smooth=1,
    ),
    "cuneate": dict(
        kind="outline", size=(0.03, 0.07), points=[(0, 0), (0.26, 0.72, 1), (0.22, 0.92), (0.1, 0.99), (0, 1)], smooth=1
    ),
    "rhomboid": dict(kind="outline", size=(0.03, 0.07), points=[(0, 0), (0.3, 0.42, 1), (0, 1)], smooth=0),
    "deltoid": dict(
        kind="outline",
        size=(0.03, 0.08),
        points=[(0, 0), (0.3, 0.0), (0.44, 0.1, 1), (0.3, 0.42), (0.13, 0.75), (0, 1)],
        smooth=1,
    ),
    "cordate": dict(
        kind="outline",
        size=(0.04, 0.10),
        points=[
            (0, 0),
            (0.1, -0.08),
            (0.26, -0.1),
            (0.38, -0.02),
            (0.42, 0.14),
            (0.36, 0.36),
            (0.22, 0.6),
            (0.08, 0.8),
            (0, 0.9),
        ],
        smooth=1,
    ),
    "reniform": dict(
        kind="outline",
        size=(0.03, 0.07),
        points=[
            (0, 0),
            (0.12, -0.12),
            (0.35, -0.16),
            (0.56, -0.05),
            (0.64, 0.16),
            (0.56, 0.38),
            (0.32, 0.52),
            (0, 0.56),
        ],
        smooth=1,
    ),
    "peltate": dict(
        kind="outline",
        size=(0.04, 0.09),  # attached at the blade centre (nasturtium)
        points=[(0, -0.5), (0.3, -0.4), (0.48, -0.12), (0.48, 0.14), (0.32, 0.38), (0, 0.5)],
        smooth=1,
    ),
    "obcordate": dict(
        kind="outline",
        size=(0.015, 0.04),
        points=[(0, 0), (0.16, 0.3), (0.34, 0.66), (0.34, 0.9), (0.2, 1.0), (0.06, 0.96), (0, 0.88, 1)],
        smooth=1,
    ),
    "hastate": dict(
        kind="outline",
        size=(0.04, 0.10),
        points=[(0, 0), (0.08, 0.0), (0.4, -0.08, 1), (0.14, 0.14, 1), (0.17, 0.42), (0.1, 0.72), (0, 1)],
        smooth=1,
    ),
    "sagittate": dict(
        kind="outline",
        size=(0.05, 0.12),
        points=[(0, 0), (0.07, -0.03), (0.26, -0.3, 1), (0.27, 0.0), (0.27, 0.28), (0.16, 0.6), (0, 1)],
        smooth=1,
    ),
    "oak": dict(
        kind="outline",
        size=(0.06, 0.12),
        points=[
            (0, 0),
            (0.06, 0.03),
            (0.15, 0.1),
            (0.15, 0.17),
            (0.1, 0.22, 1),
            (0.24, 0.27),
            (0.28, 0.34),
            (0.23, 0.4),
            (0.11, 0.43, 1),
            (0.27, 0.48),
            (0.31, 0.55),
            (0.25, 0.61),
            (0.1, 0.64, 1),
            (0.23, 0.69),
            (0.25, 0.76),
            (0.18, 0.8),
            (0.08, 0.83, 1),
            (0.15, 0.88),
            (0.13, 0.96),
            (0, 1),
        ],
        smooth=1,
    ),
    "maple": dict(
        kind="outline",
        size=(0.06, 0.14),
        smooth=0,
        points=[
            (0, 0, 1),
            (0.05, 0.0, 1),
            (0.3, -0.05, 1),
            (0.24, 0.05, 1),
            (0.32, 0.1, 1),
            (0.16, 0.18, 1),
            (0.46, 0.3, 1),
            (0.6, 0.46, 1),
            (0.47, 0.44, 1),
            (0.46, 0.52, 1),
            (0.14, 0.5, 1),
            (0.24, 0.64, 1),
            (0.29, 0.68, 1),
            (0.2, 0.72, 1),
            (0.2, 0.84, 1),
            (0, 1, 1),
        ],
    ),
    "ivy": dict(
        kind="outline",
        size=(0.04, 0.09),
        points=[
            (0, 0),
            (0.1, -0.04),
            (0.3, -0.03),
            (0.38, 0.1, 1),
            (0.27, 0.22),
            (0.46, 0.36, 1),
            (0.22, 0.48),
            (0.16, 0.68),
            (0.05, 0.9),
            (0, 1, 1),
        ],
        smooth=1,
    ),
    "scale": dict(
        kind="outline",
        size=(0.04, 0.09),
        fold=(0.0, 0.1),  # flat thuja/cypress spray
        points=[
            (0, 0),
            (0.05, 0.05),
            (0.14, 0.1, 1),
            (0.08, 0.2),
            (0.22, 0.28, 1),
            (0.1, 0.38),
            (0.26, 0.47, 1),
            (0.1, 0.57),
            (0.22, 0.66, 1),
            (0.08, 0.75),
            (0.15, 0.84, 1),
            (0.04, 0.92),
            (0, 1),
        ],
        smooth=0,
    ),
    "pectinate": dict(
        kind="outline",
        size=(0.05, 0.10),
        fold=(0.0, 0.12),
        smooth=0,  # flat yew/fir sprig
        points=[
            (0, 0),
            (0.03, 0.02, 1),
            (0.22, 0.1, 1),
            (0.04, 0.16, 1),
            (0.26, 0.28, 1),
            (0.04, 0.34, 1),
            (0.26, 0.46, 1),
            (0.04, 0.52, 1),
            (0.24, 0.64, 1),
            (0.04, 0.7, 1),
            (0.2, 0.82, 1),
            (0.03, 0.86, 1),
            (0.1, 0.96, 1),
            (0, 1),
        ],
    ),
    # ---- compound leaves and sprays: leaflets = (type, (x, y), angle_deg, scale[, width factor])
    "trifoliate": dict(
        kind="compound",
        size=(0.03, 0.06),
        rachis=(0.012, 0.35),
        leaflets=[
            ("obcordate", (0, 0.35), 0, 0.65),
            ("obcordate", (0, 0.35), 115, 0.65),
            ("obcordate", (0, 0.35), -115, 0.65),
        ],
    ),
    "palmate_compound": dict(
        kind="compound",
        size=(0.08, 0.18),
        rachis=(0.01, 0.3),
        leaflets=[("obovate", (0, 0.3), a, s) for a, s in ((0, 0.7), (38, 0.62), (-38, 0.62), (76, 0.46), (-76, 0.46))],
    ),
    "pinnate": dict(
        kind="compound",
        size=(0.08, 0.16),
        rachis=(0.012, 0.78),
        leaflets=[("serrated_elliptic", (0, 0.7), 0, 0.32)]
        + [("serrated_elliptic", (0, y), s * a, 0.3) for y, a in ((0.2, 62), (0.45, 55)) for s in (1, -1)],
    ),
    "needle_spray": dict(
        kind="compound",
        size=(0.05, 0.10),
        rachis=(0.01, 0.96),
        fold=(0.0, 0.1),
        leaflets=[("needle", (0, 0.92), 0, 0.2, 1.8)]
        + [("needle", (0, y), s * 72, 0.26, 1.8) for y in (0.1, 0.24, 0.38, 0.52, 0.66, 0.8) for s in (1, -1)],
    ),
}

#: The leaf types a hedge or topiary draws its one leaf type from (per bush variant) unless its
#: preset lists its own ``leaves.types``: every type but the grass-like ones (linear, strap), the
#: lone needle, and the compound leaves too fine for a hedge's tens of thousands of leaves (oak,
#: pinnate, trifoliate and needle_spray cost 54-112 triangles a leaf).
BUSH_LEAF_TYPES: tuple[str, ...] = (
    "elliptic",
    "ovate",
    "obovate",
    "lanceolate",
    "oblong",
    "orbicular",
    "serrated_elliptic",
    "acuminate",
    "spatulate",
    "cuneate",
    "rhomboid",
    "deltoid",
    "cordate",
    "reniform",
    "peltate",
    "obcordate",
    "hastate",
    "sagittate",
    "maple",
    "ivy",
    "scale",
    "pectinate",
    "palmate_compound",
)

# Petal shapes for the flower models (same machinery; not counted as leaf types).
PETAL_TYPES: dict[str, dict] = {
    "petal_round": dict(
        kind="outline",
        size=(0.02, 0.05),
        points=[(0, 0), (0.08, 0.12), (0.3, 0.45), (0.42, 0.72), (0.36, 0.92), (0.16, 1.0), (0, 0.97)],
        smooth=1,
    ),
    "petal_ray": dict(kind="profile", aspect=0.2, a=1.0, b=0.3, stations=3, size=(0.015, 0.04)),
    "tepal": dict(kind="profile", aspect=0.6, a=1.3, b=0.55, stations=5, size=(0.04, 0.07)),
    "petal_notched": dict(
        kind="outline",
        size=(0.008, 0.02),
        points=[(0, 0), (0.12, 0.25), (0.36, 0.68), (0.36, 0.92), (0.2, 1.0), (0.06, 0.96), (0, 0.86, 1)],
        smooth=0,
    ),
    "floret": dict(kind="outline", size=(0.004, 0.008), points=[(0, 0), (0.4, 0.5, 1), (0, 1)], smooth=0),
}

ALL_TYPES: dict[str, dict] = {**LEAF_TYPES, **PETAL_TYPES}


# ----------------------------------------------------------------- card leaves (trees)
def _card(outline, fold=None, agg_len=0.5):
    """A low-poly leaf card from an outline around vertex 0 (the leaf base), fanned into triangles.

    Coordinates are (u across the width in [-0.5, 0.5], v along the length in [0, 1]) and a
    fold offset w along the normal; ``agg_len`` is the share of a merged leaf's growth that
    goes into its length (the rest widens it)."""
    pts = np.asarray(outline, dtype=np.float64)
    w = np.zeros(len(pts)) if fold is None else np.asarray(fold, dtype=np.float64)
    verts = np.column_stack([pts, w])
    m = len(pts)
    faces = np.array([[0, i, i + 1] for i in range(1, m - 1)], dtype=np.int64)
    return {"kind": "card", "verts": verts, "faces": faces, "agg_len": agg_len}


def _palmate_outline():
    """Maple-like: five lobes around the petiole point."""
    ang = np.radians([-115, -80, -55, -25, 0, 25, 55, 80, 115])
    rad = np.array([0.65, 0.32, 0.9, 0.38, 1.0, 0.38, 0.9, 0.32, 0.65])
    return [(0.0, 0.0)] + [(0.55 * r * np.sin(a), r * np.cos(a)) for a, r in zip(ang, rad, strict=True)]


# Tree leaves are cards of 2-8 triangles (a tree has up to ~100k of them), not the finer
# outlines above: same words in the presets, different (coarser) geometry, hence own names.
CARD_LEAVES: dict[str, dict] = {
    "elliptic_card": _card(
        [(0, 0), (0.42, 0.2), (0.48, 0.58), (0, 1), (-0.48, 0.58), (-0.42, 0.2)], [0, 0.03, 0.05, 0.0, 0.05, 0.03]
    ),
    "ovate_card": _card(
        [(0, 0), (0.5, 0.28), (0.36, 0.68), (0, 1), (-0.36, 0.68), (-0.5, 0.28)], [0, 0.04, 0.05, 0.0, 0.05, 0.04]
    ),
    "lanceolate_card": _card(
        [(0, 0), (0.5, 0.3), (0.3, 0.72), (0, 1), (-0.3, 0.72), (-0.5, 0.3)],
        [0, 0.05, 0.04, 0, 0.04, 0.05],
        agg_len=0.35,
    ),
    "deltoid_card": _card(
        [(0, 0), (0.5, 0.12), (0.36, 0.5), (0, 1), (-0.36, 0.5), (-0.5, 0.12)], [0, 0.03, 0.04, 0, 0.04, 0.03]
    ),
    "round_card": _card(
        [(0, 0), (0.45, 0.12), (0.5, 0.55), (0.22, 0.95), (-0.22, 0.95), (-0.5, 0.55), (-0.45, 0.12)],
        [0, 0.03, 0.05, 0.04, 0.04, 0.05, 0.03],
    ),
    # three-lobed (sassafras mitten / oak-like)
    "lobed_card": _card(
        [(0, 0), (0.3, 0.25), (0.5, 0.65), (0.16, 0.55), (0, 1), (-0.16, 0.55), (-0.5, 0.65), (-0.3, 0.25)],
        [0, 0.03, 0.06, 0.02, 0.0, 0.02, 0.06, 0.03],
    ),
    "palmate_card": _card(_palmate_outline(), [0] + [0.04] * 9),
    "needle_card": _card([(0, 0), (0.5, 0.5), (0, 1), (-0.5, 0.5)], [0, 0.0, 0, 0.0], agg_len=0.25),
    # palm leaflet: long, folded along the midrib (V section)
    "palm_card": _card(
        [(0, 0), (0.5, 0.3), (0.25, 0.75), (0, 1), (-0.25, 0.75), (-0.5, 0.3)],
        [0, -0.45, -0.3, 0, -0.3, -0.45],
        agg_len=0.4,
    ),
    "disc_card": _card([(0, 0), (0.5, 0.25), (0.5, 0.75), (0, 1), (-0.5, 0.75), (-0.5, 0.25)]),
    # tiny closed blob (desert bush): a tetrahedron spanning the leaf box
    "sphere_card": {
        "kind": "card",
        "agg_len": 0.5,
        "verts": np.array([[0.0, 0.0, 0.0], [0.5, 0.6, -0.3], [-0.5, 0.6, -0.3], [0.0, 0.7, 0.55], [0.0, 1.0, 0.0]]),
        "faces": np.array([[0, 1, 3], [0, 3, 2], [0, 2, 1], [4, 3, 1], [4, 2, 3], [4, 1, 2]]),
    },
}


# ----------------------------------------------------------------- strip profiles (lawn)
# Lawn blades and weed leaves are strips along a centreline (eden_pipe.models.lawn_strips);
# a strip profile gives the relative width at the base, the position of the widest point,
# the width at the tip (0 = pointed) and how sharply it narrows to the tip.
STRIP_PROFILES: dict[str, dict] = {
    "grass_strip": dict(kind="strip", base=0.85, peak=0.12, tip=0.0, sharp=0.5),
    "needle_strip": dict(kind="strip", base=1.0, peak=0.05, tip=0.0, sharp=0.35),
    "lanceolate_strip": dict(kind="strip", base=0.15, peak=0.45, tip=0.0, sharp=1.0),
    "elliptic_strip": dict(kind="strip", base=0.25, peak=0.5, tip=0.1, sharp=0.8),
    "oblanceolate_strip": dict(kind="strip", base=0.1, peak=0.68, tip=0.0, sharp=1.0),
    "obovate_strip": dict(kind="strip", base=0.3, peak=0.68, tip=0.45, sharp=0.7),
    "round_strip": dict(kind="strip", base=0.45, peak=0.5, tip=0.3, sharp=0.6),
    "cordate_strip": dict(kind="strip", base=0.75, peak=0.25, tip=0.0, sharp=1.2),
    "reniform_strip": dict(kind="strip", base=0.85, peak=0.4, tip=0.45, sharp=0.5),
    "ovate_strip": dict(kind="strip", base=0.4, peak=0.35, tip=0.0, sharp=1.1),
}

#: The one leaf library: every named leaf, petal, card and strip shape, each with its ``kind``.
LEAF_SHAPES: dict[str, dict] = {**ALL_TYPES, **CARD_LEAVES, **STRIP_PROFILES}


def shape_name(word: str, kind: str) -> str:
    """The table name a preset's shape word means for a model that meshes leaves as ``kind``.

    Presets write plain words (``ovate``); a tree (cards) or a lawn (strips) reads the
    word as ``<word>_card`` / ``<word>_strip`` unless the word already names a shape of
    that kind. Unknown words raise :class:`ConfigError` listing the allowed words."""
    word = str(word)
    for name in (word, f"{word}_{kind}"):
        spec = LEAF_SHAPES.get(name)
        if spec is not None and spec["kind"] == kind:
            return name
    allowed = sorted(n[: -len(kind) - 1] for n, v in LEAF_SHAPES.items() if v["kind"] == kind)
    raise ConfigError(f"unknown {kind} leaf shape {word!r}; allowed: {', '.join(allowed)}")


def card_leaf(word: str) -> dict:
    """The card leaf (``verts`` (m, 3), ``faces``, ``agg_len``) a tree preset's ``leaf_shape`` names."""
    return LEAF_SHAPES[shape_name(word, "card")]


def strip_profile(word: str) -> dict:
    """A fresh copy of the strip width profile (base, peak, tip, sharp) a lawn preset's shape word names."""
    spec = dict(LEAF_SHAPES[shape_name(word, "strip")])
    del spec["kind"]
    return spec
