"""The family table: one row per placed family (fence, trees, bushes, flowers, obstacles).

What a placed family *is* lives here and nowhere else: its semantic class, how its
instances are placed (:class:`PlacementKind`: bases scattered ``spacing_m`` apart, or
runs along the garden's edges), how the recipe samples it from its config section
``garden.<config_key>`` (:meth:`ModelFamily.sample`), the kind of species preset its
types name (``conf/species/<kind>/``), its builder, and the names its random draws are
seeded from. The recipe (``scene.recipe``), the model and scene stages, the placement
(``scene.placement``), config validation and the pre-flight checks read :data:`FAMILIES`
and name no family.

As in Infinigen's AssetFactory (``core/placement/factory.py``), seeding is in one place
(the base class) and a family overrides few methods: :meth:`ModelFamily.build` and
:meth:`ModelFamily.read_preset` always; the config hooks (``settings`` ... ``sample``,
``model_options``) only when its config section is not a ``PoolConfig`` (the fence).
Builders are imported inside ``build`` (lazily: a garden without flowers never imports the
flower model), with a plain ``from ... import`` so the stage cache's code fingerprint
still sees every builder a stage may run.
"""

from __future__ import annotations

import enum
from collections.abc import Callable
from dataclasses import asdict, dataclass, field

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import Mesh
from eden_pipe.rng import child_seed, rng_for


class PlacementKind(enum.Enum):
    """How a family's instances are placed; ``scene.placement.place`` runs the kinds in this order."""

    # One run of the model along each of the garden's four edges, facing inward (a fence): first,
    # so that the sampler keeps every base clear of the runs.
    ALONG_EDGES = "along_edges"
    # The seeded sampler: bases anywhere inside the garden, ``spacing_m`` apart; it may leave an
    # instance out where no spot is free.
    SCATTERED = "scattered"

    @property
    def may_leave_out(self) -> bool:
        """Whether an instance can find no room: ``scene.json`` counts requested and placed instances of these."""
        return self is PlacementKind.SCATTERED

    @property
    def instances_per_draw(self) -> int:
        """Scene instances one instance of the recipe becomes (a run per edge of the square garden)."""
        return 4 if self is PlacementKind.ALONG_EDGES else 1


@dataclass
class BuiltModel:
    """A model and the facts its builder drew (a bush's leaf type and colour, ...): the model stage
    records the facts with the model, so users and tests see what each variant is."""

    mesh: Mesh
    facts: dict = field(default_factory=dict)


@dataclass
class InstanceDraw:
    type: str
    model_seed: int
    scale: float


@dataclass
class PoolDraw:
    """One family's part of one garden's recipe: the sampled types, their model seeds and the instances to place."""

    types: list[str] = field(default_factory=list)
    variants: dict[str, list[int]] = field(default_factory=dict)
    instances: list[InstanceDraw] = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"types": self.types, "variants": self.variants, "instances": [asdict(i) for i in self.instances]}

    @classmethod
    def from_dict(cls, d: dict) -> PoolDraw:
        return cls(
            list(d["types"]),
            {k: list(v) for k, v in d["variants"].items()},
            [InstanceDraw(**i) for i in d["instances"]],
        )


def choose_types(rng: np.random.Generator, types: list[str], per_garden) -> list[str]:
    """``per_garden`` = [lo, hi]: between lo and hi of ``types`` (no repeats), in their order."""
    lo, hi = int(per_garden[0]), int(per_garden[1])
    k = min(len(types), int(rng.integers(lo, hi + 1)))
    picked = rng.choice(len(types), size=k, replace=False)
    return [types[i] for i in sorted(picked)]


