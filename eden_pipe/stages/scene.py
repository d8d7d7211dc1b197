"""Scene stage: place the recipe's instances without overlap on the terrain.

pybullet does the collision work (eden_pipe.scene.physics). Output, under
``stages/scene/<key>/``:

- ``scene.json``: garden id, seed, terrain and lawn facts, and every instance
  (id, class, pool, type, model seed, 4x4 transform, world bounding box) -
  written and read as :class:`~eden_pipe.scene.description.SceneDescription`;
- ``geometry.npz``: the flattened world mesh (Mesh arrays) plus ``instance``,
  the per-face instance id (0 = terrain, lawn, skirt) - the renderer-agnostic
  scene every backend consumes;
- ``geometry.ply``: the same mesh and per-face attributes as the published scene mesh
  (``<garden>/geometry.ply``, :mod:`eden_pipe.io.mesh_ply`; publishing links it), see
  :func:`save_published_geometry`;
- ``proxies.npz``: in world coordinates, the rig's obstacles for the
  trajectory stage (``points``/``offsets``/``ids``: convex pieces of
  everything the rig could touch) and each instance's base body
  (``base_points``/``base_offsets``/``base_ids``), see
  :func:`save_proxies` and :mod:`eden_pipe.scene.placement`.

Every sampled instance is placed unless no free spot exists for its base;
those are logged (warning on the ``eden_pipe`` logger) and listed in
``scene.json`` under ``unplaced``. Inputs: the model artifact (its Recipe and
models) and the typed ``CameraConfig`` (the rig height decides how much of
each model the rig could touch). Every instance's family (the family table,
``eden_pipe.models.registry.FAMILIES``) gives its placement kind, spacing and
class; ``requested``/``placed`` count the families whose placement may leave
an instance out.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from eden_pipe import labels, metadata
from eden_pipe.io.mesh_ply import write_mesh_ply
from eden_pipe.models import registry
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.scene.description import SceneDescription, SceneInstance
from eden_pipe.scene.physics import PhysicsWorld
from eden_pipe.scene.placement import ModelBodies, PlacementRequest, place
from eden_pipe.scene.recipe import Recipe
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash
from eden_pipe.stages.model import load_lawn, load_model_keys, load_terrain, model_name

log = logging.getLogger("eden_pipe")
SINK_M = 0.02  # bury bases slightly so nothing floats over relief


def yaw_scale_matrix(position, yaw: float, scale: float) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    m = np.eye(4)
    m[:3, :3] = scale * np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    m[:3, 3] = position
    return m


def run_scene_stage(garden_cfg, camera_cfg, model_art: Artifact, cache: StageCache) -> Artifact:
    """(garden config, CameraConfig or DictConfig slice, model artifact) -> scene artifact.
    The garden's content comes from the model artifact (its key covers the garden config)."""
    clip = float(camera_cfg.height_m) + 0.4  # what the rig could touch
    key = config_hash(model_art.key, clip, code_fingerprint(__name__))

    def builder(folder: Path) -> dict:
        return build_scene(folder, model_art, cache, clip)

    return cache.build("scene", key, builder)


