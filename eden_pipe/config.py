"""Structured config schemas, their semantic checks, and the one conversion to typed objects.

The dataclasses are registered with Hydra's ConfigStore as ``eden_schema`` and
form the base of ``conf/config.yaml``: an unknown key or a wrong type fails at
startup. Each dataclass has a ``check(prefix)`` method beside it for what a
schema cannot express (ranges with lo > hi, negative counts, unknown species or
options); :func:`validate` walks them and raises :class:`ConfigError` with one
message that names the key, the value and what is allowed.

Hydra hands the job a DictConfig; :func:`to_config` turns it (once, in
``run_job``) into an :class:`EdenConfig` of plain dataclasses, and each stage
receives its typed slice (``GardenConfig``, ``CameraConfig``, ...). Stage
entry points also accept a DictConfig slice and convert it with
:func:`as_typed`. :func:`to_plain` gives the JSON form used in cache keys.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, fields
from typing import Any, List, Optional, TypeVar

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, ListConfig, OmegaConf

from eden_pipe.errors import ConfigError  # noqa: F401  (re-exported: raised by every check)
from eden_pipe.lighting import SCENARIOS, LightingConfig, check_lighting  # noqa: F401  (schema and check live with the scenario table)

STAGES = ("model", "scene", "trajectory", "sky_visibility", "render", "manifest")
from eden_pipe.modalities import DEFAULT_MODALITIES, MODALITIES  # noqa: E402,F401  (the modality table's names)
TERRAIN_TYPES = ("grass", "pebbles", "gravel", "dirt", "pavement")
FENCE_STYLES = ("picket", "panel", "post_and_rail", "slat")


def to_plain(node) -> Any:
    """A config node (DictConfig, structured dataclass or plain mapping) as plain dicts and lists."""
    import dataclasses

    if isinstance(node, (DictConfig, ListConfig)):
        return OmegaConf.to_container(node, resolve=True)
    if dataclasses.is_dataclass(node) and not isinstance(node, type):
        return {f.name: to_plain(getattr(node, f.name)) for f in dataclasses.fields(node)}
    if isinstance(node, dict):
        return {k: to_plain(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [to_plain(v) for v in node]
    return node


T = TypeVar("T")


def as_typed(node, cls: type[T]) -> T:
    """``node`` (a DictConfig, a plain mapping or already a ``cls``) as a ``cls`` instance.

    Keys the schema does not know (e.g. the ``hydra`` node a callback sees) are dropped;
    interpolations are resolved; values are type-checked by OmegaConf on the way.
    """
    if isinstance(node, cls):
        return node
    names = {f.name for f in fields(cls)}
    if isinstance(node, DictConfig):
        extra = [k for k in node.keys() if k not in names]
        if extra:
            node = OmegaConf.masked_copy(node, [k for k in node.keys() if k in names])
    elif isinstance(node, dict):
        node = {k: v for k, v in node.items() if k in names}
    return OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(cls), node))


def to_config(cfg) -> "EdenConfig":
    """The whole job config as typed dataclasses: called once per job, in ``run_job``.

    A key the schema does not know (``+garden.tress.count=[5,6]``) raises :class:`ConfigError`
    (see :func:`check_known_keys`) instead of being dropped without a word."""
    if isinstance(cfg, EdenConfig):
        return cfg
    check_known_keys(cfg)
    return as_typed(cfg, EdenConfig)


# ------------------------------------------------------------------ known keys
#: Top-level nodes that are not the job's config (Hydra's own settings).
RUNTIME_NODES = ("hydra",)


def schema_fields(cls: type) -> dict[str, Any]:
    """Field name -> its resolved type annotation (a dataclass for nested sections)."""
    import typing

    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in fields(cls)}


def _section_type(annotation) -> type | None:
    """The dataclass a field holds (``X`` or ``Optional[X]``); None for a leaf or a free-form value."""
    import dataclasses
    import typing

    candidates = [a for a in typing.get_args(annotation) if a is not type(None)] or [annotation]
    for cand in candidates:
        if dataclasses.is_dataclass(cand):
            return cand
    return None


def schema_keys(cls: type | None = None, prefix: str = "") -> list[str]:
    """Every dotted key of the schema (sections and leaves), derived from the dataclasses."""
    cls = cls or EdenConfig
    keys = []
    for name, annotation in schema_fields(cls).items():
        key = _name(prefix, name)
        keys.append(key)
        section = _section_type(annotation)
        if section is not None:
            keys += schema_keys(section, key)
    return keys


def schema_type(key: str) -> Any:
    """The annotation of the dotted ``key`` in the schema (KeyError if unknown)."""
    cls: Any = EdenConfig
    annotation: Any = None
    for part in key.split("."):
        if cls is None:
            raise KeyError(key)
        annotation = schema_fields(cls)[part]
        cls = _section_type(annotation)
    return annotation


def describe_type(annotation) -> str:
    """What a value of a schema type looks like, in words (for error messages)."""
    import typing

    origin, args = typing.get_origin(annotation), typing.get_args(annotation)
    if annotation is Any:
        return "any value"
    if origin is typing.Union:
        inner = [a for a in args if a is not type(None)]
        return "null or " + " or ".join(describe_type(a) for a in inner)
    if origin in (list, List):
        return "a list of " + describe_type(args[0]).split(" ", 1)[-1].rstrip("s") + "s" if args else "a list"
    if _section_type(annotation) is not None:
        return "a section with the keys " + ", ".join(schema_fields(annotation))
    return {bool: "true or false", int: "an integer", float: "a number", str: "a string"}.get(annotation, str(annotation))


def unknown_key_message(key: str, value: Any = None, show_value: bool = True) -> str:
    """One line for a key the schema lacks: a did-you-mean where one is close, and what is allowed there."""
    import difflib

    parent, _, leaf = key.rpartition(".")
    known = schema_keys()
    siblings = [k.rpartition(".")[2] for k in known if k.rpartition(".")[0] == parent]
    guess = [k for k in known if k.endswith("." + key)]  # a section left out: trees.count -> garden.trees.count
    guess = guess or [_name(parent, m) for m in difflib.get_close_matches(leaf, siblings, n=1, cutoff=0.6)]
    guess = guess or difflib.get_close_matches(key, known, n=1, cutoff=0.75)
    hint = f" (did you mean {guess[0]}?)" if guess else ""
    where = f"under {parent}" if parent else "at the top level"
    shown = f"={value!r}" if show_value else ""
    return f"invalid config: {key}{shown} is not a known key{hint}; allowed {where}: {', '.join(sorted(siblings))}"


def check_known_keys(cfg) -> None:
    """Raise :class:`ConfigError` on the first key of ``cfg`` (DictConfig or mapping) that the typed
    schema does not know. Allowed keys come from the dataclasses (so a field added to one is accepted
    at once); a field typed ``Any`` or ``dict`` (``split.overrides``) holds free-form keys."""
    if isinstance(cfg, (DictConfig, ListConfig)):
        cfg = OmegaConf.to_container(cfg, resolve=False)
    if not isinstance(cfg, dict):
        return
    _walk_known(cfg, EdenConfig, "")


def _walk_known(node: dict, cls: type, prefix: str) -> None:
    known = schema_fields(cls)
    for name, value in node.items():
        if not prefix and name in RUNTIME_NODES:
            continue
        key = _name(prefix, str(name))
        if name not in known:
            _raise(unknown_key_message(key, value))
        section = _section_type(known[name])
        if section is not None and isinstance(value, dict):
            _walk_known(value, section, key)


def _raise(message: str) -> None:
    raise ConfigError(message)


# ----------------------------------------------------------------------- schemas
@dataclass
class TerrainConfig:
    cells_per_m: int = 8
    relief_m: float = 0.12
    relief_scale_m: float = 4.0
    patch_types: List[str] = field(default_factory=lambda: list(TERRAIN_TYPES))
    patch_weights: List[float] = field(default_factory=lambda: [0.6, 0.1, 0.1, 0.1, 0.1])
    types_per_garden: List[int] = field(default_factory=lambda: [2, 4])

    def check(self, prefix: str) -> None:
        _positive(self, "cells_per_m", at=prefix)
        _positive(self, "relief_m", strict=False, at=prefix)
        _positive(self, "relief_scale_m", at=prefix)
        _members(self, "patch_types", TERRAIN_TYPES, nonempty=True, at=prefix)
        weights = list(self.patch_weights)
        if len(weights) != len(self.patch_types) or any(w < 0 for w in weights) or sum(weights) <= 0:
            _fail(f"{prefix}.patch_weights", weights, f"{len(self.patch_types)} non-negative numbers (one per patch type) with a positive sum")
        _range(self, "types_per_garden", 1, None, integer=True, at=prefix)


@dataclass
class PoolConfig:
    count: List[int] = field(default_factory=lambda: [0, 0])
    types: List[str] = field(default_factory=list)
    types_per_garden: List[int] = field(default_factory=lambda: [2, 4])
    variants: int = 2
    scale: List[float] = field(default_factory=lambda: [0.9, 1.1])  # per instance, times the model's own size
    # Removed: sizes come from each species preset (e.g. conf/species/trees/<name>.yaml height_m).
    # Kept in the schema only so that an old config fails with a message saying so.
    height_m: Optional[List[float]] = None

    def check(self, prefix: str, species: list[str]) -> None:
        """``species``: the preset names this pool's family allows for ``types``."""
        _range(self, "count", 0, None, integer=True, at=prefix)
        _range(self, "types_per_garden", 1, None, integer=True, at=prefix)
        if self.height_m is not None:
            _fail(f"{prefix}.height_m", list(self.height_m),
                  "nothing (removed: each species preset sets its own height range, height_m in "
                  f"conf/species/<kind>/<name>.yaml; scale instances with {prefix}.scale)")
        _range(self, "scale", 0.01, None, at=prefix)
        _positive(self, "variants", at=prefix)
        if self.count[1] > 0:
            _members(self, "types", species, nonempty=True, at=prefix)


