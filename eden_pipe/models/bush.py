"""Hedges and topiaries: ivy grown on a hidden skeleton, as in EDEN.

``build_bush(bush_type, seed)`` reads the preset ``conf/species/bushes/<type>.yaml``
and returns one :class:`Mesh` in the model frame (Z up, base centred at the
origin, z >= 0). A preset gives

- ``semantic``: ``hedge`` (label 4) or ``topiary`` (label 5), for every face;
- ``skeleton``: the shape the ivy climbs (``box``, ``sphere``, ``cone``,
  ``stacked_spheres``, ``spiral``) with size ranges ``[lo, hi]``;
- ``ivy``: :class:`eden_pipe.models.ivy.IvyParams` fields plus the seeding
  (``seeds_per_m2`` over the skeleton surface, ``seed_up_bias`` of the initial
  directions, ``seed_low_boost`` to seed the lower parts more densely, since
  ivy climbs);
- ``leaves``: the leaf types a variant draws its one leaf type from (``types``: a list,
  or a mapping to weights; absent: :data:`~eden_pipe.models.leaves.BUSH_LEAF_TYPES`, 23
  types), size range, density (``coverage``: one-sided leaf area per skeleton area;
  ``even_cell``: voxel size of the light-competition thinning that evens out the
  foliage), ``max_triangles`` (leaf triangle budget: a type with many triangles a
  leaf gets fewer, larger leaves) and orientation;
- ``stems``: ivy stem tube radius, node decimation and sides;
- ``colors``: sRGB leaf colour(s) with per-plant (``plant_hsv``: the variant's colour
  augmentation, a hue shift in turns and relative saturation and value changes drawn
  uniformly within +-these) and per-leaf HSV jitter, stem and bark colours;
- ``material``: leaf translucency / specular;
- ``wood``: inner branches feeding the surface (and a trunk for topiaries), which show between leaves.

Every scalar written as ``[lo, hi]`` is drawn uniformly per (type, seed);
all randomness comes from ``rng_for(seed, "bush", bush_type, <part>)``. The
variant's look (leaf type and colour augmentation) has its own stream
(``"look"``) and is reported by :meth:`BushModel.facts`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe import labels
from eden_pipe.colour import jitter_colors, shift_hsv, srgb_to_linear
from eden_pipe.errors import ConfigError
from eden_pipe.models import ivy as ivy_mod
from eden_pipe.models.leaves import BUSH_LEAF_TYPES, LEAF_TYPES, leaf_template, lift_leaves_above_ground, place_leaves
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.models.presets import draw, draw_array, load_preset
from eden_pipe.models.species import list_species
from eden_pipe.models.tubes import tube_mesh
from eden_pipe.rng import rng_for

SEMANTICS = {"hedge": labels.HEDGE, "topiary": labels.TOPIARY}
SEEDING_KEYS = ("seeds_per_m2", "seed_up_bias", "seed_low_boost")


def preset_keys() -> dict:
    """Allowed keys of a bush preset, by section (``None``: the top level)."""
    return {
        None: {"semantic", "skeleton", "ivy", "leaves", "stems", "wood", "colors", "material"},
        "skeleton": ivy_mod.skeleton_preset_keys(),
        "ivy": set(ivy_mod.IvyParams.__dataclass_fields__) | set(SEEDING_KEYS),
        "leaves": {
            "types",
            "size",
            "coverage",
            "max_triangles",
            "per_node",
            "probability",
            "weight_floor",
            "normal_jitter",
            "up_bias",
            "offset",
            "spread",
            "even_cell",
            "oversample",
        },
        "stems": {"radius", "every", "sides"},
        "wood": {
            "trunk",
            "trunk_radius",
            "trunk_sides",
            "branch_fraction",
            "branch_radius",
            "inset",
            "segments",
            "sides",
        },
        "colors": {"leaf", "leaf_weights", "plant_hsv", "leaf_hsv", "stem", "bark"},
        "material": {"leaf_translucency", "leaf_specular"},
    }


def load_bush_preset(bush_type) -> dict:
    """The checked preset (a name, or a path to a YAML file)."""
    return load_preset("bushes", bush_type, preset_keys())


def bush_types() -> list[str]:
    return list_species("bushes")


DEFAULT_PLANT_HSV = (0.04, 0.25, 0.25)  # per-variant colour augmentation bounds (hue turns, rel. S, rel. V)

#: Leaf triangles a bush may use (``leaves.max_triangles``); about what 20k six-triangle leaves take.
MAX_LEAF_TRIANGLES = 150_000


@dataclass
class BushModel:
    mesh: Mesh
    skeleton: ivy_mod.Skeleton
    params: dict  # resolved skeleton parameters, counts and the variant's look

    def facts(self) -> dict:
        """What this variant drew, for the model stage's records: leaf type, leaf size range (m),
        the variant's HSV shift (hue turns, relative saturation and value) and its main leaf
        colour after the shift (sRGB)."""
        keys = ("leaf_type", "leaf_size_m", "leaf_hsv_shift", "leaf_colour_srgb", "leaves")
        return {k: self.params[k] for k in keys}


# --------------------------------------------------------------------------- build
def build_bush(bush_type: str, seed: int) -> Mesh:
    """The hedge or topiary preset ``bush_type`` grown for ``seed`` (deterministic)."""
    return build_bush_model(bush_type, seed).mesh


def build_bush_model(bush_type: str, seed: int) -> BushModel:
    preset = load_bush_preset(bush_type)
    semantic = SEMANTICS[preset.get("semantic", "hedge")]
    r_shape = rng_for(seed, "bush", bush_type, "shape")
    r_ivy = rng_for(seed, "bush", bush_type, "ivy")
    r_leaf = rng_for(seed, "bush", bush_type, "leaves")
    r_col = rng_for(seed, "bush", bush_type, "colour")
    r_wood = rng_for(seed, "bush", bush_type, "wood")
    lc = preset.get("leaves", {})
    colors = preset.get("colors", {})
    leaf_type, hsv_shift = variant_look(preset, rng_for(seed, "bush", bush_type, "look"))

    sk_spec, trunk_top = ivy_mod.draw_skeleton_spec(preset["skeleton"], r_shape)
    skeleton = ivy_mod.make_skeleton(sk_spec)

    # ---- ivy growth from seeds spread over the skeleton surface
    ivy_cfg = dict(preset.get("ivy", {}))
    params = ivy_mod.IvyParams.from_dict({k: draw(v, r_ivy) for k, v in ivy_cfg.items()}, ignore=SEEDING_KEYS)
    n_seeds = max(8, int(round(skeleton.area() * float(ivy_cfg.get("seeds_per_m2", 60)))))
    seeds, seed_n = _sample_seeds(skeleton, n_seeds, float(ivy_cfg.get("seed_low_boost", 0.0)), r_ivy)
    seeds = seeds + seed_n * 0.002
    seeds[:, 2] = np.maximum(seeds[:, 2], params.ground_z + 0.005)
    dirs = ivy_mod.surface_directions(seed_n, r_ivy, float(ivy_cfg.get("seed_up_bias", 0.5)))
    growth = ivy_mod.grow_ivy(skeleton, seeds, dirs, params, r_ivy)

    # ---- leaves
    template = leaf_template(leaf_type)
    lo, hi = (float(x) for x in lc.get("size", (0.03, 0.05)))
    expected = None
    if "coverage" in lc:  # total one-sided leaf area = coverage x skeleton area
        mean_s2 = (hi**3 - lo**3) / (3 * (hi - lo)) if hi > lo else lo * lo
        expected = float(lc["coverage"]) * skeleton.area() / (template.area() * mean_s2 * 1.05**2)
        # Over the triangle budget, fewer and larger leaves keep the same leaf area.
        budget = float(lc.get("max_triangles", MAX_LEAF_TRIANGLES))
        grow = float(np.sqrt(max(1.0, expected * template.faces_per_leaf / budget)))
        lo, hi, expected = lo * grow, hi * grow, expected / grow**2
    sites = ivy_mod.ivy_leaves(
        growth,
        r_leaf,
        per_node=float(lc.get("per_node", 1.0)),
        probability=float(lc.get("probability", params.leaf_probability)),
        weight_floor=float(lc.get("weight_floor", 0.0)),
        normal_jitter=float(lc.get("normal_jitter", 0.4)),
        up_bias=float(lc.get("up_bias", 0.2)),
        offset=tuple(lc.get("offset", (0.0, 0.0))),
        expected_count=expected,
        spread=float(lc.get("spread", 0.0)),
        even_cell=float(lc.get("even_cell", 0.0)),
        oversample=float(lc.get("oversample", 2.5)),
    )
    n_leaves = len(sites.positions)
    # Luft: leaves grow with the relative length along the root
    sizes = draw_array((lo, hi), r_leaf, n_leaves) * (0.8 + 0.3 * sites.weights)

    leaf_palette = colors.get("leaf", [[0.25, 0.42, 0.14]])
    if isinstance(leaf_palette[0], (int, float)):
        leaf_palette = [leaf_palette]
    leaf_palette = [shift_hsv(base, *hsv_shift) for base in leaf_palette]
    pw = np.array(colors.get("leaf_weights", [1.0] * len(leaf_palette)), np.float64)
    leaf_jit = colors.get("leaf_hsv", [0.02, 0.12, 0.18])

    mat = preset.get("material", {})
    parts: list[Mesh] = []
    if n_leaves:
        v, f = place_leaves(leaf_type, sites.positions, sites.normals, sites.tangents, sizes, r_leaf)
        v = lift_leaves_above_ground(v, n_leaves, params.ground_z)
        fpl = len(f) // n_leaves
        pal = r_col.choice(len(leaf_palette), size=n_leaves, p=pw / pw.sum())
        cols = np.zeros((n_leaves, 3), np.float32)
        for j, base in enumerate(leaf_palette):
            m = pal == j
            if m.any():
                cols[m] = jitter_colors(base, int(m.sum()), r_col, *leaf_jit)
        parts.append(
            Mesh(
                v,
                f,
                np.full(len(f), semantic),
                np.full(len(f), MATERIALS["leaf"]),
                np.repeat(cols, fpl, axis=0),
                float(mat.get("leaf_translucency", 0.25)),
                float(mat.get("leaf_specular", 0.04)),
            )
        )

    # ---- ivy stems
    sc = preset.get("stems", {})
    sv, sf = ivy_mod.ivy_stems(
        growth,
        radius=float(sc.get("radius", 0.0015)),
        every=int(sc.get("every", 3)),
        sides=int(sc.get("sides", 3)),
        ground_z=params.ground_z,
    )
    stem_col = srgb_to_linear(colors.get("stem", [0.33, 0.30, 0.18]))
    parts.append(Mesh.from_arrays(sv, sf, semantic=semantic, material="stem", albedo=stem_col))

    # ---- wood: inner branches to some seeds, trunk for topiaries
    wood = preset.get("wood", {})
    bark_col = srgb_to_linear(colors.get("bark", [0.30, 0.24, 0.17]))
    wv, wf = _wood(skeleton, sk_spec, seeds, seed_n, trunk_top, wood, r_wood)
    parts.append(Mesh.from_arrays(wv, wf, semantic=semantic, material="bark", albedo=bark_col))

    mesh = Mesh.concatenate(parts)
    info = dict(
        skeleton=sk_spec,
        seeds=n_seeds,
        roots=growth.n_roots,
        nodes=growth.n_nodes,
        leaves=n_leaves,
        leaf_type=leaf_type,
        leaf_size_m=[round(lo, 4), round(hi, 4)],
        leaf_hsv_shift=[round(float(x), 4) for x in hsv_shift],
        leaf_colour_srgb=[round(float(x), 4) for x in leaf_palette[0]],
    )
    return BushModel(mesh=mesh, skeleton=skeleton, params=info)


def leaf_type_pool(types) -> tuple[list[str], np.ndarray]:
    """The leaf types a preset's ``leaves.types`` allows and their probabilities: absent ->
    :data:`BUSH_LEAF_TYPES` (uniform), a name, a list (uniform) or a mapping name -> weight."""
    if types is None:
        types = list(BUSH_LEAF_TYPES)
    if isinstance(types, str):
        types = [types]
    weights = types if isinstance(types, dict) else dict.fromkeys(types, 1.0)
    names = list(weights)
    unknown = [n for n in names if n not in LEAF_TYPES]
    if unknown or not names:
        raise ConfigError(f"bush leaves.types={names!r}: allowed: leaf types from {', '.join(LEAF_TYPES)}")
    w = np.array([float(weights[n]) for n in names])
    return names, w / w.sum()


def variant_look(preset: dict, rng: np.random.Generator) -> tuple[str, np.ndarray]:
    """A variant's look, drawn from its own stream: one leaf type from the preset's pool
    (:func:`leaf_type_pool`) and the colour augmentation, an HSV shift (hue turns, relative
    saturation, relative value) uniform within +-``colors.plant_hsv``."""
    names, p = leaf_type_pool(preset.get("leaves", {}).get("types"))
    leaf_type = names[int(rng.choice(len(names), p=p))]
    bound = np.asarray(preset.get("colors", {}).get("plant_hsv", DEFAULT_PLANT_HSV), np.float64)
    return leaf_type, rng.uniform(-1, 1, 3) * bound


def _sample_seeds(skeleton, n: int, low_boost: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """Surface seeds, denser low down by ``1 + low_boost * (1 - z/height)**2`` (ivy climbs, so the
    base of a shape would otherwise stay bare)."""
    if low_boost <= 0:
        return skeleton.sample_surface(n, rng)
    pts, nrm = skeleton.sample_surface(3 * n, rng)
    lo, hi = skeleton.bounds()
    zf = np.clip((pts[:, 2] - lo[2]) / max(hi[2] - lo[2], 1e-9), 0.0, 1.0)
    w = 1.0 + low_boost * (1.0 - zf) ** 2
    pick = rng.choice(len(pts), size=n, replace=False, p=w / w.sum())
    return pts[pick], nrm[pick]


def _wood(skeleton, sk_spec, seeds, seed_n, trunk_top, cfg: dict, rng) -> tuple[np.ndarray, np.ndarray]:
    verts, faces = [], []
    offset = 0

    def add(v, f):
        nonlocal offset
        verts.append(v)
        faces.append(f + offset)
        offset += len(v)

    # trunk (topiaries): ground to the shape, with a slight lean
    if trunk_top > 0 and cfg.get("trunk", True):
        tr = float(draw(cfg.get("trunk_radius", [0.02, 0.035]), rng))
        top = np.array([*(rng.normal(0, 0.01, 2)), trunk_top])
        pts, ids = ivy_mod.branch_paths(np.zeros((1, 3)), top[None], rng, segments=6, wobble=0.02)
        rad = tr * np.linspace(1.15, 0.6, len(pts))
        v, f = tube_mesh(pts, rad, ids, sides=int(cfg.get("trunk_sides", 7)))
        add(v, f)
    # inner branches: from core points (or the ground under a hedge) to a fraction of the seeds
    frac = float(cfg.get("branch_fraction", 0.15))
    nb = int(round(frac * len(seeds)))
    if nb > 0:
        pick = rng.choice(len(seeds), size=nb, replace=False)
        ends = seeds[pick] - seed_n[pick] * float(cfg.get("inset", 0.02))
        if sk_spec["type"] == "box":
            lo, hi = skeleton.bounds()
            starts = np.stack(
                [rng.uniform(lo[0] * 0.85, hi[0] * 0.85, nb), rng.uniform(lo[1] * 0.4, hi[1] * 0.4, nb), np.zeros(nb)],
                1,
            )
            # pull the branch towards the end laterally so it rises inside the box
            starts[:, 0] = 0.6 * starts[:, 0] + 0.4 * ends[:, 0]
        else:
            core = skeleton.core_points()
            d = np.linalg.norm(ends[:, None] - core[None], axis=2)
            starts = core[np.argmin(d, axis=1)] + rng.normal(0, 0.02, (nb, 3))
        starts[:, 2] = np.maximum(starts[:, 2], 0.0)
        pts, ids = ivy_mod.branch_paths(starts, ends, rng, segments=int(cfg.get("segments", 4)), wobble=0.12)
        r0 = draw_array(cfg.get("branch_radius", [0.004, 0.009]), rng, nb)
        t = np.tile(np.linspace(0, 1, int(cfg.get("segments", 4)) + 1), nb)
        rad = np.repeat(r0, int(cfg.get("segments", 4)) + 1) * (1.0 - 0.65 * t)
        pts[:, 2] = np.maximum(pts[:, 2], rad)
        v, f = tube_mesh(pts, rad, ids, sides=int(cfg.get("sides", 4)))
        add(v, f)
    if not verts:
        return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32)
    v = np.concatenate(verts)
    v[:, 2] = np.maximum(v[:, 2], 0.0)  # a leaning trunk's base ring would dip below the ground
    return v, np.concatenate(faces)
