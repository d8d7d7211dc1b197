"""Hedges, topiaries (ivy on skeletons), leaf types and flowering plants."""

from __future__ import annotations

import numpy as np
import pytest
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

from eden_pipe import labels
from eden_pipe.colour import jitter_colors
from eden_pipe.models import ivy
from eden_pipe.models.bush import build_bush, build_bush_model, bush_types
from eden_pipe.models.flower import build_flower, flower_types
from eden_pipe.models.leaves import LEAF_TYPES, PETAL_TYPES, leaf_template, leaf_types, place_leaves
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.models.species import load_species

BUSHES = bush_types()
FLOWERS = flower_types()


@pytest.fixture(scope="module")
def bush_models():
    return {name: build_bush_model(name, 0) for name in BUSHES}


@pytest.fixture(scope="module")
def flower_meshes():
    return {name: build_flower(name, 0) for name in FLOWERS}


def _same(a: Mesh, b: Mesh) -> bool:
    da, db = a.to_npz_dict(), b.to_npz_dict()
    return da.keys() == db.keys() and all(np.array_equal(da[k], db[k]) for k in da)


# ------------------------------------------------------------------ leaves
def test_at_least_20_leaf_types_with_valid_templates():
    names = leaf_types()
    assert len(names) >= 20
    for required in (
        "elliptic",
        "ovate",
        "obovate",
        "lanceolate",
        "linear",
        "cordate",
        "reniform",
        "orbicular",
        "deltoid",
        "rhomboid",
        "spatulate",
        "oak",
        "maple",
        "needle",
        "scale",
        "acuminate",
        "serrated_elliptic",
        "hastate",
        "sagittate",
        "trifoliate",
    ):
        assert required in names
    for name in list(LEAF_TYPES) + list(PETAL_TYPES):
        tpl = leaf_template(name)
        t = tpl.xy[tpl.faces]
        a, b = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
        signed = 0.5 * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])
        assert np.all(signed > 0), name  # counter-clockwise seen from +z, nothing degenerate
        assert np.ptp(tpl.xy[:, 1]) == pytest.approx(1.0), name  # unit length along the midrib
        assert 0.02 < tpl.area() < 1.5, name
        lo, hi = LEAF_TYPES.get(name, PETAL_TYPES.get(name))["size"]
        assert 0 < lo < hi < 0.5


def test_leaf_outlines_are_simple_polygons():
    # Mirrored halves never overlap: summed triangle area equals the polygon's coverage area
    # measured on a raster (no triangle covers another).
    for name in ("oak", "maple", "sagittate", "hastate", "cordate", "ivy"):
        tpl = leaf_template(name)
        g = np.stack(np.meshgrid(np.linspace(-0.8, 0.8, 321), np.linspace(-0.5, 1.1, 321)), -1).reshape(-1, 2)
        cover = np.zeros(len(g), int)
        for a, b, c in tpl.xy[tpl.faces]:
            d1 = (b[0] - a[0]) * (g[:, 1] - a[1]) - (b[1] - a[1]) * (g[:, 0] - a[0])
            d2 = (c[0] - b[0]) * (g[:, 1] - b[1]) - (c[1] - b[1]) * (g[:, 0] - b[0])
            d3 = (a[0] - c[0]) * (g[:, 1] - c[1]) - (a[1] - c[1]) * (g[:, 0] - c[0])
            cover += (d1 > 1e-9) & (d2 > 1e-9) & (d3 > 1e-9)
        assert cover.max() == 1, name


