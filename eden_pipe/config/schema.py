"""The config schema: one dataclass per section, each key's default and domain declared once.

``setting(default, domain)`` (``config.domains``) declares a key; ``section(cls, *checks,
**values)`` a section, with its own defaults where they differ from the class's (the four
pools) and its cross-key rules. The defaults are the values of the shipped ``conf/`` files
(``tests/test_config_schema.py`` checks them equal, key by key); Hydra's ``eden_schema``
(``config.compose.register_schemas``) is this schema, so an unknown key or a wrong type fails
while composing, and ``config.keys.check_values`` checks every domain before any stage runs.

Stages receive their typed section (``GardenConfig``, ``CameraConfig``, ...); a section builds
the runtime object it configures where one is built from it alone (``TerrainConfig.build``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, cast

from eden_pipe.config.domains import (
    AllOrMembers,
    AtMostOne,
    Deprecated,
    Interval,
    MappingOf,
    Members,
    Name,
    Number,
    OneOf,
    Program,
    Removed,
    ScenarioLimits,
    SumsToOne,
    Weights,
    Where,
    WritableFolder,
    section,
    setting,
)
from eden_pipe.lighting import LightingConfig
from eden_pipe.modalities import DEFAULT_MODALITIES, DEPTH_FORMATS, MODALITIES, STORAGE_MODES
from eden_pipe.models.assets import FENCE_STYLES
from eden_pipe.models.terrain import TERRAIN_TYPES

STAGES = ("model", "scene", "trajectory", "sky_visibility", "render", "manifest")
RENDER_MODES = ("standard", "reference")
# render.tracer: which path traces Embree (eden_pipe.render.embree; docs/design.md, "Ray tracing").
TRACERS = ("auto", "native", "embreex")
SPLITS = ("train", "val", "test")
#: ``garden.lawn.species: all``: every grass and weed preset under ``conf/species/grass/``.
ALL_SPECIES = "all"

POSITIVE = Number(lo=0, above=True)
NON_NEGATIVE = Number(lo=0)
PROBABILITY = Number(lo=0, hi=1)
FINITE = Number()


# ------------------------------------------------------------------ choices read when checked
def family_presets(where: Where) -> list[str]:
    """The presets of the family whose pool holds the key (``garden.trees.types``: tree presets)."""
    from eden_pipe.models.registry import family

    return family(where.section_key.rpartition(".")[2]).species()


def grass_presets(where: Where) -> list[str]:
    from eden_pipe.models.species import list_species

    return list_species("grass")


def backend_names(where: Where) -> tuple[str, ...]:
    from eden_pipe.render.backends import names

    return names()


# ``render.glossy_mirror``, with the bake: what the light along glossy's mirror direction is.
GLOSSY_MIRRORS = {
    "predicted": "the sky where the bake's visible fraction along the mirror direction says it is likelier seen, "
    "the mean light of what hides the sky where not; an any-hit ray decides for the render.mirror_rays "
    "share of upward glossy pixels where that guess is least sure",
    "any_hit": "one any-hit ray for every upward glossy pixel: the sky where it escapes, the mean light of what "
    "hides the sky where not",
    "traced": "one closest-hit ray: the sky where it escapes, the surface it meets lit by the bake",
}


def glossy_mirrors(where: Where) -> tuple[str, ...]:
    return tuple(GLOSSY_MIRRORS)


def draws_instances(pool: PoolConfig) -> bool:
    return pool.count[1] > 0


def is_fenced(fences: FenceConfig) -> bool:
    return fences.probability > 0


def lawn_enabled(lawn: LawnConfig) -> bool:
    return lawn.enabled


# ------------------------------------------------------------------ garden
@dataclass
class TerrainConfig:
    cells_per_m: int = setting(8, POSITIVE)
    relief_m: float = setting(0.12, NON_NEGATIVE)  # fBm displacement amplitude
    relief_scale_m: float = setting(4.0, POSITIVE)
    patch_types: list[str] = setting(list(TERRAIN_TYPES), Members(tuple(TERRAIN_TYPES), needed=True))
    patch_weights: list[float] = setting([0.6, 0.1, 0.1, 0.1, 0.1], Weights(per="patch_types"))
    types_per_garden: list[int] = setting([2, 4], Interval(lo=1))

    def build(self, seed: int, size_m: float):
        """The garden's terrain (``models.terrain.Terrain``): heights and patches."""
        from eden_pipe.models.terrain import build_terrain

        return build_terrain(
            seed,
            size_m,
            self.cells_per_m,
            self.relief_m,
            self.relief_scale_m,
            self.patch_types,
            self.patch_weights,
            cast("tuple[int, int]", tuple(self.types_per_garden)),  # a pair: its Interval domain checks two
        )


