"""Terrain: labels of every type as rendered, determinism, exact heights, types per garden, zones."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from omegaconf import OmegaConf

from eden_pipe import labels
from eden_pipe.camera.rig import Intrinsics, look_rotation
from eden_pipe.models.noise import _GRADIENTS, Perlin
from eden_pipe.models.terrain import TERRAIN_TYPES, build_terrain
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.gallery import StudioLight
from eden_pipe.render.view import SceneArrays, primary_rays, render_view

REPO = Path(__file__).resolve().parents[1]
DEFAULT = OmegaConf.to_container(OmegaConf.load(REPO / "conf" / "garden" / "default.yaml"))
EXPECTED_LABEL = {
    "grass": labels.GRASS,
    "pebbles": labels.GROUND,
    "gravel": labels.GROUND,
    "dirt": labels.GROUND,
    "pavement": labels.PAVEMENT,
}


def default_terrain(seed: int, **changes):
    t = {**DEFAULT["terrain"], **changes}
    return build_terrain(
        seed,
        DEFAULT["size_m"],
        t["cells_per_m"],
        t["relief_m"],
        t["relief_scale_m"],
        t["patch_types"],
        t["patch_weights"],
        tuple(t["types_per_garden"]),
    )


def one_type_terrain(type_name: str, seed: int = 0, size_m: float = 4.0):
    return build_terrain(seed, size_m, 8, 0.12, 2.0, [type_name], [1.0], (1, 1))


def components(mask: np.ndarray) -> int:
    """Number of 4-connected components of a boolean grid."""
    seen = np.zeros_like(mask, bool)
    count = 0
    for start in zip(*np.nonzero(mask), strict=True):
        if seen[start]:
            continue
        count += 1
        stack = [start]
        seen[start] = True
        while stack:
            y, x = stack.pop()
            for ny, nx in ((y + 1, x), (y - 1, x), (y, x + 1), (y, x - 1)):
                if 0 <= ny < mask.shape[0] and 0 <= nx < mask.shape[1] and mask[ny, nx] and not seen[ny, nx]:
                    seen[ny, nx] = True
                    stack.append((ny, nx))
    return count


def test_expected_labels_cover_every_type():
    assert set(EXPECTED_LABEL) == set(TERRAIN_TYPES)
    assert {TERRAIN_TYPES[t][0] for t in TERRAIN_TYPES} == {labels.GRASS, labels.GROUND, labels.PAVEMENT}


@pytest.mark.parametrize("type_name", sorted(TERRAIN_TYPES))
def test_each_terrain_type_renders_with_its_label(type_name):
    """A camera high above a one-type garden, looking down: garden pixels carry the type's label, the skirt 9."""
    terrain = one_type_terrain(type_name)
    assert terrain.patch_types == [type_name]
    mesh = terrain.mesh()
    s = terrain.size_m
    intr = Intrinsics(80, 60, 60.0, 60.0, 40.0, 30.0)  # wide: the view spans the garden and its surroundings
    pose = np.eye(4)
    pose[:3, :3] = look_rotation(0.3, np.deg2rad(-80.0))
    pose[:3, 3] = (s / 2, s / 2 - 0.8, 5.0)
    with RayTracer(mesh, threads=1) as tracer:
        out = render_view(
            tracer,
            SceneArrays(mesh, np.zeros(mesh.n_faces, np.uint16)),
            intr,
            pose,
            StudioLight(),
            want={"semantic", "instance", "rgb"},
        )
        origins, dirs = primary_rays(intr, pose)
    sem = out["semantic"].ravel()
    depth = out["depth"].ravel()
    assert np.all(np.isfinite(depth)), "looking down, every pixel hits the ground or the skirt"
    points = origins + dirs * depth[:, None]
    x, y = points[:, 0], points[:, 1]
    margin = 0.05
    inside = (x > margin) & (x < s - margin) & (y > margin) & (y < s - margin)
    outside = (x < -margin) | (x > s + margin) | (y < -margin) | (y > s + margin)
    assert inside.sum() > 500 and outside.sum() > 500, "the view must show both the garden and the skirt"
    assert np.all(sem[inside] == EXPECTED_LABEL[type_name])
    assert np.all(sem[outside] == labels.BACKGROUND)
    assert not np.any(sem == labels.VOID)
    assert np.all(out["instance"] == 0)  # terrain and skirt belong to no instance
    rgb = out["rgb_linear"].reshape(-1, 3)
    assert np.all(np.isfinite(rgb)) and rgb[inside].mean() > 0.01  # lit and textured, not black