def build_scene(folder: Path, model_art: Artifact, cache: StageCache, clip: float) -> dict:
    recipe = Recipe.load(model_art.path)
    model_keys = load_model_keys(model_art)
    seed = recipe.seed
    terrain = load_terrain(model_art, recipe)
    size = terrain.size_m
    ground = terrain.mesh()
    lawn = load_lawn(model_art)
    meshes: dict[str, Mesh] = {}

    def model(name: str) -> Mesh:
        if name not in meshes:
            meshes[name] = Mesh.load(cache.path("model", model_keys[name]) / "mesh.npz")
        return meshes[name]

    instances: list[SceneInstance] = []
    parts: list[Mesh] = [ground, lawn]
    part_ids: list[np.ndarray] = [np.zeros(ground.n_faces, np.uint16), np.zeros(lawn.n_faces, np.uint16)]
    reach: list[tuple[int, np.ndarray]] = []  # (instance id, world points) per rig-proxy piece
    bases: list[np.ndarray] = []  # world points of each instance's base body
    # Every instance of the recipe, family by family in table order: the order of the instance ids.
    drawn = [(fam, i, inst) for fam in registry.FAMILIES for i, inst in enumerate(recipe.pools[fam.pool].instances)]
    requested = {
        fam.pool: len(recipe.pools[fam.pool].instances) for fam in registry.FAMILIES if fam.placement.may_leave_out
    }
    placed = dict.fromkeys(requested, 0)
    unplaced: list[dict] = []

    # Bodies are built once per model, for the smallest scale it is placed at (the rig's reach is a
    # fixed height in the world, so the smallest instance reaches furthest up its model): conservative
    # for the larger instances, and no garden builds them twice.
    smallest_scale: dict[str, float] = {}
    for fam, _, inst in drawn:
        name = model_name(fam.pool, inst.type, inst.model_seed)
        smallest_scale[name] = min(smallest_scale.get(name, np.inf), inst.scale)
    bodies: dict[str, ModelBodies] = {}

    def bodies_of(pool: str, name: str) -> ModelBodies:
        if name not in bodies:
            bodies[name] = ModelBodies.of(pool, model(name), clip / smallest_scale.get(name, 1.0))
        return bodies[name]

    def add_instance(pool, name, type_name, model_seed, transform, cls_name):
        world_mesh = model(name).transformed(transform)
        inst_id = len(instances) + 1
        lo, hi = world_mesh.bounds()
        instances.append(
            SceneInstance(
                inst_id,
                cls_name,
                int(labels.BY_NAME[cls_name]),
                pool,
                type_name,
                model_seed,
                model_keys[name],
                np.round(transform, 9).tolist(),
                lo.tolist(),
                hi.tolist(),
                world_mesh.n_faces,
            )
        )
        parts.append(world_mesh)
        part_ids.append(np.full(world_mesh.n_faces, inst_id, np.uint16))
        body = bodies_of(pool, name)
        reach.extend((inst_id, piece @ transform[:3, :3].T + transform[:3, 3]) for piece in body.pieces)
        bases.append(body.base @ transform[:3, :3].T + transform[:3, 3])

    with PhysicsWorld() as world:
        n_cells = terrain.heights.shape[0] - 1
        world.add_terrain(ground.vertices[: terrain.heights.size], ground.faces[: 2 * n_cells * n_cells])
        requests = []
        for key, (fam, i, inst) in enumerate(drawn):
            body = bodies_of(fam.pool, model_name(fam.pool, inst.type, inst.model_seed))
            requests.append(
                PlacementRequest(
                    key,
                    body.base * inst.scale,
                    body.reach_radius * inst.scale,
                    fam.spacing_m,
                    fam.placement_rng(seed, i),
                    fam.placement,
                )
            )
        spots, missing = place(world, requests, size, recipe.placement_attempts, SINK_M)

    # Instances are numbered in recipe order (family by family), whatever order they were placed in; the
    # runs of an edge-placed instance keep their edge order (the sort is stable).
    for spot in sorted(spots, key=lambda p: p.key):
        fam, i, inst = drawn[spot.key]
        name = model_name(fam.pool, inst.type, inst.model_seed)
        add_instance(
            fam.pool,
            name,
            inst.type,
            inst.model_seed,
            yaw_scale_matrix(spot.position, spot.yaw, inst.scale),
            fam.instance_class(model(name)),
        )
        if fam.pool in placed:
            placed[fam.pool] += 1
    for miss in sorted(missing, key=lambda m: m.key):
        fam, i, inst = drawn[miss.key]
        log.warning(
            "garden %s: %s #%d (%s, model seed %d) not placed: %s",
            recipe.garden_id,
            fam.pool,
            i,
            inst.type,
            inst.model_seed,
            miss.reason,
        )
        unplaced.append(
            {"pool": fam.pool, "index": i, "type": inst.type, "model_seed": inst.model_seed, "reason": miss.reason}
        )

    world_mesh = Mesh.concatenate(parts)
    instance = np.concatenate(part_ids) if part_ids else np.zeros(0, np.uint16)
    # numpy's stub types allow_pickle beside **kwds: mypy cannot rule that key out of **arrays.
    np.savez(folder / "geometry.npz", instance=instance, **world_mesh.to_npz_dict())  # type: ignore[arg-type]
    geometry_bytes = save_published_geometry(folder, recipe.garden_id, world_mesh, instance)
    save_proxies(folder, reach, bases, [i.id for i in instances])
    recipe_json = recipe.to_dict()
    scene = SceneDescription(
        recipe.garden_id,
        seed,
        size,
        terrain.patch_types,
        recipe_json["lawn"],
        requested,
        placed,
        instances,
        world_mesh.n_faces,
        unplaced,
    )
    scene.save(folder)
    return {
        "faces": world_mesh.n_faces,
        "instances": len(instances),
        "placed": placed,
        "requested": requested,
        "unplaced": len(unplaced),
        "geometry_bytes": geometry_bytes,
    }


