"""The garden recipe: what goes into one garden, drawn from the config's pools.

As in the EDEN paper, each garden samples 2-4 types from every pool (tree
species, bush types, flowers, obstacles, lawn species, terrain types) and each
instance gets one of the sampled types. Each type is built in a few seeded
variants (models are cached per (type, seed) and shared by instances).
Every draw has its own named generator (DESIGN section 6), so changing a count
never changes another instance's type or variant.

:class:`Recipe` is the typed form of ``recipe.json``: the model stage samples
and saves it (:meth:`Recipe.save`), the scene and trajectory stages read it
(:meth:`Recipe.load`) - nobody else parses the file.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from eden_pipe.config import GardenConfig, as_typed
from eden_pipe.models.registry import FAMILIES, POOLS  # noqa: F401  (POOLS re-exported)
from eden_pipe.rng import child_seed, rng_for

RECIPE_FILE = "recipe.json"


class _Keyed:
    """Read-only ``obj["field"]`` access, for callers written against the old JSON dicts."""

    def __getitem__(self, key: str):
        return getattr(self, key)


@dataclass
class InstanceDraw(_Keyed):
    type: str
    model_seed: int
    scale: float


@dataclass
class PoolDraw(_Keyed):
    """One pool of one garden: the sampled types, their model seeds and the instances to place."""

    types: list[str] = field(default_factory=list)
    variants: dict[str, list[int]] = field(default_factory=dict)
    instances: list[InstanceDraw] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"types": self.types, "variants": self.variants, "instances": [asdict(i) for i in self.instances]}

    @classmethod
    def from_dict(cls, d: dict) -> PoolDraw:
        return cls(list(d["types"]), {k: list(v) for k, v in d["variants"].items()},
                   [InstanceDraw(**i) for i in d["instances"]])


@dataclass
class FenceDraw(_Keyed):
    style: str
    model_seed: int


@dataclass
class LawnDraw(_Keyed):
    species: list[str]
    weights: list[float]
    freshness: float
    brownness: float
    wetness: float
    trim: float
    stripes: bool
    triangles_per_m2: int


@dataclass
class TerrainFacts(_Keyed):
    types: list[str]
    size_m: float
    cells_per_m: int


@dataclass
class Recipe(_Keyed):
    """Everything one garden contains, without geometry (``recipe.json``)."""

    garden_id: str
    seed: int
    pools: dict[str, PoolDraw]
    placement_attempts: int
    fence: FenceDraw | None = None
    lawn: LawnDraw | None = None
    terrain: TerrainFacts | None = None  # set by the model stage once the terrain is built

    def to_dict(self) -> dict:
        out = {"garden_id": self.garden_id, "seed": self.seed, "pools": {p: d.to_dict() for p, d in self.pools.items()},
               "placement_attempts": self.placement_attempts,
               "fence": asdict(self.fence) if self.fence else None, "lawn": asdict(self.lawn) if self.lawn else None}
        if self.terrain is not None:
            out["terrain"] = asdict(self.terrain)
        return out

    @classmethod
    def from_dict(cls, d: dict) -> Recipe:
        return cls(d["garden_id"], int(d["seed"]), {p: PoolDraw.from_dict(v) for p, v in d["pools"].items()},
                   int(d.get("placement_attempts", 60)),
                   FenceDraw(**d["fence"]) if d.get("fence") else None, LawnDraw(**d["lawn"]) if d.get("lawn") else None,
                   TerrainFacts(**d["terrain"]) if d.get("terrain") else None)

    def save(self, folder: Path) -> None:
        (Path(folder) / RECIPE_FILE).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def load(cls, folder: Path) -> Recipe:
        return cls.from_dict(json.loads((Path(folder) / RECIPE_FILE).read_text()))


def _uniform(rng: np.random.Generator, interval) -> float:
    """One uniform draw in a config's closed interval ``[lo, hi]``."""
    lo, hi = interval
    return float(rng.uniform(lo, hi))


