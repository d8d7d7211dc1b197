"""The job's config: its schema (``schema``), what each key allows (``domains``), every key
derived from the dataclasses (``keys``) and the composition from ``conf/`` (``compose``).

Every public name is importable from ``eden_pipe.config``.
"""

from eden_pipe.config.compose import (
    CONF_DIR, RUNTIME_NODES, as_typed, check_known_keys, make_cfg, register_schemas, to_config, to_plain,
    unknown_key_message, validate,
)
from eden_pipe.config.domains import Domain, SectionCheck, Where, fail, section, setting
from eden_pipe.config.keys import (
    Key, check_values, describe_key, describe_type, schema_fields, schema_items, schema_keys, schema_type,
)
from eden_pipe.config.schema import (
    ALL_SPECIES, RENDER_MODES, SPLITS, STAGES, CameraConfig, EdenConfig, FenceConfig, GardenConfig, LawnConfig,
    PathsConfig, PoolConfig, RenderConfig, SkyVisibilityConfig, SplitConfig, TerrainConfig, TestSubsampleConfig,
    TrajectoryConfig,
)
from eden_pipe.errors import ConfigError
from eden_pipe.lighting import SCENARIOS, LightingConfig, check_lighting
from eden_pipe.modalities import DEFAULT_MODALITIES, MODALITIES

__all__ = [
    "ALL_SPECIES", "CONF_DIR", "DEFAULT_MODALITIES", "MODALITIES", "RENDER_MODES", "RUNTIME_NODES", "SCENARIOS",
    "SPLITS", "STAGES", "CameraConfig", "ConfigError", "Domain", "EdenConfig", "FenceConfig", "GardenConfig", "Key",
    "LawnConfig", "LightingConfig", "PathsConfig", "PoolConfig", "RenderConfig", "SectionCheck",
    "SkyVisibilityConfig", "SplitConfig", "TerrainConfig", "TestSubsampleConfig", "TrajectoryConfig", "Where",
    "as_typed", "check_known_keys", "check_lighting", "check_values", "describe_key", "describe_type", "fail",
    "make_cfg", "register_schemas", "schema_fields", "schema_items", "schema_keys", "schema_type", "section",
    "setting", "to_config", "to_plain", "unknown_key_message", "validate",
]
