"""Weber-Penn trees (eden_pipe.models.tree): presets, structure statistics, meshes, budget."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.models.mesh import MATERIALS
from eden_pipe.models.tree import (
    build_tree,
    carry_round,
    envelope_inside,
    grow_skeleton,
    list_tree_species,
    place_leaves,
    shape_ratio,
    tree_params,
)

SPECIES = [
    "quaking_aspen",
    "black_tupelo",
    "weeping_willow",
    "ca_black_oak",
    "sassafras",
    "palm",
    "fan_palm",
    "european_larch",
    "tamarack",
    "balsam_fir",
    "lombardy_poplar",
    "eastern_cottonwood",
    "desert_bush",
    "douglas_fir",
    "japanese_maple",
    "small_maple",
    "small_pine",
    "white_birch",
    "callistemon",
]
SMALL = 20_000


def test_all_19_presets_exist_and_resolve():
    assert sorted(list_tree_species()) == sorted(SPECIES)
    for name in SPECIES:
        p = tree_params(name)
        assert 1 <= p.levels <= 4
        lo, hi = p["height_m"]
        assert 0.5 <= lo < hi <= 8.0
        for key in ("leaf_color", "bark_color"):
            col = np.asarray(p[key], float)
            assert col.shape == (3,) and np.all((col >= 0) & (col <= 1))
        assert 0.0 < float(p["leaf_translucency"]) < 0.6
        assert p["Leaves"] != 0
        assert all(len(v) == 4 for v in p.lv.values())


def test_shape_ratios_and_carried_rounding():
    r = np.array([0.0, 0.5, 1.0])
    np.testing.assert_allclose(shape_ratio(0, r), [0.2, 0.6, 1.0])
    np.testing.assert_allclose(shape_ratio(1, r), [0.2, 1.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(shape_ratio(3, r), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(shape_ratio(4, r), [0.5, 0.75, 1.0])
    np.testing.assert_allclose(shape_ratio(5, [0.7, 1.0]), [1.0, 0.0])
    np.testing.assert_allclose(shape_ratio(7, [0.0, 0.7, 1.0]), [0.5, 1.0, 0.5])
    env = shape_ratio(8, [-0.1, 0.4, 1.1], tree_params("weeping_willow"))
    assert env[0] == 0 and env[2] == 0 and abs(env[1] - 1.0) < 1e-9  # peak at 1 - PruneWidthPeak
    x = np.random.default_rng(0).random(1000) * 3.7
    counts, _ = carry_round(x)
    assert abs(counts.sum() - x.sum()) <= 0.5 + 1e-9
    assert np.all(counts >= np.floor(x) - 1) and np.all(counts <= np.ceil(x) + 1)


def _arrays(mesh):
    return mesh.to_npz_dict()


def test_determinism():
    a = build_tree("quaking_aspen", 7, triangle_budget=SMALL)
    b = build_tree("quaking_aspen", 7, triangle_budget=SMALL)
    for key, value in _arrays(a).items():
        np.testing.assert_array_equal(value, _arrays(b)[key], err_msg=key)
    c = build_tree("quaking_aspen", 8, triangle_budget=SMALL)
    assert a.n_vertices != c.n_vertices or not np.array_equal(a.vertices, c.vertices)
    # the skeleton too, and another species with clones and pruning
    s1, s2 = grow_skeleton("weeping_willow", 3), grow_skeleton("weeping_willow", 3)
    for l1, l2 in zip(s1.levels, s2.levels, strict=True):
        np.testing.assert_array_equal(l1.points, l2.points)
    s3 = grow_skeleton("weeping_willow", 4)
    assert s3.levels[1].n != s1.levels[1].n or not np.allclose(s3.levels[1].points, s1.levels[1].points)


@pytest.mark.parametrize("species", ["quaking_aspen", "palm", "balsam_fir", "weeping_willow", "japanese_maple"])
def test_height_in_range_and_model_frame(species):
    heights = []
    for seed in (0, 1):
        m = build_tree(species, seed, height_range=(3.0, 4.0), triangle_budget=SMALL)
        lo, hi = m.bounds()
        assert 3.0 - 1e-4 <= hi[2] <= 4.0 + 1e-4
        assert lo[2] >= -1e-5  # nothing below the ground plane
        bark = m.vertices[np.unique(m.faces[m.material == MATERIALS["bark"]])]
        bottom = bark[bark[:, 2] < 0.01]
        assert len(bottom) and np.abs(bottom[:, :2].mean(axis=0)).max() < 0.05  # trunk base at the origin
        heights.append(hi[2])
    assert heights[0] != heights[1]


def _trunk_expectation(skel):
    p = skel.params
    trunk = skel.levels[0]
    base = float(p["BaseSize"])
    a = np.maximum(base, trunk.start / trunk.res)
    return float(p.lv["nBranches"][1]) * (1 - a) / (1 - base)


@pytest.mark.parametrize("species", ["quaking_aspen", "black_tupelo", "sassafras", "lombardy_poplar"])
def test_trunk_carries_nbranches(species):
    """Level-1 stems on the trunk: nBranches above BaseSize (no trunk splits in these presets)."""
    p = tree_params(species)
    counts = []
    for seed in range(4):
        skel = grow_skeleton(species, seed)
        assert skel.levels[0].n == 1
        counts.append(skel.children_per_stem(1)[0])
    nb = float(p.lv["nBranches"][1])
    assert abs(np.mean(counts) - nb) <= max(1.0, 0.05 * nb), counts


@pytest.mark.parametrize("species", ["ca_black_oak", "eastern_cottonwood", "weeping_willow"])
def test_split_trunks_share_the_branch_density(species):
    skel = grow_skeleton(species, 1)
    assert skel.levels[0].n > 1  # base splits made clones
    observed = skel.children_per_stem(1).sum()
    expected = _trunk_expectation(skel).sum()
    assert abs(observed - expected) <= 0.05 * expected + 2


def test_deeper_levels_follow_weber_penn_counts():
    """Level-2 per level-1 stem: nBranches*(0.2+0.8*(L/Lpar)/lmax); level 3: nBranches*(1-0.5*off/Lpar)."""
    for species, d in (("quaking_aspen", 2), ("black_tupelo", 2), ("black_tupelo", 3), ("sassafras", 3)):
        p = tree_params(species)
        nb = float(p.lv["nBranches"][d])
        obs, exp = 0, 0.0
        for seed in range(3):
            skel = grow_skeleton(species, seed)
            par = skel.levels[d - 1]
            a = np.maximum(float(p.lv["nBaseSize"][d - 1]), par.start / par.res)
            if d == 2:
                per = nb * (0.2 + 0.8 * (par.length / par.parent_length) / par.lmax)
            else:
                per = nb * (1 - 0.5 * par.offset / par.parent_length)
            thin = skel.levels[d].weight / par.weight  # > 1 only where a huge level was thinned
            exp += float((per * (1 - a) / thin).sum())
            obs += int(skel.children_per_stem(d).sum())
        assert abs(obs - exp) <= 0.03 * exp + 3, (species, d, obs, exp)


def test_leaf_counts_and_leaf_bend():
    p = tree_params("quaking_aspen")
    skel = grow_skeleton("quaking_aspen", 2, p)
    last = skel.levels[-1]
    start = float(p["LeafStart"])
    cov = (1 - np.maximum(start, last.start / last.res)) / (1 - start)
    expected = float(p["Leaves"]) * shape_ratio(4, last.offset / last.parent_length) * cov
    assert abs(skel.n_leaves_full - expected.sum()) <= 1.0
    assert skel.leaf_counts.min() >= 0 and skel.n_leaves_full > 1000
    # LeafBend turns leaves toward the sky and outward
    ups = []
    for bend in (0.0, 1.0):
        q = tree_params("quaking_aspen")
        q.g["LeafBend"] = bend
        leaves = place_leaves(grow_skeleton("quaking_aspen", 2, q))
        ups.append(float(np.mean(leaves.y[:, 2])))
        assert leaves.n == skel.n_leaves_full
    assert ups[1] > ups[0] + 0.05


def test_pruning_envelope_and_ground():
    skel = grow_skeleton("weeping_willow", 0)
    p = skel.params
    for lvl in skel.levels[1:]:
        owned = np.arange(lvl.res + 1)[None, :] >= np.maximum(lvl.start, 1)[:, None]
        inside = envelope_inside(lvl.points, p, skel.scale)
        assert np.mean(~inside[owned]) < 0.01
        assert lvl.points[..., 2][owned].min() >= 0.0
    # AttractionUp -2: the willow's level-2 stems end lower than they start on average
    l2 = skel.levels[2]
    assert np.mean(l2.points[:, -1, 2] - l2.points[:, 0, 2]) < 0


@pytest.mark.parametrize("species", SPECIES)
def test_every_species_builds_a_valid_mesh(species):
    m = build_tree(species, 0, triangle_budget=SMALL)
    m.validate()
    assert 0 < m.n_faces <= SMALL
    assert np.all(np.isfinite(m.vertices))
    assert m.degenerate_fraction() < 1e-3
    assert np.all(m.semantic == labels.TREE)
    leaf = m.material == MATERIALS["leaf"]
    bark = m.material == MATERIALS["bark"]
    assert leaf.sum() > 0 and bark.sum() > 0 and np.all(leaf | bark)
    assert np.all(m.translucency[bark] == 0) and np.all((m.translucency[leaf] > 0.05) & (m.translucency[leaf] < 0.6))
    assert np.all((m.specular[leaf] > 0) & (m.specular[leaf] < 0.15))
    assert np.all((m.albedo >= 0) & (m.albedo <= 1))
    # per-leaf colour variation
    assert np.unique(m.albedo[leaf], axis=0).shape[0] > 10
    lo, hi = tree_params(species)["height_m"]
    assert lo - 1e-4 <= m.bounds()[1, 2] <= hi + 1e-4


def test_budget_degrades_instead_of_failing():
    full = build_tree("ca_black_oak", 0)
    assert full.n_faces <= 150_000
    for budget in (5_000, 1_500):
        m = build_tree("ca_black_oak", 0, triangle_budget=budget)
        assert m.n_faces <= budget
        assert (m.material == MATERIALS["leaf"]).sum() > 0
        # the crown keeps roughly its extent
        ext = np.ptp(m.vertices[:, :2], axis=0)
        ext_full = np.ptp(full.vertices[:, :2], axis=0)
        assert np.all(ext > 0.5 * ext_full)
    # colour per instance differs between seeds
    a = build_tree("small_maple", 0, triangle_budget=SMALL)
    b = build_tree("small_maple", 1, triangle_budget=SMALL)
    leaf_a = a.albedo[a.material == MATERIALS["leaf"]].mean(axis=0)
    leaf_b = b.albedo[b.material == MATERIALS["leaf"]].mean(axis=0)
    assert not np.allclose(leaf_a, leaf_b, atol=1e-3)
