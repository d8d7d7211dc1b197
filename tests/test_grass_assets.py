"""Lawn blades and weeds (models.grass), garden assets and fences (models.assets),
and the generic primitives (models.primitives). Fast: a few seconds in all."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.models import assets, grass
from eden_pipe.models import primitives as prim
from eden_pipe.models.mesh import MATERIALS


def flat(x, y):
    return np.zeros_like(x)


def slope(x, y):
    return 0.3 + 0.08 * x - 0.05 * y + 0.02 * np.sin(7.0 * x) * np.cos(5.0 * y)


def patch(species, weights=None, seed=0, x0=2.0, y0=3.0, size=1.0, height=flat, **kw):
    weights = weights or [1.0] * len(species)
    return grass.build_lawn_patch(
        x0, y0, size, species, weights, seed, grass.LawnParams(**kw), height, return_blades=True
    )


def same(a, b) -> bool:
    da, db = a.to_npz_dict(), b.to_npz_dict()
    return da.keys() == db.keys() and all(np.array_equal(da[k], db[k]) for k in da)


# ---------------------------------------------------------------- grass presets
REQUIRED = [
    "st_augustine",
    "bahia",
    "centipede",
    "bermuda",
    "tall_fescue",
    "fine_fescue",
    "perennial_ryegrass",
    "annual_ryegrass",
    "kentucky_bluegrass",
    "zoysia",
    "buffalo",
    "creeping_bentgrass",
    "carpetgrass",
    "kikuyu",
    "dandelion",
    "speedwell",
    "prickly_lettuce",
    "white_clover",
    "broadleaf_plantain",
    "crabgrass",
    "chickweed",
    "creeping_charlie",
]


def test_grass_presets_cover_lawn_grasses_and_weeds():
    names = grass.list_grass_species()
    assert len(names) >= 30
    assert set(REQUIRED) <= set(names)
    kinds = {grass.grass_preset(n)["kind"] for n in names}
    assert kinds == set(grass.KINDS)
    assert grass.grass_preset("dandelion")["kind"] == "rosette" and grass.grass_preset("dandelion")["lobes"] > 0
    assert (
        grass.grass_preset("white_clover")["kind"] == "trifoliate"
        and grass.grass_preset("white_clover")["leaflets"] == 3
    )


@pytest.mark.parametrize("name", grass.list_grass_species())
def test_every_grass_preset_builds_a_patch(name):
    mesh, blades = patch([name], height=slope)
    mesh.validate()
    assert mesh.n_faces > 0 and len(blades.root) > 0
    assert np.all(np.isfinite(mesh.vertices))
    assert mesh.degenerate_fraction() < 1e-3
    assert mesh.n_faces <= 20000
    assert np.all(mesh.semantic == labels.GRASS)
    assert np.all(mesh.material == MATERIALS["grass"])
    assert mesh.albedo.min() >= 0 and mesh.albedo.max() <= 1
    # Green: the green channel dominates on average (fresh lawn).
    assert mesh.albedo[:, 1].mean() > mesh.albedo[:, 0].mean() and mesh.albedo[:, 1].mean() > mesh.albedo[:, 2].mean()
    assert 0.1 <= mesh.translucency.mean() <= 0.5
    # Everything stays within a plant's reach of the patch.
    lo, hi = mesh.bounds()
    assert lo[0] > 2.0 - 0.3 and hi[0] < 3.0 + 0.3 and lo[1] > 3.0 - 0.3 and hi[1] < 4.0 + 0.3


def test_lawn_is_deterministic_and_seeded_by_patch():
    a, _ = patch(["kentucky_bluegrass", "white_clover", "dandelion"], seed=5)
    b, _ = patch(["kentucky_bluegrass", "white_clover", "dandelion"], seed=5)
    assert same(a, b)
    c, _ = patch(["kentucky_bluegrass", "white_clover", "dandelion"], seed=6)
    d, _ = patch(["kentucky_bluegrass", "white_clover", "dandelion"], seed=5, x0=3.0)
    assert not np.array_equal(a.vertices[:100], c.vertices[:100])
    assert not np.array_equal(a.vertices[:100] - [2, 3, 0], d.vertices[:100] - [3, 3, 0])
    # int and float origins name the same patch
    e = grass.build_lawn_patch(
        2, 3, 1, ["kentucky_bluegrass", "white_clover", "dandelion"], [1, 1, 1], 5, grass.LawnParams(), flat
    )
    assert same(a, e)


def test_blades_are_rooted_on_the_terrain():
    mesh, blades = patch(["perennial_ryegrass", "dandelion", "white_clover", "chickweed"], height=slope)
    roots = grass.measure_blade_roots(mesh, blades)
    np.testing.assert_allclose(roots[:, 2], slope(roots[:, 0], roots[:, 1]), atol=2e-5)
    np.testing.assert_allclose(roots, blades.root, atol=2e-5)
    assert roots[:, 0].min() >= 2.0 and roots[:, 0].max() < 3.0 and roots[:, 1].min() >= 3.0 and roots[:, 1].max() < 4.0
    # Blades grow upwards from their roots.
    assert np.all(grass.measure_blade_heights(mesh, blades) > 0)


@pytest.mark.parametrize("name", ["kentucky_bluegrass", "tall_fescue", "bermuda"])
def test_blade_height_follows_config_and_trim(name):
    preset = grass.grass_preset(name)
    cfg = float(np.mean(preset["length_m"]))
    mesh, blades = patch([name])
    assert blades.length.mean() == pytest.approx(cfg, rel=0.05)
    h1 = grass.measure_blade_heights(mesh, blades).mean()
    assert 0.6 * cfg < h1 <= cfg  # leaning, curving blades stand a little lower than long
    for trim in (0.7, 0.5, 0.3):
        m, b = patch([name], trim=trim)
        assert grass.measure_blade_heights(m, b).mean() / h1 == pytest.approx(trim, rel=0.04)
    m, b = patch([name], trim=0.01)  # clipped at min_trim
    assert grass.measure_blade_heights(m, b).mean() / h1 == pytest.approx(grass.LawnParams().min_trim, rel=0.04)


@pytest.mark.parametrize(
    "name,size", [("kentucky_bluegrass", 1.0), ("st_augustine", 0.5), ("dandelion", 1.0), ("white_clover", 1.0)]
)
def test_density_follows_config_when_the_budget_allows(name, size):
    preset = grass.grass_preset(name)
    expected = preset["density_per_m2"] * size * size
    _, blades = patch([name], size=size, triangles_per_m2=10**7)
    assert blades.density_scale == 1.0
    assert abs(blades.units[0] - expected) <= max(1.0, 0.01 * expected)
    per_unit = 1 if preset["kind"] == "blade" else preset.get("leaves", preset.get("stems"))
    assert len(blades.root) == blades.units[0] * per_unit


def test_mix_weights_split_the_density():
    _, blades = patch(["kentucky_bluegrass", "st_augustine"], [3.0, 1.0], triangles_per_m2=10**7)
    np.testing.assert_allclose(blades.units, [0.75 * 20000, 0.25 * 6000], atol=1)


@pytest.mark.parametrize("budget", [500, 5000, 20000, 60000])
def test_triangle_budget_is_respected(budget):
    species = ["perennial_ryegrass", "fine_fescue", "white_clover", "dandelion", "creeping_charlie"]
    mesh, blades = patch(species, [0.5, 0.3, 0.1, 0.05, 0.05], triangles_per_m2=budget)
    assert mesh.n_faces <= budget
    if blades.density_scale < 1.0:  # thinned to the budget, not far below it
        assert mesh.n_faces >= 0.95 * budget - 200
    # The default budget reads as a lawn: within the 15-25K triangles/m^2 target.
    if budget == 20000:
        assert mesh.n_faces >= 15000


def test_budget_thins_blades_to_the_budget_count():
    mesh, blades = patch(["kentucky_bluegrass"])  # config 20000 blades/m^2, far above the budget
    assert blades.density_scale < 1.0
    per_blade = grass.triangles_per_unit(grass.grass_preset("kentucky_bluegrass"))
    assert blades.units[0] == 20000 // per_blade
    assert mesh.n_faces == blades.units[0] * per_blade


def test_lawn_params_change_the_look():
    sp = ["perennial_ryegrass"]
    base, _ = patch(sp)
    wet, _ = patch(sp, wetness=1.0)
    assert wet.specular.mean() == pytest.approx(base.specular.mean() + 0.12, abs=1e-6)  # wetness adds up to 0.12
    dry, _ = patch(sp, freshness=0.0)

    def ratio(m):
        return m.albedo[:, 0].mean() / m.albedo[:, 1].mean()

    assert ratio(dry) > ratio(base) + 0.3
    brown, _ = patch(sp, brownness=0.5)
    browned = brown.albedo[:, 0] > brown.albedo[:, 1] * 0.9
    assert 0.35 < browned.mean() < 0.65
    striped, bs = patch(sp, stripes=True, y0=0.0)
    idx = bs.vertex_start[:, None] + np.arange(bs.vertex_count[0])[None, :]
    lean_x = striped.vertices[idx, 0].mean(1) - bs.root[:, 0]
    band = np.floor(bs.root[:, 1] / 0.5).astype(int) % 2
    assert lean_x[band == 0].mean() > 0.005 and lean_x[band == 1].mean() < -0.005
    bright = striped.albedo.reshape(len(bs.root), -1, 3).mean((1, 2))
    assert bright[band == 0].mean() > bright[band == 1].mean()


def test_lawn_patch_input_errors():
    with pytest.raises(ValueError):
        grass.build_lawn_patch(0, 0, 1, ["bahia", "zoysia"], [1.0], 0, grass.LawnParams(), flat)
    with pytest.raises(ValueError):
        grass.build_lawn_patch(0, 0, 1, ["bahia"], [0.0], 0, grass.LawnParams(), flat)
    with pytest.raises(KeyError):
        grass.build_lawn_patch(0, 0, 1, ["astroturf"], [1.0], 0, grass.LawnParams(), flat)
    with pytest.raises(ValueError):
        grass.build_lawn_patch(0, 0, 1, ["bahia", "bahia"], [1.0, 1.0], 0, grass.LawnParams(), flat)


# ---------------------------------------------------------------- assets
ROCKS = [t for t in assets.list_asset_types() if assets.asset_preset(t)["family"] == "rock"]
OTHERS = [t for t in assets.list_asset_types() if t not in ROCKS]
ALLOWED_MATERIALS = {MATERIALS[m] for m in ("rock", "terracotta", "wood", "metal", "dirt", "generic")}


def test_asset_catalogue():
    types = set(assets.list_asset_types())
    families = {assets.asset_preset(t)["family"] for t in types}
    assert {"rock", "pot", "planter", "bench", "fence"} <= families
    styles = {assets.asset_preset(t).get("style") for t in ROCKS}
    assert {"round", "faceted"} <= styles
    assert {"rock_round", "rock_faceted", "rock_flat", "pot_terracotta", "planter_box", "bench"} <= types
    assert {"picket", "panel", "post_and_rail"} <= set(assets.list_fence_styles())


@pytest.mark.parametrize("asset_type", assets.list_asset_types())
def test_every_asset_builds(asset_type):
    for seed in (0, 1):
        m = assets.build_asset(asset_type, seed)
        m.validate()
        assert m.n_faces > 0 and np.all(np.isfinite(m.vertices))
        assert m.degenerate_fraction() < 1e-3
        assert np.all(m.semantic == labels.OBSTACLE)
        assert set(np.unique(m.material)) <= ALLOWED_MATERIALS
        assert m.albedo.min() >= 0 and m.albedo.max() <= 1
        lo, hi = m.bounds()
        height = hi[2] - lo[2]
        assert height > 0.02
        if asset_type in ROCKS:  # partially sunk
            assert -0.5 * height <= lo[2] < 0.0 < hi[2]
        else:
            assert abs(lo[2]) < 1e-5
        if not asset_type.startswith("fence_"):  # footprint centred on the origin
            assert np.all(np.abs(lo[:2] + hi[:2]) < 1e-3)
    assert same(assets.build_asset(asset_type, 3), assets.build_asset(asset_type, 3))
    assert not np.array_equal(assets.build_asset(asset_type, 3).albedo, assets.build_asset(asset_type, 4).albedo)


def test_asset_sizes_follow_presets():
    for seed in range(4):
        pot = assets.build_asset("pot_terracotta", seed)
        lo, hi = pot.bounds()
        assert 0.14 - 1e-6 <= hi[2] <= 0.3 + 1e-6
        assert np.any(pot.material == MATERIALS["dirt"]) and np.any(pot.material == MATERIALS["terracotta"])
        rock = assets.build_asset("rock_round", seed)
        lo, hi = rock.bounds()
        assert 0.15 * 0.7 <= hi[0] - lo[0] <= 0.45 * 1.4
        bench = assets.build_asset("bench", seed)
        assert {MATERIALS["wood"], MATERIALS["metal"]} <= set(np.unique(bench.material))
        assert 0.75 < bench.bounds()[1, 2] < 1.0


@pytest.mark.parametrize("style", assets.list_fence_styles())
@pytest.mark.parametrize("length", [0.3, 2.0, 7.5])
def test_fences(style, length):
    m = assets.build_fence(style, length, seed=2)
    m.validate()
    lo, hi = m.bounds()
    assert lo[0] >= -1e-5 and hi[0] <= length + 1e-5 and hi[0] - lo[0] > 0.97 * length
    assert abs(lo[2]) < 1e-5 and 0.8 <= hi[2] <= 1.6
    assert np.all(np.abs([lo[1], hi[1]]) < 0.2)
    assert m.degenerate_fraction() < 1e-3
    assert np.all(m.semantic == labels.OBSTACLE)
    assert same(m, assets.build_fence(style, length, seed=2))


def test_fence_errors():
    with pytest.raises(KeyError):
        assets.build_fence("electric", 2.0, 0)
    with pytest.raises(ValueError):
        assets.build_fence("picket", 0.0, 0)


# ---------------------------------------------------------------- primitives
def test_primitives_are_closed_and_outward():
    v, f = prim.box_batch([[0, 0, 0], [3, 0, 0]], [[1, 2, 3], [1, 1, 1]], prim.rotation_z([0.3, 1.0]))
    assert prim.signed_volume(v, f) == pytest.approx(7.0)
    v, f = prim.beam_batch([[0, 0, 0]], [[1, 1, 1]], 0.1, 0.2)
    assert prim.signed_volume(v, f) == pytest.approx(np.sqrt(3) * 0.02)
    poly = np.array([[-0.5, 0], [0.5, 0], [0.5, 1], [0, 1.5], [-0.5, 1]])
    v, f = prim.prism_batch(poly, 0.1, [[0, 0, 0], [1, 0, 0]])
    assert prim.signed_volume(v, f) == pytest.approx(0.25)
    v, f = prim.lathe([1, 1], [0, 1], 256, True, True)
    assert prim.signed_volume(v, f) == pytest.approx(np.pi, rel=1e-3)
    v, f = prim.icosphere(3)
    assert len(f) == 1280 and prim.signed_volume(v, f) == pytest.approx(4 / 3 * np.pi, rel=0.01)
    pts = np.random.default_rng(0).normal(size=(80, 3))
    v, f = prim.convex_hull(pts)
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    assert (pts @ n.T - np.sum(n * v[f[:, 0]], 1)).max() < 1e-9  # every point inside every face plane
    assert prim.signed_volume(v, f) > 0 and len(f) == 2 * len(v) - 4
