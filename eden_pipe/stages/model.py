"""Model stage: the garden recipe, its terrain and lawn, and every plant/asset mesh.

Each (pool, type, seed) model is its own cached artifact
``stages/model/<pool>-<type>-<seed>-<hash>/`` shared by every garden that
uses it; the garden's artifact ``stages/model/garden-<hash>/`` holds the
recipe (:class:`~eden_pipe.scene.recipe.Recipe`), the ground (terrain +
lawn) and the keys of its models. Input: the typed ``GardenConfig``.
Readers of the artifact: :func:`load_terrain`, :func:`load_lawn`,
:func:`load_model_keys`, :func:`load_model_facts` and ``Recipe.load(model_art.path)``.

Model facts: each model's marker records its faces, bounds, height and what its
builder drew (a bush's leaf type and leaf colour, see ``BuiltModel.facts``);
the garden artifact gathers them per model name in ``model_facts.json``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import cast

import numpy as np

from eden_pipe.config import GardenConfig, to_plain
from eden_pipe.models import registry
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.species import presets_fingerprint
from eden_pipe.models.terrain import Terrain
from eden_pipe.scene.recipe import LawnDraw, Recipe, TerrainFacts, sample_recipe
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash

MODELS_FILE = "models.json"
MODEL_FACTS_FILE = "model_facts.json"


def model_key(pool: str, type_name: str, seed: int, extra: dict) -> str:
    # Code and preset files are part of the key: an edited builder or species preset rebuilds.
    fingerprints = (code_fingerprint(__name__), presets_fingerprint())
    return f"{pool}-{type_name}-{seed}-{config_hash(pool, type_name, seed, extra, fingerprints, length=8)}"


def build_cached_model(cache: StageCache, pool: str, type_name: str, seed: int, **options) -> Artifact:
    """One model of a placed family; ``options``: the family's ``model_options`` for the garden."""

    def builder(folder: Path) -> dict:
        built = registry.build_model(pool, type_name, seed, **options)
        mesh = built.mesh
        mesh.validate()
        mesh.save(folder / "mesh.npz")
        bounds = mesh.bounds()
        return {
            "faces": mesh.n_faces,
            "bounds": bounds.tolist(),
            "height_m": round(float(bounds[1, 2]), 4),
            **built.facts,
        }

    return cache.build("model", model_key(pool, type_name, seed, options), builder)


def build_lawn(terrain: Terrain, lawn: LawnDraw, seed: int) -> Mesh:
    from eden_pipe.models.grass import LawnParams, build_lawn_patch

    params = LawnParams(
        freshness=lawn.freshness,
        brownness=lawn.brownness,
        wetness=lawn.wetness,
        trim=lawn.trim,
        stripes=lawn.stripes,
        triangles_per_m2=lawn.triangles_per_m2,
    )
    patches = [
        build_lawn_patch(float(px), float(py), 1.0, lawn.species, lawn.weights, seed, params, terrain.height_at)
        for px, py in terrain.patches_of("grass")
    ]
    return Mesh.concatenate(patches)


def run_model_stage(garden: GardenConfig, cache: StageCache) -> Artifact:
    """(garden config) -> artifact with recipe.json, ground.npz and models.json."""
    key = "garden-" + config_hash(to_plain(garden), code_fingerprint(__name__), presets_fingerprint())

    def builder(folder: Path) -> dict:
        recipe = sample_recipe(garden)
        terrain = garden.terrain.build(garden.seed, garden.size_m)
        start = time.perf_counter()
        lawn = build_lawn(terrain, recipe.lawn, garden.seed) if recipe.lawn else Mesh.empty()
        lawn_seconds = time.perf_counter() - start
        np.savez(
            folder / "ground.npz",
            heights=terrain.heights,
            patch_grid=terrain.patch_grid,
            patch_tint=terrain.patch_tint,
            **lawn.to_npz_dict("lawn_"),  # type: ignore[arg-type]  # numpy's stub: **arrays might hold allow_pickle
        )
        models: dict[str, str] = {}
        facts: dict[str, dict] = {}
        built = cached = 0
        for fam in registry.FAMILIES:
            options = fam.model_options(garden)
            for type_name, seeds in recipe.pools[fam.pool].variants.items():
                for model_seed in seeds:
                    art = build_cached_model(cache, fam.pool, type_name, model_seed, **options)
                    name = model_name(fam.pool, type_name, model_seed)
                    models[name], facts[name] = art.key, _model_facts(art)
                    built, cached = built + (not art.cached), cached + art.cached
        recipe.terrain = TerrainFacts(terrain.patch_types, terrain.size_m, terrain.cells_per_m)
        recipe.save(folder)
        (folder / MODELS_FILE).write_text(json.dumps(models, indent=1, sort_keys=True))
        (folder / MODEL_FACTS_FILE).write_text(json.dumps(facts, indent=1, sort_keys=True))
        return {
            "models_built": built,
            "models_cached": cached,
            "lawn_faces": lawn.n_faces,
            "lawn_seconds": round(lawn_seconds, 3),
        }

    return cache.build("model", key, builder)


def model_name(pool: str, type_name: str, model_seed: int) -> str:
    """A model's name in ``models.json``: ``<pool>/<type>/<seed>``."""
    return f"{pool}/{type_name}/{model_seed}"


def load_model_keys(model_art: Artifact) -> dict[str, str]:
    """model name (:func:`model_name`) -> key of its ``model`` artifact."""
    return json.loads((model_art.path / MODELS_FILE).read_text())


def _model_facts(art: Artifact) -> dict:
    """A model artifact's recorded facts: its marker less the cache's own bookkeeping."""
    return {k: v for k, v in art.marker().items() if k not in ("stage", "key", "seconds")}


def load_model_facts(model_art: Artifact) -> dict[str, dict]:
    """model name (:func:`model_name`) -> its facts: faces, bounds, height_m and what its builder
    drew (for bushes ``leaf_type``, ``leaf_colour_srgb``, ``leaf_hsv_shift``)."""
    return json.loads((model_art.path / MODEL_FACTS_FILE).read_text())


def load_terrain(model_art: Artifact, recipe: Recipe | None = None) -> Terrain:
    # The model stage sets a recipe's terrain before it writes ground.npz.
    t = cast(TerrainFacts, (recipe or Recipe.load(model_art.path)).terrain)
    with np.load(model_art.path / "ground.npz") as data:
        return Terrain(data["heights"], t.size_m, t.cells_per_m, t.types, data["patch_grid"], data["patch_tint"])


def load_lawn(model_art: Artifact) -> Mesh:
    with np.load(model_art.path / "ground.npz") as data:
        return Mesh.from_npz_dict(data, "lawn_")
