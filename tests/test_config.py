"""The typed config (one conversion, checks beside each dataclass), the family table and the
typed artifact readers (Recipe, SceneDescription). Fast: no stage runs here."""

from __future__ import annotations

import json
from dataclasses import fields

import numpy as np
import pytest
from omegaconf import OmegaConf

from eden_pipe import labels
from eden_pipe.config import ConfigError, EdenConfig, GardenConfig, PoolConfig, as_typed, to_config, to_plain, validate
from eden_pipe.models.registry import FAMILIES, POOLS, family
from eden_pipe.scene.description import SceneDescription, SceneInstance
from eden_pipe.scene.recipe import Recipe, sample_recipe


def test_to_config_gives_typed_objects_with_the_same_values(cfg_factory):
    cfg = cfg_factory(["garden=small"])
    typed = to_config(cfg)
    assert isinstance(typed, EdenConfig) and isinstance(typed.garden, GardenConfig)
    assert isinstance(typed.garden.trees, PoolConfig) and typed.garden.trees.count == [1, 2]
    assert to_plain(typed) == OmegaConf.to_container(cfg, resolve=True)
    assert to_config(typed) is typed


def test_as_typed_drops_keys_outside_the_schema(cfg_factory):
    cfg = cfg_factory()
    with_hydra = OmegaConf.merge(OmegaConf.create({"hydra": {"job": {"name": "x"}}}), cfg)
    assert to_plain(to_config(with_hydra)) == to_plain(to_config(cfg))
    assert as_typed(OmegaConf.to_container(cfg.garden), GardenConfig) == to_config(cfg).garden


def test_validate_takes_dictconfig_and_typed_config_alike(cfg_factory):
    cfg = cfg_factory(["garden.trees.count=[17,5]"])
    messages = []
    for node in (cfg, to_config(cfg)):
        with pytest.raises(ConfigError) as err:
            validate(node)
        messages.append(str(err.value))
    assert messages[0] == messages[1] and "garden.trees.count='[17, 5]'" in messages[0]


def test_family_table_covers_every_pool_of_the_garden_schema():
    sections = [f.name for f in fields(GardenConfig)]
    pools = [f.name for f in fields(GardenConfig) if f.type in ("PoolConfig", PoolConfig)]
    assert set(pools) <= {fam.config_key for fam in FAMILIES} <= set(sections)  # a row per pool, a section per row
    assert POOLS == tuple(fam.pool for fam in FAMILIES) and len(set(POOLS)) == len(POOLS)
    assert POOLS[:5] == ("fence", "trees", "bushes", "flowers", "obstacles")  # the order of instance ids
    for fam in FAMILIES:
        assert fam.semantic in labels.NAMES and fam.species(), fam
        assert (fam.spacing_m > 0) == fam.placement.may_leave_out  # the sampler keeps a clearance; runs meet
        assert family(fam.pool) is fam
    with pytest.raises(KeyError, match="unknown model pool"):
        family("hedgehogs")


def test_recipe_is_deterministic_and_round_trips_through_json(cfg_factory, tmp_path):
    garden = to_config(cfg_factory(["garden=small"])).garden
    recipe = sample_recipe(garden)
    assert recipe == sample_recipe(to_config(cfg_factory(["garden=small"])).garden)  # a second config, same draws
    assert recipe.garden_id == "small-s0" and set(recipe.pools) == set(POOLS)
    recipe.save(tmp_path)
    assert Recipe.load(tmp_path) == recipe
    assert json.loads((tmp_path / "recipe.json").read_text()) == recipe.to_dict()


def test_scene_description_round_trips_through_json(tmp_path):
    inst = SceneInstance(
        1, "tree", labels.TREE, "trees", "palm", 7, "k", [[1.0, 0, 0, 0]] * 4, [0, 0, 0], [1, 1, 1], 12
    )
    scene = SceneDescription("g-s0", 3, 10.0, ["grass"], None, {"trees": 1}, {"trees": 1}, [inst], 99)
    scene.save(tmp_path)
    raw = json.loads((tmp_path / "scene.json").read_text())
    assert raw["instances"][0]["class"] == "tree" and raw["seed"] == 3
    loaded = SceneDescription.load(tmp_path)
    assert loaded == scene and loaded["seed"] == 3 and loaded["instances"][0]["class"] == "tree"


def test_trajectory_frames_range_and_the_deprecated_min_steps_alias(cfg_factory):
    typed = to_config(cfg_factory())
    assert typed.camera.trajectory.frame_range() == (100, 132)  # EDEN: at least 100, train mean ~116
    assert typed.camera.trajectory.share_across_lightings is False
    old = to_config(cfg_factory(["camera.trajectory.min_steps=7"]))
    assert old.camera.trajectory.frame_range() == (7, 7)
    with pytest.warns(FutureWarning, match=r"camera.trajectory.frames=\[7,7\]"):
        validate(old)
    with pytest.raises(ConfigError, match=r"camera.trajectory.frames='\[120, 110\]'.*lo <= hi"):
        validate(cfg_factory(["camera.trajectory.frames=[120,110]"]))


def test_fence_probability_draws_fences_per_garden_and_keeps_each_seed_style(cfg_factory):
    garden = to_config(cfg_factory(["garden=small"])).garden

    def fences(probability):
        garden.fences.probability = probability
        out = []
        for seed in range(200):
            garden.seed = seed
            draw = sample_recipe(garden).pools["fence"]
            out.append(draw.instances[0] if draw.instances else None)
        return out

    always, never, default = fences(1.0), fences(0.0), fences(0.7)
    assert all(f is not None for f in always) and all(f is None for f in never)
    assert 0.6 <= np.mean([f is not None for f in default]) <= 0.8
    assert all(d is None or d == a for d, a in zip(default, always, strict=True))  # presence has its own generator
    assert len({f.type for f in always}) == len(garden.fences.styles)  # the style is drawn per garden
    with pytest.raises(ConfigError, match=r"garden.fences.probability=-0.1; allowed: a number in \[0, 1\]"):
        validate(cfg_factory(["garden.fences.probability=-0.1"]))