def save_published_geometry(folder: Path, garden: str, mesh: Mesh, instance: np.ndarray) -> int:
    """``geometry.ply`` (metadata.GEOMETRY_FILE): the world mesh with every per-face value the renderer
    reads, its header naming the class and material ids; returns its size in bytes."""
    comments = (
        f"eden-pipe scene mesh of garden {garden}: world frame (right-handed, Z up), metres",
        "instance: id in the instance PNGs and scene.json (0 = terrain, lawn, no instance)",
        "class: " + " ".join(f"{i}={name}" for i, name in enumerate(labels.NAMES)),
        "material: " + " ".join(f"{i}={name}" for name, i in sorted(MATERIALS.items(), key=lambda kv: kv[1])),
        "albedo_r/g/b: linear diffuse colour; translucency: transmitted fraction; specular: glossy reflectance",
    )
    arrays = {
        "vertices": mesh.vertices,
        "faces": mesh.faces,
        "instance": instance,
        "class": mesh.semantic,
        "material": mesh.material,
        "albedo": mesh.albedo,
        "translucency": mesh.translucency,
        "specular": mesh.specular,
    }
    return write_mesh_ply(folder / metadata.GEOMETRY_FILE, arrays, comments)


def save_proxies(folder: Path, reach: list[tuple[int, np.ndarray]], bases: list[np.ndarray], ids: list[int]) -> None:
    """``proxies.npz``: the rig's obstacles (``points``/``offsets``/``ids``, one convex piece per row of
    ``offsets``) and each instance's base body (``base_points``/``base_offsets``, one per id in ``base_ids``)."""

    def packed(chunks):
        offsets = np.cumsum([0] + [len(c) for c in chunks])
        return (np.concatenate(chunks) if chunks else np.zeros((0, 3))), offsets

    points, offsets = packed([p for _, p in reach])
    base, base_offsets = packed(bases)
    np.savez(
        folder / "proxies.npz",
        points=points,
        offsets=offsets,
        ids=np.array([i for i, _ in reach], np.int64),
        base_points=base,
        base_offsets=base_offsets,
        base_ids=np.array(ids, np.int64),
    )


def load_scene(scene_art: Artifact):
    """(SceneDescription, SceneArrays) for the renderers; ``read_scene`` alone for the description."""
    from eden_pipe.scene.arrays import SceneArrays

    scene = SceneDescription.load(scene_art.path)
    with np.load(scene_art.path / "geometry.npz") as data:
        mesh = Mesh.from_npz_dict(data)
        instance = data["instance"].astype(np.uint16)
    return scene, SceneArrays(mesh, instance)
