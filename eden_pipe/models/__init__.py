"""Procedural models: every plant, asset and terrain tile as a :class:`Mesh`."""

from eden_pipe.models.mesh import MATERIALS, Mesh

__all__ = ["MATERIALS", "Mesh"]