def test_place_leaves_is_vectorised_and_oriented():
    rng = np.random.default_rng(0)
    n = 500
    pos = rng.normal(size=(n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    tan = rng.normal(size=(n, 3))
    size = rng.uniform(0.02, 0.06, n)
    v, f = place_leaves("ovate", pos, nrm, tan, size, np.random.default_rng(1), fold=0.0, curl=0.0, width_jitter=0.0)
    tpl = leaf_template("ovate")
    assert v.shape == (n * len(tpl.xy), 3) and v.dtype == np.float32
    assert f.shape == (n * len(tpl.faces), 3) and f.dtype == np.int32
    m = Mesh.from_arrays(v, f, semantic=4, material="leaf", albedo=(0, 1, 0))
    fn = m.face_normals().reshape(n, -1, 3)
    assert np.all(np.sum(fn * nrm[:, None], -1) > 0.999)  # flat leaves face their normals
    vv = v.reshape(n, -1, 3)
    assert np.allclose(vv[:, 0], pos, atol=1e-5)  # base at the position
    ext = np.linalg.norm(vv - pos[:, None], axis=2).max(1)
    assert np.all(ext <= size * 1.01 + 1e-6) and np.all(ext >= size * 0.99 - 1e-6)
    # deterministic for the same generator state
    a = place_leaves("maple", pos, nrm, tan, size, np.random.default_rng(5))
    b = place_leaves("maple", pos, nrm, tan, size, np.random.default_rng(5))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert place_leaves("needle", np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3)), [], rng)[1].shape == (0, 3)


def test_jitter_colors_stays_in_gamut():
    c = jitter_colors([0.3, 0.5, 0.1], 1000, np.random.default_rng(0), 0.05, 0.3, 0.4)
    assert c.shape == (1000, 3) and np.all(c >= 0) and np.all(c <= 1)
    assert np.all(c[:, 1] >= c[:, 2])  # still green-dominant


# ------------------------------------------------------------------ skeletons and ivy
SKELETONS = [
    ivy.BoxSkeleton(center=[0, 0, 0.5], half=[1.0, 0.4, 0.5], rounding=0.05),
    ivy.BoxSkeleton(center=[0, 0, 0.5], half=[1.0, 0.4, 0.5], rounding=0.0),
    ivy.SphereSkeleton(center=[0, 0, 0.8], radius=0.45),
    ivy.ConeSkeleton(z0=0.05, radius=0.4, height=1.3),
    ivy.StackedSpheresSkeleton(centers=[[0, 0, 0.4], [0, 0, 1.0], [0, 0, 1.4]], radii=[0.35, 0.25, 0.18]),
    ivy.HelixTubeSkeleton(z0=0.15, z1=1.5, turns=3.0, coil0=0.3, coil1=0.12, tube0=0.14, tube1=0.09),
]


@pytest.mark.parametrize("sk", SKELETONS, ids=lambda s: s.kind)
def test_skeleton_closest_point_matches_dense_surface(sk):
    rng = np.random.default_rng(0)
    lo, hi = sk.bounds()
    pts = rng.uniform(lo - 0.3, hi + 0.3, (400, 3))
    cp, nrm, sd = sk.query(pts)
    assert np.all(np.isfinite(cp)) and np.allclose(np.linalg.norm(nrm, axis=1), 1.0, atol=1e-6)
    # the closest point lies on the surface, at |sd| from the query, along the normal
    assert np.abs(sk.signed_distance(cp)).max() < 2e-3
    assert np.allclose(np.linalg.norm(pts - cp, axis=1), np.abs(sd), atol=2e-3)
    assert np.allclose(pts, cp + sd[:, None] * nrm, atol=2e-3)
    # outside points: no surface sample is nearer than the returned closest point
    dense, dense_n = sk.sample_surface(40000, rng)
    assert np.abs(sk.signed_distance(dense)).max() < 2e-3
    out = sd > 0.01
    d_brute = np.sqrt(((pts[out, None, :] - dense[None]) ** 2).sum(-1)).min(1)
    assert np.all(sd[out] <= d_brute + 2e-3)
    # sampled normals agree with the query's normals
    _, qn, _ = sk.query(dense[:2000])
    assert np.mean(np.sum(qn * dense_n[:2000], 1) > 0.95) > 0.97


