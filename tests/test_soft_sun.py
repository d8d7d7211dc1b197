"""Soft sun shadows from one ray a pixel (``render.soft_shadow_radius``; ``shading.direct_sun``).

The disc's strata and their spread over pixel blocks, the penumbra filter against a brute-force
loop, and the whole path against the exact penumbra of a straight edge: a black sheet 1 m over a
floor under a sun 6 degrees wide, whose visible share of the disc at each floor point is a circular
segment in closed form. The same sheet 2 mm over the floor casts a penumbra far under a pixel: the
filter then keeps each pixel's own ray, and the shadow stays as sharp as the hard one.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.render import pixel_sky
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.pixel_sky import PairSky, SkyShare
from eden_pipe.render.shading import ShadingSettings, direct_sun, primary_surface, sun_image
from eden_pipe.render.view import PIXEL_SUN, primary_rays, render_view
from eden_pipe.scene.arrays import SceneArrays
from tests.sky_scenes import UniformSky, grid, uniform_settings

RADIUS_RAD = np.radians(3.0)  # the sun's angular radius: a 6-degree disc, as a hazy sun's halo


class WideSun(UniformSky):
    sun_direction = np.array([0.0, 0.0, 1.0])
    sun_irradiance = np.full(3, 2.0)
    sun_angular_radius = RADIUS_RAD
    casts_cloud_shadows = False


def test_disc_directions_are_stratum_centres_of_equal_area_within_the_disc():
    axis = np.array([0.3, -0.2, 0.9])
    axis /= np.linalg.norm(axis)
    dirs = pixel_sky.sun_disc_directions(axis, 0.02)
    assert dirs.shape == (pixel_sky.SUN_BLOCK**2, 3)
    assert np.allclose(np.linalg.norm(dirs, axis=1), 1.0)
    # In the plane tangent at the axis, ring k's centres lie at tan(R) sqrt((k + 0.5) / SUN_BLOCK).
    offset = dirs / (dirs @ axis)[:, None] - axis
    radius = np.linalg.norm(offset, axis=1) / np.tan(0.02)
    ring = np.arange(len(dirs)) // pixel_sky.SUN_BLOCK
    assert np.allclose(radius, np.sqrt((ring + 0.5) / pixel_sky.SUN_BLOCK))
    assert np.linalg.norm(offset.mean(axis=0)) < 1e-3 * np.tan(0.02)  # centred on the axis


def test_every_block_of_pixels_traces_every_stratum_once():
    width = 12
    stratum = pixel_sky.sun_disc_stratum(np.arange(8 * width), width).reshape(8, width)
    block = pixel_sky.SUN_BLOCK
    for y in range(0, 8, block):
        for x in range(0, width, block):
            assert sorted(stratum[y : y + block, x : x + block].ravel()) == list(range(block * block))


def test_a_pixel_alone_on_its_face_side_traces_the_discs_centre():
    """A pixel whose window of ``radius`` holds no other pixel of its key (face side) has no
    neighbours to average its ray with: it traces the disc's centre (index SUN_BLOCK**2), the
    rest their strata, as a loop over each window finds."""
    rng = np.random.default_rng(5)
    height, width, radius = 12, 15, 2
    pixels = np.sort(rng.choice(height * width, size=90, replace=False)).astype(np.int64)
    keys = rng.integers(0, 12, size=len(pixels)).astype(np.int64)
    got = pixel_sky.sun_disc_rays(pixels, (height, width), keys, radius)
    y, x = np.divmod(pixels, width)
    stratum = pixel_sky.sun_disc_stratum(pixels, width)
    centre = pixel_sky.SUN_BLOCK**2
    for i in range(len(pixels)):
        window = (np.abs(y - y[i]) <= radius) & (np.abs(x - x[i]) <= radius) & (keys == keys[i])
        assert got[i] == (centre if window.sum() == 1 else stratum[i])
    assert 0 < np.count_nonzero(got == centre) < len(pixels)  # the draw holds both cases


def test_penumbra_mean_against_a_loop():
    """Each pixel: its window's blocked rays' mean distance times ``spread`` over its footprint is
    its reach (rounded, capped at the radius); the mean of ``seen`` over its key's pixels within
    the reach; its own ray where its window's rays all agree; NaN (the disc's centre decides, in
    the render) where they do not and the reach is 0."""
    rng = np.random.default_rng(2)
    height, width, radius, spread = 14, 17, 3, 0.05
    n = 200
    pixels = np.sort(rng.choice(height * width, size=n, replace=False)).astype(np.int64)
    keys = rng.integers(0, 3, size=n).astype(np.int64)
    seen = rng.random(n) < 0.6
    shade = pixels < 4 * width  # the top four rows: a face of their own, in its shadow throughout
    keys[shade], seen[shade] = 3, False
    blocker = np.where(seen, np.inf, rng.random(n) * 2.0)
    footprint = 0.01 + rng.random(n) * 0.05
    penumbrae = pixel_sky.Penumbrae.of(pixels, (height, width), keys, seen, radius)
    got = penumbrae.fraction(blocker, footprint, spread)
    y, x = np.divmod(pixels, width)
    reaches = set()
    for i in range(n):
        window = (np.abs(y - y[i]) <= radius) & (np.abs(x - x[i]) <= radius) & (keys == keys[i])
        far = window & ~seen
        reach = min(radius, int(blocker[far].mean() * spread / footprint[i] + 0.5)) if far.any() else 0
        near = (np.abs(y - y[i]) <= reach) & (np.abs(x - x[i]) <= reach) & (keys == keys[i])
        mixed = seen[window].any() and not seen[window].all()
        if mixed and reach == 0:
            assert np.isnan(got[i])
        else:
            assert got[i] == pytest.approx(seen[near].mean(), abs=1e-6)
            reaches.add(reach if mixed else -1)
    assert reaches >= {-1, 1, 2, 3} and np.isnan(got).any()  # the draw exercises every case
    # Only the blocked rays of windows holding both answers have their distances read: any other
    # distance may be anything (the render traces closest hits for those rays only).
    assert 0 < len(penumbrae.far) < np.count_nonzero(~seen) and not seen[penumbrae.far].any()
    assert not np.isin(np.flatnonzero(shade), penumbrae.far).any() and np.all(got[shade] == 0.0)
    unread = np.full(n, np.nan)
    unread[penumbrae.far] = blocker[penumbrae.far]
    assert np.array_equal(penumbrae.fraction(unread, footprint, spread), got, equal_nan=True)


def visible_share(x: np.ndarray, height: float) -> np.ndarray:
    """The share of a uniform disc of angular radius RADIUS_RAD seen from a floor point ``x`` (m)
    beside the edge of a sheet covering x < 0 at ``height``: a circular segment."""
    s = np.clip(-x / (height * np.tan(RADIUS_RAD)), -1.0, 1.0)  # the edge's chord across the disc
    blocked = 0.5 + (s * np.sqrt(1.0 - s * s) + np.arcsin(s)) / np.pi
    return 1.0 - blocked


def sheet_over_floor(height: float) -> Mesh:
    """A floor of two faces (windows are not cut by edges) under a black sheet ``height`` over it,
    covering x < 0."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 1, albedo=0.5)
    floor.material[:] = MATERIALS["generic"]
    sheet = grid(-3.0, 0.0, -3.0, 3.0, height, 2, albedo=0.0, flip=True, semantic=labels.OBSTACLE)
    return Mesh.concatenate([floor, sheet])