@dataclass(frozen=True)
class ModelFamily:
    """One placed family of the garden. The config hooks read a ``PoolConfig`` section
    (``count``, ``types``, ``types_per_garden``, ``variants``, ``scale``)."""

    pool: str  # the name in recipes, scenes, model keys and random draws
    semantic: str  # class (labels.NAMES) of an instance whose mesh has no faces to vote with
    spacing_m: float  # clearance the sampler keeps between this family's bases and every placed body
    species_kind: str  # preset folder under conf/species/ that the family's types name
    placement: PlacementKind = PlacementKind.SCATTERED
    base_is_trunk: bool = False  # placement keeps trunks apart and lets crowns overlap (else the whole model in reach)
    config_key: str = ""  # its section under ``garden`` (the pool's name unless set); recipe draws are named after it

    def __post_init__(self) -> None:
        if not self.config_key:
            object.__setattr__(self, "config_key", self.pool)

    # ------------------------------------------------------------ overridden per family
    def build(self, type_name: str, seed: int, **options) -> BuiltModel:
        """The model of ``type_name`` built from ``seed``, in its model frame, at the size its
        preset draws (instances are scaled by the scale the recipe drew when placed).
        ``options``: :meth:`model_options`."""
        raise NotImplementedError

    def read_preset(self, type_name: str):
        """The preset of ``type_name`` read and checked by this family's own loader (what ``build``
        would reject, raised before any work: the pre-flight check calls it)."""
        raise NotImplementedError

    # ------------------------------------------------------------ config hooks
    def settings(self, garden):
        """This family's config section of a typed ``GardenConfig``."""
        return getattr(garden, self.config_key)

    def presets_in_use(self, garden) -> list[tuple[str, str, Callable]]:
        """(kind, preset name, reader) of every preset a garden config can make this family read."""
        section = self.settings(garden)
        return [(self.species_kind, str(name), self.read_preset) for name in section.types if section.count[1] > 0]

    def max_instances(self, garden) -> int:
        """The most scene instances a garden config can give this family (the disk estimate)."""
        return int(self.settings(garden).count[1]) * self.placement.instances_per_draw

    def sample(self, garden, seed: int) -> PoolDraw:
        """This family's part of the garden's recipe: some of its ``types``, ``count`` instances, each of
        one type, variant and scale. Every draw has its own named generator, so changing a count never
        changes another instance's type or variant."""
        section = self.settings(garden)
        if int(section.count[1]) == 0 or not section.types:
            return PoolDraw()
        types = choose_types(self.recipe_rng(seed, "types"), list(section.types), section.types_per_garden)
        count = int(self.recipe_rng(seed, "count").integers(section.count[0], section.count[1] + 1))
        variants = {t: [self.variant_seed(seed, t, v) for v in range(int(section.variants))] for t in types}
        instances = []
        for i in range(count):
            rng = self.recipe_rng(seed, "instance", i)
            t = types[int(rng.integers(len(types)))]
            instances.append(
                InstanceDraw(t, variants[t][int(rng.integers(len(variants[t])))], float(rng.uniform(*section.scale)))
            )
        return PoolDraw(types, variants, instances)

    def model_options(self, garden) -> dict:
        """Keyword arguments of :meth:`build` that the garden decides (part of each model's cache key)."""
        return {}

    # ------------------------------------------------------------ in one place
    def species(self) -> list[str]:
        """The type names this family's config may use."""
        from eden_pipe.models.species import list_species

        return list_species(self.species_kind)

    def model_seed(self, garden_seed: int, *names: object) -> int:
        """Seed of a model of this family in a garden, named by ``names``."""
        return child_seed(garden_seed, "model", self.pool, *names)

    def variant_seed(self, garden_seed: int, type_name: str, variant: int) -> int:
        """Seed of model variant ``variant`` of ``type_name`` in a garden."""
        return self.model_seed(garden_seed, type_name, variant)

    def recipe_rng(self, garden_seed: int, *names: object) -> np.random.Generator:
        """Generator for a recipe draw of this family (``"types"``, ``"count"``, ``"instance", i``)."""
        return rng_for(garden_seed, "recipe", self.config_key, *names)

    def placement_rng(self, garden_seed: int, index: int) -> np.random.Generator:
        """Generator for placing instance ``index`` of this family in the scene."""
        return rng_for(garden_seed, "place", self.pool, index)

    def instance_class(self, mesh: Mesh) -> str:
        """An instance's class: the most common semantic id of its faces (the family's class if none)."""
        if mesh.n_faces == 0:
            return self.semantic
        return labels.NAMES[int(np.bincount(mesh.semantic, minlength=len(labels.NAMES)).argmax())]


class TreeFamily(ModelFamily):
    def build(self, type_name, seed, **options):
        from eden_pipe.models.tree import build_tree

        return BuiltModel(build_tree(type_name, seed))  # height drawn from the species preset's height_m

    def read_preset(self, type_name):
        from eden_pipe.models.tree.parameters import tree_params

        return tree_params(type_name)


