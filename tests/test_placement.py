"""Placement: bases that never overlap, canopies that may, rig-reach pieces, and the counts a garden honours."""

from __future__ import annotations

import logging

import numpy as np
import pybullet as pb
import pytest
import trimesh

from eden_pipe import labels, metadata
from eden_pipe.config import to_config
from eden_pipe.models.mesh import Mesh
from eden_pipe.rng import rng_for
from eden_pipe.scene.description import read_scene
from eden_pipe.scene.physics import PhysicsWorld
from eden_pipe.scene.placement import (
    TRUNK_HEIGHT_M,
    PlacementRequest,
    base_points,
    place,
    reach_pieces,
    scene_base_gap,
    smallest_gap,
    trunk_points,
)
from eden_pipe.stages.cache import StageCache
from eden_pipe.stages.model import run_model_stage
from eden_pipe.stages.scene import run_scene_stage
from tests.conftest import TINY, make_cfg
from tests.tiny_dataset import tiny_root

CLIP = 1.2  # rig height 0.8 m + 0.4 m, as the scene stage computes it


def _mesh(parts: list[tuple[trimesh.Trimesh, str]]) -> Mesh:
    return Mesh.concatenate(
        [
            Mesh.from_arrays(t.vertices, t.faces, semantic=labels.TREE, material=material, albedo=(0.3, 0.3, 0.3))
            for t, material in parts
        ]
    )


def fir() -> Mesh:
    """A trunk (radius 0.12 m) inside a solid crown whose lowest branches sweep 1.6 m out at 0.03 m."""
    trunk = trimesh.creation.cylinder(radius=0.12, height=3.0)
    trunk.apply_translation([0, 0, 1.5])
    crown = trimesh.creation.cone(radius=1.6, height=2.6)
    crown.apply_translation([0, 0, 0.03])
    return _mesh([(trunk, "bark"), (crown, "leaf")])


def drooping_tree() -> Mesh:
    """A trunk (radius 0.15 m) and one branch from 1.5 m up that comes down to rest on the ground 2 m out."""
    trunk = trimesh.creation.cylinder(radius=0.15, height=3.0)
    trunk.apply_translation([0, 0, 1.5])
    branch = trimesh.creation.cylinder(radius=0.04, segment=[[0.1, 0, 1.5], [2.0, 0, 0.04]])
    v, f = trimesh.remesh.subdivide_to_size(branch.vertices, branch.faces, max_edge=0.1)
    return _mesh([(trunk, "bark"), (trimesh.Trimesh(v, f), "bark")])


def flower_box() -> Mesh:
    box = trimesh.creation.box(extents=(0.3, 0.3, 0.4))
    box.apply_translation([0, 0, 0.2])
    return _mesh([(box, "stem")])


def place_on_flat_ground(requests, size: float):
    with PhysicsWorld() as world:
        world.add_terrain(
            np.array([[-1, -1, 0], [size + 1, -1, 0], [size + 1, size + 1, 0], [-1, size + 1, 0.0]]),
            np.array([[0, 1, 2], [0, 2, 3]]),
        )
        placed, unplaced = place(world, requests, size, attempts=60, sink_m=0.0)
    return placed, unplaced


def world_base(req: PlacementRequest, spot) -> np.ndarray:
    c, s = np.cos(spot.yaw), np.sin(spot.yaw)
    return req.base @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]).T + spot.position


def fir_garden(fir_base: np.ndarray, flowers: int, size: float = 4.0):
    requests = [PlacementRequest(0, fir_base, 1.6, 0.25, rng_for(0, "test", "fir"))]
    requests += [
        PlacementRequest(k, base_points("flowers", flower_box(), CLIP), 0.22, 0.1, rng_for(0, "test", k))
        for k in range(1, flowers + 1)
    ]
    placed, unplaced = place_on_flat_ground(requests, size)
    return requests, placed, unplaced


def test_a_fir_with_low_branches_no_longer_blocks_its_neighbourhood():
    requests, placed, unplaced = fir_garden(base_points("trees", fir(), CLIP), flowers=16)
    assert unplaced == [] and sorted(p.key for p in placed) == list(range(17))
    spots = {p.key: p for p in placed}
    bases = [world_base(requests[k], spots[k]) for k in range(17)]
    assert smallest_gap(bases) >= 0.1 - 1e-6  # no two bases closer than the flowers' spacing
    # Flowers grow under the fir's low branches: the crown is not part of its base.
    centre = np.array(spots[0].position[:2])
    under = [k for k in range(1, 17) if np.hypot(*(np.array(spots[k].position[:2]) - centre)) < 1.4]
    assert under
    # The whole-model proxy the scene stage used before (everything below the rig's reach) leaves most out.
    _, placed_before, unplaced_before = fir_garden(base_points("obstacles", fir(), CLIP), flowers=16)
    assert len(unplaced_before) >= 4 and len(placed_before) + len(unplaced_before) == 17
    assert all("no free spot" in u.reason for u in unplaced_before)


