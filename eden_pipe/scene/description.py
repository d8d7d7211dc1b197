"""The scene description (``scene.json``): the garden's id, seed and instance table.

Written by the scene stage (:meth:`SceneDescription.save`) and read by every
stage after it (:func:`read_scene` / :meth:`SceneDescription.load`); the
geometry arrays beside it (``geometry.npz``) are read with
``eden_pipe.stages.scene.load_scene``. Nobody else parses the file.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

SCENE_FILE = "scene.json"


@dataclass
class SceneInstance:
    """One placed object; ``id`` is its value in the instance images (0 = none)."""

    id: int
    class_name: str  # "class" in scene.json
    semantic: int
    pool: str  # its family's pool (the family table, models/registry.py)
    type: str
    model_seed: int
    model_key: str
    transform: list  # 4x4 model-to-world, row-major
    bbox_min: list
    bbox_max: list
    faces: int

    def to_dict(self) -> dict:
        return {
            "id": self.id,
            "class": self.class_name,
            "semantic": self.semantic,
            "pool": self.pool,
            "type": self.type,
            "model_seed": self.model_seed,
            "model_key": self.model_key,
            "transform": self.transform,
            "bbox_min": self.bbox_min,
            "bbox_max": self.bbox_max,
            "faces": self.faces,
        }

    @classmethod
    def from_dict(cls, d: dict) -> SceneInstance:
        d = dict(d)
        return cls(class_name=d.pop("class"), **d)


@dataclass
class SceneDescription:
    """The garden as placed: what ``scene.json`` holds."""

    garden_id: str
    seed: int
    size_m: float
    terrain_types: list[str]
    lawn: dict | None  # the recipe's lawn draw, as JSON
    # Instances per pool in the recipe, and those that found a free spot: the families whose placement may
    # leave an instance out (``PlacementKind.may_leave_out``; a fence's runs are always laid).
    requested: dict[str, int]
    placed: dict[str, int]
    instances: list[SceneInstance] = field(default_factory=list)
    faces: int = 0
    # Instances of the recipe that found no free spot: {pool, index, type, model_seed, reason} each
    # (also logged as a warning by the scene stage): a garden is never silently sparser than sampled.
    unplaced: list[dict] = field(default_factory=list)

    def __getitem__(self, key: str) -> Any:
        """Read-only ``scene["seed"]`` access (JSON form), for callers written against the old dict."""
        return self.to_dict()[key] if key == "instances" else getattr(self, key)

    def to_dict(self) -> dict:
        return {
            "garden_id": self.garden_id,
            "seed": self.seed,
            "size_m": self.size_m,
            "terrain_types": self.terrain_types,
            "lawn": self.lawn,
            "requested": self.requested,
            "placed": self.placed,
            "instances": [i.to_dict() for i in self.instances],
            "faces": self.faces,
            "unplaced": self.unplaced,
        }

    @classmethod
    def from_dict(cls, d: dict) -> SceneDescription:
        return cls(
            d["garden_id"],
            int(d["seed"]),
            d["size_m"],
            list(d["terrain_types"]),
            d["lawn"],
            dict(d["requested"]),
            dict(d["placed"]),
            [SceneInstance.from_dict(i) for i in d["instances"]],
            int(d["faces"]),
            list(d.get("unplaced", [])),
        )

    def save(self, folder: Path) -> None:
        (Path(folder) / SCENE_FILE).write_text(json.dumps(self.to_dict(), indent=1))

    @classmethod
    def load(cls, folder: Path) -> SceneDescription:
        return cls.from_dict(json.loads((Path(folder) / SCENE_FILE).read_text()))


def read_scene(scene_art) -> SceneDescription:
    """The scene description of a scene-stage artifact (anything with a ``path``)."""
    return SceneDescription.load(scene_art.path)
