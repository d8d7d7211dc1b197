"""Leaf (and petal) shapes as data, and vectorised instancing of many leaves at once.

Every leaf type is a 2-D outline in a unit leaf frame: x across the blade, y
along the midrib (petiole/base at the origin, the blade extending towards +y,
total extent along y normalised to 1), z the blade normal. A type is one of

- ``profile``: a symmetric simple leaf from a half-width profile
  ``w(t) = aspect/2 * sin(pi * t**a)**b`` (optionally toothed or lobed by
  alternating stations), sampled at ``stations`` points along the midrib;
- ``outline``: a symmetric simple leaf from right-half control points running
  from the base ``(0, y0)`` to the tip ``(0, y1)`` with ``x >= 0``; points
  flagged sharp keep their corner, the others are rounded by Chaikin corner
  cutting (``smooth`` passes);
- ``compound``: leaflets (other types, each translated/rotated/scaled) on an
  optional rachis strip (trifoliate, palmate, pinnate leaves, needle sprays).

A simple leaf is triangulated half by half: the right-half polygon (outline
plus the midrib edge tip -> base) is ear-clipped (for a convex half this is a
fan from the base, for a profile leaf a strip along the midrib) and mirrored,
so the midrib is an edge of the mesh and the blade can fold along it. At
placement each leaf gets a fold (``z += fold * |x|``, V-shaped about its
midrib) and a curl (``z += curl * y**2``, bending along its length).

:func:`place_leaves` instances N leaves of one type in one vectorised pass
(no per-leaf Python loop); faces come grouped per leaf, ``faces_per_leaf``
consecutive faces each, so per-leaf attributes expand with ``np.repeat``.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from eden_pipe.errors import ConfigError
from eden_pipe.geometry import any_perpendicular, normalize

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


_DEFAULT_FOLD = (0.05, 0.35)
_DEFAULT_CURL = (-0.05, 0.25)


def leaf_types() -> list[str]:
    """The leaf type names (petal shapes excluded), in table order."""
    return list(LEAF_TYPES)


def size_range(leaf_type: str) -> tuple[float, float]:
    return tuple(float(s) for s in _spec(leaf_type)["size"])  # type: ignore[return-value]


def _spec(leaf_type: str) -> dict:
    try:
        return ALL_TYPES[leaf_type]
    except KeyError:
        raise KeyError(f"unknown leaf type {leaf_type!r}; allowed: {', '.join(ALL_TYPES)}") from None


# ----------------------------------------------------------------- templates
@dataclass(frozen=True)
class LeafTemplate:
    """A unit leaf: (n, 2) vertices, (f, 3) faces (counter-clockwise seen from +z),
    per-vertex fold coordinate (distance from the leaflet midrib) and curl coordinate."""

    xy: np.ndarray
    faces: np.ndarray
    fold_coord: np.ndarray
    curl_coord: np.ndarray
    fold: tuple[float, float]
    curl: tuple[float, float]

    @property
    def faces_per_leaf(self) -> int:
        return len(self.faces)

    def area(self) -> float:
        """Flat area of the unit leaf (length 1)."""
        t = self.xy[self.faces]
        a, b = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        return float(0.5 * np.abs(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]).sum())


def _profile_half(spec: dict) -> np.ndarray:
    k = int(spec["stations"])
    t = (np.arange(1, k + 1) - 0.5) / k  # stations strictly inside (0, 1)
    t = 0.5 - 0.5 * np.cos(np.pi * t)  # denser towards base and tip
    w = np.sin(np.pi * t ** spec.get("a", 1.0)) ** spec.get("b", 0.6)
    if spec.get("teeth"):
        w = w * np.where(np.arange(k) % 2 == 1, 1.0 - spec["teeth"], 1.0)
    w = 0.5 * spec["aspect"] * w
    return np.concatenate([[[0.0, 0.0]], np.stack([w, t], 1), [[0.0, 1.0]]])


def _outline_half(spec: dict) -> np.ndarray:
    pts = [(float(p[0]), float(p[1]), bool(p[2]) if len(p) > 2 else False) for p in spec["points"]]
    for _ in range(int(spec.get("smooth", 1))):
        out = [pts[0]]
        for i in range(1, len(pts) - 1):
            x, y, sharp = pts[i]
            if sharp:
                out.append(pts[i])
                continue
            (xa, ya, _), (xb, yb, _) = pts[i - 1], pts[i + 1]
            out.append((0.75 * x + 0.25 * xa, 0.75 * y + 0.25 * ya, False))
            out.append((0.75 * x + 0.25 * xb, 0.75 * y + 0.25 * yb, False))
        out.append(pts[-1])
        pts = out
    return np.array([(x, y) for x, y, _ in pts], dtype=np.float64)


def _ear_clip(poly: np.ndarray) -> np.ndarray:
    """Triangulate a simple counter-clockwise polygon; zero-area ears are dropped."""
    idx = list(range(len(poly)))
    tris: list[tuple[int, int, int]] = []

    def cross(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])

    guard = 0
    while len(idx) > 3 and guard < 10000:
        guard += 1
        n = len(idx)
        clipped = False
        for j in range(n):
            i0, i1, i2 = idx[j - 1], idx[j], idx[(j + 1) % n]
            a, b, c = poly[i0], poly[i1], poly[i2]
            if cross(a, b, c) <= 1e-12:
                continue
            inside = False
            for k in idx:
                if k in (i0, i1, i2):
                    continue
                p = poly[k]
                if cross(a, b, p) >= -1e-12 and cross(b, c, p) >= -1e-12 and cross(c, a, p) >= -1e-12:
                    inside = True
                    break
            if inside:
                continue
            tris.append((i0, i1, i2))
            del idx[j]
            clipped = True
            break
        if not clipped:  # only collinear runs left
            j = 0
            del idx[j]
    if len(idx) == 3 and cross(poly[idx[0]], poly[idx[1]], poly[idx[2]]) > 1e-12:
        tris.append(tuple(idx))  # type: ignore[arg-type]
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _simple_leaf(spec: dict) -> tuple[np.ndarray, np.ndarray]:
    half = _profile_half(spec) if spec["kind"] == "profile" else _outline_half(spec)
    if np.any(half[1:-1, 0] <= 0) or half[0, 0] != 0 or half[-1, 0] != 0:
        raise ValueError("a half outline must run from the base to the tip on x > 0")
    tri = _ear_clip(half)  # polygon closed by the midrib edge tip -> base: counter-clockwise
    m = len(half)
    # Mirror: interior outline points get new vertices, base and tip are shared.
    mirror_idx = np.concatenate([[0], np.arange(m, 2 * m - 2), [m - 1]])
    xy = np.concatenate([half, half[1:-1] * [-1.0, 1.0]])
    faces = np.concatenate([tri, mirror_idx[tri][:, ::-1]])
    return xy, faces


@cache
def leaf_template(leaf_type: str) -> LeafTemplate:
    """The unit template of a leaf or petal type (cached)."""
    spec = _spec(leaf_type)
    if spec["kind"] == "compound":
        parts_xy, parts_f, fold_c = [], [], []
        count = 0
        if spec.get("rachis"):
            w, length = spec["rachis"]
            parts_xy.append(np.array([[-w / 2, 0], [w / 2, 0], [w / 2, length], [-w / 2, length]]))
            parts_f.append(np.array([[0, 1, 2], [0, 2, 3]]))
            fold_c.append(np.zeros(4))
            count = 4
        for name, (ox, oy), angle, scale, *wide in spec["leaflets"]:
            sub = leaf_template(name)
            a = np.radians(angle)
            rot = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])  # +angle turns +y towards -x
            widen = float(wide[0]) if wide else 1.0
            parts_xy.append((sub.xy * [widen, 1.0]) @ rot.T * scale + [ox, oy])
            parts_f.append(sub.faces + count)
            fold_c.append(sub.fold_coord * widen * scale)
            count += len(sub.xy)
        xy = np.concatenate(parts_xy)
        faces = np.concatenate(parts_f)
        fold_coord = np.concatenate(fold_c)
    else:
        xy, faces = _simple_leaf(spec)
        fold_coord = np.abs(xy[:, 0])
    # Normalise the extent along the midrib to 1, keeping the base at the origin.
    extent = xy[:, 1].max() - xy[:, 1].min()
    xy = xy / extent
    fold_coord = fold_coord / extent
    # Drop any zero-area triangle (never expected; keeps instancing clean).
    t = xy[faces]
    area = 0.5 * (
        (t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0])
    )
    if np.any(area <= 0):
        raise ValueError(f"leaf type {leaf_type!r} has a triangle with non-positive area")
    curl_coord = xy[:, 1] - min(0.0, xy[:, 1].min())
    return LeafTemplate(
        xy=xy.astype(np.float64),
        faces=faces.astype(np.int32),
        fold_coord=fold_coord,
        curl_coord=curl_coord,
        fold=tuple(spec.get("fold", _DEFAULT_FOLD)),
        curl=tuple(spec.get("curl", _DEFAULT_CURL)),
    )


def faces_per_leaf(leaf_type: str) -> int:
    return leaf_template(leaf_type).faces_per_leaf


# ----------------------------------------------------------------- instancing
def lift_leaves_above_ground(v: np.ndarray, count: int, ground: float = 0.0) -> np.ndarray:
    """Raise each of ``count`` leaves (their vertices in leaf order) that reaches below ``ground``
    so that it rests 0.1 mm above it; leaves are lifted whole, never squashed."""
    vv = v.reshape(count, -1, 3)
    dz = np.maximum(ground + 1e-4 - vv[:, :, 2].min(1), 0.0)
    vv[:, :, 2] += dz[:, None]
    return vv.reshape(-1, 3)


def leaf_frames(normals: np.ndarray, tangents: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal (across, along, normal) axes; tangents are made perpendicular to the normals."""
    n = normalize(np.asarray(normals, np.float64).reshape(-1, 3))
    t = np.asarray(tangents, np.float64).reshape(-1, 3)
    t = t - np.sum(t * n, axis=1, keepdims=True) * n
    bad = np.linalg.norm(t, axis=1) < 1e-9
    t = normalize(t)
    if np.any(bad):
        t[bad] = any_perpendicular(n[bad])
    b = np.cross(t, n)  # x = y cross z
    return b, t, n