def _choose_types(rng: np.random.Generator, types: list[str], per_garden) -> list[str]:
    lo, hi = int(per_garden[0]), int(per_garden[1])
    k = min(len(types), int(rng.integers(lo, hi + 1)))
    picked = rng.choice(len(types), size=k, replace=False)
    return [types[i] for i in sorted(picked)]


def _choose_lawn(rng: np.random.Generator, pool: list[str], per_garden) -> list[str]:
    """2-4 (``per_garden``) species of the lawn pool, the dominant one first.

    The dominant species is a lawn grass whenever the pool has one: weeds grow at a few
    plants per square metre, so a lawn of weeds alone would be bare soil. Companions
    (grasses or weeds) follow in pool order."""
    from eden_pipe.models.grass import is_lawn_grass

    grasses = [s for s in pool if is_lawn_grass(s)] or list(pool)
    dominant = grasses[int(rng.integers(len(grasses)))]
    rest = [s for s in pool if s != dominant]
    return [dominant] + _choose_types(rng, rest, (int(per_garden[0]) - 1, int(per_garden[1]) - 1)) if rest else [dominant]


def sample_recipe(garden) -> Recipe:
    """The garden's content (no geometry) drawn from its config (a GardenConfig, DictConfig or dict)."""
    g = as_typed(garden, GardenConfig)
    seed = int(g.seed)
    recipe = Recipe(garden_id(g), seed, {}, int(g.placement_attempts))
    for fam in FAMILIES:
        pc = g.pool(fam.pool)
        if int(pc.count[1]) == 0 or not pc.types:
            recipe.pools[fam.pool] = PoolDraw()
            continue
        types = _choose_types(fam.recipe_rng(seed, "types"), list(pc.types), pc.types_per_garden)
        count = int(fam.recipe_rng(seed, "count").integers(pc.count[0], pc.count[1] + 1))
        variants = {t: [fam.variant_seed(seed, t, v) for v in range(int(pc.variants))] for t in types}
        instances = []
        for i in range(count):
            rng = fam.recipe_rng(seed, "instance", i)
            t = types[int(rng.integers(len(types)))]
            instances.append(InstanceDraw(t, variants[t][int(rng.integers(len(variants[t])))], _uniform(rng, pc.scale)))
        recipe.pools[fam.pool] = PoolDraw(types, variants, instances)
    # Whether the garden is fenced has its own generator, so the style drawn for a seed is the same
    # whatever the probability (and the same as before fences became optional).
    if rng_for(seed, "recipe", "fences", "present").random() < g.fences.probability:
        rng = rng_for(seed, "recipe", "fences")
        recipe.fence = FenceDraw(str(rng.choice(g.fences.styles)), child_seed(seed, "model", "fence"))
    lawn = g.lawn
    pool = lawn.species_pool()
    if lawn.enabled and pool:
        rng = rng_for(seed, "recipe", "lawn")
        species = _choose_lawn(rng, pool, lawn.types_per_garden)
        weights = rng.dirichlet(np.ones(len(species)) * 2.0)
        # The first species dominates a real lawn; weeds and companions are sparser.
        weights = np.sort(weights)[::-1]
        recipe.lawn = LawnDraw(
            species=species,
            weights=[float(w) for w in weights],
            freshness=_uniform(rng, lawn.freshness),
            brownness=_uniform(rng, lawn.brownness),
            wetness=_uniform(rng, lawn.wetness),
            trim=_uniform(rng, lawn.trim),
            stripes=bool(rng.random() < lawn.stripes_probability),
            triangles_per_m2=int(lawn.triangles_per_m2),
        )
    return recipe


def garden_id(garden) -> str:
    """``<name>-s<seed>``: the garden's folder name in the dataset and its key in the manifest."""
    name, seed = (garden["name"], garden["seed"]) if isinstance(garden, dict) else (garden.name, garden.seed)
    return f"{name}-s{int(seed)}"
