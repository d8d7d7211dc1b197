"""One entry point per model kind, so stages never import a builder by hand.

Builders are imported lazily: a garden without flowers never imports the
flower model.
"""

from __future__ import annotations

from eden_pipe.models.mesh import Mesh


def build_model(pool: str, type_name: str, seed: int, height_range: tuple[float, float] | None = None) -> Mesh:
    """Build one model of a garden pool (trees, bushes, flowers, obstacles) in its model frame."""
    if pool == "trees":
        from eden_pipe.models.tree import build_tree

        return build_tree(type_name, seed, height_range=height_range)
    if pool == "bushes":
        from eden_pipe.models.bush import build_bush

        return build_bush(type_name, seed)
    if pool == "flowers":
        from eden_pipe.models.flower import build_flower

        return build_flower(type_name, seed)
    if pool == "obstacles":
        from eden_pipe.models.assets import build_asset

        return build_asset(type_name, seed)
    raise KeyError(f"unknown model pool {pool!r}; allowed: trees, bushes, flowers, obstacles")


def build_fence_model(style: str, length: float, seed: int) -> Mesh:
    from eden_pipe.models.assets import build_fence

    return build_fence(style, length, seed)
