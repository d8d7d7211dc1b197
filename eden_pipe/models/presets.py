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
allowed keys, and every value of a form the other presets of its kind never use
for that key (:func:`check_values`).

Draws happen in the order the model asks for them; the grammar itself never
draws more than the one call it is asked for (seeded output stays stable).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np
import yaml

from eden_pipe.errors import ConfigError
from eden_pipe.models.species import load_species, species_dir

#: Allowed keys of a preset: one set for a flat preset, or ``{section: keys}`` where the
#: section ``None`` is the top level and other sections are nested mappings.
AllowedKeys = set | Mapping


def is_range(value) -> bool:
    """``[lo, hi]``: a two-item list or tuple of numbers."""
    return isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value)


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
            raise ConfigError(
                f"{source}: unknown preset key(s) {', '.join(map(repr, unknown))}{where}; "
                f"allowed: {', '.join(sorted(keys))}"
            )


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
    check_values(preset, kind, source)
    return preset


# ------------------------------------------------------------- value forms
def value_form(value) -> str:
    """The grammar form of a preset value: bool, string, scalar (a number or a ``{choice}`` of
    numbers), range (``[lo, hi]``), list<n> (n numbers), list (anything else), section, empty."""
    if value is None:
        return "empty"
    if isinstance(value, bool):
        return "bool"
    if isinstance(value, (int, float)):
        return "scalar"
    if isinstance(value, str):
        return "string"
    if isinstance(value, Mapping):
        if set(value) == {"choice"}:
            items = value["choice"] if isinstance(value["choice"], list) else []
            return "string" if items and all(isinstance(v, str) for v in items) else "scalar"
        return "section"
    if isinstance(value, (list, tuple)):
        if is_range(value):
            return "range"
        numeric = all(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)) for v in value)
        return f"list{len(value)}" if numeric else "list"  # a null item: that level's default
    return type(value).__name__


_FORM_WORDS = {
    "bool": "true or false",
    "string": "a string or {choice: [strings]}",
    "section": "a section of keys",
    "scalar": "a number, [lo, hi] or {choice: [numbers]}",
    "range": "[lo, hi] (or a number)",
    "list": "a list",
}


def _describe_forms(forms: set[str]) -> str:
    words = [_FORM_WORDS.get(f) or f"a list of {f[4:]} numbers" for f in sorted(forms)]
    return " or ".join(dict.fromkeys(words))


def _fits(form: str, reference: set[str]) -> bool:
    """Whether a value of ``form`` may stand where the other presets of its kind use ``reference``."""
    if form in reference:
        return True
    drawn = {"scalar", "range"}
    if form in drawn and reference & drawn:  # the grammar: a number, [lo, hi] or a choice alike
        return True
    lists = {f for f in reference if f.startswith("list") or f == "range"}
    return (form.startswith("list") or form == "range") and len(lists) > 1  # a key of varying length


@functools.cache
def _reference_forms(kind: str) -> dict[str, dict[str, set[str]]]:
    """file stem -> {dotted key: forms} of every shipped preset of ``kind``."""
    from eden_pipe.models.species import list_species

    def walk(node: Mapping, prefix: str, out: dict) -> dict:
        for key, value in node.items():
            name = f"{prefix}{key}"
            form = value_form(value)
            out.setdefault(name, set()).add(form)
            if form == "section":
                walk(value, name + ".", out)
        return out

    return {name: walk(load_species(kind, name), "", {}) for name in list_species(kind)}


def check_values(preset: Mapping, kind: str, source: str) -> None:
    """Raise :class:`ConfigError` for a value outside the grammar (empty, NaN, an empty choice) or of a
    form no other preset of ``kind`` uses for that key (a string where numbers go, three numbers
    where a colour has four...). The other presets are the reference, so no second schema is kept;
    a key no other preset has is left to its loader."""
    own = Path(source).stem
    reference: dict[str, set[str]] = {}
    for name, forms in _reference_forms(kind).items():
        if name != own:
            for key, kinds in forms.items():
                reference.setdefault(key, set()).update(kinds)

    def walk(node: Mapping, prefix: str) -> None:
        for key, value in node.items():
            name = f"{prefix}{key}"
            form = value_form(value)
            if form == "empty":
                _bad(source, name, value, "a value (the key is empty)")
            numbers = value["choice"] if isinstance(value, Mapping) and set(value) == {"choice"} else value
            if isinstance(value, Mapping) and set(value) == {"choice"} and not (isinstance(numbers, list) and numbers):
                _bad(source, name, value, "{choice: [a non-empty list]}")
            flat = numbers if isinstance(numbers, (list, tuple)) else [numbers]
            if any(isinstance(v, float) and not math.isfinite(v) for v in flat):
                _bad(source, name, value, "finite numbers")
            if name in reference and not _fits(form, reference[name]):
                _bad(source, name, value, f"{_describe_forms(reference[name])}, as in the other {kind} presets")
            if form == "section":
                walk(value, name + ".")

    walk(preset, "")


def _bad(source: str, key: str, value, allowed: str) -> None:
    raise ConfigError(f"{source}: invalid preset value {key}={value!r}; allowed: {allowed}")
