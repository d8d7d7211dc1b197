"""The paper's diversity by default (docs/diversity.md): every grass and weed species in the lawn
pool, bush leaf types from more than 20 with colour augmentation, tree heights from each species
preset scaled per instance, and the model facts that record what each variant drew."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.colour import rgb_to_hsv
from eden_pipe.config import ConfigError, to_config, validate
from eden_pipe.models.bush import bush_types, load_bush_preset, variant_look
from eden_pipe.models.grass import is_lawn_grass
from eden_pipe.models.leaves import BUSH_LEAF_TYPES, LEAF_TYPES, faces_per_leaf
from eden_pipe.models.mesh import MATERIALS
from eden_pipe.models.registry import build_model
from eden_pipe.models.species import list_species
from eden_pipe.models.tree import tree_params
from eden_pipe.rng import rng_for
from eden_pipe.scene.recipe import sample_recipe


# ------------------------------------------------------------------ lawn
def test_default_lawn_pool_is_every_grass_and_weed_preset(cfg_factory):
    folder = list_species("grass")
    assert len(folder) == 41
    for garden in ("default", "small"):
        lawn = to_config(cfg_factory([f"garden={garden}"])).garden.lawn
        assert lawn.species == "all" and lawn.species_pool() == folder, garden
    # an explicit list still works and is what the pool then is
    lawn = to_config(cfg_factory(["garden.lawn.species=[dandelion,bermuda]"])).garden.lawn
    assert lawn.species_pool() == ["dandelion", "bermuda"]


def test_lawns_draw_from_the_whole_pool_led_by_a_lawn_grass(cfg_factory):
    garden = to_config(cfg_factory()).garden
    drawn, dominant_weeds = set(), 0
    for seed in range(150):
        garden.seed = seed
        lawn = sample_recipe(garden).lawn
        assert 2 <= len(lawn.species) <= 4 and len(set(lawn.species)) == len(lawn.species)
        assert lawn.weights == sorted(lawn.weights, reverse=True)
        dominant_weeds += not is_lawn_grass(lawn.species[0])
        drawn.update(lawn.species)
    assert dominant_weeds == 0  # weeds alone (a few plants per m2) would leave the lawn bare
    assert len(drawn) >= 38, sorted(set(list_species("grass")) - drawn)
    assert any(not is_lawn_grass(s) for s in drawn)
    # a pool of weeds only is still honoured
    garden.lawn.species = ["dandelion", "white_clover", "chickweed"]
    assert set(sample_recipe(garden).lawn.species) <= set(garden.lawn.species)


@pytest.mark.parametrize(
    "value, message",
    [
        ("everything", "garden.lawn.species='everything'; allowed: 'all' or a list of grass presets"),
        ("[bermuda,moss]", "garden.lawn.species='moss'"),
    ],
)
def test_lawn_species_errors_name_the_key(cfg_factory, value, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("(", r"\(")):
        validate(cfg_factory([f"garden.lawn.species={value}"]))


def _preset_look(name: str) -> dict:
    from eden_pipe.models.species import load_species

    return {k: v for k, v in load_species("grass", name).items() if k not in ("name", "latin", "role")}


def test_grass_presets_are_pairwise_distinct():
    names = list_species("grass")
    looks = [_preset_look(n) for n in names]
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            assert looks[i] != looks[j], (names[i], names[j])


def test_every_grass_preset_builds_its_own_look():
    """Each of the 41 presets builds a non-empty, finite patch, and no two patches look alike:
    (triangles, mean height, mean colour) differ for every pair."""
    from eden_pipe.models.grass import LawnParams, build_lawn_patch

    looks = {}
    for name in list_species("grass"):
        mesh = build_lawn_patch(0.0, 0.0, 0.5, [name], [1.0], 3, LawnParams(triangles_per_m2=8000), lambda x, y: 0 * x)
        assert mesh.n_faces > 0 and np.all(np.isfinite(mesh.vertices)) and np.all(np.isfinite(mesh.albedo)), name
        looks[name] = np.array(
            [mesh.n_faces / 1000.0, mesh.vertices[:, 2].mean() * 100.0, *(mesh.albedo.mean(0) * 100.0)]
        )
    names = list(looks)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            assert np.abs(looks[a] - looks[b]).max() > 0.05, (a, b, looks[a], looks[b])


# ------------------------------------------------------------------ bushes
def test_bush_leaf_pool_has_more_than_20_types():
    assert len(BUSH_LEAF_TYPES) >= 20 and len(set(BUSH_LEAF_TYPES)) == len(BUSH_LEAF_TYPES)
    assert set(BUSH_LEAF_TYPES) <= set(LEAF_TYPES)


@pytest.mark.parametrize("bush", bush_types())
def test_each_bush_draws_its_leaf_type_from_20_or_more_with_bounded_colour(bush):
    preset = load_bush_preset(bush)
    bound = np.asarray(preset["colors"]["plant_hsv"])
    assert np.all(bound >= [0.03, 0.2, 0.2]) and np.all(bound <= [0.06, 0.35, 0.35])  # sensible, visible
    looks = [variant_look(preset, rng_for(seed, "bush", bush, "look")) for seed in range(400)]
    types = {t for t, _ in looks}
    shifts = np.array([s for _, s in looks])
    assert len(types) >= 20, sorted(types)
    assert np.all(np.abs(shifts) <= bound)
    assert np.all(shifts.max(0) > 0.8 * bound) and np.all(shifts.min(0) < -0.8 * bound)  # the whole range


def test_bush_facts_match_the_mesh_and_colours_vary_within_bounds():
    """Built variants use the leaf type they report; their leaf colour is the preset's shifted by the
    reported HSV shift; different seeds give different leaf types and colours."""
    preset = load_bush_preset("topiary_stacked_spheres")
    base_hsv = rgb_to_hsv(np.asarray(preset["colors"]["leaf"][0], np.float64))
    bound = np.asarray(preset["colors"]["plant_hsv"])
    seen_types, mean_albedo = set(), []
    for seed in range(4):
        built = build_model("bushes", "topiary_stacked_spheres", seed)
        facts = built.facts
        leaf_type, shift = variant_look(preset, rng_for(seed, "bush", "topiary_stacked_spheres", "look"))
        assert facts["leaf_type"] == leaf_type and facts["leaf_hsv_shift"] == pytest.approx(shift, abs=1e-4)
        leaf = built.mesh.material == MATERIALS["leaf"]
        assert leaf.sum() == facts["leaves"] * faces_per_leaf(facts["leaf_type"])
        hsv = rgb_to_hsv(np.asarray(facts["leaf_colour_srgb"]))
        dh = (hsv[0] - base_hsv[0] + 0.5) % 1.0 - 0.5
        assert abs(dh) <= bound[0] + 1e-3
        assert np.all(np.abs(hsv[1:] / base_hsv[1:] - 1.0) <= bound[1:] + 1e-3)
        seen_types.add(facts["leaf_type"])
        mean_albedo.append(built.mesh.albedo[leaf].mean(0))
    assert len(seen_types) >= 3
    spread = np.ptp(np.array(mean_albedo), axis=0)
    assert spread.max() > 0.01  # variants differ in colour, visibly


# ------------------------------------------------------------------ trees
def test_old_global_tree_height_key_is_a_clear_error(cfg_factory):
    with pytest.raises(ConfigError, match=r"garden\.trees\.height_m=\[2\.0, 4\.5\]; allowed: nothing \(removed"):
        validate(cfg_factory(["garden.trees.height_m=[2.0,4.5]"]))
    validate(cfg_factory())  # the default config has no such key


def test_every_tree_species_has_a_garden_height_range():
    ranges = {name: tree_params(name)["height_m"] for name in list_species("trees")}
    for name, (lo, hi) in ranges.items():
        assert 1.0 <= lo < hi <= 8.0, name
    assert len({tuple(r) for r in ranges.values()}) >= 8  # species differ, not one range for all


def test_tree_heights_follow_each_species_preset():
    """A weeping willow and a japanese maple built by the model family differ as their presets say."""
    heights = {}
    for species in ("weeping_willow", "japanese_maple"):
        lo, hi = tree_params(species)["height_m"]
        heights[species] = [build_model("trees", species, seed).mesh.bounds()[1, 2] for seed in (0, 1, 2)]
        assert all(lo - 1e-4 <= h <= hi + 1e-4 for h in heights[species]), (species, heights[species])
    assert min(heights["weeping_willow"]) >= max(heights["japanese_maple"])


# ------------------------------------------------------------------ through the stages
def test_model_stage_records_facts_and_each_tree_is_scaled_per_instance(cfg_factory, tmp_path):
    from eden_pipe.scene.description import read_scene
    from eden_pipe.scene.recipe import Recipe
    from eden_pipe.stages.cache import StageCache
    from eden_pipe.stages.model import load_model_facts, load_model_keys, run_model_stage
    from eden_pipe.stages.scene import run_scene_stage

    cfg = to_config(
        cfg_factory(
            [
                "garden=small",
                "garden.trees.types=[weeping_willow,japanese_maple]",
                "garden.trees.types_per_garden=[2,2]",
                "garden.trees.count=[3,3]",
                "garden.trees.variants=1",
                "garden.trees.scale=[0.6,1.4]",
                "garden.bushes.count=[0,0]",
                "garden.flowers.count=[0,0]",
                "garden.obstacles.count=[0,0]",
                "garden.lawn.enabled=false",
                "garden.fences.probability=0",
            ]
        )
    )
    cache = StageCache(tmp_path / "stages")
    model_art = run_model_stage(cfg.garden, cache)
    facts = load_model_facts(model_art)
    assert set(facts) == set(load_model_keys(model_art))
    for name, f in facts.items():
        pool, type_name, _ = name.split("/")
        assert f["height_m"] == pytest.approx(f["bounds"][1][2], abs=1e-4)
        if pool == "trees":
            lo, hi = tree_params(type_name)["height_m"]
            assert lo - 1e-4 <= f["height_m"] <= hi + 1e-4, name

    recipe = Recipe.load(model_art.path)
    scales = {(i.type, i.model_seed): set() for i in recipe.pools["trees"].instances}
    for i in recipe.pools["trees"].instances:
        scales[(i.type, i.model_seed)].add(round(i.scale, 9))
    assert len({s for v in scales.values() for s in v}) == 3  # three instances, three scales
    trees = [
        i for i in read_scene(run_scene_stage(cfg.garden, cfg.camera, model_art, cache)).instances if i.pool == "trees"
    ]
    assert trees
    for inst in trees:
        transform = np.asarray(inst.transform)
        scale = float(transform[2, 2])
        assert round(scale, 9) in scales[(inst.type, inst.model_seed)]
        model = facts[f"trees/{inst.type}/{inst.model_seed}"]
        model_height = model["bounds"][1][2] - model["bounds"][0][2]
        assert inst.bbox_max[2] - inst.bbox_min[2] == pytest.approx(model_height * scale, abs=2e-3)
