"""The one geometry container every model produces and every backend consumes.

A :class:`Mesh` is a triangle soup with per-face attributes, numpy-first:

- ``vertices`` (V, 3) float32, metres, model frame (Z up, base at z=0)
- ``faces`` (F, 3) int32 vertex indices, counter-clockwise seen from outside
- ``semantic`` (F,) uint8 class id (``eden_pipe.labels``)
- ``material`` (F,) uint8 material kind id (``MATERIALS``), which the renderer
  uses for procedural texturing evaluated at hit points
- ``albedo`` (F, 3) float32 linear RGB diffuse colour (Dcol) in [0, 1]
- ``translucency`` (F,) float32 fraction of incident light transmitted
  through thin surfaces (leaves, petals, grass blades), 0 for opaque
- ``specular`` (F,) float32 glossy reflectance at normal incidence
  (wet grass, pavement, waxy leaves)

Thin surfaces (leaves, petals, blades) are single-sided polygons: the renderer
treats faces as two-sided, so no alpha cards are ever needed and masks, depth
and normals stay exact.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

# Material kinds. Ids are part of the scene artifact format: append, never reorder.
MATERIALS = {
    "generic": 0,
    "bark": 1,
    "leaf": 2,
    "petal": 3,
    "grass": 4,
    "dirt": 5,
    "gravel": 6,
    "pebbles": 7,
    "pavement": 8,
    "rock": 9,
    "wood": 10,
    "metal": 11,
    "terracotta": 12,
    "stem": 13,
    "grass_soil": 14,
}


@dataclass(init=False)
class Mesh:
    vertices: np.ndarray
    faces: np.ndarray
    semantic: np.ndarray
    material: np.ndarray
    albedo: np.ndarray
    translucency: np.ndarray
    specular: np.ndarray

    def __init__(
        self,
        vertices: npt.ArrayLike,
        faces: npt.ArrayLike,
        semantic: npt.ArrayLike,
        material: npt.ArrayLike,
        albedo: npt.ArrayLike,
        translucency: npt.ArrayLike | None = None,
        specular: npt.ArrayLike | None = None,
    ) -> None:
        """Any array-like in the layouts of the module doc; a per-face attribute may be one scalar for every face
        (``translucency`` and ``specular`` default to 0)."""
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
        self.faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
        n = len(self.faces)
        self.semantic = _per_face(semantic, n, np.uint8, "semantic")
        self.material = _per_face(material, n, np.uint8, "material")
        alb = np.asarray(albedo, dtype=np.float32)
        self.albedo = np.ascontiguousarray(np.broadcast_to(alb, (n, 3)))
        self.translucency = _per_face(0.0 if translucency is None else translucency, n, np.float32, "translucency")
        self.specular = _per_face(0.0 if specular is None else specular, n, np.float32, "specular")

    # ------------------------------------------------------------------ basics
    @classmethod
    def empty(cls) -> Mesh:
        return cls(np.zeros((0, 3)), np.zeros((0, 3)), [], [], np.zeros((0, 3)))

    @classmethod
    def from_arrays(
        cls, vertices, faces, *, semantic: int, material: str | int, albedo, translucency=0.0, specular=0.0
    ) -> Mesh:
        """One-material mesh: scalar attributes broadcast to every face."""
        faces = np.asarray(faces).reshape(-1, 3)
        mat = MATERIALS[material] if isinstance(material, str) else int(material)
        n = len(faces)
        return cls(
            vertices,
            faces,
            np.full(n, semantic),
            np.full(n, mat),
            np.broadcast_to(np.asarray(albedo, np.float32), (n, 3)),
            np.full(n, translucency),
            np.full(n, specular),
        )

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    def bounds(self) -> np.ndarray:
        """(2, 3) min and max corner; zeros for an empty mesh."""
        if self.n_vertices == 0:
            return np.zeros((2, 3), np.float32)
        return np.stack([self.vertices.min(0), self.vertices.max(0)])

    def face_normals(self) -> np.ndarray:
        tri = self.vertices[self.faces]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        return n / np.maximum(length, 1e-20)

    def face_areas(self) -> np.ndarray:
        tri = self.vertices[self.faces].astype(np.float64)
        return 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)

    # ------------------------------------------------------------ operations
    def transformed(self, matrix: np.ndarray) -> Mesh:
        """A copy with vertices mapped by a 4x4 affine matrix (orientation kept)."""
        m = np.asarray(matrix, dtype=np.float64)
        v = self.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        faces = self.faces if np.linalg.det(m[:3, :3]) >= 0 else self.faces[:, ::-1]
        return Mesh(v, faces, self.semantic, self.material, self.albedo, self.translucency, self.specular)

    def with_attributes(self, **changes) -> Mesh:
        """A copy with some per-face attributes replaced (scalars broadcast)."""
        data = dict(
            vertices=self.vertices,
            faces=self.faces,
            semantic=self.semantic,
            material=self.material,
            albedo=self.albedo,
            translucency=self.translucency,
            specular=self.specular,
        )
        for key, value in changes.items():
            if key not in data or key in ("vertices", "faces"):
                raise KeyError(f"unknown per-face attribute {key!r}")
            data[key] = (
                np.broadcast_to(np.asarray(value), data[key].shape) if np.ndim(value) < data[key].ndim else value
            )
        return Mesh(**data)

    @staticmethod
    def concatenate(meshes: list[Mesh]) -> Mesh:
        meshes = [m for m in meshes if m.n_faces]
        if not meshes:
            return Mesh.empty()
        offsets = np.cumsum([0] + [m.n_vertices for m in meshes[:-1]])
        return Mesh(
            np.concatenate([m.vertices for m in meshes]),
            np.concatenate([m.faces + o for m, o in zip(meshes, offsets, strict=True)]),
            np.concatenate([m.semantic for m in meshes]),
            np.concatenate([m.material for m in meshes]),
            np.concatenate([m.albedo for m in meshes]),
            np.concatenate([m.translucency for m in meshes]),
            np.concatenate([m.specular for m in meshes]),
        )

    def degenerate_fraction(self, eps: float = 1e-12) -> float:
        if self.n_faces == 0:
            return 0.0
        return float(np.mean(self.face_areas() <= eps))

    def validate(self) -> None:
        """Raise ValueError if the mesh is malformed (used by tests and the model stage)."""
        if not np.all(np.isfinite(self.vertices)):
            raise ValueError("mesh has non-finite vertices")
        if self.n_faces and (self.faces.min() < 0 or self.faces.max() >= self.n_vertices):
            raise ValueError("mesh face index out of range")
        if np.any(self.semantic > 9):
            raise ValueError("mesh semantic id outside 0..9")

    # ------------------------------------------------------------ persistence
    def to_npz_dict(self, prefix: str = "") -> dict[str, np.ndarray]:
        return {
            prefix + k: getattr(self, k)
            for k in ("vertices", "faces", "semantic", "material", "albedo", "translucency", "specular")
        }

    @classmethod
    def from_npz_dict(cls, data, prefix: str = "") -> Mesh:
        return cls(
            *(
                np.asarray(data[prefix + k])
                for k in ("vertices", "faces", "semantic", "material", "albedo", "translucency", "specular")
            )
        )

    def save(self, path) -> None:
        arrays: dict[str, Any] = self.to_npz_dict()  # Any: numpy's stub reads a ** mapping as its keyword options
        np.savez(path, **arrays)

    @classmethod
    def load(cls, path) -> Mesh:
        with np.load(path) as data:
            return cls.from_npz_dict(data)


def _per_face(value, n: int, dtype, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=dtype)
    if arr.ndim == 0:
        return np.full(n, arr, dtype=dtype)
    if arr.shape != (n,):
        raise ValueError(f"per-face attribute {name!r} has shape {arr.shape}, expected ({n},)")
    return np.ascontiguousarray(arr)