class BushFamily(ModelFamily):
    def build(self, type_name, seed, **options):
        from eden_pipe.models.bush import build_bush_model

        bush = build_bush_model(type_name, seed)
        return BuiltModel(bush.mesh, bush.facts())

    def read_preset(self, type_name):
        from eden_pipe.models.bush import load_bush_preset

        return load_bush_preset(type_name)


class FlowerFamily(ModelFamily):
    def build(self, type_name, seed, **options):
        from eden_pipe.models.flower import build_flower

        return BuiltModel(build_flower(type_name, seed))

    def read_preset(self, type_name):
        from eden_pipe.models.flower import load_flower_preset

        return load_flower_preset(type_name)


class AssetFamily(ModelFamily):
    def build(self, type_name, seed, **options):
        from eden_pipe.models.assets import build_asset

        return BuiltModel(build_asset(type_name, seed))

    def read_preset(self, type_name):
        from eden_pipe.models.assets import asset_preset

        return asset_preset(type_name)


class FenceFamily(ModelFamily):
    """The garden's fence: with ``garden.fences.probability`` a garden has one, of a style drawn from
    ``garden.fences.styles`` (the ``fence_<style>`` asset presets); one model as long as the garden's
    side, laid along its four edges. Its config section is a ``FenceConfig``."""

    def build(self, type_name, seed, **options):
        from eden_pipe.models.assets import build_fence

        return BuiltModel(build_fence(type_name, options["length_m"], seed))

    def read_preset(self, type_name):
        from eden_pipe.models.assets import asset_preset

        return asset_preset(f"fence_{type_name}")

    def species(self):
        from eden_pipe.models.assets import list_fence_styles

        return list_fence_styles()

    def presets_in_use(self, garden):
        from eden_pipe.models.assets import asset_preset

        fences = self.settings(garden)
        return [
            (self.species_kind, f"fence_{style}", asset_preset) for style in fences.styles if fences.probability > 0
        ]

    def max_instances(self, garden):
        return self.placement.instances_per_draw if self.settings(garden).probability > 0 else 0

    def sample(self, garden, seed):
        # Whether the garden is fenced has its own generator, so the style drawn for a seed is the same
        # whatever the probability.
        fences = self.settings(garden)
        if not self.recipe_rng(seed, "present").random() < fences.probability:
            return PoolDraw()
        style = str(self.recipe_rng(seed).choice(fences.styles))
        model_seed = self.model_seed(seed)
        return PoolDraw([style], {style: [model_seed]}, [InstanceDraw(style, model_seed, 1.0)])

    def model_options(self, garden):
        # A run is as long as the garden's side, written as 10 m per 10 m of side: the expression the
        # fences of earlier datasets were built with, so every size gives the same float.
        return {"length_m": 10.0 * garden.size_m / 10.0}


# The order is the order of the instance ids in scene.json (and of recipe sampling and model building);
# the placement runs kind by kind in PlacementKind's order, and within a kind in this order. Do not
# reorder: a garden's ids and placement would change.
FAMILIES: tuple[ModelFamily, ...] = (
    FenceFamily(
        "fence",
        semantic="obstacle",
        spacing_m=0.0,
        species_kind="assets",
        placement=PlacementKind.ALONG_EDGES,
        config_key="fences",
    ),  # fences are garden assets
    TreeFamily("trees", semantic="tree", spacing_m=0.25, species_kind="trees", base_is_trunk=True),  # trunks kept apart
    BushFamily("bushes", semantic="hedge", spacing_m=0.15, species_kind="bushes"),
    FlowerFamily("flowers", semantic="flower", spacing_m=0.1, species_kind="flowers"),
    AssetFamily("obstacles", semantic="obstacle", spacing_m=0.15, species_kind="assets"),
)
POOLS: tuple[str, ...] = tuple(f.pool for f in FAMILIES)


def family(pool: str) -> ModelFamily:
    """The row of ``pool`` (read from :data:`FAMILIES` at each call)."""
    for fam in FAMILIES:
        if fam.pool == pool:
            return fam
    raise KeyError(f"unknown model pool {pool!r}; allowed: {', '.join(f.pool for f in FAMILIES)}")


def build_model(pool: str, type_name: str, seed: int, **options) -> BuiltModel:
    """Build one model of a placed family in its model frame."""
    return family(pool).build(type_name, seed, **options)