@dataclass
class PoolConfig:
    """One placed family's instances (the family table, ``models.registry.FAMILIES``, names the pools)."""

    count: list[int] = setting([0, 0], Interval(lo=0))
    types: list[str] = setting([], Members(family_presets, needed=draws_instances))
    types_per_garden: list[int] = setting([2, 4], Interval(lo=1))
    variants: int = setting(2, POSITIVE)
    scale: list[float] = setting([0.9, 1.1], Interval(lo=0.01))  # per instance, times the model's own size
    # Removed: sizes come from each species preset (e.g. conf/species/trees/<name>.yaml height_m).
    # Kept in the schema only so that an old config fails with a message saying so.
    height_m: list[float] | None = setting(
        None,
        Removed(
            "each species preset sets its own height range, height_m in conf/species/<kind>/<name>.yaml; "
            "scale instances with {section}.scale"
        ),
    )


@dataclass
class FenceConfig:
    # Chance that a garden is fenced (EDEN: "the fences, if any"); 0 = never, 1 = every garden.
    probability: float = setting(0.7, PROBABILITY)
    styles: list[str] = setting(list(FENCE_STYLES), Members(FENCE_STYLES, needed=is_fenced))


@dataclass
class LawnConfig:
    enabled: bool = setting(True)
    # "all" (every preset in conf/species/grass/) or a list of preset names
    species: Any = setting(
        ALL_SPECIES, AllOrMembers(ALL_SPECIES, "grass presets", Members(grass_presets, needed=lawn_enabled))
    )
    types_per_garden: list[int] = setting([2, 4], Interval(lo=1))
    triangles_per_m2: int = setting(20000, POSITIVE)  # no lawn: enabled=false
    freshness: list[float] = setting([0.7, 1.0], Interval(lo=0.0, hi=1.0))
    brownness: list[float] = setting([0.0, 0.2], Interval(lo=0.0, hi=1.0))
    wetness: list[float] = setting([0.0, 0.3], Interval(lo=0.0, hi=1.0))
    trim: list[float] = setting([0.5, 1.0], Interval(lo=0.0, hi=1.0))
    stripes_probability: float = setting(0.5, PROBABILITY)

    def species_pool(self) -> list[str]:
        """The grass presets a garden's lawn draws from (``all``: every preset in the folder, sorted)."""
        from eden_pipe.models.species import list_species

        return list_species("grass") if self.species == ALL_SPECIES else list(self.species)


