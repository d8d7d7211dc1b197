"""Model stage: the garden recipe, its terrain and lawn, and every plant/asset mesh.

Each (pool, type, seed) model is its own cached artifact
``stages/model/<pool>-<type>-<seed>-<hash>/`` shared by every garden that
uses it; the garden's artifact ``stages/model/garden-<hash>/`` holds the
recipe, the ground (terrain + lawn) and the keys of its models.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from eden_pipe.models.mesh import Mesh
from eden_pipe.models.registry import build_fence_model, build_model
from eden_pipe.models.species import presets_fingerprint
from eden_pipe.models.terrain import Terrain, build_terrain
from eden_pipe.scene.recipe import POOLS, sample_recipe
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash

FENCE_LENGTH_M = 10.0


def model_key(pool: str, type_name: str, seed: int, extra: dict) -> str:
    # Code and preset files are part of the key: an edited builder or species preset rebuilds.
    fingerprints = (code_fingerprint(__name__), presets_fingerprint())
    return f"{pool}-{type_name}-{seed}-{config_hash(pool, type_name, seed, extra, fingerprints, length=8)}"


def build_cached_model(cache: StageCache, pool: str, type_name: str, seed: int, **options) -> Artifact:
    def builder(folder: Path) -> dict:
        if pool == "fence":
            mesh = build_fence_model(type_name, options["length"], seed)
        else:
            height = options.get("height_range")
            mesh = build_model(pool, type_name, seed, tuple(height) if height is not None else None)
        mesh.validate()
        mesh.save(folder / "mesh.npz")
        return {"faces": mesh.n_faces, "bounds": mesh.bounds().tolist()}

    return cache.build("model", model_key(pool, type_name, seed, options), builder)


def build_lawn(terrain: Terrain, lawn: dict, seed: int) -> Mesh:
    from eden_pipe.models.grass import LawnParams, build_lawn_patch

    params = LawnParams(freshness=lawn["freshness"], brownness=lawn["brownness"], wetness=lawn["wetness"],
                        trim=lawn["trim"], stripes=lawn["stripes"], triangles_per_m2=lawn["triangles_per_m2"])
    patches = [build_lawn_patch(float(px), float(py), 1.0, lawn["species"], lawn["weights"], seed, params, terrain.height_at)
               for px, py in terrain.patches_of("grass")]
    return Mesh.concatenate(patches)


def run_model_stage(garden_cfg, cache: StageCache) -> Artifact:
    """(garden config) -> artifact with recipe.json, ground.npz and models.json."""
    garden = OmegaConf.to_container(garden_cfg, resolve=True)
    key = "garden-" + config_hash(garden, code_fingerprint(__name__), presets_fingerprint())

    def builder(folder: Path) -> dict:
        recipe = sample_recipe(garden)
        t = garden["terrain"]
        terrain = build_terrain(garden["seed"], garden["size_m"], t["cells_per_m"], t["relief_m"], t["relief_scale_m"],
                                t["patch_types"], t["patch_weights"], tuple(t["types_per_garden"]))
        start = time.perf_counter()
        lawn = build_lawn(terrain, recipe["lawn"], garden["seed"]) if recipe["lawn"] else Mesh.empty()
        lawn_seconds = time.perf_counter() - start
        np.savez(folder / "ground.npz", heights=terrain.heights, patch_grid=terrain.patch_grid, patch_tint=terrain.patch_tint,
                 **lawn.to_npz_dict("lawn_"))
        models: dict[str, str] = {}
        built = cached = 0
        for pool in POOLS:
            spec = recipe["pools"][pool]
            height = spec.get("height_m") if pool == "trees" else None
            for type_name, seeds in spec["variants"].items():
                for model_seed in seeds:
                    art = build_cached_model(cache, pool, type_name, model_seed, height_range=height)
                    models[f"{pool}/{type_name}/{model_seed}"] = art.key
                    built, cached = built + (not art.cached), cached + art.cached
        if recipe["fence"]:
            f = recipe["fence"]
            art = build_cached_model(cache, "fence", f["style"], f["model_seed"], length=FENCE_LENGTH_M * garden["size_m"] / 10.0)
            models[f"fence/{f['style']}/{f['model_seed']}"] = art.key
        recipe["terrain"] = {"types": terrain.patch_types, "size_m": terrain.size_m, "cells_per_m": terrain.cells_per_m}
        (folder / "recipe.json").write_text(json.dumps(recipe, indent=1))
        (folder / "models.json").write_text(json.dumps(models, indent=1, sort_keys=True))
        return {"models_built": built, "models_cached": cached, "lawn_faces": lawn.n_faces,
                "lawn_seconds": round(lawn_seconds, 3)}

    return cache.build("model", key, builder)


def load_terrain(model_art: Artifact) -> Terrain:
    recipe = json.loads((model_art.path / "recipe.json").read_text())
    with np.load(model_art.path / "ground.npz") as data:
        t = recipe["terrain"]
        return Terrain(data["heights"], t["size_m"], t["cells_per_m"], t["types"], data["patch_grid"], data["patch_tint"])


def load_lawn(model_art: Artifact) -> Mesh:
    with np.load(model_art.path / "ground.npz") as data:
        return Mesh.from_npz_dict(data, "lawn_")
