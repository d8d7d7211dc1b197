"""Each pixel's own visible sky (``render.pixel_sky_rays``, :mod:`eden_pipe.render.pixel_sky`).

The kernels against their definitions (cosine-weighted, stratified directions; the pooled ratio
against a brute-force sum), and the whole path on a floor beside a black roof under a unit sky,
where the shading of every floor point is exactly the sky the roof leaves it (a view factor in
closed form): the pixels' own rays follow it inside the bake's probe cells, the bake cannot. A
stereo pair's right camera takes the left's factors where it sees the same face side.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.camera.rig import Intrinsics
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.render import pixel_sky
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.shading import shade
from eden_pipe.render.view import PIXEL_SKY, render_view
from eden_pipe.render.visibility.bake import bake
from eden_pipe.scene.arrays import SceneArrays
from tests.sky_scenes import ROOF_HALF, ROOF_HEIGHT, UniformSky, grid, parallel_rectangle_factor, uniform_settings


def test_directions_are_cosine_weighted_and_stratified_over_pixel_blocks():
    """Every direction is a unit vector on the normal's side; a pixel's ``k`` rays and a 4 x 4
    block's pixels fall in distinct strata of (1 - cos^2, phi / 2 pi); over many, cos has the
    cosine-weighted mean 2/3."""
    rng = np.random.default_rng(3)
    width, k = 8, 4
    normal = np.array([0.3, -0.5, 0.8])
    normal /= np.linalg.norm(normal)
    pixels = np.arange(64, dtype=np.int64)  # an 8 x 8 image: four 4 x 4 blocks
    normals = np.tile(normal, (64, 1))
    dirs = pixel_sky._cosine_directions(normals, pixels, width, k, rng.random((64, k, 2)), np.empty((64 * k, 3)))
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    cos = dirs @ normal
    assert np.all(cos > 0)
    # Back to the unit square: u1 = 1 - cos^2, u2 = phi / 2 pi in the same frame the kernel builds.
    sign = 1.0 if normal[2] >= 0 else -1.0
    a = -1.0 / (sign + normal[2])
    b = normal[0] * normal[1] * a
    tangent = np.array([1.0 + sign * normal[0] ** 2 * a, sign * b, -sign * normal[0]])
    bitangent = np.array([b, sign + normal[1] ** 2 * a, -normal[1]])
    u1 = 1.0 - cos**2
    u2 = np.mod(np.arctan2(dirs @ bitangent, dirs @ tangent) / (2 * np.pi), 1.0)
    stratum = (np.floor(u1 * 4).clip(0, 3) + 4 * np.floor(u2 * 4).clip(0, 3)).astype(int).reshape(8, 8, k)
    for y in range(8):
        for x in range(8):
            assert len(set(stratum[y, x])) == k  # a pixel's rays: distinct strata
    for by in (0, 4):
        for bx in (0, 4):
            block = stratum[by : by + 4, bx : bx + 4, 0].ravel()
            assert len(set(block)) == 16  # a block's first rays: every stratum once
    many = pixel_sky._cosine_directions(
        np.tile(normal, (4096, 1)), np.arange(4096, dtype=np.int64), 64, 4, rng.random((4096, 4, 2)),
        np.empty((4096 * 4, 3)),
    )  # fmt: skip
    assert abs((many @ normal).mean() - 2.0 / 3.0) < 0.01


def test_pooled_ratio_sums_the_same_face_within_the_radius():
    """Against a brute-force sum: each estimated pixel pools the escaping and bake fractions of the
    pixels within the radius that see its face, the bake counted ``prior`` times for itself."""
    rng = np.random.default_rng(5)
    height, width, radius, prior = 12, 15, 2, 1.5
    pixels = np.sort(rng.choice(height * width, size=120, replace=False)).astype(np.int64)
    faces = rng.integers(0, 3, size=120).astype(np.int64)
    seen, bake_frac = rng.random(120), rng.random(120) * 0.5
    slot = np.full(height * width, -1, np.int64)
    slot[pixels] = np.arange(120)
    got = pixel_sky._pooled_ratio(slot, width, height, pixels, seen, bake_frac, faces, radius, prior, np.empty(120))
    y, x = np.divmod(pixels, width)
    for i in range(120):
        near = (np.abs(y - y[i]) <= radius) & (np.abs(x - x[i]) <= radius) & (faces == faces[i])
        want = (seen[near].sum() + prior * bake_frac[i]) / (bake_frac[near].sum() + prior * bake_frac[i])
        assert got[i] == pytest.approx(want, rel=1e-12)
    none = pixel_sky._pooled_ratio(
        slot, width, height, pixels, seen, np.zeros(120), faces, radius, prior, np.empty(120)
    )
    assert np.all(none == 1.0)  # no bake fraction to divide by: the exposure is kept


def roof_edge_mesh() -> Mesh:
    """A floor of 2.5 cm faces (lit through probes) under the edge of a black roof."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 160, albedo=0.5)
    floor.material[:] = MATERIALS["generic"]  # no terrain texture bumps the normals
    roof = grid(-ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT, 4, albedo=0.0, flip=True)
    return Mesh.concatenate([floor, roof])


