"""The garden recipe: what goes into one garden, drawn from the config's pools.

As in the EDEN paper, each garden samples 2-4 types from every pool (tree
species, bush types, flowers, obstacles, lawn species, terrain types) and each
instance gets one of the sampled types. Each type is built in a few seeded
variants (models are cached per (type, seed) and shared by instances). Each
placed family samples its own part (``ModelFamily.sample`` in the family table,
``eden_pipe.models.registry``); every draw has its own named generator (docs/design.md,
Randomness and reproducibility), so changing a count never changes another instance's type or variant.

:class:`Recipe` is the typed form of ``recipe.json``: the model stage samples
and saves it (:meth:`Recipe.save`), the scene and trajectory stages read it
(:meth:`Recipe.load`) - nobody else parses the file.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import cast

import numpy as np

from eden_pipe.config import GardenConfig
from eden_pipe.models import registry
from eden_pipe.models.registry import PoolDraw, choose_types
from eden_pipe.rng import rng_for

RECIPE_FILE = "recipe.json"


class _Keyed:
    """Read-only ``obj["field"]`` access, for callers written against the old JSON dicts."""

    def __getitem__(self, key: str):
        return getattr(self, key)


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
    lawn: LawnDraw | None = None
    terrain: TerrainFacts | None = None  # set by the model stage once the terrain is built

    def to_dict(self) -> dict:
        out = {
            "garden_id": self.garden_id,
            "seed": self.seed,
            "pools": {p: d.to_dict() for p, d in self.pools.items()},
            "placement_attempts": self.placement_attempts,
            "lawn": asdict(self.lawn) if self.lawn else None,
        }
        if self.terrain is not None:
            out["terrain"] = asdict(self.terrain)
        return out

    @classmethod
    def from_dict(cls, d: dict) -> Recipe:
        return cls(
            d["garden_id"],
            int(d["seed"]),
            {p: PoolDraw.from_dict(v) for p, v in d["pools"].items()},
            int(d.get("placement_attempts", 60)),
            LawnDraw(**d["lawn"]) if d.get("lawn") else None,
            TerrainFacts(**d["terrain"]) if d.get("terrain") else None,
        )

    def save(self, folder: Path) -> None:
        (Path(folder) / RECIPE_FILE).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def load(cls, folder: Path) -> Recipe:
        return cls.from_dict(json.loads((Path(folder) / RECIPE_FILE).read_text()))


def _interval(values: list[float]) -> tuple[float, float]:
    """An interval setting's [lo, hi], typed as the pair its Interval domain checks it is (the same list)."""
    return cast("tuple[float, float]", values)


def _choose_lawn(rng: np.random.Generator, pool: list[str], per_garden) -> list[str]:
    """2-4 (``per_garden``) species of the lawn pool, the dominant one first.

    The dominant species is a lawn grass whenever the pool has one: weeds grow at a few
    plants per square metre, so a lawn of weeds alone would be bare soil. Companions
    (grasses or weeds) follow in pool order."""
    from eden_pipe.models.grass import is_lawn_grass

    grasses = [s for s in pool if is_lawn_grass(s)] or list(pool)
    dominant = grasses[int(rng.integers(len(grasses)))]
    rest = [s for s in pool if s != dominant]
    if not rest:
        return [dominant]
    return [dominant] + choose_types(rng, rest, (int(per_garden[0]) - 1, int(per_garden[1]) - 1))


def sample_recipe(g: GardenConfig) -> Recipe:
    """The garden's content (no geometry) drawn from its typed config."""
    seed = int(g.seed)
    recipe = Recipe(garden_id(g), seed, {}, int(g.placement_attempts))
    for fam in registry.FAMILIES:
        recipe.pools[fam.pool] = fam.sample(g, seed)
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
            freshness=float(rng.uniform(*_interval(lawn.freshness))),
            brownness=float(rng.uniform(*_interval(lawn.brownness))),
            wetness=float(rng.uniform(*_interval(lawn.wetness))),
            trim=float(rng.uniform(*_interval(lawn.trim))),
            stripes=bool(rng.random() < lawn.stripes_probability),
            triangles_per_m2=int(lawn.triangles_per_m2),
        )
    return recipe


def garden_id(garden) -> str:
    """``<name>-s<seed>``: the garden's folder name in the dataset and its key in the manifest."""
    name, seed = (garden["name"], garden["seed"]) if isinstance(garden, dict) else (garden.name, garden.seed)
    return f"{name}-s{int(seed)}"