def test_ivy_growth_hugs_the_skeleton_and_branches():
    sk = SKELETONS[2]
    rng = np.random.default_rng(3)
    seeds, n = sk.sample_surface(40, rng)
    params = ivy.IvyParams(max_length=0.4, adhesion_weight=0.3, max_float_length=0.1, trim_distance=0.02)
    g = ivy.grow_ivy(sk, seeds, ivy.surface_directions(n, rng, 0.0), params, rng)
    assert g.n_roots > 40 and g.root_generation.max() <= params.max_generations - 1
    sd = sk.signed_distance(g.pos)
    assert sd.min() > -1e-6 and sd.max() <= params.trim_distance + 1e-6  # reflected, trimmed
    assert np.all(np.diff(g.root) >= 0) and np.all(g.root_count >= 1)
    assert g.root_length().max() <= params.max_length + params.ivy_size
    steps = np.linalg.norm(np.diff(g.pos, axis=0), axis=1)[np.diff(g.root) == 0]
    assert steps.max() < 3 * params.ivy_size
    sites = ivy.ivy_leaves(g, rng, per_node=1.0, probability=0.8)
    assert len(sites.positions) > 100 and np.all((sites.weights >= 0) & (sites.weights <= 1))
    v, f = ivy.ivy_stems(g)
    assert len(f) > 0 and np.all(np.isfinite(v))


def test_ivy_defaults_follow_luft():
    p = ivy.IvyParams()
    assert (p.max_length, p.primary_weight, p.random_weight, p.gravity_weight, p.adhesion_weight) == (
        1.0,
        0.5,
        0.2,
        1.0,
        0.1,
    )
    assert (p.branching_probability, p.leaf_probability, p.ivy_size, p.max_float_length, p.max_adhesion_distance) == (
        0.05,
        0.35,
        0.02,
        0.5,
        1.0,
    )
    assert p.max_generations == 3


def test_tube_mesh_faces_outward():
    t = np.linspace(0, 1, 9)
    pts = np.stack([0.3 * np.sin(3 * t), 0.2 * t, t], 1)
    v, f = ivy.tube_mesh(pts, 0.01, np.zeros(9, int), sides=5)
    m = Mesh.from_arrays(v, f, semantic=0, material="stem", albedo=(0, 0, 0))
    assert m.degenerate_fraction() == 0.0 and m.n_faces == 8 * 5 * 2
    centre = np.repeat(pts[:-1], 10, axis=0)  # segment start for each face
    c = m.vertices[m.faces].mean(1)
    assert np.mean(np.sum(m.face_normals() * (c - centre), 1) > 0) > 0.95


# ------------------------------------------------------------------ bushes
def test_bush_presets_cover_the_required_shapes():
    kinds = {load_species("bushes", n)["skeleton"]["type"] for n in BUSHES}
    assert {"box", "sphere", "cone", "stacked_spheres", "spiral"} <= kinds
    for name in ("hedge_box", "topiary_sphere", "topiary_cone", "topiary_stacked_spheres", "topiary_spiral"):
        assert name in BUSHES
    assert len(BUSHES) >= 7


def test_bushes_are_valid_meshes(bush_models):
    for name, bm in bush_models.items():
        m = bm.mesh
        m.validate()
        assert 30_000 < m.n_faces < 400_000, (name, m.n_faces)
        assert m.degenerate_fraction() < 1e-3, name
        sem = labels.HEDGE if load_species("bushes", name)["semantic"] == "hedge" else labels.TOPIARY
        assert np.all(m.semantic == sem), name
        mats = set(np.unique(m.material).tolist())
        assert {MATERIALS["leaf"], MATERIALS["stem"], MATERIALS["bark"]} <= mats, name
        leaf = m.material == MATERIALS["leaf"]
        assert np.mean(leaf) > 0.5
        assert np.allclose(m.translucency[leaf], load_species("bushes", name)["material"]["leaf_translucency"])
        assert np.all(m.translucency[~leaf] == 0)
        assert 0 < m.specular[leaf].max() < 0.2
        assert np.all((m.albedo >= 0) & (m.albedo <= 1))
        lo, hi = m.bounds()
        assert lo[2] >= 0.0 and abs(lo[0] + hi[0]) < 0.15 and abs(lo[1] + hi[1]) < 0.15, name
        # foliage follows the skeleton: every leaf vertex is near its surface
        sd = bm.skeleton.signed_distance(m.vertices[m.faces[leaf, 0]])
        assert np.percentile(sd, 99) < 0.1 and np.percentile(sd, 1) > -0.1, name


