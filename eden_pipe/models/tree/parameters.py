"""Weber-Penn tree parameters: preset keys and defaults, the resolved :class:`TreeParams`,
the crown shape ratio and the pruning envelope, and the limits that keep presets tractable."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from eden_pipe.models.presets import load_preset
from eden_pipe.models.species import list_species

DEG = np.pi / 180.0

LEVEL_KEYS = (
    "nLength",
    "nLengthV",
    "nTaper",
    "nSegSplits",
    "nSplitAngle",
    "nSplitAngleV",
    "nCurveRes",
    "nCurve",
    "nCurveBack",
    "nCurveV",
    "nDownAngle",
    "nDownAngleV",
    "nRotate",
    "nRotateV",
    "nBranches",
)
LEVEL_DEFAULTS = {
    "nLength": 0.5,
    "nLengthV": 0.0,
    "nTaper": 1.0,
    "nSegSplits": 0.0,
    "nSplitAngle": 0.0,
    "nSplitAngleV": 0.0,
    "nCurveRes": 3,
    "nCurve": 0.0,
    "nCurveBack": 0.0,
    "nCurveV": 0.0,
    "nDownAngle": 45.0,
    "nDownAngleV": 0.0,
    "nRotate": 140.0,
    "nRotateV": 0.0,
    "nBranches": 0,
    "nBaseSize": 0.0,
    "nWhorl": 0,
}
GLOBAL_DEFAULTS = {
    "Shape": 0,
    "Levels": 3,
    "Scale": 10.0,
    "ScaleV": 0.0,
    "BaseSize": 0.2,
    "Ratio": 0.015,
    "RatioPower": 1.2,
    "Flare": 0.5,
    "Lobes": 0,
    "LobeDepth": 0.0,
    "0Scale": 1.0,
    "0ScaleV": 0.0,
    "0BaseSplits": 0,
    "Leaves": 0,
    "LeafScale": 0.2,
    "LeafScaleX": 1.0,
    "LeafBend": 0.3,
    "LeafStemLen": 0.0,
    "LeafQuality": 1.0,
    "LeafDistrib": 4,
    "AttractionUp": 0.0,
    "PruneRatio": 0.0,
    "PruneWidth": 0.5,
    "PruneWidthPeak": 0.5,
    "PrunePowerLow": 0.5,
    "PrunePowerHigh": 0.5,
    "SplitHeight": None,
    "FanAngle": 180.0,
    "FanTilt": 0.0,
    "LeafStart": 0.1,
    "leaf_shape": "elliptic",
    "leaf_color": [0.06, 0.14, 0.03],
    "bark_color": [0.12, 0.09, 0.07],
    "leaf_translucency": 0.3,
    "leaf_specular": 0.05,
    "height_m": [3.0, 5.0],
    "leaf_color_alt": None,
    "leaf_alt_fraction": 0.0,
}

MAX_TRUNK_STEMS = 12  # trunk plus its clones
MAX_FAMILY = 8  # a branch plus its clones (Weber-Penn splitting is exponential)
MAX_STEMS_PER_LEVEL = 40000
MAX_CHILDREN = 20000  # stems per level; above it children are thinned and leaves carry the weight
MIN_RADIUS = 1.5e-4  # smallest stem radius, as a fraction of the tree scale
MAX_LEAF_AREA_GROWTH = 16.0  # a merged leaf is at most this many times the area of a preset leaf
RING_EPS = 1e-6


@dataclass
class TreeParams:
    """A species preset resolved to plain values; per-level values are 4-lists."""

    name: str
    g: dict
    lv: dict  # key -> np.ndarray (4,)
    attraction: np.ndarray  # (4,) effective AttractionUp per level

    @property
    def levels(self) -> int:
        return int(np.clip(self.g["Levels"], 1, 4))

    def __getitem__(self, key):
        return self.g[key]


#: Every key a tree preset may use: Weber-Penn globals, per-level lists and the extensions.
PRESET_KEYS = set(GLOBAL_DEFAULTS) | set(LEVEL_DEFAULTS) | {"name", "nAttractionUp"}


def tree_params(species: str | Path | dict) -> TreeParams:
    """Resolve a preset name, a preset file or an already loaded dict into :class:`TreeParams`."""
    if isinstance(species, (str, Path)):
        data = load_preset("trees", species, PRESET_KEYS)
    else:
        data = dict(species)
    name = data.get("name", str(species) if isinstance(species, (str, Path)) else "custom")
    g: dict[str, Any] = dict(GLOBAL_DEFAULTS)  # a preset's values: checked where they are used
    for key, value in data.items():
        if not (key.startswith("n") and key[1:2].isupper()):
            g[str(key)] = value
    lv = {}
    for key in LEVEL_KEYS + ("nBaseSize", "nWhorl"):
        raw = data.get(key, LEVEL_DEFAULTS[key])
        vals = list(raw) if isinstance(raw, (list, tuple)) else [raw]
        vals = [LEVEL_DEFAULTS[key] if v is None else v for v in vals]
        vals = (vals + [vals[-1]] * 4)[:4]
        lv[key] = np.asarray(vals, dtype=np.float64)
    lv["nCurveRes"] = np.maximum(1, np.round(lv["nCurveRes"])).astype(int)
    att = np.array([0.0, 0.0, float(g["AttractionUp"]), float(g["AttractionUp"])])
    override = data.get("nAttractionUp")
    if override is not None:
        for i, v in enumerate(list(override)[:4]):
            if v is not None:
                att[i] = float(v)
    return TreeParams(name=name, g=g, lv=lv, attraction=att)


def list_tree_species() -> list[str]:
    return list_species("trees")


def shape_ratio(shape: int, r, p: TreeParams | None = None) -> np.ndarray:
    """Weber-Penn shape ratio for crown shape ``shape`` at ratio ``r`` (0 top .. 1 base)."""
    r = np.asarray(r, dtype=np.float64)
    shape = int(shape)
    if shape == 8:
        peak = float(p["PruneWidthPeak"]) if p else 0.5
        lo = float(p["PrunePowerLow"]) if p else 0.5
        hi = float(p["PrunePowerHigh"]) if p else 0.5
        peak = min(max(peak, 1e-3), 1 - 1e-3)
        rc = np.clip(r, 0.0, 1.0)
        upper = (rc / (1.0 - peak)) ** hi
        lower = np.clip((1.0 - rc) / peak, 0.0, None) ** lo
        out = np.where(rc < 1.0 - peak, upper, lower)
        return np.where((r < 0) | (r > 1), 0.0, out)
    r = np.clip(r, 0.0, 1.0)
    if shape == 0:
        return 0.2 + 0.8 * r
    if shape == 1:
        return 0.2 + 0.8 * np.sin(np.pi * r)
    if shape == 2:
        return 0.2 + 0.8 * np.sin(0.5 * np.pi * r)
    if shape == 3:
        return np.ones_like(r)
    if shape == 4:
        return 0.5 + 0.5 * r
    if shape == 5:
        return np.where(r <= 0.7, r / 0.7, (1.0 - r) / 0.3)
    if shape == 6:
        return 1.0 - 0.8 * r
    if shape == 7:
        return np.where(r <= 0.7, 0.5 + 0.5 * r / 0.7, 0.5 + 0.5 * (1.0 - r) / 0.3)
    raise ValueError(f"unknown Weber-Penn shape {shape}")


def envelope_inside(pts: np.ndarray, p: TreeParams, scale: float) -> np.ndarray:
    """Weber-Penn pruning envelope test for points (..., 3), trunk base at the origin."""
    base = float(p["BaseSize"])
    ratio = (scale - pts[..., 2]) / (scale * max(1.0 - base, 1e-6))
    env = shape_ratio(8, ratio, p)
    rad = np.hypot(pts[..., 0], pts[..., 1]) / scale
    return (rad < float(p["PruneWidth"]) * env) & (ratio >= 0) & (ratio <= 1)