def floor_under_sheet(height: float, radius: int, sun=None, camera_z: float = 0.5):
    """(the direct sun's share of the disc, x) at the floor pixels of a 96 x 96 image looking down
    on the floor across the edge of a black sheet ``height`` over it, covering x < 0."""
    sun = sun or WideSun()
    mesh = sheet_over_floor(height)
    side = 96
    u = np.linspace(-0.15, 0.15, side)
    X, Y = np.meshgrid(u, u * 0.5)
    camera = np.array([0.0, 0.0, camera_z])
    targets = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    o = np.tile(camera, (len(targets), 1)).astype(np.float32)
    d = (targets - camera).astype(np.float32)
    settings = ShadingSettings(soft_shadow_radius=radius)
    with RayTracer(mesh, 1) as tracer:
        hits = tracer.intersect(o, d, image=(side, side))
        s = primary_surface(mesh, hits, o, d)
        assert len(s.idx) == side * side
        front, _ = direct_sun(
            tracer, s.points, s.n_shade, sun, settings, np.random.default_rng(0),
            geometric=s.n, image=sun_image(s, hits, d, len(o), side),
        )  # fmt: skip
    on_floor = mesh.semantic[s.prim] == labels.GROUND
    cos = float(np.asarray(sun.sun_direction)[2])
    return front[on_floor, 0] / (2.0 / np.pi * cos), s.points[on_floor, 0].astype(np.float64)