@dataclass
class FenceConfig:
    # Chance that a garden is fenced (EDEN: "the fences, if any"); 0 = never, 1 = every garden.
    probability: float = 0.7
    styles: List[str] = field(default_factory=lambda: ["picket", "panel"])

    def check(self, prefix: str) -> None:
        if not 0.0 <= self.probability <= 1.0:
            _fail(f"{prefix}.probability", self.probability, "a number in [0, 1]")
        _members(self, "styles", FENCE_STYLES, nonempty=self.probability > 0, at=prefix)


#: ``garden.lawn.species: all``: every grass and weed preset under ``conf/species/grass/``.
ALL_SPECIES = "all"


@dataclass
class LawnConfig:
    enabled: bool = True
    species: Any = ALL_SPECIES  # "all" (every preset in conf/species/grass/) or a list of preset names
    types_per_garden: List[int] = field(default_factory=lambda: [2, 4])
    triangles_per_m2: int = 20000
    freshness: List[float] = field(default_factory=lambda: [0.7, 1.0])
    brownness: List[float] = field(default_factory=lambda: [0.0, 0.2])
    wetness: List[float] = field(default_factory=lambda: [0.0, 0.3])
    trim: List[float] = field(default_factory=lambda: [0.5, 1.0])
    stripes_probability: float = 0.5

    def check(self, prefix: str, needs_species: bool) -> None:
        """``needs_species``: the terrain has grass patches for this lawn to cover."""
        from eden_pipe.models.species import list_species

        if isinstance(self.species, str) and self.species != ALL_SPECIES:
            _fail(f"{prefix}.species", self.species, f"{ALL_SPECIES!r} or a list of grass presets")
        if self.enabled and needs_species and self.species != ALL_SPECIES:
            _members(self, "species", list_species("grass"), nonempty=True, at=prefix)
        _range(self, "types_per_garden", 1, None, integer=True, at=prefix)
        for key in ("freshness", "brownness", "wetness", "trim"):
            _range(self, key, 0.0, 1.0, at=prefix)
        _positive(self, "triangles_per_m2", strict=False, at=prefix)
        if not 0.0 <= self.stripes_probability <= 1.0:
            _fail(f"{prefix}.stripes_probability", self.stripes_probability, "a number in [0, 1]")

    def species_pool(self) -> list[str]:
        """The grass presets a garden's lawn draws from (``all``: every preset in the folder, sorted)."""
        from eden_pipe.models.species import list_species

        return list_species("grass") if self.species == ALL_SPECIES else list(self.species)