def test_terrain_is_deterministic_per_seed():
    a, b, c = default_terrain(3), default_terrain(3), default_terrain(4)
    assert a.patch_types == b.patch_types
    for name in ("heights", "patch_grid", "patch_tint"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert np.array_equal(a.mesh().vertices, b.mesh().vertices)
    assert not np.allclose(a.heights, c.heights)
    assert a.patch_types != c.patch_types or not np.array_equal(a.patch_grid, c.patch_grid)


def test_height_at_matches_ray_hits_on_the_mesh():
    terrain = default_terrain(5)
    mesh = terrain.mesh()
    rng = np.random.default_rng(0)
    n = 4000
    xy = rng.uniform(0.0, terrain.size_m, size=(n, 2))
    xy[:200] = rng.integers(0, 81, size=(200, 2)) / 8.0 + rng.uniform(-1e-3, 1e-3, size=(200, 2))  # near vertices
    xy[200:400, 1] = xy[200:400, 0] + rng.uniform(-1e-3, 1e-3, 200)  # near the cell diagonals
    xy = np.clip(xy, 1e-4, terrain.size_m - 1e-4)
    top = float(terrain.heights.max()) + 5.0
    origins = np.c_[xy, np.full(n, top)]
    dirs = np.broadcast_to([0.0, 0.0, -1.0], (n, 3))
    with RayTracer(mesh, threads=1) as tracer:
        hits = tracer.intersect(origins, dirs)
    assert np.all(hits.hit)
    assert np.all(mesh.semantic[hits.prim] != labels.BACKGROUND)  # the garden surface, not the skirt below it
    z_ray = top - hits.t.astype(np.float64)
    z_fn = terrain.height_at(xy[:, 0], xy[:, 1])
    assert np.abs(z_ray - z_fn).max() < 2e-5  # float32 ray parameter
    assert np.ptp(terrain.heights) > 0.05  # real relief, not a flat plane


def test_two_to_four_types_per_garden_from_the_pool():
    pool = DEFAULT["terrain"]["patch_types"]
    counts = set()
    for seed in range(30):
        terrain = default_terrain(seed)
        types = terrain.patch_types
        counts.add(len(types))
        assert 2 <= len(types) <= 4, (seed, types)
        assert set(types) <= set(pool) and len(set(types)) == len(types)
        assert types == [t for t in pool if t in types]  # pool order: grass first when present
        present = np.unique(terrain.patch_grid)
        assert present.tolist() == list(range(len(types))), (seed, types, present)  # every chosen type is used
        # Labels of the mesh faces follow the patches.
        mesh_sem = set(np.unique(terrain.mesh().semantic).tolist())
        assert mesh_sem == {EXPECTED_LABEL[t] for t in types} | {labels.BACKGROUND}
    assert counts == {2, 3, 4}


def test_a_narrower_types_per_garden_is_respected():
    for seed in range(10):
        assert len(default_terrain(seed, types_per_garden=[3, 3]).patch_types) == 3
        assert default_terrain(
            seed, patch_types=["dirt"], patch_weights=[1.0], types_per_garden=[1, 1]
        ).patch_types == ["dirt"]


def test_zones_are_contiguous():
    """Each type's patches form few connected regions (beds, paths, lawns), not a checkerboard."""
    sizes = []
    for seed in range(30):
        terrain = default_terrain(seed)
        for code, name in enumerate(terrain.patch_types):
            mask = terrain.patch_grid == code
            n = components(mask)
            assert 1 <= n <= 4, (seed, name, n)
            sizes.append(mask.sum() / n)
    assert np.mean(sizes) >= 10.0  # patches per connected region, on average


def numpy_perlin(perm: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Improved Perlin noise written plainly in numpy (the oracle of the compiled lattice sum)."""
    p = np.asarray(points, np.float64)
    cell = np.floor(p)
    f = p - cell
    i = cell.astype(np.int64) & 255
    u = f * f * f * (f * (f * 6.0 - 15.0) + 10.0)
    result = np.zeros(p.shape[:-1])
    for dx in (0, 1):
        wx = u[..., 0] if dx else 1.0 - u[..., 0]
        a = perm[i[..., 0] + dx]
        for dy in (0, 1):
            wy = u[..., 1] if dy else 1.0 - u[..., 1]
            b = perm[a + i[..., 1] + dy]
            for dz in (0, 1):
                wz = u[..., 2] if dz else 1.0 - u[..., 2]
                g = _GRADIENTS[perm[b + i[..., 2] + dz] & 15]
                result = result + wx * wy * wz * np.sum(g * (f - np.array([dx, dy, dz], np.float64)), axis=-1)
    return result


@pytest.mark.parametrize("scale", [0.7, 13.0, 450.0])
def test_compiled_perlin_noise_is_the_numpy_sum_bit_for_bit(scale):
    rng = np.random.default_rng(int(scale * 10))
    perlin = Perlin(np.random.default_rng(4))
    points = rng.normal(size=(40, 500, 3)) * scale  # negative cells too; any leading shape
    points[0, :50] = np.round(points[0, :50])  # lattice points
    got = perlin.noise(points)
    assert got.shape == (40, 500) and got.tobytes() == numpy_perlin(perlin.perm, points).tobytes()
    assert np.all(got[0, :50] == 0.0)  # gradient noise vanishes on the lattice
    assert np.all(np.abs(got) <= 1.5)
    octaves = sum(0.5**o * numpy_perlin(perlin.perm, points * 2.0**o + 17.31 * o) for o in range(3)) / 1.75
    assert perlin.fbm(points, 3).tobytes() == octaves.tobytes()
