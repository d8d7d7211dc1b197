"""The parts of a flowering plant: the part collector and the shared geometric pieces.

Split from :mod:`eden_pipe.models.flower` (which holds the per-kind builders
that assemble a plant and the preset handling). :class:`_Builder` collects one
plant's parts - petals and leaves instanced with :func:`leaves.place_leaves`,
stem tubes, raw meshes - each face carrying the flower label (docs/design.md,
Semantic labels), and draws its colours; the helpers below give stem curves,
petal whorls, composite disks and leaf sites along stems.
"""

from __future__ import annotations

import numpy as np

from eden_pipe import labels
from eden_pipe.colour import jitter_colors, srgb_to_linear
from eden_pipe.geometry import any_perpendicular, normalize, uniform_sphere
from eden_pipe.models.ivy import tube_mesh
from eden_pipe.models.leaves import lift_leaves_above_ground, place_leaves
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.models.presets import draw
from eden_pipe.rng import rng_for


class _Builder:
    """Collects parts of one plant; every face gets the flower label."""

    def __init__(self, preset: dict, seed: int, name: str):
        self.p = preset
        self.seed = seed
        self.name = name
        self.parts: list[Mesh] = []
        self.col_rng = self.rng("colour")
        mat = self.p.get("material", {})
        self.petal_trans = float(mat.get("petal_translucency", 0.35))
        self.leaf_trans = float(mat.get("leaf_translucency", 0.25))

    def rng(self, *names) -> np.random.Generator:
        return rng_for(self.seed, "flower", self.name, *names)

    def get(self, key, default, rng=None):
        v = self.p.get(key, default)
        return draw(v, rng) if rng is not None else v

    # -- geometry sinks
    def leaves(
        self,
        kind,
        leaf_type,
        pos,
        nrm,
        tan,
        size,
        rng,
        colors_lin,
        *,
        fold=None,
        curl=None,
        translucency=None,
        specular=0.03,
    ):
        if len(pos) == 0:
            return
        v, f = place_leaves(leaf_type, pos, nrm, tan, size, rng, fold=fold, curl=curl)
        v = lift_leaves_above_ground(v, len(pos))
        fpl = len(f) // len(pos)
        cols = np.repeat(np.broadcast_to(np.asarray(colors_lin, np.float32), (len(pos), 3)), fpl, axis=0)
        if translucency is None:
            translucency = self.petal_trans if kind == "petal" else self.leaf_trans
        self.parts.append(
            Mesh(v, f, np.full(len(f), labels.FLOWER), np.full(len(f), MATERIALS[kind]), cols, translucency, specular)
        )

    def tubes(self, pts, radii, ids, sides, color_srgb, kind="stem"):
        v, f = tube_mesh(pts, radii, ids, sides=sides)
        v[:, 2] = np.maximum(v[:, 2], 0.0)
        self.parts.append(
            Mesh.from_arrays(
                v, f, semantic=labels.FLOWER, material=kind, albedo=srgb_to_linear(color_srgb), translucency=0.05
            )
        )

    def raw(self, v, f, kind, colors_lin, translucency=0.1, specular=0.02):
        self.parts.append(
            Mesh(
                v,
                f,
                np.full(len(f), labels.FLOWER),
                np.full(len(f), MATERIALS[kind]),
                np.asarray(colors_lin, np.float32),
                translucency,
                specular,
            )
        )

    # -- colours
    def petal_palette(self, count: int, key="petal_colors", jitter_key="petal_hsv") -> np.ndarray:
        """One linear colour per blossom: a palette colour per plant (or per blossom), HSV-jittered."""
        pal = self.p.get(key, [[0.8, 0.1, 0.1]])
        if isinstance(pal[0], (int, float)):
            pal = [pal]
        hsv = self.p.get(jitter_key, [0.02, 0.08, 0.1])
        if self.p.get("color_per_blossom", False):
            pick = self.col_rng.integers(len(pal), size=count)
        else:
            pick = np.full(count, int(self.col_rng.integers(len(pal))))
        out = np.zeros((count, 3), np.float32)
        for j in np.unique(pick):
            m = pick == j
            out[m] = jitter_colors(pal[j], int(m.sum()), self.col_rng, *hsv)
        return out

    def leaf_colors(self, count: int) -> np.ndarray:
        return jitter_colors(
            self.p.get("leaf_color", [0.25, 0.42, 0.15]),
            count,
            self.col_rng,
            *self.p.get("leaf_hsv", [0.02, 0.1, 0.15]),
        )

    def mesh(self) -> Mesh:
        return Mesh.concatenate(self.parts)