def test_one_ray_a_pixel_pooled_follows_the_exact_penumbra():
    """The sheet 1 m up, the camera under it: the penumbra is 2 H tan(R) = 10.5 cm wide, 33 pixels."""
    hard, x = floor_under_sheet(1.0, 0)
    soft, _ = floor_under_sheet(1.0, 4)
    exact = visible_share(x, 1.0)
    assert len(x) == 96 * 96
    assert set(np.unique(hard)) <= {0.0, 1.0}  # one ray to the disc's centre: a step
    penumbra = np.abs(x) < np.tan(RADIUS_RAD)
    assert penumbra.mean() > 0.3
    hard_error = np.abs(hard - exact)[penumbra].mean()
    soft_error = np.abs(soft - exact)[penumbra].mean()
    assert hard_error > 0.15
    assert soft_error < 0.3 * hard_error, (soft_error, hard_error)
    assert abs(soft[penumbra].mean() - exact[penumbra].mean()) < 0.02  # no bias across the edge
    # Radius 2 (the accurate preset's): the mean of at most 5 x 5 rays, coarser here.
    preset, _ = floor_under_sheet(1.0, 2)
    preset_error = np.abs(preset - exact)[penumbra].mean()
    assert preset_error < 0.4 * hard_error, (preset_error, hard_error)
    assert abs(preset[penumbra].mean() - exact[penumbra].mean()) < 0.02
    # Monotone across the edge, as the exact share: the means of each block's four columns.
    blocks = soft.reshape(96, 24, 4).mean(axis=(0, 2))
    assert np.all(np.diff(blocks) >= -0.01), blocks


def test_a_sheet_just_over_the_floor_keeps_a_sharp_shadow():
    """6.3 mm up under a sun 45 degrees from the zenith, the sheet's shadow edge falls on the floor
    beside it, with a penumbra 0.7 mm wide, far under the 3 mm a pixel spans: every pixel keeps its
    own ray, which decides as the disc's centre does at that distance: the hard shadow exactly."""

    class LowSun(WideSun):
        sun_direction = np.array([-np.sqrt(0.5), 0.0, np.sqrt(0.5)])

    hard, x = floor_under_sheet(0.0063, 0, LowSun(), camera_z=0.3)
    soft, _ = floor_under_sheet(0.0063, 4, LowSun(), camera_z=0.3)
    shadowed = x < 0.0063
    assert shadowed.any() and (~shadowed).any()
    assert np.allclose(hard, ~shadowed, atol=1e-6)  # lit 1, shadowed 0
    assert np.array_equal(soft, hard)
    # 2.5 cm up the blockers are still too near for a penumbra a pixel wide, but by the edge a
    # stratum's ray says otherwise than the disc's centre at some pixels (24 when each kept its
    # stratum's answer): the centre decides there, as in the hard shadow.
    hard, _ = floor_under_sheet(0.025, 0, LowSun(), camera_z=0.3)
    soft, _ = floor_under_sheet(0.025, 4, LowSun(), camera_z=0.3)
    assert np.array_equal(soft, hard)


PAIR_INTR = Intrinsics(96, 96, 160.0, 160.0, 47.5, 47.5)  # 0.3 m of floor across, 0.5 m down


def pair_under_sheet():
    """The sheet 1 m over the floor and the two poses of a stereo pair 3 cm apart under it, 0.5 m
    over the floor, looking down across the sheet's edge."""
    poses = []
    for x in (-0.015, 0.015):
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = np.diag([1.0, -1.0, -1.0]), [x, 0.0, 0.5]
        poses.append(pose)
    return sheet_over_floor(1.0), poses


def counted_occlusion_rays(monkeypatch) -> list[int]:
    """The number of rays of each ``RayTracer.occluded`` call from now on."""
    traced: list[int] = []
    occluded = RayTracer.occluded

    def counted(self, origins, *args, **kwargs):
        traced.append(len(origins))
        return occluded(self, origins, *args, **kwargs)

    monkeypatch.setattr(RayTracer, "occluded", counted)
    return traced


def sun_of_view(tracer, mesh, pose, settings, pair):
    """(the direct sun's front irradiance/pi over 2/pi: the share of the disc under the overhead
    sun, the surface) of every pixel of the pair's view from ``pose``."""
    o, d = primary_rays(PAIR_INTR, pose)
    hits = tracer.intersect(o, d, image=(PAIR_INTR.height, PAIR_INTR.width))
    s = primary_surface(mesh, hits, o, d)
    front, _ = direct_sun(
        tracer, s.points, s.n_shade, WideSun(), settings, np.random.default_rng(0), geometric=s.n,
        image=sun_image(s, hits, d, len(o), PAIR_INTR.width), pair=pair,
    )  # fmt: skip
    return front[:, 0] / (2.0 / np.pi), s