@dataclass
class GardenConfig:
    name: str = "default"
    seed: int = 0
    size_m: float = 10.0
    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    lawn: LawnConfig = field(default_factory=LawnConfig)
    trees: PoolConfig = field(default_factory=PoolConfig)
    bushes: PoolConfig = field(default_factory=PoolConfig)
    flowers: PoolConfig = field(default_factory=PoolConfig)
    obstacles: PoolConfig = field(default_factory=PoolConfig)
    fences: FenceConfig = field(default_factory=FenceConfig)
    placement_attempts: int = 60

    def pool(self, name: str) -> PoolConfig:
        """The pool config of a placed family (``trees``, ``bushes``, ``flowers``, ``obstacles``)."""
        return getattr(self, name)

    def check(self, prefix: str) -> None:
        from eden_pipe.models.registry import FAMILIES

        if self.seed < 0:
            _fail(f"{prefix}.seed", self.seed, "an integer >= 0")
        _positive(self, "size_m", at=prefix)
        self.terrain.check(f"{prefix}.terrain")
        for family in FAMILIES:
            family.check_settings(self, prefix)
        self.lawn.check(f"{prefix}.lawn", needs_species="grass" in self.terrain.patch_types)
        _positive(self, "placement_attempts", at=prefix)


@dataclass
class TrajectoryConfig:
    speed_mps: float = 0.5
    fps: float = 10.0
    # Frames of each trajectory, drawn per trajectory from [lo, hi] (EDEN: at least 100; its train
    # split averages about 116, the mean of the default range).
    frames: List[int] = field(default_factory=lambda: [100, 132])
    # Deprecated alias of frames=[n, n] (every trajectory exactly n frames), kept so old command lines
    # and other revisions' overrides still run; frames is ignored when it is set.
    min_steps: Optional[int] = None
    # false: a new random walk per lighting of a garden, seeded from garden and lighting (EDEN);
    # true: one walk per garden shared by every lighting (same views under each lighting, paired studies).
    share_across_lightings: bool = False
    run_steps: List[int] = field(default_factory=lambda: [10, 40])
    turn_deg: List[float] = field(default_factory=lambda: [30.0, 120.0])
    abrupt_turn_probability: float = 0.3
    gradual_turn_steps: List[int] = field(default_factory=lambda: [5, 15])
    spin_deg_per_step: List[float] = field(default_factory=lambda: [-2.0, 2.0])
    clearance_m: float = 0.25
    max_attempts: int = 200

    def frame_range(self) -> tuple[int, int]:
        """The [lo, hi] range each trajectory's frame count is drawn from (``min_steps`` n -> (n, n))."""
        if self.min_steps is not None:
            return int(self.min_steps), int(self.min_steps)
        return int(self.frames[0]), int(self.frames[1])

    def check(self, prefix: str) -> None:
        _positive(self, "speed_mps", at=prefix)
        _positive(self, "fps", at=prefix)
        _range(self, "frames", 2, None, integer=True, at=prefix)  # flow needs two frames
        if self.min_steps is not None:
            if self.min_steps < 2:
                _fail(f"{prefix}.min_steps", self.min_steps, "null or an integer >= 2 (deprecated: use frames=[n, n])")
            warnings.warn(f"{prefix}.min_steps is deprecated: use {prefix}.frames=[{self.min_steps},{self.min_steps}]",
                          FutureWarning, stacklevel=2)
        _range(self, "run_steps", 1, None, integer=True, at=prefix)
        _range(self, "turn_deg", 0.0, 180.0, at=prefix)
        _range(self, "gradual_turn_steps", 1, None, integer=True, at=prefix)
        _range(self, "spin_deg_per_step", -45.0, 45.0, at=prefix)
        if not 0.0 <= self.abrupt_turn_probability <= 1.0:
            _fail(f"{prefix}.abrupt_turn_probability", self.abrupt_turn_probability, "a number in [0, 1]")
        _positive(self, "clearance_m", strict=False, at=prefix)
        _positive(self, "max_attempts", at=prefix)


