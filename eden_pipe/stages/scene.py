"""Scene stage: place the recipe's instances without overlap on the terrain.

pybullet does the collision work (eden_pipe.scene.physics). Output, under
``stages/scene/<key>/``:

- ``scene.json``: garden id, seed, terrain and lawn facts, and every instance
  (id, class, pool, type, model seed, 4x4 transform, world bounding box) -
  written and read as :class:`~eden_pipe.scene.description.SceneDescription`;
- ``geometry.npz``: the flattened world mesh (Mesh arrays) plus ``instance``,
  the per-face instance id (0 = terrain, lawn, skirt) - the renderer-agnostic
  scene every backend consumes;
- ``proxies.npz``: the collision proxies in world coordinates, for the
  trajectory stage.

Inputs: the model artifact (its Recipe and models) and the typed
``CameraConfig`` (the rig height decides how much of each model is a
collision proxy). Per-pool placement facts (spacing, class) come from the
family table, ``eden_pipe.models.registry.FAMILIES``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from eden_pipe import labels
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.registry import FAMILIES, FENCE_SEMANTIC
from eden_pipe.scene.description import SceneDescription, SceneInstance
from eden_pipe.scene.physics import PhysicsWorld, proxy_points
from eden_pipe.scene.recipe import Recipe
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash
from eden_pipe.stages.model import load_lawn, load_model_keys, load_terrain, model_name

EDGE_MARGIN = 0.35
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
    proxies: list[np.ndarray] = []
    requested, placed = {}, {}

    with PhysicsWorld() as world:
        n_cells = terrain.heights.shape[0] - 1
        world.add_terrain(ground.vertices[: terrain.heights.size], ground.faces[: 2 * n_cells * n_cells])

        def add_instance(pool, name, type_name, model_seed, transform, body_points, cls_name):
            mesh = model(name).transformed(transform)
            inst_id = len(instances) + 1
            lo, hi = mesh.bounds()
            instances.append(SceneInstance(inst_id, cls_name, int(labels.BY_NAME[cls_name]), pool, type_name, model_seed,
                                           model_keys[name], np.round(transform, 9).tolist(), lo.tolist(), hi.tolist(),
                                           mesh.n_faces))
            parts.append(mesh)
            part_ids.append(np.full(mesh.n_faces, inst_id, np.uint16))
            proxies.append(body_points @ transform[:3, :3].T + transform[:3, 3])

        # Fences along the four edges, facing inward.
        if recipe.fence:
            f = recipe.fence
            name = model_name("fence", f.style, f.model_seed)
            fence = model(name)
            inset = 0.05
            edges = [((0.0, inset), 0.0), ((size - inset, 0.0), np.pi / 2), ((size, size - inset), np.pi), ((inset, size), 1.5 * np.pi)]
            for (x, y), yaw in edges:
                along = np.array([np.cos(yaw), np.sin(yaw)])
                xy = np.array([x, y]) + np.linspace(0, size, 21)[:, None] * along
                z = float(np.nanmin(world.ground_heights(xy))) - SINK_M
                transform = yaw_scale_matrix((x, y, z), yaw, 1.0)
                pts = proxy_points(fence.vertices, clip)
                world.add_proxy(pts, (x, y, z), yaw)
                add_instance("fence", name, f.style, f.model_seed, transform, pts, FENCE_SEMANTIC)

        for fam in FAMILIES:
            pool = fam.pool
            spec = recipe.pools[pool]
            requested[pool] = len(spec.instances)
            placed[pool] = 0
            for i, inst in enumerate(spec.instances):
                name = model_name(pool, inst.type, inst.model_seed)
                mesh = model(name)
                pts = proxy_points(mesh.vertices, clip / inst.scale) * inst.scale
                cls_name = fam.instance_class(mesh)
                rng = fam.placement_rng(seed, i)
                radius = float(np.max(np.linalg.norm(pts[:, :2], axis=1))) if len(pts) else 0.1
                lo_xy = EDGE_MARGIN + min(radius, size / 4)
                body = None
                for _attempt in range(recipe.placement_attempts):
                    x, y = rng.uniform(lo_xy, size - lo_xy, size=2)
                    yaw = float(rng.uniform(0, 2 * np.pi))
                    rot = yaw_scale_matrix((0, 0, 0), yaw, 1.0)[:3, :3]
                    foot = (pts @ rot.T)[:, :2] + [x, y]
                    z = float(np.nanmin(world.ground_heights(foot[:: max(1, len(foot) // 16)]))) - SINK_M
                    if body is None:
                        body = world.add_proxy(pts, (x, y, z), yaw)
                    else:
                        world.move(body, (x, y, z), yaw)
                    if not world.collides(body, margin=fam.spacing_m):
                        add_instance(pool, name, inst.type, inst.model_seed,
                                     yaw_scale_matrix((x, y, z), yaw, inst.scale), pts / inst.scale, cls_name)
                        placed[pool] += 1
                        body = None
                        break
                if body is not None:
                    world.remove(body)

    world_mesh = Mesh.concatenate(parts)
    instance = np.concatenate(part_ids) if part_ids else np.zeros(0, np.uint16)
    np.savez(folder / "geometry.npz", instance=instance, **world_mesh.to_npz_dict())
    offsets = np.cumsum([0] + [len(p) for p in proxies])
    np.savez(folder / "proxies.npz", points=np.concatenate(proxies) if proxies else np.zeros((0, 3)), offsets=offsets,
             ids=np.array([i.id for i in instances], np.int64))
    recipe_json = recipe.to_dict()
    scene = SceneDescription(recipe.garden_id, seed, size, terrain.patch_types, recipe_json["lawn"], recipe_json["fence"],
                             requested, placed, instances, world_mesh.n_faces)
    scene.save(folder)
    return {"faces": world_mesh.n_faces, "instances": len(instances), "placed": placed, "requested": requested}


def load_scene(scene_art: Artifact):
    """(SceneDescription, SceneArrays) for the renderers; ``read_scene`` alone for the description."""
    from eden_pipe.scene.arrays import SceneArrays

    scene = SceneDescription.load(scene_art.path)
    with np.load(scene_art.path / "geometry.npz") as data:
        mesh = Mesh.from_npz_dict(data)
        instance = data["instance"].astype(np.uint16)
    return scene, SceneArrays(mesh, instance)