def roof_edge_pair(mesh: Mesh) -> tuple[SceneArrays, Intrinsics, list[np.ndarray]]:
    """(scene, intrinsics, the two cameras' poses) of a stereo pair looking down on the roof's
    edge from under it, 3 cm apart along the image's rows."""
    scene = SceneArrays(mesh=mesh, instance=np.zeros(mesh.n_faces, np.uint16))
    intr = Intrinsics(48, 48, 34.0, 34.0, 23.5, 23.5)
    looking_down = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    poses = []
    for x in (0.5, 0.53):
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = looking_down, [x, 0.0, 0.35]
        poses.append(pose)
    return scene, intr, poses


def roof_edge_bake(mesh: Mesh, tracer: RayTracer, **priors):
    return bake(
        mesh, tracer, np.random.default_rng(0), directions=64, spacing_m=0.02, rays=16, cell_m=0.1,
        cell_height_m=0.03, ground_rays=0, **priors,
    )  # fmt: skip


ROOF_EDGE_SIDE = 48  # pixels across the floor view of roof_edge_view


def roof_edge_view() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(origins, directions, floor targets) float32, float32, float64 (N, 3) of the rays of a
    ROOF_EDGE_SIDE x ROOF_EDGE_SIDE image of the floor across the roof's edge (x 0.25-0.75, the edge
    at 0.5; y -0.25-0.25), row-major with rows along y, from a camera under the roof."""
    u = np.linspace(0.25, 0.75, ROOF_EDGE_SIDE)
    v = np.linspace(-0.25, 0.25, ROOF_EDGE_SIDE)
    X, Y = np.meshgrid(u, v)
    targets = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    camera = np.array([0.5, 0.0, 0.35])
    o = np.tile(camera, (len(targets), 1)).astype(np.float32)
    return o, (targets - camera).astype(np.float32), targets


def roof_edge_shading(pixel_sky_rays: int, seed: int = 0, **priors):
    """Shading and the exact answer (1 - the roof's view factor) of a 48 x 48 image of the floor
    across the roof's edge, seen from a camera under the roof, with its own-sky rays a pixel."""
    mesh = roof_edge_mesh()
    side = ROOF_EDGE_SIDE
    o, d, targets = roof_edge_view()
    sky = UniformSky()
    with RayTracer(mesh, 1) as tracer:
        vis = roof_edge_bake(mesh, tracer, **priors)
        hits = tracer.intersect(o, d)
        assert np.all(hits.hit)
        out = shade(
            tracer, mesh, hits, o, d, sky, uniform_settings(sky_visibility=vis, pixel_sky_rays=pixel_sky_rays),
            np.random.default_rng(seed), layers=("shading",), image_width=side,
        )  # fmt: skip
    return out["shading"][:, 1], 1.0 - parallel_rectangle_factor(
        (targets[:, 0], targets[:, 1]), -ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT
    )


@pytest.mark.parametrize(
    "priors,gain",
    [({}, 0.8), ({"part_prior_hits": 0.0, "prior_hits": 4.0}, 0.5)],
    ids=["parts", "sides"],
)
def test_own_sky_rays_follow_the_exact_sky_where_the_bake_holds_a_probe_mean(priors, gain):
    """Across the roof's edge the floor's sky changes within each 10 cm probe cell. The bake's
    shading is off by its cells' spread (the floor is one part: pooled over it, each face holds
    about its cell's mean) and, where each face side keeps its own few bundle rays
    (``part_prior_hits=0``), by their noise too; with 16 rays a pixel the mean error is under 0.035
    either way, under 0.8 (0.5) of the bake's, with no bias beyond the rays' noise, and a seed
    changes only that noise."""
    baked, exact = roof_edge_shading(0, **priors)
    own, _ = roof_edge_shading(16, **priors)
    again, _ = roof_edge_shading(16, seed=1, **priors)
    bake_error = np.abs(baked - exact).mean()
    own_error = np.abs(own - exact).mean()
    assert bake_error > 0.03, bake_error  # the probe cells are visibly too coarse here
    assert own_error < min(gain * bake_error, 0.035), (own_error, bake_error)
    assert abs(own.mean() / exact.mean() - 1) < 0.02
    assert not np.array_equal(own, again) and np.abs(own - again).mean() < own_error * 2


def test_share_lookup_takes_the_factor_of_the_pixel_a_point_projects_to():
    """A point a pixel sees, moved within the pixel's footprint, finds that pixel's factor where it
    lies on the same face side; another side, a pixel without a factor, a point behind the camera or
    outside the image finds none."""
    intr = Intrinsics(16, 12, 20.0, 22.0, 7.5, 5.5)
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # camera z along world y
    pose[:3, 3] = [1.0, -2.0, 0.5]
    pixels = np.arange(0, 192, 2)  # every other pixel has a factor
    sides = 7 * pixels + 1
    factor = np.linspace(0.5, 2.0, len(pixels)).astype(np.float32)
    share = pixel_sky.SkyShare.of(pose, intr, pixels, sides, factor)
    rng = np.random.default_rng(0)
    every = np.arange(192)
    u = every % 16 + rng.uniform(-0.45, 0.45, 192)
    v = every // 16 + rng.uniform(-0.45, 0.45, 192)
    z = rng.uniform(0.5, 5.0, 192)
    cam = np.stack([(u - intr.cx) / intr.fx * z, (v - intr.cy) / intr.fy * z, z], axis=1)
    points = cam @ pose[:3, :3].T + pose[:3, 3]
    got = share.lookup(points, 7 * every + 1)
    assert np.array_equal(got[pixels], factor)
    assert np.all(np.isnan(got[every % 2 == 1]))  # no factor there
    assert np.all(np.isnan(share.lookup(points[pixels], sides + 2)))  # another face side
    behind = pose[:3, 3] - (points[pixels] - pose[:3, 3])
    assert np.all(np.isnan(share.lookup(behind, sides)))
    outside = cam[:1] + np.array([[10.0, 0.0, 0.0]])
    assert np.isnan(share.lookup(outside @ pose[:3, :3].T + pose[:3, 3], sides[:1]))[0]


def test_right_camera_takes_the_left_factors_where_it_sees_the_same_face(monkeypatch):
    """A stereo pair over the roof's edge, 16 rays a pixel. The right view renders the same with
    or without the left's factors but for: where its point projects to a left pixel of the same
    face side, its factor is the left's, exactly, and it traces rays only for the other pixels; its
    shading's error against the exact sky stays under 0.03 and 0.8 of the bake's, like the left's
    own."""
    mesh = roof_edge_mesh()
    scene, intr, poses = roof_edge_pair(mesh)
    traced: list[int] = []  # the pixels each call traces rays for
    scale = pixel_sky.pixel_exposure_scale

    def counted(tracer, pixels, *args, **kwargs):
        traced.append(len(pixels))
        return scale(tracer, pixels, *args, **kwargs)

    monkeypatch.setattr(pixel_sky, "pixel_exposure_scale", counted)
    sky = UniformSky()
    with RayTracer(mesh, 1) as tracer:
        vis = roof_edge_bake(mesh, tracer)

        def view(pose, seed, partner=None, rays=16):
            settings = uniform_settings(sky_visibility=vis, pixel_sky_rays=rays)
            rng = np.random.default_rng(seed)
            want = {"rgb", "shading", "depth"}
            return render_view(tracer, scene, intr, pose, sky, want=want, settings=settings, rng=rng, partner=partner)

        left = view(poses[0], 0)
        alone = view(poses[1], 1)
        paired = view(poses[1], 1, partner=left)
        baked = view(poses[1], 1, rays=0)
    share, right = left[PIXEL_SKY], paired[PIXEL_SKY]
    assert traced[0] == traced[1] == intr.width * intr.height  # the left and the lone right trace every pixel
    estimated = np.flatnonzero(right.side >= 0)
    assert np.array_equal(estimated, np.flatnonzero(alone[PIXEL_SKY].side >= 0))
    # The right view's hit points, from its depth (z along the camera's axis).
    u, v = estimated % intr.width, estimated // intr.width
    z = paired["depth"].ravel()[estimated].astype(np.float64)
    cam = np.stack([(u - intr.cx) / intr.fx * z, (v - intr.cy) / intr.fy * z, z], axis=1)
    expected = share.lookup(cam @ poses[1][:3, :3].T + poses[1][:3, 3], right.side[estimated])
    taken = np.isfinite(expected)
    assert taken.mean() > 0.8, taken.mean()
    assert np.mean(right.factor[estimated][taken] == expected[taken]) > 0.99
    assert traced[2] == len(estimated) - int(np.count_nonzero(right.factor[estimated] == expected))
    # Against the exact sky at the right view's floor points.
    points = cam @ poses[1][:3, :3].T + poses[1][:3, 3]
    exact = 1.0 - parallel_rectangle_factor(
        (points[:, 0], points[:, 1]), -ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT
    )
    errors = {
        name: np.abs(out["shading"][..., 1].ravel()[estimated] - exact).mean()
        for name, out in (("paired", paired), ("alone", alone), ("baked", baked))
    }
    assert errors["paired"] < min(0.8 * errors["baked"], 0.03), errors
    assert errors["alone"] < min(0.8 * errors["baked"], 0.03), errors
