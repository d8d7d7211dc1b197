"""The garden recipe: what goes into one garden, drawn from the config's pools.

As in the EDEN paper, each garden samples 2-4 types from every pool (tree
species, bush types, flowers, obstacles, lawn species, terrain types) and each
instance gets one of the sampled types. Each type is built in a few seeded
variants (models are cached per (type, seed) and shared by instances).
Every draw has its own named generator (DESIGN section 6), so changing a count
never changes another instance's type or variant.
"""

from __future__ import annotations

import numpy as np
from omegaconf import OmegaConf

from eden_pipe.rng import child_seed, rng_for

POOLS = ("trees", "bushes", "flowers", "obstacles")
SPECIES_KIND = {"trees": "trees", "bushes": "bushes", "flowers": "flowers", "obstacles": "assets"}


def _choose_types(rng: np.random.Generator, types: list[str], per_garden) -> list[str]:
    lo, hi = int(per_garden[0]), int(per_garden[1])
    k = int(min(len(types), rng.integers(lo, hi + 1)))
    picked = rng.choice(len(types), size=k, replace=False)
    return [types[i] for i in sorted(picked)]


def sample_recipe(garden) -> dict:
    """A JSON-serialisable description of the garden's content (no geometry)."""
    g = OmegaConf.to_container(garden, resolve=True) if not isinstance(garden, dict) else garden
    seed = int(g["seed"])
    recipe: dict = {"garden_id": garden_id(g), "seed": seed, "pools": {}, "placement_attempts": int(g["placement_attempts"])}
    for pool in POOLS:
        pc = g[pool]
        if int(pc["count"][1]) == 0 or not pc["types"]:
            recipe["pools"][pool] = {"types": [], "variants": {}, "instances": []}
            continue
        types = _choose_types(rng_for(seed, "recipe", pool, "types"), list(pc["types"]), pc["types_per_garden"])
        count = int(rng_for(seed, "recipe", pool, "count").integers(pc["count"][0], pc["count"][1] + 1))
        variants = {t: [child_seed(seed, "model", pool, t, v) for v in range(int(pc["variants"]))] for t in types}
        instances = []
        for i in range(count):
            rng = rng_for(seed, "recipe", pool, "instance", i)
            t = types[int(rng.integers(len(types)))]
            instances.append({"type": t, "model_seed": variants[t][int(rng.integers(len(variants[t])))],
                              "scale": float(rng.uniform(*pc["scale"]))})
        recipe["pools"][pool] = {"types": types, "variants": variants, "instances": instances,
                                 "height_m": list(pc["height_m"])}
    fences = g["fences"]
    if fences["enabled"]:
        rng = rng_for(seed, "recipe", "fences")
        recipe["fence"] = {"style": str(rng.choice(fences["styles"])), "model_seed": child_seed(seed, "model", "fence")}
    else:
        recipe["fence"] = None
    lawn = g["lawn"]
    if lawn["enabled"] and lawn["species"]:
        rng = rng_for(seed, "recipe", "lawn")
        species = _choose_types(rng, list(lawn["species"]), lawn["types_per_garden"])
        weights = rng.dirichlet(np.ones(len(species)) * 2.0)
        # The first species dominates a real lawn; weeds and companions are sparser.
        weights = np.sort(weights)[::-1]
        recipe["lawn"] = {
            "species": species,
            "weights": [float(w) for w in weights],
            "freshness": float(rng.uniform(*lawn["freshness"])),
            "brownness": float(rng.uniform(*lawn["brownness"])),
            "wetness": float(rng.uniform(*lawn["wetness"])),
            "trim": float(rng.uniform(*lawn["trim"])),
            "stripes": bool(rng.random() < lawn["stripes_probability"]),
            "triangles_per_m2": int(lawn["triangles_per_m2"]),
        }
    else:
        recipe["lawn"] = None
    return recipe


def garden_id(garden) -> str:
    return f"{garden['name']}-s{int(garden['seed'])}"