def place_leaves(
    leaf_type: str,
    positions,
    normals,
    tangents,
    sizes,
    rng: np.random.Generator,
    *,
    fold=None,
    curl=None,
    width_jitter: float = 0.1,
) -> tuple[np.ndarray, np.ndarray]:
    """Instance N leaves of one type: base at ``positions``, blade facing ``normals``,
    midrib along ``tangents`` (projected into the blade plane), length ``sizes``.

    ``fold``/``curl`` are scalars, per-leaf arrays or ``None`` (drawn from the type's
    default ranges with ``rng``); the width varies by +-``width_jitter``. Returns
    float32 (N*n, 3) vertices and int32 (N*f, 3) faces, f faces per leaf in leaf order.
    """
    tpl = leaf_template(leaf_type)
    pos = np.asarray(positions, np.float64).reshape(-1, 3)
    count = len(pos)
    if count == 0:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    b, t, n = leaf_frames(normals, tangents)
    size = np.broadcast_to(np.asarray(sizes, np.float64), (count,))
    fold_v = rng.uniform(*tpl.fold, count) if fold is None else np.broadcast_to(np.asarray(fold, np.float64), (count,))
    curl_v = rng.uniform(*tpl.curl, count) if curl is None else np.broadcast_to(np.asarray(curl, np.float64), (count,))
    width = rng.uniform(1.0 - width_jitter, 1.0 + width_jitter, count) if width_jitter else np.ones(count)
    x = tpl.xy[None, :, 0] * width[:, None]  # (N, n)
    y = np.broadcast_to(tpl.xy[None, :, 1], x.shape)
    z = fold_v[:, None] * tpl.fold_coord[None, :] + curl_v[:, None] * tpl.curl_coord[None, :] ** 2
    s = size[:, None, None]
    verts = pos[:, None, :] + s * (
        x[..., None] * b[:, None, :] + y[..., None] * t[:, None, :] + z[..., None] * n[:, None, :]
    )
    faces = tpl.faces[None, :, :] + (np.arange(count, dtype=np.int64) * len(tpl.xy))[:, None, None]
    return verts.reshape(-1, 3).astype(np.float32), faces.reshape(-1, 3).astype(np.int32)


__all__ = [
    "BUSH_LEAF_TYPES",
    "CARD_LEAVES",
    "LEAF_SHAPES",
    "LEAF_TYPES",
    "PETAL_TYPES",
    "STRIP_PROFILES",
    "LeafTemplate",
    "card_leaf",
    "faces_per_leaf",
    "leaf_frames",
    "leaf_template",
    "leaf_types",
    "place_leaves",
    "shape_name",
    "size_range",
    "strip_profile",
]
