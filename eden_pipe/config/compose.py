"""From ``conf/`` to typed config: Hydra composition, the one conversion, the known-key check.

Hydra hands the job a DictConfig; :func:`to_config` turns it (once, in ``run_job`` and the
pre-flight check) into an :class:`EdenConfig` of plain dataclasses, rejecting keys the schema
does not know (:func:`check_known_keys`, with a did-you-mean). :func:`validate` is that
conversion and the walk over every key's domain (``config.keys.check_values``).
:func:`make_cfg` composes ``conf/`` as the command line does, for tests, benchmarks and
scripts. :func:`to_plain` gives the JSON form used in cache keys and published configs.
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar, cast

from omegaconf import DictConfig, ListConfig, OmegaConf

from eden_pipe.config.keys import check_values, join, schema_fields, schema_keys, section_type
from eden_pipe.config.schema import EdenConfig
from eden_pipe.errors import ConfigError
from eden_pipe.models.species import CONF_DIR  # conf/: config.yaml and its groups, the species presets

#: Top-level nodes that are not the job's config (Hydra's own settings).
RUNTIME_NODES = ("hydra",)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

T = TypeVar("T", bound="DataclassInstance")  # as_typed converts to dataclasses only


def register_schemas() -> None:
    """The schema as Hydra's ``eden_schema``, the base of ``conf/config.yaml``."""
    from hydra.core.config_store import ConfigStore

    ConfigStore.instance().store(name="eden_schema", node=EdenConfig)


def make_cfg(root: str | Path | None, overrides: Sequence[str] = ()) -> DictConfig:
    """``conf/`` composed exactly as ``python -m eden_pipe`` composes it, with the stage cache and
    the dataset under ``root`` (``<root>/stages``, ``<root>/dataset``; None: where ``conf/`` puts
    them) and ``overrides`` on top."""
    from hydra import compose, initialize_config_dir
    from hydra.core.global_hydra import GlobalHydra

    paths = [] if root is None else [f"paths.stages={root}/stages", f"paths.dataset={root}/dataset"]
    register_schemas()
    GlobalHydra.instance().clear()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return compose("config", overrides=[*paths, *overrides])


def to_plain(node) -> Any:
    """A config node (DictConfig, structured dataclass or plain mapping) as plain dicts and lists."""
    if isinstance(node, (DictConfig, ListConfig)):
        return OmegaConf.to_container(node, resolve=True)
    if dataclasses.is_dataclass(node) and not isinstance(node, type):
        return {f.name: to_plain(getattr(node, f.name)) for f in dataclasses.fields(node)}
    if isinstance(node, dict):
        return {k: to_plain(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [to_plain(v) for v in node]
    return node


def as_typed(node, cls: type[T]) -> T:
    """``node`` (a DictConfig, a plain mapping or already a ``cls``) as a ``cls`` instance.

    Keys the schema does not know (e.g. the ``hydra`` node a callback sees) are dropped;
    interpolations are resolved; values are type-checked by OmegaConf on the way.
    """
    if isinstance(node, cls):
        return node
    names = {f.name for f in dataclasses.fields(cls)}
    if isinstance(node, DictConfig) and OmegaConf.get_type(node) is cls:
        # Composed over the schema (Hydra's eden_schema): typed already, each section its dataclass.
        return cls(**{name: _as_object(node[name]) for name in names if name in node})
    if isinstance(node, DictConfig):
        extra = [k for k in node if k not in names]
        if extra:
            node = OmegaConf.masked_copy(node, [k for k in node if k in names])
    elif isinstance(node, dict):
        node = {k: v for k, v in node.items() if k in names}
    # A structured config of ``cls`` converts to a ``cls`` instance (OmegaConf's return type is not generic).
    return cast(T, OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(cls), node)))


def _as_object(value: Any) -> Any:
    return OmegaConf.to_object(value) if isinstance(value, (DictConfig, ListConfig)) else value


def to_config(cfg) -> EdenConfig:
    """The whole job config as typed dataclasses: called once per job, in ``run_job``.

    A key the schema does not know (``+garden.tress.count=[5,6]``) raises :class:`ConfigError`
    (see :func:`check_known_keys`) instead of being dropped without a word."""
    if isinstance(cfg, EdenConfig):
        return cfg
    check_known_keys(cfg)
    return as_typed(cfg, EdenConfig)


def validate(cfg) -> None:
    """Raise ConfigError on the first value outside what is allowed. ``cfg``: the job config
    (DictConfig, as Hydra gives it, or an EdenConfig); every key is checked by its domain."""
    check_values(to_config(cfg))


# ------------------------------------------------------------------ known keys
def unknown_key_message(key: str, value: Any = None, show_value: bool = True) -> str:
    """One line for a key the schema lacks: a did-you-mean where one is close, and what is allowed there."""
    parent, _, leaf = key.rpartition(".")
    known = schema_keys()
    siblings = [k.rpartition(".")[2] for k in known if k.rpartition(".")[0] == parent]
    guess = [k for k in known if k.endswith("." + key)]  # a section left out: trees.count -> garden.trees.count
    guess = guess or [join(parent, m) for m in difflib.get_close_matches(leaf, siblings, n=1, cutoff=0.6)]
    guess = guess or difflib.get_close_matches(key, known, n=1, cutoff=0.75)
    hint = f" (did you mean {guess[0]}?)" if guess else ""
    where = f"under {parent}" if parent else "at the top level"
    shown = f"={value!r}" if show_value else ""
    return f"invalid config: {key}{shown} is not a known key{hint}; allowed {where}: {', '.join(sorted(siblings))}"


def check_known_keys(cfg) -> None:
    """Raise :class:`ConfigError` on the first key of ``cfg`` (DictConfig or mapping) that the typed
    schema does not know. Allowed keys come from the dataclasses (so a field added to one is accepted
    at once); a field typed ``Any`` or a mapping (``split.overrides``) holds free-form keys."""
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
        key = join(prefix, str(name))
        if name not in known:
            raise ConfigError(unknown_key_message(key, value))
        section = section_type(known[name])
        if section is not None and isinstance(value, dict):
            _walk_known(value, section, key)