def _write_preset(tmp_path, kind, name, changes):
    """A shipped preset with ``changes`` applied, written to ``tmp_path``."""
    import yaml

    data = load_species(kind, name)
    for key, value in changes.items():
        if isinstance(key, tuple):
            data[key[0]][key[1]] = value
        else:
            data[key] = value
    path = tmp_path / f"{name}_bad.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.mark.parametrize(
    "kind, name, loader, bad_key, section",
    [
        ("bushes", "topiary_sphere", "eden_pipe.models.bush:load_bush_preset", ("leaves", "covrage"), "leaves"),
        ("bushes", "topiary_sphere", "eden_pipe.models.bush:load_bush_preset", ("skeleton", "radiuss"), "skeleton"),
        ("bushes", "hedge_box", "eden_pipe.models.bush:load_bush_preset", "colour", None),
        ("flowers", "tulip", "eden_pipe.models.flower:load_flower_preset", "stem_lenght", None),
        ("trees", "sassafras", "eden_pipe.models.tree:tree_params", "LeafScal", None),
        ("grass", "annual_bluegrass", "eden_pipe.models.grass:grass_preset", "density", None),
        ("assets", "pot_terracotta", "eden_pipe.models.assets:asset_preset", "hieght_m", None),
    ],
)
def test_unknown_preset_key_is_a_config_error(tmp_path, kind, name, loader, bad_key, section):
    import importlib

    from eden_pipe.errors import ConfigError

    module, func = loader.split(":")
    load = getattr(importlib.import_module(module), func)
    good = _write_preset(tmp_path, kind, name, {})
    load(good)  # an unchanged preset loads from a file too
    path = _write_preset(tmp_path, kind, name, {bad_key: 1.0})
    key = bad_key[1] if isinstance(bad_key, tuple) else bad_key
    with pytest.raises(ConfigError) as err:
        load(path)
    msg = str(err.value)
    assert str(path) in msg and repr(key) in msg and "allowed:" in msg, msg
    if section:
        assert repr(section) in msg


def test_every_shipped_preset_passes_its_key_check():
    from eden_pipe.models import assets, bush, flower, grass, tree
    from eden_pipe.models.species import list_species

    for n in list_species("bushes"):
        bush.load_bush_preset(n)
    for n in list_species("flowers"):
        flower.load_flower_preset(n)
    for n in list_species("trees"):
        tree.tree_params(n)
    for n in list_species("grass"):
        grass.grass_preset(n)
    for n in list_species("assets"):
        assets.asset_preset(n)


def test_preset_grammar():
    from eden_pipe.models.presets import draw, draw_array, draw_float, draw_int

    rng = np.random.default_rng(0)
    assert draw(0.5, rng) == 0.5 and draw("box", rng) == "box"
    state = rng.bit_generator.state
    assert draw([0.3, 0.3], rng) == 0.3 and rng.bit_generator.state == state  # lo == hi: no draw
    vals = [draw([1.0, 2.0], rng) for _ in range(200)]
    assert all(1.0 <= v < 2.0 for v in vals) and np.std(vals) > 0.2
    assert {draw({"choice": ["a", "b", "c"]}, rng) for _ in range(100)} == {"a", "b", "c"}
    assert {draw_int([2, 4], rng) for _ in range(100)} == {2, 3, 4} and draw_int(5, rng) == 5
    assert isinstance(draw_float(1, rng), float)
    a = draw_array([0.1, 0.2], rng, 50)
    assert a.shape == (50,) and a.min() >= 0.1 and a.max() < 0.2
    assert np.all(draw_array(0.4, rng, 3) == 0.4)
    # the same draws as a plain generator: the grammar never adds or reorders draws
    r1, r2 = np.random.default_rng(7), np.random.default_rng(7)
    got = [draw([0.0, 1.0], r1), draw_int([0, 9], r1), *draw_array([1.0, 2.0], r1, 2)]
    want = [r2.uniform(0.0, 1.0), int(r2.integers(0, 10)), *r2.uniform(1.0, 2.0, 2)]
    assert got == want


