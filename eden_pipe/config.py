"""Structured config schemas and the semantic checks run before any work.

The dataclasses are registered with Hydra's ConfigStore as ``eden_schema`` and
form the base of ``conf/config.yaml``: an unknown key or a wrong type fails at
startup. :func:`validate` adds the checks a schema cannot express (ranges with
lo > hi, negative counts, unknown species or options) and raises
:class:`ConfigError` with one message that names the key, the value and what is
allowed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, List, Optional

from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, ListConfig, OmegaConf

from eden_pipe.errors import ConfigError  # noqa: F401  (re-exported: raised by every check)
from eden_pipe.lighting import SCENARIOS, LightingConfig, check_lighting  # noqa: F401  (schema and check live with the scenario table)

STAGES = ("model", "scene", "trajectory", "render", "manifest")
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


# ----------------------------------------------------------------------- schemas
@dataclass
class TerrainConfig:
    cells_per_m: int = 8
    relief_m: float = 0.12
    relief_scale_m: float = 4.0
    patch_types: List[str] = field(default_factory=lambda: list(TERRAIN_TYPES))
    patch_weights: List[float] = field(default_factory=lambda: [0.6, 0.1, 0.1, 0.1, 0.1])
    types_per_garden: List[int] = field(default_factory=lambda: [2, 4])


@dataclass
class PoolConfig:
    count: List[int] = field(default_factory=lambda: [0, 0])
    types: List[str] = field(default_factory=list)
    types_per_garden: List[int] = field(default_factory=lambda: [2, 4])
    height_m: List[float] = field(default_factory=lambda: [1.0, 2.0])
    variants: int = 2
    scale: List[float] = field(default_factory=lambda: [0.9, 1.1])


@dataclass
class FenceConfig:
    enabled: bool = True
    styles: List[str] = field(default_factory=lambda: ["picket", "panel"])


@dataclass
class LawnConfig:
    enabled: bool = True
    species: List[str] = field(default_factory=list)
    types_per_garden: List[int] = field(default_factory=lambda: [2, 4])
    triangles_per_m2: int = 20000
    freshness: List[float] = field(default_factory=lambda: [0.7, 1.0])
    brownness: List[float] = field(default_factory=lambda: [0.0, 0.2])
    wetness: List[float] = field(default_factory=lambda: [0.0, 0.3])
    trim: List[float] = field(default_factory=lambda: [0.5, 1.0])
    stripes_probability: float = 0.5


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


@dataclass
class TrajectoryConfig:
    speed_mps: float = 0.5
    fps: float = 10.0
    min_steps: int = 100
    run_steps: List[int] = field(default_factory=lambda: [10, 40])
    turn_deg: List[float] = field(default_factory=lambda: [30.0, 120.0])
    abrupt_turn_probability: float = 0.3
    gradual_turn_steps: List[int] = field(default_factory=lambda: [5, 15])
    spin_deg_per_step: List[float] = field(default_factory=lambda: [-2.0, 2.0])
    clearance_m: float = 0.25
    max_attempts: int = 200


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


@dataclass
class RenderConfig:
    backend: str = "raytrace"
    threads: int = 0
    workers: int = 0
    modalities: List[str] = field(default_factory=lambda: list(DEFAULT_MODALITIES))
    depth_format: str = "png16"
    rgb_spp: int = 1
    indirect_samples: int = 0
    soft_shadow_samples: int = 1
    png_compression: int = 1
    max_frames: Optional[int] = None


@dataclass
class PathsConfig:
    stages: str = "stages"
    dataset: str = "outputs/dataset"


@dataclass
class SplitConfig:
    train: float = 0.8
    val: float = 0.1
    test: float = 0.1
    overrides: Any = field(default_factory=dict)  # garden id -> split; set with ++split.overrides={...}


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


def _range(cfg, key: str, lo_min: float | None = None, hi_max: float | None = None, integer: bool = False) -> None:
    value = list(OmegaConf.select(cfg, key))
    shown = f"[{', '.join(str(v) for v in value)}]"
    kind = "integers" if integer else "numbers"
    bounds = []
    if lo_min is not None:
        bounds.append(f">= {lo_min}")
    if hi_max is not None:
        bounds.append(f"<= {hi_max}")
    allowed = f"a closed interval [lo, hi] of two {kind} with lo <= hi" + (f", both {' and '.join(bounds)}" if bounds else "")
    if len(value) != 2:
        _fail(key, shown, allowed)
    lo, hi = value
    if lo > hi or (lo_min is not None and lo < lo_min) or (hi_max is not None and hi > hi_max):
        _fail(key, shown, allowed)


def _positive(cfg, key: str, strict: bool = True) -> None:
    value = OmegaConf.select(cfg, key)
    if value is None or (value <= 0 if strict else value < 0):
        _fail(key, value, "a number > 0" if strict else "a number >= 0")


def _members(cfg, key: str, allowed: list[str] | tuple[str, ...], nonempty: bool = False) -> None:
    value = list(OmegaConf.select(cfg, key))
    bad = [v for v in value if v not in allowed]
    if bad or (nonempty and not value):
        shown = bad[0] if bad else value
        choices = "one of " + ", ".join(allowed) if allowed else "nothing (no presets are installed for this key)"
        _fail(key, shown, ("a non-empty list of " if nonempty else "") + choices)


def _one_of(cfg, key: str, allowed) -> None:
    value = OmegaConf.select(cfg, key)
    if value not in allowed:
        _fail(key, value, "one of " + ", ".join(str(a) for a in allowed))


def validate(cfg: DictConfig) -> None:
    """Raise ConfigError on the first value outside what is allowed."""
    from eden_pipe.models.species import list_species

    g = "garden"
    if cfg.garden.seed < 0:
        _fail("garden.seed", cfg.garden.seed, "an integer >= 0")
    _positive(cfg, "garden.size_m")
    _positive(cfg, "garden.terrain.cells_per_m")
    _positive(cfg, "garden.terrain.relief_m", strict=False)
    _positive(cfg, "garden.terrain.relief_scale_m")
    _members(cfg, "garden.terrain.patch_types", TERRAIN_TYPES, nonempty=True)
    weights = list(cfg.garden.terrain.patch_weights)
    if len(weights) != len(cfg.garden.terrain.patch_types) or any(w < 0 for w in weights) or sum(weights) <= 0:
        _fail("garden.terrain.patch_weights", weights, f"{len(cfg.garden.terrain.patch_types)} non-negative numbers (one per patch type) with a positive sum")
    _range(cfg, "garden.terrain.types_per_garden", 1, None, integer=True)
    pools = {"trees": "trees", "bushes": "bushes", "flowers": "flowers", "obstacles": "assets"}
    for pool, kind in pools.items():
        _range(cfg, f"{g}.{pool}.count", 0, None, integer=True)
        _range(cfg, f"{g}.{pool}.types_per_garden", 1, None, integer=True)
        _range(cfg, f"{g}.{pool}.height_m", 0.01, None)
        _range(cfg, f"{g}.{pool}.scale", 0.01, None)
        _positive(cfg, f"{g}.{pool}.variants")
        if cfg.garden[pool].count[1] > 0:
            _members(cfg, f"{g}.{pool}.types", list_species(kind), nonempty=True)
    lawn = cfg.garden.lawn
    if lawn.enabled and "grass" in cfg.garden.terrain.patch_types:
        _members(cfg, "garden.lawn.species", list_species("grass"), nonempty=True)
    _range(cfg, "garden.lawn.types_per_garden", 1, None, integer=True)
    for key in ("freshness", "brownness", "wetness", "trim"):
        _range(cfg, f"garden.lawn.{key}", 0.0, 1.0)
    _positive(cfg, "garden.lawn.triangles_per_m2", strict=False)
    if not 0.0 <= lawn.stripes_probability <= 1.0:
        _fail("garden.lawn.stripes_probability", lawn.stripes_probability, "a number in [0, 1]")
    _members(cfg, "garden.fences.styles", FENCE_STYLES, nonempty=cfg.garden.fences.enabled)
    _positive(cfg, "garden.placement_attempts")

    check_lighting(cfg.lighting)

    for key in ("width", "height", "fx", "fy", "pairs"):
        _positive(cfg, f"camera.{key}")
    _positive(cfg, "camera.baseline_m", strict=False)
    _positive(cfg, "camera.ring_radius_m", strict=False)
    _positive(cfg, "camera.height_m")
    if not -89.0 <= cfg.camera.pitch_deg <= 89.0:
        _fail("camera.pitch_deg", cfg.camera.pitch_deg, "a number in [-89, 89]")
    t = "camera.trajectory"
    _positive(cfg, f"{t}.speed_mps")
    _positive(cfg, f"{t}.fps")
    if cfg.camera.trajectory.min_steps < 2:
        _fail(f"{t}.min_steps", cfg.camera.trajectory.min_steps, "an integer >= 2 (flow needs two frames)")
    _range(cfg, f"{t}.run_steps", 1, None, integer=True)
    _range(cfg, f"{t}.turn_deg", 0.0, 180.0)
    _range(cfg, f"{t}.gradual_turn_steps", 1, None, integer=True)
    _range(cfg, f"{t}.spin_deg_per_step", -45.0, 45.0)
    if not 0.0 <= cfg.camera.trajectory.abrupt_turn_probability <= 1.0:
        _fail(f"{t}.abrupt_turn_probability", cfg.camera.trajectory.abrupt_turn_probability, "a number in [0, 1]")
    _positive(cfg, f"{t}.clearance_m", strict=False)
    _positive(cfg, f"{t}.max_attempts")

    from eden_pipe.render.backends import names as backend_names

    _one_of(cfg, "render.backend", backend_names())
    _members(cfg, "render.modalities", MODALITIES, nonempty=True)
    _one_of(cfg, "render.depth_format", ("png16", "float"))
    for key in ("threads", "workers"):
        if cfg.render[key] < 0:
            _fail(f"render.{key}", cfg.render[key], "an integer >= 0 (0 = one per core)")
    for key in ("rgb_spp", "soft_shadow_samples"):
        _positive(cfg, f"render.{key}")
    _positive(cfg, "render.indirect_samples", strict=False)
    if not 0 <= cfg.render.png_compression <= 9:
        _fail("render.png_compression", cfg.render.png_compression, "an integer in 0..9")
    if cfg.render.max_frames is not None and cfg.render.max_frames < 1:
        _fail("render.max_frames", cfg.render.max_frames, "null or an integer >= 1")

    _members(cfg, "force", STAGES + ("all",))
    fractions = [cfg.split.train, cfg.split.val, cfg.split.test]
    if any(f < 0 for f in fractions) or abs(sum(fractions) - 1.0) > 1e-6:
        _fail("split", dict(train=fractions[0], val=fractions[1], test=fractions[2]), "non-negative train/val/test fractions summing to 1")
    overrides = cfg.split.overrides
    for garden_id, split in (overrides or {}).items():
        if split not in ("train", "val", "test"):
            _fail(f"split.overrides.{garden_id}", split, "one of train, val, test")
