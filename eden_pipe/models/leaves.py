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

The shape tables (leaf, petal, card and strip shapes) live in
:mod:`eden_pipe.models.leaf_shapes` and are re-exported here.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np

from eden_pipe.geometry import any_perpendicular, normalize
from eden_pipe.models.leaf_shapes import (
    ALL_TYPES,
    BUSH_LEAF_TYPES,
    CARD_LEAVES,
    LEAF_SHAPES,
    LEAF_TYPES,
    PETAL_TYPES,
    STRIP_PROFILES,
    card_leaf,
    shape_name,
    strip_profile,
)

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