@dataclass
class GardenConfig:
    """``conf/garden/default.yaml``: EDEN's 10 x 10 m garden with the paper's instance counts."""

    name: str = setting("default", Name())
    seed: int = setting(0, NON_NEGATIVE)
    size_m: float = setting(10.0, POSITIVE)
    terrain: TerrainConfig = section(TerrainConfig)
    lawn: LawnConfig = section(LawnConfig)
    trees: PoolConfig = section(
        PoolConfig,
        count=[5, 17],
        types=[
            "quaking_aspen",
            "black_tupelo",
            "weeping_willow",
            "ca_black_oak",
            "sassafras",
            "palm",
            "fan_palm",
            "european_larch",
            "tamarack",
            "balsam_fir",
            "lombardy_poplar",
            "eastern_cottonwood",
            "desert_bush",
            "douglas_fir",
            "japanese_maple",
            "small_maple",
            "small_pine",
            "white_birch",
            "callistemon",
        ],
    )
    bushes: PoolConfig = section(
        PoolConfig,
        count=[10, 24],
        scale=[0.85, 1.15],
        types=[
            "hedge_box",
            "hedge_boxwood",
            "hedge_privet",
            "topiary_sphere",
            "topiary_cone",
            "topiary_stacked_spheres",
            "topiary_spiral",
            "yew_cone",
        ],
    )
    flowers: PoolConfig = section(
        PoolConfig,
        count=[3, 10],
        scale=[0.8, 1.2],
        types=["rose_bush", "tulip", "daisy", "coneflower", "lavender", "ground_cover_phlox"],
    )
    obstacles: PoolConfig = section(
        PoolConfig,
        count=[3, 17],
        scale=[0.8, 1.2],
        types=[
            "rock_round",
            "rock_boulder",
            "rock_faceted",
            "rock_flat",
            "rock_slab",
            "pot_terracotta",
            "pot_terracotta_large",
            "pot_glazed",
            "planter_box",
            "planter_raised_bed",
            "planter_table",
            "bench",
            "bench_backless",
            "bird_bath",
            "stone_lantern",
        ],
    )
    fences: FenceConfig = section(FenceConfig)
    placement_attempts: int = setting(60, POSITIVE)  # random draws per instance before the systematic search

    def pool(self, name: str) -> PoolConfig:
        """The pool config of a placed family (``trees``, ``bushes``, ``flowers``, ``obstacles``)."""
        return getattr(self, name)


# ------------------------------------------------------------------ camera
@dataclass
class TrajectoryConfig:
    speed_mps: float = setting(0.5, POSITIVE)
    fps: float = setting(10.0, POSITIVE)
    # Frames of each trajectory, drawn per trajectory from [lo, hi] (EDEN: at least 100; its train
    # split averages about 116, the mean of the default range); flow needs two frames.
    frames: list[int] = setting([100, 132], Interval(lo=2))
    # Deprecated alias of frames=[n, n] (every trajectory exactly n frames), kept so old command lines
    # and other revisions' overrides still run; frames is ignored when it is set.
    min_steps: int | None = setting(
        None, Deprecated(Number(lo=2, note="deprecated: use frames=[n, n]"), use="{section}.frames=[{value},{value}]")
    )
    # false: a new random walk per lighting of a garden, seeded from garden and lighting (EDEN);
    # true: one walk per garden shared by every lighting (same views under each lighting, paired studies).
    share_across_lightings: bool = setting(False)
    run_steps: list[int] = setting([10, 40], Interval(lo=1))  # straight-run lengths between turns
    turn_deg: list[float] = setting([30.0, 120.0], Interval(lo=0.0, hi=180.0))  # turn magnitude (either side)
    abrupt_turn_probability: float = setting(0.3, PROBABILITY)  # else the turn spreads over gradual_turn_steps
    gradual_turn_steps: list[int] = setting([5, 15], Interval(lo=1))
    spin_deg_per_step: list[float] = setting([-2.0, 2.0], Interval(lo=-45.0, hi=45.0))  # self-rotation, per run
    clearance_m: float = setting(0.25, NON_NEGATIVE)  # free space kept around the ring
    max_attempts: int = setting(200, POSITIVE)

    def frame_range(self) -> tuple[int, int]:
        """The [lo, hi] range each trajectory's frame count is drawn from (``min_steps`` n -> (n, n))."""
        if self.min_steps is not None:
            return int(self.min_steps), int(self.min_steps)
        return int(self.frames[0]), int(self.frames[1])


# camera.sensor.vignetting: the lens's relative illumination (camera.sensor; docs/design.md, Camera effects).
VIGNETTING = ("none", "cos4", "polynomial")
# camera.sensor.tone_curve: the ISP's curve from linear sensor values to the 8-bit PNG.
TONE_CURVES = ("srgb", "gamma", "filmic")