def test_bushes_are_deterministic():
    for name in ("hedge_box", "topiary_spiral"):
        a, b = build_bush(name, 3), build_bush(name, 3)
        np.random.seed(123)  # noqa: NPY002  (the legacy global state must not matter)
        c = build_bush(name, 3)
        assert _same(a, b) and _same(a, c), name
        assert not np.array_equal(build_bush(name, 4).vertices[:100], a.vertices[:100])


def _fullness(bm, n=3000, seed=0):
    """Fraction of rays, from a sphere around the model aimed at random skeleton surface points,
    whose first hit is a leaf (real Embree)."""
    rng = np.random.default_rng(seed)
    target, _ = bm.skeleton.sample_surface(n, rng)
    lo, hi = bm.skeleton.bounds()
    centre = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) + 0.5
    d = target - centre
    d = d / np.linalg.norm(d, axis=1, keepdims=True) + 0.3 * rng.normal(size=(n, 3))
    origin = centre + radius * d / np.linalg.norm(d, axis=1, keepdims=True)
    origin[:, 2] = np.maximum(origin[:, 2], 0.05)  # viewpoints above the ground
    direction = target - origin
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, bm.mesh.vertices.astype(np.float32), bm.mesh.faces.astype(np.int32))
    res = scene.run(origin.astype(np.float32), direction.astype(np.float32), output=1)
    prim = res["primID"]
    hit = prim >= 0
    first = np.where(hit, bm.mesh.material[np.maximum(prim, 0)], 255)
    return float(np.mean(first == MATERIALS["leaf"])), float(np.mean(~hit))


def test_hedges_and_topiaries_are_full(bush_models):
    for name, bm in bush_models.items():
        leaf_first, miss = _fullness(bm)
        assert leaf_first >= 0.90, (name, leaf_first, miss)


def test_fullness_holds_for_other_seeds():
    for name in ("hedge_boxwood", "topiary_stacked_spheres"):
        leaf_first, _ = _fullness(build_bush_model(name, 7), seed=1)
        assert leaf_first >= 0.90, (name, leaf_first)


def test_stems_show_inside():
    # internal structure: stems and woody branches exist inside the leaf shell
    bm = build_bush_model("hedge_box", 1)
    m = bm.mesh
    wood = np.isin(m.material, [MATERIALS["stem"], MATERIALS["bark"]])
    sd = bm.skeleton.signed_distance(m.vertices[m.faces[wood, 0]])
    assert np.mean(sd < 0) > 0.005 and wood.sum() > 1000


# ------------------------------------------------------------------ flowers
def test_flower_presets(flower_meshes):
    kinds = {load_species("flowers", n)["kind"] for n in FLOWERS}
    assert {"rose", "tulip", "composite", "lavender", "groundcover"} <= kinds
    assert len(FLOWERS) >= 5
    for name, m in flower_meshes.items():
        m.validate()
        assert 500 < m.n_faces < 60_000, (name, m.n_faces)
        assert m.degenerate_fraction() < 1e-3, name
        assert np.all(m.semantic == labels.FLOWER), name
        mats = set(np.unique(m.material).tolist())
        assert {MATERIALS["petal"], MATERIALS["leaf"], MATERIALS["stem"]} <= mats, name
        petal = m.material == MATERIALS["petal"]
        assert 0.25 <= np.median(m.translucency[petal]) <= 0.45, name
        assert m.bounds()[0][2] >= 0.0 and m.bounds()[1][2] < 1.5, name


def test_flowers_are_deterministic_and_vary_in_colour():
    for name in FLOWERS:
        a, b = build_flower(name, 2), build_flower(name, 2)
        assert _same(a, b), name
    # colour variation between seeds (palettes of several colours)
    for name in ("rose_bush", "tulip"):
        cols = set()
        for seed in range(8):
            m = build_flower(name, seed)
            petal = m.material == MATERIALS["petal"]
            cols.add(tuple(np.round(np.median(m.albedo[petal], axis=0), 1)))
        assert len(cols) >= 2, name
