"""Colour and mesh helpers shared by the garden-asset builders and the fence builder.

Used by :mod:`eden_pipe.models.assets` and :mod:`eden_pipe.models.fences`: the
per-instance colour drawn from a preset's ``color``/``colors`` with its
``color_var``/``hue_var`` jitter, the per-piece colour factors, and the
obstacle-labelled mesh (every asset face is semantic 7, ``labels.OBSTACLE``).
"""

from __future__ import annotations

import numpy as np

from eden_pipe import labels
from eden_pipe.models import primitives as prim
from eden_pipe.models.mesh import Mesh

OBSTACLE = labels.OBSTACLE


def _colour(rng: np.random.Generator, p: dict, key: str = "color") -> np.ndarray:
    """Per-instance colour: one of ``colors`` (or ``color``), jittered."""
    plural = key + "s" if key != "color" else "colors"
    if plural in p:
        options = np.asarray(p[plural], np.float64)
        base = options[rng.integers(len(options))]
    else:
        base = np.asarray(p[key], np.float64)
    bright = np.exp(rng.normal(0.0, p.get("color_var", 0.1)))
    hue = np.exp(rng.normal(0.0, p.get("hue_var", 0.04), 3))
    return np.clip(base * bright * hue, 0.0, 1.0)


def _piece_jitter(rng: np.random.Generator, n: int, var: float) -> np.ndarray:
    """(n, 3) multiplicative per-piece colour factors."""
    return np.exp(rng.normal(0.0, var, (n, 1))) * np.exp(rng.normal(0.0, var * 0.3, (n, 3)))


def _mesh(v, f, material: str, albedo, specular=0.0) -> Mesh:
    return prim.to_mesh(v, f, semantic=OBSTACLE, material=material, albedo=np.clip(albedo, 0.0, 1.0), specular=specular)