@dataclass
class SensorConfig:
    """The sensor and ISP the display RGB goes through (``camera.sensor``, ``camera.sensor.Sensor``;
    docs/design.md, Camera effects). Off by default: the PNG is sRGB(exposure * I) as in EDEN."""

    enabled: bool = setting(False)
    # Photo-electrons collected at linear exposure 1 (the white point) and gain 1.
    full_well_e: float = setting(10000.0, POSITIVE)
    read_noise_e: float = setting(3.0, NON_NEGATIVE)  # Gaussian read noise, electrons rms, before the gain
    # Analogue gain at a fixed image brightness (ISO): gain g collects 1/g of the electrons and amplifies them g times.
    gain: float = setting(1.0, Number(lo=1.0, hi=256.0))
    black_level: float = setting(0.0625, Number(lo=0.0, hi=0.5))  # ADC offset, a fraction of full scale (64/1024)
    bits: int = setting(10, Number(lo=1, hi=16))  # ADC bit depth
    vignetting: str = setting("none", OneOf(VIGNETTING))
    # polynomial vignetting: relative illumination 1 + k1 r^2 + k2 r^4, r the normalised image radius (x/z, y/z).
    vignetting_k1: float = setting(-0.3, Number(lo=-1.0, hi=1.0))
    vignetting_k2: float = setting(0.0, Number(lo=-1.0, hi=1.0))
    # Lateral chromatic aberration: the red and blue images magnified by 1 + this about the principal point.
    ca_red: float = setting(0.0, Number(lo=-0.05, hi=0.05))
    ca_blue: float = setting(0.0, Number(lo=-0.05, hi=0.05))
    tone_curve: str = setting("srgb", OneOf(TONE_CURVES))
    gamma: float = setting(2.2, Number(lo=1.0, hi=4.0))  # tone_curve=gamma: x^(1/gamma)


@dataclass
class CameraConfig:
    """``conf/camera/ring5_stereo.yaml``: EDEN's ring of 5 stereo pairs."""

    name: str = setting("ring5_stereo", Name())
    width: int = setting(640, POSITIVE)
    height: int = setting(480, POSITIVE)
    fx: float = setting(640.0, POSITIVE)
    fy: float = setting(640.0, POSITIVE)
    cx: float = setting(320.0, FINITE)
    cy: float = setting(240.0, FINITE)
    baseline_m: float = setting(0.03, NON_NEGATIVE)
    pairs: int = setting(5, POSITIVE)
    ring_radius_m: float = setting(0.1, NON_NEGATIVE)
    height_m: float = setting(0.8, POSITIVE)  # above the terrain under the rig centre
    pitch_deg: float = setting(-10.0, Number(lo=-89, hi=89))  # negative looks down
    trajectory: TrajectoryConfig = section(TrajectoryConfig)
    # Rolling shutter: the time from the first row's exposure to the last's (docs/design.md, Camera effects).
    readout_s: float = setting(0.0, Number(lo=0.0, hi=1.0, note="0 = global shutter"))
    # Motion blur: the exposure time the display RGB averages over ...
    exposure_s: float = setting(0.0, Number(lo=0.0, hi=1.0, note="0 = no motion blur"))
    blur_samples: int = setting(8, Number(lo=2, hi=256))  # ... in this many sub-frame samples
    sensor: SensorConfig = section(SensorConfig)


