"""Species and asset presets as data: one YAML file each under ``conf/species/<kind>/``.

Kinds: ``trees``, ``bushes``, ``flowers``, ``grass``, ``assets``. A preset is a
plain dict; the model builders interpret it. Names are file stems.
"""

from __future__ import annotations

from functools import cache
from pathlib import Path

import yaml  # PyYAML ships with omegaconf

CONF_DIR = Path(__file__).resolve().parents[2] / "conf"
SPECIES_DIR = CONF_DIR / "species"


def species_dir(kind: str) -> Path:
    return SPECIES_DIR / kind


def list_species(kind: str) -> list[str]:
    """Sorted preset names of one kind (empty if the kind has no folder)."""
    folder = species_dir(kind)
    return sorted(p.stem for p in folder.glob("*.yaml")) if folder.is_dir() else []


@cache
def _load(kind: str, name: str) -> dict:
    path = species_dir(kind) / f"{name}.yaml"
    if not path.is_file():
        allowed = ", ".join(list_species(kind)) or "(none)"
        raise KeyError(f"unknown {kind} preset {name!r}; allowed: {allowed}")
    with open(path) as fh:
        data = yaml.safe_load(fh) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping at top level")
    return data


@cache
def presets_fingerprint() -> str:
    """Hash of every preset file: part of the model stage's keys, so editing a preset rebuilds."""
    import hashlib

    digest = hashlib.sha256()
    for path in sorted(SPECIES_DIR.rglob("*.yaml")):
        digest.update(str(path.relative_to(SPECIES_DIR)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


def load_species(kind: str, name: str) -> dict:
    """The preset as a fresh dict (callers may modify their copy)."""
    import copy

    return copy.deepcopy(_load(kind, name))