# ----------------------------------------------------------------- shared pieces
def _curves(base, direction, length, bend, k: int):
    """Quadratic curves p(t) = base + L (dir t + bend t^2), t in [0,1]: (B,k,3) points and tangents."""
    t = np.linspace(0, 1, k)[None, :, None]
    L = np.asarray(length)[:, None, None]
    d = np.asarray(direction)[:, None, :]
    b = np.asarray(bend)[:, None, :]
    pts = np.asarray(base)[:, None, :] + L * (d * t + b * t * t)
    tan = normalize(d + 2 * b * t)
    return pts, tan


def _curve_at(base, direction, length, bend, t):
    """Points and tangents at parameters t (B,M) on the curves of :func:`_curves`."""
    t = np.asarray(t)[..., None]
    L = np.asarray(length)[:, None, None]
    d = np.asarray(direction)[:, None, :]
    b = np.asarray(bend)[:, None, :]
    return np.asarray(base)[:, None, :] + L * (d * t + b * t * t), normalize(d + 2 * b * t)


def _whorl(centers, axes, n, theta, radius, lift, phase):
    """Petal frames for B blossoms x n petals: positions, tangents (midribs), normals (inner faces)."""
    a = normalize(np.asarray(centers) * 0 + axes)
    e1 = any_perpendicular(a)
    e2 = np.cross(a, e1)
    phi = np.asarray(phase)[:, None] + 2 * np.pi * np.arange(n)[None, :] / n
    th = np.broadcast_to(np.asarray(theta, np.float64), phi.shape)
    r = np.cos(phi)[..., None] * e1[:, None] + np.sin(phi)[..., None] * e2[:, None]
    A = a[:, None, :]
    tan = np.cos(th)[..., None] * A + np.sin(th)[..., None] * r
    nrm = np.sin(th)[..., None] * A - np.cos(th)[..., None] * r
    pos = np.asarray(centers)[:, None, :] + np.asarray(radius)[:, None, None] * r + np.asarray(lift)[:, None, None] * A
    return pos.reshape(-1, 3), tan.reshape(-1, 3), nrm.reshape(-1, 3)


def _disk(centers, axes, radius, height, m=10):
    """Composite-flower disks: a low cone fan per head (apex raised by ``height``)."""
    B = len(centers)
    a = normalize(axes)
    e1 = any_perpendicular(a)
    e2 = np.cross(a, e1)
    ang = 2 * np.pi * np.arange(m) / m
    ring = centers[:, None] + radius[:, None, None] * (
        np.cos(ang)[None, :, None] * e1[:, None] + np.sin(ang)[None, :, None] * e2[:, None]
    )
    apex = centers + height[:, None] * a
    v = np.concatenate([apex[:, None], ring], 1).reshape(-1, 3)
    base = (np.arange(B) * (m + 1))[:, None]
    k = np.arange(m)[None]
    f = np.stack([base + 0 * k, base + 1 + k, base + 1 + (k + 1) % m], -1).reshape(-1, 3)
    return v, f


def _stem_leaves(base, direction, length, bend, n_per, t_range, rng):
    """Leaf sites along stems: positions, stem tangents, and outward directions."""
    B = len(base)
    t = rng.uniform(t_range[0], t_range[1], (B, n_per))
    pos, tan = _curve_at(base, direction, length, bend, t)
    pos, tan = pos.reshape(-1, 3), tan.reshape(-1, 3)
    side = normalize(np.cross(tan, uniform_sphere(len(pos), rng)))
    return pos, tan, side