# ------------------------------------------------------------------ render
@dataclass
class SkyVisibilityConfig:
    """The sky-visibility bake (stage ``sky_visibility``, once per garden; ``render.visibility``)."""

    enabled: bool = setting(True)  # false: the open sky everywhere (no occlusion, no bounce)
    directions: int = setting(128, POSITIVE)  # sky directions of the outside-in ray bundles
    spacing_m: float = setting(0.014, POSITIVE)  # spacing of each bundle's parallel rays
    rays: int = setting(8, NON_NEGATIVE)  # cosine rays per probe for the bounce light
    cell_m: float = setting(0.1, POSITIVE)  # probe cell width ...
    cell_height_m: float = setting(0.03, POSITIVE)  # ... and height
    ground_cell_m: float = setting(0.5, POSITIVE)  # node spacing of the ground map (the land outside) ...
    ground_reach_m: float = setting(30.0, NON_NEGATIVE)  # ... how far beyond the garden it reaches ...
    ground_rays: int = setting(128, NON_NEGATIVE)  # ... and cosine rays per node (0: no map, the open sky there)
    part_prior_hits: float = setting(64.0, NON_NEGATIVE)  # pseudo-hits shrinking a side's sky to its part's (0: none)
    prior_hits: float = setting(32.0, POSITIVE)  # ... and the part's (or the side's) toward its probe's
    camera_views: int = setting(4000, NON_NEGATIVE)  # cameras at the rig's height measuring the sky points see
    camera_rays: int = setting(4096, POSITIVE)  # ... rays each
    gain_prior_rays: float = setting(64.0, NON_NEGATIVE)  # pseudo-rays shrinking each probe's camera gain toward 1
    lightmap_cell_m: float = setting(0.07, NON_NEGATIVE)  # node spacing of wide faces' lightmaps (0: none)
    lightmap_rays: int = setting(128, NON_NEGATIVE)  # ... and cosine rays per node and side
    sun_multi_bounce: bool = setting(False)  # the bounce's multi-bounce factor on the sun's light too (docs/realism.md)
    seen_bounce: bool = setting(True)  # the bounce at the points the camera gain's rays see, not the probe's mean
    fast_rays: bool = setting(True)  # lightmap, bounce and ground-map rays without Embree's robust flag (scale-out.md)
    shadow_maps: bool = setting(False)  # keep the bundles' depth maps: each pixel's own sky at render time
    face_sky: bool = setting(True)  # the maps read in the bake at three points of each face side, blended per pixel
    face_sky_moments: bool = setting(True)  # ... and the directions each side sees the sky in: its sky term (face_sky)


@dataclass
class CyclesConfig:
    """Blender Cycles (``render.backend=cycles``, ``render.backends.cycles``; docs/realism.md, Cycles)."""

    python: str = setting("", Program())  # an interpreter with bpy==5.0.* (empty: this one)
    device: str = setting("cpu", OneOf(("cpu", "auto")))  # auto: the GPU Blender finds (OptiX, CUDA, HIP, ...)
    samples: int = setting(64, POSITIVE)  # paths per pixel, in each of a view's two renders
    seed: int = setting(0, NON_NEGATIVE)  # Cycles' sampling seed
    max_bounces: int = setting(6, NON_NEGATIVE)  # as render.reference_bounces (counted alike)
    diffuse_bounces: int = setting(6, NON_NEGATIVE)  # diffuse reflections
    glossy_bounces: int = setting(2, NON_NEGATIVE)
    # Cycles counts a translucent scattering as a transmission: at max_bounces no path ends before the
    # reference's would (docs/realism.md, Cycles).
    transmission_bounces: int = setting(6, NON_NEGATIVE)
    clamp_direct: float = setting(0.0, NON_NEGATIVE)  # 0: no clamping (unbiased)
    clamp_indirect: float = setting(0.0, NON_NEGATIVE)
    map_width: int = setting(1024, Number(lo=16))  # the sky's equirectangular maps (height: half)