@dataclass
class CameraConfig:
    name: str = "ring5_stereo"
    width: int = 640
    height: int = 480
    fx: float = 640.0
    fy: float = 640.0
    cx: float = 320.0
    cy: float = 240.0
    baseline_m: float = 0.03
    pairs: int = 5
    ring_radius_m: float = 0.1
    height_m: float = 0.8
    pitch_deg: float = -10.0
    trajectory: TrajectoryConfig = field(default_factory=TrajectoryConfig)

    def check(self, prefix: str) -> None:
        for key in ("width", "height", "fx", "fy", "pairs"):
            _positive(self, key, at=prefix)
        _positive(self, "baseline_m", strict=False, at=prefix)
        _positive(self, "ring_radius_m", strict=False, at=prefix)
        _positive(self, "height_m", at=prefix)
        if not -89.0 <= self.pitch_deg <= 89.0:
            _fail(f"{prefix}.pitch_deg", self.pitch_deg, "a number in [-89, 89]")
        self.trajectory.check(f"{prefix}.trajectory")


@dataclass
class SkyVisibilityConfig:
    """The sky-visibility bake (stage ``sky_visibility``, once per garden; ``render.visibility``)."""

    enabled: bool = True         # false: the open sky everywhere (no occlusion, no bounce)
    directions: int = 32         # sky directions of the outside-in ray bundles
    spacing_m: float = 0.007     # spacing of each bundle's parallel rays
    rays: int = 8                # cosine rays per probe for the bounce light
    cell_m: float = 0.1          # probe cell width ...
    cell_height_m: float = 0.03  # ... and height
    ground_cell_m: float = 0.5   # node spacing of the ground map (the flat land outside the garden) ...
    ground_reach_m: float = 30.0  # ... how far beyond the garden it reaches (then open sky) ...
    ground_rays: int = 128       # ... and cosine rays per node (0: no map, the open sky there)
    camera_views: int = 4000     # cameras at the rig's height whose hits measure the sky the points cameras see see (0: none)
    camera_rays: int = 4096      # ... rays each
    lightmap_cell_m: float = 0.07  # node spacing of the lightmaps of faces wider than a cell (0: none)
    lightmap_rays: int = 128     # ... and cosine rays per node and side

    def check(self, prefix: str) -> None:
        for key in ("directions", "spacing_m", "cell_m", "cell_height_m", "ground_cell_m", "camera_rays"):
            _positive(self, key, at=prefix)
        for key in ("rays", "ground_reach_m", "ground_rays", "camera_views", "lightmap_cell_m", "lightmap_rays"):
            _positive(self, key, strict=False, at=prefix)


