"""Procedural models: every plant, asset and terrain tile as a :class:`Mesh`."""

from eden_pipe.models.mesh import Mesh, MATERIALS

__all__ = ["Mesh", "MATERIALS"]