def test_the_right_camera_takes_the_left_cameras_shares_where_its_rays_agreed(monkeypatch):
    """A stereo pair 3 cm apart looking down across the sheet's edge, 1 m under it. The left view
    offers the shares of the pixels whose windows' rays all agreed (lit or shadowed: 0 or 1, the
    same half a pixel away); the right view takes them at the left pixel nearest each of its floor
    points (the same face side lit) and traces rays for the rest: the penumbra and the strip the
    left camera does not see. Its penumbra stays as close to the exact one as its own rays give."""
    mesh, poses = pair_under_sheet()
    intr, sun, settings = PAIR_INTR, WideSun(), ShadingSettings(soft_shadow_radius=4)
    traced = counted_occlusion_rays(monkeypatch)
    with RayTracer(mesh, 1) as tracer:

        def share_at(pose, pair):
            return sun_of_view(tracer, mesh, pose, settings, pair)

        left, alone, paired = PairSky(), PairSky(), PairSky()
        share_at(poses[0], left)
        own, s = share_at(poses[1], alone)
        paired.sun_partner = SkyShare.of(poses[0], intr, *left.sun_estimated)
        got, _ = share_at(poses[1], paired)
        views = {}
        for name, pose, partner in (("left", poses[0], None), ("right", poses[1], "left")):
            views[name] = render_view(
                tracer, SceneArrays(mesh=mesh, instance=np.zeros(mesh.n_faces, np.uint16)), intr, pose, sun,
                want={"rgb", "depth"}, settings=uniform_settings(soft_shadow_radius=4),
                partner=views.get(partner or ""),
            )  # fmt: skip
    n = intr.width * intr.height
    assert len(s.idx) == n  # every pixel sees the floor, lit from above
    offered = paired.sun_partner.factor[paired.sun_partner.side >= 0]
    assert 0.3 * n < len(offered) < 0.9 * n  # the penumbra's pixels are not offered
    assert set(np.unique(offered)) == {0.0, 1.0}
    expected = paired.sun_partner.lookup(s.points, s.prim.astype(np.int64) * 2)
    taken = np.isfinite(expected)
    assert 0.3 < taken.mean() < 0.9, taken.mean()
    assert traced[:3] == [n, n, int(np.count_nonzero(~taken))]  # the right view traces the rest only
    assert np.allclose(got[taken], expected[taken], atol=1e-6)
    assert set(paired.sun_estimated[0]) <= set(s.idx[~taken])  # it offers what it traced, where agreed
    x = s.points[:, 0].astype(np.float64)
    exact = visible_share(x, 1.0)
    penumbra = np.abs(x) < np.tan(RADIUS_RAD)
    assert penumbra.mean() > 0.3
    assert np.abs(got - exact)[penumbra].mean() < np.abs(own - exact)[penumbra].mean() + 0.01
    # Through the views: the left's offer reaches the right, which offers only what it traced.
    left_offer, right_offer = views["left"][PIXEL_SUN], views["right"][PIXEL_SUN]
    assert np.count_nonzero(left_offer.side >= 0) == len(offered)
    assert 0 < np.count_nonzero(right_offer.side >= 0) < int(np.count_nonzero(~taken))


def test_the_right_camera_takes_the_left_cameras_hard_sun_answers_where_they_agreed(monkeypatch):
    """The hard shadow (``soft_shadow_radius=0``: one ray to the sun's centre) of the sheet 1 m over the floor, the
    pair under it: the left view offers its answers where its same-face window agreed, the right
    view takes them at the nearest left pixel and traces only the rest; its answers are its own
    rays' but within a pixel of the shadow's edge."""
    mesh, poses = pair_under_sheet()
    intr, settings = PAIR_INTR, ShadingSettings(soft_shadow_radius=0)
    traced = counted_occlusion_rays(monkeypatch)
    with RayTracer(mesh, 1) as tracer:

        def sun_at(pose, pair):
            share, s = sun_of_view(tracer, mesh, pose, settings, pair)
            return share > 0, s

        left, paired = PairSky(), PairSky()
        sun_at(poses[0], left)
        own, s = sun_at(poses[1], None)
        paired.sun_partner = SkyShare.of(poses[0], intr, *left.sun_estimated)
        got, _ = sun_at(poses[1], paired)
    n = intr.width * intr.height
    assert len(s.idx) == n and 0.2 < own.mean() < 0.8  # the floor, part of it in the sheet's shadow
    offered = paired.sun_partner.factor[paired.sun_partner.side >= 0]
    assert 0.8 * n < len(offered) < n and set(np.unique(offered)) == {0.0, 1.0}
    taken = np.isfinite(paired.sun_partner.lookup(s.points, s.prim.astype(np.int64) * 2))
    assert 0.7 < taken.mean() < 0.95
    assert traced[:3] == [n, n, int(np.count_nonzero(~taken))]
    assert paired.sun_estimated is None  # the view that took answers offers none
    differ = got != own
    assert differ.sum() < 0.01 * n
    assert np.all(np.abs(s.points[differ, 0]) < 0.5 / 160.0)  # a pixel from the edge at x = 0
