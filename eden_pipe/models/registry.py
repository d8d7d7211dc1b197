"""The family table: one row per placed pool (trees, bushes, flowers, obstacles).

What a garden pool *is* lives here and nowhere else: its semantic class, the
clearance kept around its instances when they are placed, the kind of species
preset its ``types`` name (``conf/species/<kind>/``), its builder, and the
names its random draws are seeded from. The recipe (``scene.recipe``), the
model and scene stages and config validation all read :data:`FAMILIES`.

As in Infinigen's AssetFactory, seeding is in one place (the base class) and a
family overrides one method, :meth:`ModelFamily.build`. Builders are imported
inside ``build`` (lazily: a garden without flowers never imports the flower
model), with a plain ``from ... import`` so the stage cache's code fingerprint
still sees every builder a stage may run.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import Mesh
from eden_pipe.rng import child_seed, rng_for


@dataclass
class BuiltModel:
    """A model and the facts its builder drew (a bush's leaf type and colour, ...): the model stage
    records the facts with the model, so users and tests see what each variant is."""

    mesh: Mesh
    facts: dict = field(default_factory=dict)


@dataclass(frozen=True)
class ModelFamily:
    """One placed pool of the garden config (``garden.<pool>``)."""

    pool: str           # config key under ``garden`` and the name in recipes, scenes and model keys
    semantic: str       # class (labels.NAMES) of an instance whose mesh has no faces to vote with
    spacing_m: float    # clearance between collision proxies when placing instances of this pool
    species_kind: str   # preset folder under conf/species/ that ``garden.<pool>.types`` name
    base_is_trunk: bool = False  # placement keeps trunks apart and lets crowns overlap (else the whole model in reach)

    def build(self, type_name: str, seed: int) -> BuiltModel:
        """The model of ``type_name`` built from ``seed``, in its model frame, at the size its
        preset draws (instances are scaled by ``garden.<pool>.scale`` when placed)."""
        raise NotImplementedError

    def read_preset(self, type_name: str):
        """The preset of ``type_name`` read and checked by this family's own loader (what ``build``
        would reject, raised before any work: the pre-flight check calls it)."""
        raise NotImplementedError

    # ------------------------------------------------------------ in one place
    def species(self) -> list[str]:
        """The preset names ``garden.<pool>.types`` may use."""
        from eden_pipe.models.species import list_species

        return list_species(self.species_kind)

    def variant_seed(self, garden_seed: int, type_name: str, variant: int) -> int:
        """Seed of model variant ``variant`` of ``type_name`` in a garden."""
        return child_seed(garden_seed, "model", self.pool, type_name, variant)

    def recipe_rng(self, garden_seed: int, *names: object) -> np.random.Generator:
        """Generator for a recipe draw of this pool (``"types"``, ``"count"``, ``"instance", i``)."""
        return rng_for(garden_seed, "recipe", self.pool, *names)

    def placement_rng(self, garden_seed: int, index: int) -> np.random.Generator:
        """Generator for placing instance ``index`` of this pool in the scene."""
        return rng_for(garden_seed, "place", self.pool, index)

    def instance_class(self, mesh: Mesh) -> str:
        """An instance's class: the most common semantic id of its faces (the family's class if none)."""
        if mesh.n_faces == 0:
            return self.semantic
        return labels.NAMES[int(np.bincount(mesh.semantic, minlength=len(labels.NAMES)).argmax())]


class TreeFamily(ModelFamily):
    def build(self, type_name, seed):
        from eden_pipe.models.tree import build_tree

        return BuiltModel(build_tree(type_name, seed))  # height drawn from the species preset's height_m

    def read_preset(self, type_name):
        from eden_pipe.models.tree.parameters import tree_params

        return tree_params(type_name)


class BushFamily(ModelFamily):
    def build(self, type_name, seed):
        from eden_pipe.models.bush import build_bush_model

        bush = build_bush_model(type_name, seed)
        return BuiltModel(bush.mesh, bush.facts())

    def read_preset(self, type_name):
        from eden_pipe.models.bush import load_bush_preset

        return load_bush_preset(type_name)


class FlowerFamily(ModelFamily):
    def build(self, type_name, seed):
        from eden_pipe.models.flower import build_flower

        return BuiltModel(build_flower(type_name, seed))

    def read_preset(self, type_name):
        from eden_pipe.models.flower import load_flower_preset

        return load_flower_preset(type_name)


class AssetFamily(ModelFamily):
    def build(self, type_name, seed):
        from eden_pipe.models.assets import build_asset

        return BuiltModel(build_asset(type_name, seed))

    def read_preset(self, type_name):
        from eden_pipe.models.assets import asset_preset

        return asset_preset(type_name)


# The order is the order of recipe sampling, model building and placement: do not reorder.
FAMILIES: tuple[ModelFamily, ...] = (
    TreeFamily("trees", semantic="tree", spacing_m=0.25, species_kind="trees", base_is_trunk=True),  # trunks kept apart
    BushFamily("bushes", semantic="hedge", spacing_m=0.15, species_kind="bushes"),
    FlowerFamily("flowers", semantic="flower", spacing_m=0.1, species_kind="flowers"),
    AssetFamily("obstacles", semantic="obstacle", spacing_m=0.15, species_kind="assets"),
)
POOLS: tuple[str, ...] = tuple(f.pool for f in FAMILIES)
_BY_POOL = {f.pool: f for f in FAMILIES}


def family(pool: str) -> ModelFamily:
    try:
        return _BY_POOL[pool]
    except KeyError:
        raise KeyError(f"unknown model pool {pool!r}; allowed: {', '.join(POOLS)}") from None


def build_model(pool: str, type_name: str, seed: int) -> BuiltModel:
    """Build one model of a garden pool (trees, bushes, flowers, obstacles) in its model frame."""
    return family(pool).build(type_name, seed)


def build_fence_model(style: str, length: float, seed: int) -> Mesh:
    """The garden's fence (not a placed pool: it runs along the four edges)."""
    from eden_pipe.models.assets import build_fence

    return build_fence(style, length, seed)


FENCE_SEMANTIC = "obstacle"  # fences are garden assets (DESIGN section 3)
