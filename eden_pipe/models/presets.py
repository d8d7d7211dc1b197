"""The preset grammar every model family shares, and the one checked preset loader.

A value in a species or asset preset (``conf/species/<kind>/<name>.yaml``) is

- a number (or any other literal): used as written;
- ``[lo, hi]`` (two numbers): drawn uniformly from [lo, hi) for each (type, seed);
  ``lo == hi`` gives ``lo`` without consuming a random draw;
- ``{choice: [a, b, ...]}``: one item, drawn uniformly.

:func:`draw` draws one value, :func:`draw_int` an integer from an inclusive
``[lo, hi]``, :func:`draw_array` ``n`` independent values (one per blade, leaf
or branch). Presets are data, so a typo must not silently fall back to a
default: :func:`load_preset` rejects every key its family does not know with
one :class:`~eden_pipe.errors.ConfigError` naming the file, the key and the
allowed keys.

Draws happen in the order the model asks for them; the grammar itself never
draws more than the one call it is asked for (seeded output stays stable).
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Mapping, Union

import numpy as np
import yaml

from eden_pipe.errors import ConfigError
from eden_pipe.models.species import load_species, species_dir

#: Allowed keys of a preset: one set for a flat preset, or ``{section: keys}`` where the
#: section ``None`` is the top level and other sections are nested mappings.
AllowedKeys = Union[set, Mapping]


def is_range(value) -> bool:
    """``[lo, hi]``: a two-item list or tuple of numbers."""
    return (isinstance(value, (list, tuple)) and len(value) == 2
            and all(isinstance(v, (int, float)) for v in value))


def draw(value, rng: np.random.Generator):
    """``[lo, hi]`` -> U(lo, hi); ``{"choice": [...]}`` -> one item; anything else unchanged."""
    if isinstance(value, dict) and "choice" in value:
        items = value["choice"]
        return items[int(rng.integers(len(items)))]
    if is_range(value):
        lo, hi = float(value[0]), float(value[1])
        return lo if lo == hi else float(rng.uniform(lo, hi))
    return value


def draw_float(value, rng: np.random.Generator) -> float:
    """:func:`draw` as a float (a preset number or range)."""
    return float(draw(value, rng))


def draw_int(value, rng: np.random.Generator) -> int:
    """An integer: ``[lo, hi]`` -> uniform over lo..hi inclusive; a number -> itself."""
    if isinstance(value, (list, tuple)) and len(value) == 2:
        return int(rng.integers(int(value[0]), int(value[1]) + 1))
    return int(value)


def draw_array(value, rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` independent values: ``[lo, hi]`` -> U(lo, hi) each (always ``n`` draws, even for
    lo == hi, so the count of draws never depends on the preset); a number -> ``n`` copies."""
    if isinstance(value, (list, tuple)):
        lo, hi = value
        return rng.uniform(lo, hi, n)
    return np.full(n, float(value))


# ----------------------------------------------------------------- loading
def preset_source(kind: str, name: str | Path) -> str:
    """How error messages name a preset: its file."""
    path = Path(name) if _is_file_ref(name) else species_dir(kind) / f"{name}.yaml"
    return str(path)


def _is_file_ref(name) -> bool:
    return isinstance(name, Path) or str(name).endswith((".yaml", ".yml"))


def check_keys(preset: Mapping, allowed: AllowedKeys, source: str) -> None:
    """Raise :class:`ConfigError` if ``preset`` has a key (or a nested section's key) not in ``allowed``."""
    sections = allowed if isinstance(allowed, Mapping) else {None: allowed}
    for section, keys in sections.items():
        cfg = preset if section is None else preset.get(section)
        if not isinstance(cfg, Mapping):
            continue
        unknown = sorted(str(k) for k in set(cfg) - set(keys))
        if unknown:
            where = "" if section is None else f" in section {section!r}"
            raise ConfigError(f"{source}: unknown preset key(s) {', '.join(map(repr, unknown))}{where}; "
                              f"allowed: {', '.join(sorted(keys))}")


def load_preset(kind: str, name: str | Path, allowed: AllowedKeys | Callable[[dict], AllowedKeys]) -> dict:
    """The preset ``name`` of ``kind`` (a preset name, or a path to a YAML file) as a fresh dict,
    after checking its keys against ``allowed`` (or ``allowed(preset)`` when the allowed keys
    depend on the preset, e.g. on its ``kind``)."""
    source = preset_source(kind, name)
    if _is_file_ref(name):
        with open(name) as fh:
            preset = yaml.safe_load(fh) or {}
        if not isinstance(preset, dict):
            raise ConfigError(f"{source}: expected a mapping at top level")
    else:
        preset = load_species(kind, str(name))
    keys = allowed(preset) if callable(allowed) else allowed
    check_keys(preset, keys, source)
    return preset
