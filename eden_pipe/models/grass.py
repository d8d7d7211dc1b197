"""Lawn grass and lawn weeds as parametric blade families, built particle-style.

A lawn patch is a square of terrain (normally 1 x 1 m) covered by blades and
weed plants of several species mixed by weight. Every species is a YAML preset
under ``conf/species/grass/`` with a ``kind``:

- ``blade``: grass blades (lawn grasses and grassy weeds such as crabgrass),
  one tapered, bent, twisted strip per blade; ``density_per_m2`` counts blades.
- ``rosette``: a flat rosette of leaves from one crown (dandelion with lobed
  leaves, plantains, prickly lettuce, violets); density counts plants.
- ``trifoliate``: petioles rising from the ground, each topped by
  ``leaflets`` (3 for clovers, black medic, oxalis; 1 for dichondra).
- ``creeper``: low stems with opposite leaf pairs at every node (chickweed,
  speedwell, creeping charlie, henbit, purslane).

Everything is built from one vectorised primitive, a strip along a bent
centreline with a width profile, k segments, 2 triangles a segment and one
triangle at a pointed tip (so a pointed strip of k segments has 2k-1
triangles, a blunt one 2k). No Python loop runs per blade.

Budget: ``density_per_m2`` of every species (times its weight) is thinned by
one common factor until the patch fits ``LawnParams.triangles_per_m2`` (never
exceeded); thinned grass blades are widened (up to ``width_compensation``) to
keep the cover, and short (trimmed) blades use fewer segments
(``segment_length``), so the budget buys more blades.

Roots are placed from ``rng_for(seed, "lawn", x0, y0, species)`` (clumps plus
uniform scatter, wrapped into the patch so neighbouring patches tile without
seams) and sit exactly on ``height_at(x, y)``. Colour follows the species
preset, a garden-wide noise field (patchiness, continuous across patches),
the :class:`LawnParams` (freshness, brown/dead blades, wetness, mowing stripes)
and a darkening towards the blade base. EDEN labels weeds in a lawn as grass,
so every face is semantic 1 (``labels.GRASS``), material ``grass``.

The per-kind builders and the root placement are in :mod:`eden_pipe.models.lawn_kinds`;
this module holds the presets, the budget, the patch assembly and the colouring.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from eden_pipe.models.lawn_kinds import (  # noqa: F401  (moved; callers import it from here)
    _BUILDERS,
    STRIPE_WIDTH,
    _build_blades,
    _build_creepers,
    _build_rosettes,
    _build_trifoliate,
    _clip_to,
    _deg,
    _height,
    _jitter,
    _lengths,
    _stripe_sign,
    place_points,
)
from eden_pipe.models.lawn_strips import Strips, strip_triangles, strips_mesh
from eden_pipe.models.leaves import strip_profile
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.noise import Perlin
from eden_pipe.models.presets import load_preset
from eden_pipe.models.species import list_species, load_species
from eden_pipe.rng import rng_for

KIND = "grass"
KINDS = ("blade", "rosette", "trifoliate", "creeper")

DEAD_COLOUR = np.array([0.22, 0.15, 0.065])
DRY_COLOUR = np.array([0.20, 0.17, 0.055])


@dataclass
class LawnParams:
    freshness: float = 1.0  # 1 fresh green .. 0 dry
    brownness: float = 0.0  # 0..1 fraction of brown/dead blades
    wetness: float = 0.0  # 0..1 -> specular (and slight darkening)
    trim: float = 1.0  # 0..1 cut height fraction: blade lengths scaled by max(trim, min_trim)
    stripes: bool = False  # alternating mowing direction in 0.5 m strips along y
    triangles_per_m2: int = 20000  # budget; density is reduced (never exceeded) to meet it
    min_trim: float = 0.15  # trim is clipped here (a mower does not shave to the soil)
    width_compensation: float = 2.0  # max blade widening when the budget thins the lawn (1 = off)
    patchiness: float = 1.0  # strength of the garden-wide colour/dryness noise
    segment_length: float = 0.025  # blade LOD: segments = min(preset, max(2, ceil(mean length / this)))


@dataclass
class BladeSet:
    """Per-strip metadata of a lawn patch (ground-rooted strips only: blades,
    rosette leaves, petioles, creeper stems; leaflets and stem leaves ride on them).

    ``vertex_start``/``vertex_count`` index the strip's vertices in the mesh
    returned with it; the first two vertices of a strip straddle its root.
    """

    species_names: list[str]
    root: np.ndarray  # (N, 3) root point on the terrain
    length: np.ndarray  # (N,) centreline length after trim
    species: np.ndarray  # (N,) index into species_names
    vertex_start: np.ndarray  # (N,)
    vertex_count: np.ndarray  # (N,)
    units: np.ndarray  # (S,) blades (kind blade) or plants per species
    density_scale: float  # budget thinning factor (1 = config density)
    area: float
    n_triangles: int = 0
    extra: dict = field(default_factory=dict)


# --------------------------------------------------------------------- presets
def list_grass_species() -> list[str]:
    return list_species(KIND)


#: A preset's ``role``: a lawn grass can carry a lawn alone; a weed grows sparsely in one.
LAWN_GRASS_ROLE = "lawn grass"


def is_lawn_grass(name: str) -> bool:
    """Whether the grass preset ``name`` is a lawn grass (``role: lawn grass``), not a weed."""
    return load_species(KIND, name).get("role") == LAWN_GRASS_ROLE


#: Defaults of each kind's own keys, and its strip-shape keys with their default shape words.
KIND_DEFAULTS: dict[str, dict[str, float]] = {
    "blade": {"segments": 3},
    "rosette": {"segments": 6, "leaves": 8, "plant_radius_m": 0.004},
    "trifoliate": {
        "segments": 3,
        "leaflet_segments": 3,
        "leaflets": 3,
        "leaves": 6,
        "plant_radius_m": 0.05,
        "petiole_width_m": 0.0015,
        "leaflet_bend_deg": 80.0,
        "leaflet_aspect": 0.8,
    },
    "creeper": {
        "segments": 4,
        "leaf_segments": 2,
        "stems": 4,
        "plant_radius_m": 0.01,
        "stem_width_m": 0.0015,
        "leaf_bend_deg": 65.0,
        "leaf_aspect": 0.6,
    },
}
KIND_SHAPES: dict[str, dict[str, str]] = {
    "blade": {},
    "rosette": {},
    "trifoliate": {"leaflet_shape": "obovate"},
    "creeper": {"leaf_shape": "ovate"},
}

#: Every key a grass preset may use: identity, the keys of all kinds and their defaults below.
PRESET_KEYS = {
    "name",
    "latin",
    "role",
    "kind",
    "density_per_m2",
    "color",
    "stem_color",
    "color_var",
    "hue_var",
    "clumping",
    "clump_radius_m",
    "clump_size",
    "specular",
    "translucency",
    "base_shade",
    "length_m",
    "width_m",
    "width_var",
    "bend_deg",
    "bend_var_deg",
    "curvature_deg",
    "curvature_var_deg",
    "twist_deg",
    "shape",
    "petiole",
    "lobes",
    "lobe_depth",
    "segments",
    "leaves",
    "plant_radius_m",
    "leaflets",
    "leaflet_segments",
    "leaflet_length_m",
    "leaflet_shape",
    "leaflet_bend_deg",
    "leaflet_aspect",
    "petiole_width_m",
    "stems",
    "stem_width_m",
    "leaf_segments",
    "leaf_length_m",
    "leaf_shape",
    "leaf_bend_deg",
    "leaf_aspect",
    "leaf_petiole",
}


def grass_preset(name) -> dict:
    """Preset (a name, or a path to a YAML file) with defaults filled in (see module docstring for the kinds)."""
    p = load_preset(KIND, name, PRESET_KEYS)
    kind = p.setdefault("kind", "blade")
    if kind not in KINDS:
        raise ValueError(f"grass preset {name!r}: unknown kind {kind!r}; allowed: {', '.join(KINDS)}")
    p.setdefault("name", name)
    p.setdefault("color_var", 0.12)
    p.setdefault("hue_var", 0.05)
    p.setdefault("clumping", 0.3)
    p.setdefault("clump_radius_m", 0.02)
    p.setdefault("clump_size", 12)
    p.setdefault("specular", 0.03)
    p.setdefault("translucency", 0.3)
    p.setdefault("base_shade", 0.6)
    p.setdefault("twist_deg", 20.0)
    p.setdefault("bend_var_deg", 10.0)
    p.setdefault("curvature_var_deg", 12.0)
    p.setdefault("width_var", 0.15)
    defaults_shape = {"blade": "grass", "rosette": "oblanceolate", "trifoliate": "obovate", "creeper": "ovate"}[kind]
    p["shape"] = _shape(p.get("shape", defaults_shape))
    p.setdefault("petiole", 0.0)
    p.setdefault("lobes", 0)
    p.setdefault("lobe_depth", 0.0)
    for key, value in KIND_DEFAULTS[kind].items():
        p.setdefault(key, value)
    for key, default in KIND_SHAPES[kind].items():
        p[key] = _shape(p.get(key, default))
    return p


def _shape(spec) -> dict:
    """A strip width profile: a shape word from the leaf table, or a mapping over the ``grass`` profile."""
    if isinstance(spec, str):
        return strip_profile(spec)
    out = strip_profile("grass")
    out.update(spec)
    return out


def triangles_per_unit(preset: dict) -> int:
    """Triangles of one blade (kind blade) or one plant (other kinds)."""
    kind, k = preset["kind"], int(preset["segments"])
    if kind == "blade":
        return strip_triangles(k, preset["shape"])
    if kind == "rosette":
        return int(preset["leaves"]) * strip_triangles(k, preset["shape"])
    if kind == "trifoliate":
        leaflet = strip_triangles(int(preset["leaflet_segments"]), preset["leaflet_shape"])
        return int(preset["leaves"]) * (2 * k + int(preset["leaflets"]) * leaflet)
    leaf = strip_triangles(int(preset["leaf_segments"]), preset["leaf_shape"])
    return int(preset["stems"]) * (2 * k + 2 * k * leaf)


@lru_cache(maxsize=16)
def _colour_noise(seed: int) -> Perlin:
    return Perlin(rng_for(seed, "lawn_colour"))


# ---------------------------------------------------------------- the lawn
def build_lawn_patch(
    x0: float,
    y0: float,
    size: float,
    species: list[str],
    weights: list[float],
    seed: int,
    params: LawnParams | None,
    height_at: Callable[[np.ndarray, np.ndarray], np.ndarray],
    *,
    return_blades: bool = False,
):
    """The lawn over the square [x0, x0+size) x [y0, y0+size), world frame.

    ``species`` are grass preset names mixed by ``weights`` (fractions of the
    area). Returns the mesh, or ``(mesh, BladeSet)`` with ``return_blades``.
    """
    params = params or LawnParams()
    if len(species) != len(weights):
        raise ValueError(f"{len(species)} species but {len(weights)} weights")
    w = np.asarray(weights, np.float64)
    if len(w) == 0 or np.any(w < 0) or w.sum() <= 0:
        raise ValueError(f"weights must be >= 0 with a positive sum, got {weights}")
    if len(set(species)) != len(species):
        raise ValueError(f"duplicate species in {species}: merge their weights")
    w = w / w.sum()
    presets = [grass_preset(s) for s in species]
    area = float(size) ** 2
    x0, y0 = float(x0), float(y0)
    trim = float(np.clip(params.trim, params.min_trim, 1.0))
    for p in presets:
        if p["kind"] == "blade" and params.segment_length > 0:
            # Short (trimmed) blades need fewer segments: spend the budget on more blades.
            need_k = int(np.ceil(trim * float(np.mean(p["length_m"])) / params.segment_length))
            p["segments"] = int(min(p["segments"], max(2, need_k)))

    # Units per species at config density, then thin uniformly to the budget.
    expected = np.array([p["density_per_m2"] * wi * area for p, wi in zip(presets, w, strict=True)])
    tpu = np.array([triangles_per_unit(p) for p in presets], np.float64)
    budget = float(params.triangles_per_m2) * area
    need = float(np.sum(expected * tpu))
    rng = rng_for(seed, "lawn", x0, y0)
    scale = min(1.0, budget / need) if need > 0 else 1.0
    # Stochastic rounding: a sparse species (a weed at under one plant per patch) still appears in
    # some patches, in proportion, instead of vanishing from the whole lawn.
    counts = np.floor(expected * scale + rng.random(len(expected))).astype(np.int64)
    # Rounding up may overshoot the budget: trim back (never exceed it).
    while np.sum(counts * tpu) > budget:
        counts[np.argmax(np.where(counts > 0, tpu, -1))] -= 1
    width_gain = float(np.clip(scale**-0.5, 1.0, max(1.0, params.width_compensation)))
    perlin = _colour_noise(int(seed))

    meshes, meta = [], []
    v_offset = 0
    for i, (name, preset) in enumerate(zip(species, presets, strict=True)):
        n = int(counts[i])
        if n <= 0:
            continue
        srng = rng_for(seed, "lawn", x0, y0, name)
        builder = _BUILDERS[preset["kind"]]
        parts, ground = builder(srng, n, preset, x0, y0, float(size), trim, width_gain, params, height_at)
        mesh = _colour_parts(srng, parts, preset, params, perlin, n)
        g_strips = ground
        nv = g_strips.vertices.shape[1]
        starts = v_offset + np.arange(g_strips.n) * nv  # ground batch is always the first part
        meta.append((i, g_strips.centre[:, 0].copy(), _centre_length(g_strips), starts, np.full(g_strips.n, nv)))
        v_offset += mesh.n_vertices
        meshes.append(mesh)
    mesh = Mesh.concatenate(meshes)
    if not return_blades:
        return mesh
    if meta:
        blades = BladeSet(
            list(species),
            np.concatenate([m[1] for m in meta]),
            np.concatenate([m[2] for m in meta]),
            np.concatenate([np.full(len(m[1]), m[0]) for m in meta]),
            np.concatenate([m[3] for m in meta]),
            np.concatenate([m[4] for m in meta]),
            counts,
            scale,
            area,
            mesh.n_faces,
        )
    else:
        blades = BladeSet(
            list(species),
            np.zeros((0, 3)),
            np.zeros(0),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
            np.zeros(0, np.int64),
            counts,
            scale,
            area,
            0,
        )
    return mesh, blades


def _centre_length(strips: Strips) -> np.ndarray:
    return np.linalg.norm(np.diff(strips.centre, axis=1), axis=-1).sum(1)


def measure_blade_heights(mesh: Mesh, blades: BladeSet) -> np.ndarray:
    """Per ground-rooted strip: highest vertex z minus root z, from the mesh itself."""
    z = mesh.vertices[:, 2].astype(np.float64)
    out = np.empty(len(blades.vertex_start))
    for count in np.unique(blades.vertex_count):
        sel = blades.vertex_count == count
        idx = blades.vertex_start[sel][:, None] + np.arange(count)[None, :]
        out[sel] = z[idx].max(1) - blades.root[sel, 2]
    return out


def measure_blade_roots(mesh: Mesh, blades: BladeSet) -> np.ndarray:
    """Per ground-rooted strip: midpoint of its first two vertices (the root)."""
    v = mesh.vertices.astype(np.float64)
    return 0.5 * (v[blades.vertex_start] + v[blades.vertex_start + 1])


# ------------------------------------------------------------------ colour
def _colour_parts(rng, parts, p, params: LawnParams, perlin: Perlin, n_units: int) -> Mesh:
    """Colour every part of a species batch and mesh it."""
    base = np.asarray(p["color"], np.float64)
    # Per-unit (blade or plant) colour: brightness and hue jitter.
    bright = np.exp(rng.normal(0.0, p["color_var"], n_units))
    hue = np.exp(rng.normal(0.0, p["hue_var"], (n_units, 3)))
    unit_col = base[None, :] * bright[:, None] * hue
    meshes = []
    for strips, unit, role, dead in parts:
        col = unit_col[unit]
        if role == "stem" and "stem_color" in p:
            col = np.asarray(p["stem_color"], np.float64)[None, :] * bright[unit, None]
        root = strips.centre[:, 0]
        pts = np.column_stack([root[:, 0] * 0.6, root[:, 1] * 0.6])
        noise_a = _fbm(perlin, pts, 0.37)
        noise_b = _fbm(perlin, pts * 1.7, 5.71)
        patch = float(params.patchiness)
        col = col * (1.0 + 0.12 * patch * noise_a)[:, None]
        dry = np.clip(
            (1.0 - params.freshness) * (1.0 + 0.6 * patch * noise_b) + 0.06 * patch * np.maximum(noise_b, 0.0), 0.0, 1.0
        )
        dry_col = DRY_COLOUR * (np.mean(col, axis=1, keepdims=True) / max(1e-6, float(np.mean(base))) * 0.5 + 0.5)
        col = col * (1.0 - dry[:, None]) + dry_col * dry[:, None]
        dead_col = (
            DEAD_COLOUR[None, :]
            * np.exp(rng.normal(0.0, 0.15, (len(col), 1)))
            * np.exp(rng.normal(0, 0.05, (len(col), 3)))
        )
        col = np.where(dead[:, None], dead_col, col)
        if params.stripes:
            col = col * (1.0 + 0.07 * _stripe_sign(root[:, 1]))[:, None]
        col = col * (1.0 - 0.18 * float(params.wetness))
        trans = np.where(dead, 0.1, p["translucency"] * (1.0 - 0.5 * dry))
        spec = np.full(len(col), p["specular"] + 0.12 * float(params.wetness))
        shade = np.full(len(col), p["base_shade"] if role != "stem" else 0.85)
        meshes.append(strips_mesh(strips, np.clip(col, 0.0, 1.0), trans, spec, shade))
    return Mesh.concatenate(meshes)


def _fbm(perlin: Perlin, xy: np.ndarray, z: float) -> np.ndarray:
    pts = np.column_stack([xy, np.full(len(xy), z)])
    return perlin.fbm(pts, octaves=2)