RENDER_MODES = ("standard", "reference")


@dataclass
class RenderConfig:
    backend: str = "raytrace"
    threads: int = 0
    workers: int = 0
    modalities: List[str] = field(default_factory=lambda: list(DEFAULT_MODALITIES))
    depth_format: str = "png16"
    storage: str = "compact"
    rgb_spp: int = 1
    indirect_samples: int = 0
    soft_shadow_samples: int = 1
    png_compression: int = 1
    max_frames: Optional[int] = None
    mode: str = "standard"       # reference: converged path tracing to measure against (slow)
    reference_samples: int = 256
    reference_bounces: int = 6
    glossy_mirror: str = "predicted"  # with the bake: predicted | any_hit | traced (render.shading.GLOSSY_MIRRORS)
    mirror_rays: float = 0.6  # with glossy_mirror predicted: the share of upward glossy hits whose mirror a ray tests
    sky_visibility: SkyVisibilityConfig = field(default_factory=SkyVisibilityConfig)

    def check(self, prefix: str) -> None:
        """Everything but ``backend`` and ``modalities`` (checked in :func:`validate`)."""
        from eden_pipe.modalities import DEPTH_FORMATS, STORAGE_MODES
        from eden_pipe.render.shading import GLOSSY_MIRRORS

        _one_of(self, "depth_format", tuple(DEPTH_FORMATS), at=prefix)
        _one_of(self, "storage", tuple(STORAGE_MODES), at=prefix)
        _one_of(self, "glossy_mirror", tuple(GLOSSY_MIRRORS), at=prefix)
        if not 0 <= self.mirror_rays <= 1:
            _fail(f"{prefix}.mirror_rays", self.mirror_rays, "a number in [0, 1] (the share of upward glossy pixels)")
        for key in ("threads", "workers"):
            if getattr(self, key) < 0:
                _fail(f"{prefix}.{key}", getattr(self, key), "an integer >= 0 (0 = one per core)")
        for key in ("rgb_spp", "soft_shadow_samples"):
            _positive(self, key, at=prefix)
        _positive(self, "indirect_samples", strict=False, at=prefix)
        if not 0 <= self.png_compression <= 9:
            _fail(f"{prefix}.png_compression", self.png_compression, "an integer in 0..9")
        if self.max_frames is not None and self.max_frames < 1:
            _fail(f"{prefix}.max_frames", self.max_frames, "null or an integer >= 1")
        _one_of(self, "mode", RENDER_MODES, at=prefix)
        for key in ("reference_samples", "reference_bounces"):
            _positive(self, key, at=prefix)
        self.sky_visibility.check(f"{prefix}.sky_visibility")


