"""Semantic classes (3DRMS ids and colours), defined once for the whole project."""

from __future__ import annotations

import numpy as np

VOID, GRASS, GROUND, PAVEMENT, HEDGE, TOPIARY, FLOWER, OBSTACLE, TREE, BACKGROUND = range(10)

NAMES = ("void", "grass", "ground", "pavement", "hedge", "topiary", "flower", "obstacle", "tree", "background")

COLORS = np.array(
    [
        (0, 0, 0),
        (0, 204, 0),
        (77, 128, 0),
        (179, 204, 230),
        (128, 128, 0),
        (0, 179, 179),
        (230, 0, 0),
        (51, 51, 230),
        (77, 179, 26),
        (26, 26, 26),
    ],
    dtype=np.uint8,
)

BY_NAME = {name: i for i, name in enumerate(NAMES)}


def palette_rgb() -> np.ndarray:
    """256x3 uint8 palette for indexed PNGs: the ten classes, then black."""
    pal = np.zeros((256, 3), np.uint8)
    pal[: len(COLORS)] = COLORS
    return pal