def test_trunk_base_leaves_out_branches_resting_on_the_ground():
    tree = drooping_tree()
    v, base = tree.vertices, trunk_points(tree)
    radius = np.hypot(base[:, 0], base[:, 1])
    assert 0.14 < radius.max() < 0.17  # the trunk (0.15 m), not the branch tip 2 m out
    assert base[:, 2].min() == pytest.approx(v[:, 2].min()) and base[:, 2].max() >= TRUNK_HEIGHT_M


def test_reach_pieces_cover_what_the_rig_could_touch_and_keep_the_gaps():
    tree = drooping_tree()
    v, pieces = tree.vertices, reach_pieces(tree.vertices, tree.faces, CLIP)
    with PhysicsWorld() as world:
        for piece in pieces:
            world.add_proxy(piece)
        probe = pb.createMultiBody(
            0,
            pb.createCollisionShape(pb.GEOM_SPHERE, radius=0.03, physicsClientId=world.client),
            physicsClientId=world.client,
        )

        def hit(x, y, z):
            world.move(probe, (x, y, z))
            return world.collides(probe, others=world.bodies)

        # Every part of the trunk and branch below the rig's reach is covered...
        low = v[v[:, 2] <= CLIP]
        assert all(hit(*p) for p in low[:: max(1, len(low) // 60)])
        assert hit(0.0, 0.0, 0.3) and hit(1.9, 0.0, 0.08)
        # ...but not the open space under the branch, which one hull of the low parts would fill.
        assert not hit(1.0, 0.0, 0.1) and not hit(1.0, 0.6, 0.5)
    # A single convex piece would not do: the pieces split the tree along the 0.5 m grid.
    assert len(pieces) >= 4


def test_placement_is_deterministic():
    a = fir_garden(base_points("trees", fir(), CLIP), flowers=8)[1]
    b = fir_garden(base_points("trees", fir(), CLIP), flowers=8)[1]
    assert [(p.key, p.position, p.yaw) for p in a] == [(p.key, p.position, p.yaw) for p in b]


# ------------------------------------------------------------------ through the scene stage
def build_scene(root, overrides):
    cfg = to_config(make_cfg(root, overrides))
    cache = StageCache(cfg.paths.stages)
    model = run_model_stage(cfg.garden, cache)
    return run_scene_stage(cfg.garden, cfg.camera, model, cache)


def test_small_garden_places_every_sampled_instance(tmp_path_factory):
    scene_art = build_scene(tiny_root(tmp_path_factory), TINY)  # the tiny dataset's garden: cached in a full run
    scene = read_scene(scene_art)
    assert scene.placed == scene.requested and scene.unplaced == [] and sum(scene.placed.values()) > 0
    assert scene_base_gap(scene_art.path) >= 0.1 - 1e-6


def test_what_cannot_be_placed_is_logged_and_recorded(tmp_path, caplog):
    # A 3 m garden cannot hold six 2.5 m privet hedges (and this one has no fence).
    overrides = [
        "garden=small",
        "garden.size_m=3",
        "garden.fences.probability=0",
        "garden.lawn.triangles_per_m2=500",
        "garden.bushes.count=[6,6]",
        "garden.bushes.types=[hedge_privet]",
        "garden.bushes.types_per_garden=[1,1]",
        *[f"garden.{pool}.count=[0,0]" for pool in ("trees", "flowers", "obstacles")],
    ]
    with caplog.at_level(logging.WARNING, logger="eden_pipe"):
        scene_art = build_scene(tmp_path, overrides)
    scene = read_scene(scene_art)
    assert scene.requested == {"trees": 0, "bushes": 6, "flowers": 0, "obstacles": 0}
    assert 1 <= scene.placed["bushes"] < 6 and len(scene.unplaced) == 6 - scene.placed["bushes"]
    assert all(
        u["pool"] == "bushes"
        and u["type"] == "hedge_privet"
        and "no free spot" in u["reason"]
        and isinstance(u["model_seed"], int)
        for u in scene.unplaced
    )
    warnings = [
        r.getMessage() for r in caplog.records if r.levelno == logging.WARNING and "not placed" in r.getMessage()
    ]
    assert len(warnings) == len(scene.unplaced)
    for u, line in zip(scene.unplaced, warnings, strict=True):
        assert (
            f"{u['pool']} #{u['index']} ({u['type']}, model seed {u['model_seed']}) not placed: {u['reason']}" in line
        )
    # No fence: no fence instance, and null in the published scene.json (metadata.scene_metadata).
    assert not [i for i in scene.instances if i.pool == "fence"]
    published = metadata.scene_metadata(scene.to_dict())
    assert published["unplaced"] == scene.unplaced and published["fence_style"] is None


@pytest.mark.slow
def test_default_garden_places_what_it_sampled(tmp_path):
    """garden=default seed 0 samples 16 trees, 15 bushes, 9 flowers and 6 obstacles (it used to place 5, 12, 9, 4)."""
    scene_art = build_scene(
        tmp_path, ["garden=default", "garden.seed=0", "garden.lawn.enabled=false", "progress=false"]
    )
    scene = read_scene(scene_art)
    assert scene.requested == {"trees": 16, "bushes": 15, "flowers": 9, "obstacles": 6}
    assert scene.placed == scene.requested and scene.unplaced == []
    assert scene_base_gap(scene_art.path) >= 0.1 - 1e-6