@dataclass
class PathsConfig:
    stages: str = "stages"
    dataset: str = "outputs/dataset"
    check_free_space: bool = True  # refuse to start when the disk cannot hold what the job writes (preflight)


@dataclass
class TestSubsampleConfig:
    """EDEN evaluates on a seeded uniform subsample of its test rows (20K of ~60K): a count or a fraction."""

    __test__ = False  # not a pytest class
    count: Optional[int] = None
    fraction: Optional[float] = None
    seed: int = 0

    def check(self, prefix: str) -> None:
        if self.count is not None and self.fraction is not None:
            _fail(prefix, dict(count=self.count, fraction=self.fraction), "a count or a fraction, not both")
        if self.count is not None and self.count < 0:
            _fail(f"{prefix}.count", self.count, "null or an integer >= 0")
        if self.fraction is not None and not 0.0 <= self.fraction <= 1.0:
            _fail(f"{prefix}.fraction", self.fraction, "null or a number in [0, 1]")

    @property
    def enabled(self) -> bool:
        return self.count is not None or self.fraction is not None


@dataclass
class SplitConfig:
    preset: str = "hash"  # hash: by the fractions below; eden: EDEN's 127 train / 20 test gardens by seed (0..146)
    train: float = 0.8
    val: float = 0.1
    test: float = 0.1
    overrides: Any = field(default_factory=dict)  # garden id -> split; set with ++split.overrides={...}
    test_subsample: TestSubsampleConfig = field(default_factory=TestSubsampleConfig)

    def check(self, prefix: str) -> None:
        _one_of(self, "preset", ("hash", "eden"), at=prefix)
        self.test_subsample.check(f"{prefix}.test_subsample")
        fractions = [self.train, self.val, self.test]
        if any(f < 0 for f in fractions) or abs(sum(fractions) - 1.0) > 1e-6:
            _fail(prefix, dict(train=fractions[0], val=fractions[1], test=fractions[2]), "non-negative train/val/test fractions summing to 1")
        for garden_id, split in (self.overrides or {}).items():
            if split not in ("train", "val", "test"):
                _fail(f"{prefix}.overrides.{garden_id}", split, "one of train, val, test")