@dataclass
class RenderConfig:
    """``conf/render/raytrace.yaml``: the Embree backend and its light model."""

    backend: str = setting("raytrace", OneOf(backend_names))
    threads: int = setting(0, Number(lo=0, note="0 = one per core"))
    workers: int = setting(0, Number(lo=0, note="0 = one per core"))
    tracer: str = setting("auto", OneOf(TRACERS))  # speed, not pixels: every path gives the same hits
    modalities: list[str] = setting(list(DEFAULT_MODALITIES), Members(MODALITIES, needed=True))
    depth_format: str = setting("png16", OneOf(tuple(DEPTH_FORMATS)))
    storage: str = setting("compact", OneOf(tuple(STORAGE_MODES)))
    rgb_spp: int = setting(1, POSITIVE)
    indirect_samples: int = setting(0, NON_NEGATIVE)
    soft_shadow_samples: int = setting(1, POSITIVE)
    # One shadow ray a pixel to a stratum of the sun's disc, pooled over the pixels this near on
    # the same face side: soft shadows at one ray's cost (docs/realism.md, the sun's penumbra; the
    # default since "The soft sun as the default"). 0: hard, one ray to the disc's centre.
    soft_shadow_radius: int = setting(2, Number(lo=0, hi=16, note="pixels the disc's rays are pooled over, 0 = hard"))
    png_compression: int = setting(1, Number(lo=0, hi=9))
    max_frames: int | None = setting(None, Number(lo=1))  # render only the first N frames (null = all)
    mode: str = setting("standard", OneOf(RENDER_MODES))  # reference: converged path tracing (slow)
    reference_samples: int = setting(256, POSITIVE)
    reference_bounces: int = setting(6, POSITIVE)
    # With the bake: predicted | any_hit | traced (GLOSSY_MIRRORS above).
    glossy_mirror: str = setting("predicted", OneOf(glossy_mirrors))
    # With glossy_mirror predicted: the share of upward glossy hits whose mirror a ray tests.
    mirror_rays: float = setting(0.6, Number(lo=0, hi=1, note="the share of upward glossy pixels"))
    # With the bake: cosine-weighted any-hit rays a pixel for its own visible sky (0: the bake's).
    pixel_sky_rays: int = setting(0, Number(lo=0, hi=64, note="any-hit rays a pixel, 0 = the bake's sky"))
    pixel_sky_radius: int = setting(4, Number(lo=0, hi=16, note="pixels the filter pools rays over"))
    sky_visibility: SkyVisibilityConfig = section(SkyVisibilityConfig)
    cycles: CyclesConfig = section(CyclesConfig)


# ------------------------------------------------------------------ job
@dataclass
class PathsConfig:
    stages: str = setting("stages", WritableFolder())  # the stage cache
    dataset: str = setting("outputs/dataset", WritableFolder())  # the dataset root
    check_free_space: bool = setting(True)  # refuse to start when the disk cannot hold what the job writes


@dataclass
class TestSubsampleConfig:
    """EDEN evaluates on a seeded uniform subsample of its test rows (20K of ~60K): a count or a fraction."""

    __test__ = False  # not a pytest class
    count: int | None = setting(None, NON_NEGATIVE)
    fraction: float | None = setting(None, PROBABILITY)
    seed: int = setting(0, FINITE)

    @property
    def enabled(self) -> bool:
        return self.count is not None or self.fraction is not None


@dataclass
class SplitConfig:
    preset: str = setting("hash", OneOf(("hash", "eden")))  # eden: EDEN's 127 train / 20 test gardens by seed
    train: float = setting(0.8, PROBABILITY)
    val: float = setting(0.1, PROBABILITY)
    test: float = setting(0.1, PROBABILITY)
    overrides: dict[str, str] = setting({}, MappingOf(OneOf(SPLITS)))  # garden id -> split
    test_subsample: TestSubsampleConfig = section(
        TestSubsampleConfig, AtMostOne(("count", "fraction"), "a count or a fraction", example=(1, 0.5))
    )


@dataclass
class EdenConfig:
    garden: GardenConfig = section(GardenConfig)
    lighting: LightingConfig = section(LightingConfig, ScenarioLimits())  # defaults: the clear scenario's
    camera: CameraConfig = section(CameraConfig)
    render: RenderConfig = section(RenderConfig)
    paths: PathsConfig = section(PathsConfig)
    split: SplitConfig = section(SplitConfig, SumsToOne(SPLITS))
    force: list[str] = setting([], Members(STAGES + ("all",)))  # stages to recompute even if cached
    progress: bool = setting(True)
