"""The family table: a placed family is one row, its builder and its presets.

Two toy families are added here, in the test, and nowhere else: crates (boxes scattered by the
sampler) and a kerb (a low wall laid along the garden's edges, as the fence is). The recipe, the
model and scene stages, the pre-flight preset check and the published scene table find them
through the table alone."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels, metadata
from eden_pipe.config import PoolConfig, to_config, validate
from eden_pipe.models import primitives, registry
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.registry import BuiltModel, ModelFamily, PlacementKind
from eden_pipe.preflight import mesh_bytes, presets_in_use
from eden_pipe.rng import rng_for
from eden_pipe.scene.description import read_scene
from eden_pipe.scene.placement import edge_runs, scene_base_gap
from eden_pipe.scene.recipe import Recipe
from eden_pipe.stages.cache import StageCache
from eden_pipe.stages.model import load_model_facts, run_model_stage
from eden_pipe.stages.scene import run_scene_stage
from tests.conftest import make_cfg

CRATE_SIDES_M = (0.2, 0.4)


def box(lo, hi, semantic: int) -> Mesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v, f = primitives.box_batch([(lo + hi) / 2], [hi - lo])
    return Mesh.from_arrays(v, f, semantic=semantic, material="wood", albedo=(0.4, 0.3, 0.2))


class ToyFamily(ModelFamily):
    """A family whose config section is made here (a real one is a ``PoolConfig`` field of ``GardenConfig``)."""

    def settings(self, garden):
        if self.placement is PlacementKind.SCATTERED:
            return PoolConfig(count=[3, 3], types=["crate"], types_per_garden=[1, 1], variants=2, scale=[0.8, 1.2])
        return PoolConfig(count=[1, 1], types=["kerb"], types_per_garden=[1, 1], variants=1, scale=[1.0, 1.0])

    def species(self):
        return [self.pool[:-1]]

    def read_preset(self, type_name):
        if type_name not in self.species():
            raise KeyError(type_name)
        return {"name": type_name}


class Crates(ToyFamily):
    def build(self, type_name, seed, **options):
        side = float(rng_for(seed, "crate").uniform(*CRATE_SIDES_M))
        crate = box((-side / 2, -side / 2, 0.0), (side / 2, side / 2, side), labels.OBSTACLE)
        return BuiltModel(crate, {"side_m": side})


class Kerbs(ToyFamily):
    def model_options(self, garden):
        return {"length_m": garden.size_m}

    def build(self, type_name, seed, **options):
        return BuiltModel(box((0.0, 0.0, 0.0), (options["length_m"], 0.1, 0.12), labels.PAVEMENT))


CRATES = Crates("crates", semantic="obstacle", spacing_m=0.1, species_kind="toys")
KERBS = Kerbs("kerbs", semantic="pavement", spacing_m=0.0, species_kind="toys", placement=PlacementKind.ALONG_EDGES)
# A garden of crates and a kerb only (no fence: its runs would stand where the kerb's do).
OVERRIDES = [
    "garden=small",
    "garden.lawn.enabled=false",
    "garden.fences.probability=0",
    "progress=false",
    *[f"garden.{pool}.count=[0,0]" for pool in ("trees", "bushes", "flowers", "obstacles")],
]


@pytest.fixture
def toy_table(monkeypatch):
    monkeypatch.setattr(registry, "FAMILIES", registry.FAMILIES + (CRATES, KERBS))


def test_a_family_added_to_the_table_is_sampled_built_and_placed(toy_table, tmp_path):
    cfg = to_config(make_cfg(tmp_path, OVERRIDES))
    cache = StageCache(cfg.paths.stages)
    model_art = run_model_stage(cfg.garden, cache)

    recipe = Recipe.load(model_art.path)
    crates, kerbs = recipe.pools["crates"], recipe.pools["kerbs"]
    assert crates.types == ["crate"] and len(crates.variants["crate"]) == 2 and len(crates.instances) == 3
    assert {i.model_seed for i in crates.instances} <= set(crates.variants["crate"])
    assert len(kerbs.instances) == 1 and not recipe.pools["fence"].instances
    facts = load_model_facts(model_art)
    for seed in crates.variants["crate"]:
        side = facts[f"crates/crate/{seed}"]["side_m"]  # the builder's facts, recorded with its model
        assert CRATE_SIDES_M[0] <= side <= CRATE_SIDES_M[1]
        assert facts[f"crates/crate/{seed}"]["height_m"] == pytest.approx(side, abs=1e-4)
    kerb_seed = kerbs.instances[0].model_seed
    assert facts[f"kerbs/kerb/{kerb_seed}"]["bounds"][1][0] == pytest.approx(cfg.garden.size_m)  # model_options

    scene_art = run_scene_stage(cfg.garden, cfg.camera, model_art, cache)
    scene = read_scene(scene_art)
    by_pool = {pool: [i for i in scene.instances if i.pool == pool] for pool in ("crates", "kerbs")}
    assert len(scene.instances) == 3 + 4 == sum(len(v) for v in by_pool.values())
    # Ids in table order: the crates' row comes before the kerbs'; each crate keeps the scale the recipe drew.
    assert [i.id for i in by_pool["crates"]] == [1, 2, 3] and [i.id for i in by_pool["kerbs"]] == [4, 5, 6, 7]
    for inst, draw in zip(by_pool["crates"], crates.instances, strict=True):  # every crate placed (see below)
        assert (inst.class_name, inst.type, inst.model_seed) == ("obstacle", "crate", draw.model_seed)
        scale = np.linalg.norm(np.array(inst.transform)[:3, 0])
        assert scale == pytest.approx(draw.scale, abs=1e-6)
        assert all(0.35 <= c <= scene.size_m - 0.35 for c in np.array(inst.transform)[:2, 3])  # inside the edge margin
    # The kerb is laid along the four edges, one run each, as the placement kind says.
    assert len(by_pool["kerbs"]) == PlacementKind.ALONG_EDGES.instances_per_draw == len(edge_runs(scene.size_m))
    for inst, ((x, y), yaw) in zip(by_pool["kerbs"], edge_runs(scene.size_m), strict=True):
        m = np.array(inst.transform)
        assert inst.class_name == "pavement" and m[:2, 3] == pytest.approx([x, y], abs=1e-8)
        assert np.arctan2(m[1, 0], m[0, 0]) % (2 * np.pi) == pytest.approx(yaw % (2 * np.pi), abs=1e-8)
    # Only the sampler may leave an instance out: it alone is counted.
    assert scene.requested == scene.placed == {"trees": 0, "bushes": 0, "flowers": 0, "obstacles": 0, "crates": 3}
    assert scene_base_gap(scene_art.path) >= CRATES.spacing_m - 1e-6  # crates clear of each other and of the kerb

    with np.load(scene_art.path / "geometry.npz") as geometry:
        assert set(np.unique(geometry["instance"]).tolist()) == {0, *range(1, 8)}
    published = metadata.scene_metadata(scene.to_dict())
    assert [(i["pool"], i["species"]) for i in published["instances"]] == [("crates", "crate")] * 3 + [
        ("kerbs", "kerb")
    ] * 4
    assert published["fence_style"] is None


def test_the_config_checks_and_preflight_read_a_family_from_the_table(toy_table, tmp_path):
    cfg = to_config(make_cfg(tmp_path, OVERRIDES))
    validate(cfg)  # each row checks its own section
    used = presets_in_use(cfg)
    assert ("toys", "crate", CRATES.read_preset) in used and ("toys", "kerb", KERBS.read_preset) in used
    assert not [u for u in used if u[0] == "assets"]  # no obstacles, no fence: none of their presets
    assert CRATES.max_instances(cfg.garden) == 3 and KERBS.max_instances(cfg.garden) == 4


def test_the_fence_is_a_row_of_the_table(tmp_path):
    fence = registry.family("fence")
    assert fence is registry.FAMILIES[0] and fence.placement is PlacementKind.ALONG_EDGES  # first: ids 1-4
    assert fence.config_key == "fences" and fence.species()
    assert fence.read_preset(fence.species()[0])["family"] == "fence"
    cfg = to_config(make_cfg(tmp_path, ["garden=small", "garden.fences.probability=1"]))
    assert fence.max_instances(cfg.garden) == 4
    assert {name for kind, name, _ in presets_in_use(cfg) if name.startswith("fence_")} == {
        f"fence_{s}" for s in cfg.garden.fences.styles
    }
    no_fence = to_config(make_cfg(tmp_path, ["garden=small", "garden.fences.probability=0"]))
    assert fence.max_instances(no_fence.garden) == 0 and fence.presets_in_use(no_fence.garden) == []
    assert mesh_bytes(cfg) > mesh_bytes(no_fence)
    draw = fence.sample(cfg.garden, 3)
    assert len(draw.instances) == 1 and draw.instances[0].type in cfg.garden.fences.styles
    built = fence.build(draw.types[0], draw.instances[0].model_seed, **fence.model_options(cfg.garden))
    assert fence.instance_class(built.mesh) == fence.semantic == "obstacle"
    assert built.mesh.bounds()[1, 0] == pytest.approx(cfg.garden.size_m, abs=1e-6)  # a run spans the side