@dataclass
class EdenConfig:
    garden: GardenConfig = field(default_factory=GardenConfig)
    lighting: LightingConfig = field(default_factory=LightingConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    paths: PathsConfig = field(default_factory=PathsConfig)
    split: SplitConfig = field(default_factory=SplitConfig)
    force: List[str] = field(default_factory=list)
    progress: bool = True


def register_schemas() -> None:
    ConfigStore.instance().store(name="eden_schema", node=EdenConfig)


# ------------------------------------------------------------- semantic checks
def _fail(key: str, value: Any, allowed: str) -> None:
    raise ConfigError(f"invalid config: {key}={value!r}; allowed: {allowed}")


def _get(node, key: str) -> Any:
    """``node``'s value at the dotted ``key``, by attribute (dataclasses and DictConfig alike)."""
    for part in key.split("."):
        node = getattr(node, part)
    return node


def _name(at: str, key: str) -> str:
    return f"{at}.{key}" if at else key


def _range(cfg, key: str, lo_min: float | None = None, hi_max: float | None = None, integer: bool = False, at: str = "") -> None:
    value = list(_get(cfg, key))
    shown = f"[{', '.join(str(v) for v in value)}]"
    kind = "integers" if integer else "numbers"
    bounds = []
    if lo_min is not None:
        bounds.append(f">= {lo_min}")
    if hi_max is not None:
        bounds.append(f"<= {hi_max}")
    allowed = f"a closed interval [lo, hi] of two {kind} with lo <= hi" + (f", both {' and '.join(bounds)}" if bounds else "")
    if len(value) != 2:
        _fail(_name(at, key), shown, allowed)
    lo, hi = value
    if lo > hi or (lo_min is not None and lo < lo_min) or (hi_max is not None and hi > hi_max):
        _fail(_name(at, key), shown, allowed)


def _positive(cfg, key: str, strict: bool = True, at: str = "") -> None:
    value = _get(cfg, key)
    if value is None or (value <= 0 if strict else value < 0):
        _fail(_name(at, key), value, "a number > 0" if strict else "a number >= 0")


def _members(cfg, key: str, allowed: list[str] | tuple[str, ...], nonempty: bool = False, at: str = "") -> None:
    value = list(_get(cfg, key))
    bad = [v for v in value if v not in allowed]
    if bad or (nonempty and not value):
        shown = bad[0] if bad else value
        choices = "one of " + ", ".join(allowed) if allowed else "nothing (no presets are installed for this key)"
        _fail(_name(at, key), shown, ("a non-empty list of " if nonempty else "") + choices)


def _one_of(cfg, key: str, allowed, at: str = "") -> None:
    value = _get(cfg, key)
    if value not in allowed:
        _fail(_name(at, key), value, "one of " + ", ".join(str(a) for a in allowed))


def validate(cfg) -> None:
    """Raise ConfigError on the first value outside what is allowed.

    ``cfg`` is the job config (DictConfig, as Hydra gives it, or an EdenConfig); each part
    is checked by its dataclass's ``check`` method, in the order of the config file.
    """
    cfg = to_config(cfg)
    cfg.garden.check("garden")

    check_lighting(cfg.lighting)

    cfg.camera.check("camera")

    from eden_pipe.render.backends import names as backend_names

    _one_of(cfg, "render.backend", backend_names())
    _members(cfg, "render.modalities", MODALITIES, nonempty=True)
    cfg.render.check("render")

    _members(cfg, "force", STAGES + ("all",))
    cfg.split.check("split")
