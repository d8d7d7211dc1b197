"""Sky visibility (bake + render-time lighting) and the reference path tracer, against closed forms.

Mostly on a floor under a square roof in a uniform sky (:mod:`tests.sky_scenes`):
with a black roof the diffuse shading under its centre is exactly ``1 - F``, F
the roof's view factor. What glossy mirrors see over the bake is tested in
``tests/test_glossy_mirror.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.models.mesh import Mesh
from eden_pipe.render import sh
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.lightmap import Lightmaps, bake_lightmaps
from eden_pipe.render.pathtrace import reference_shade
from eden_pipe.render.shading import EnvironmentMap, shade
from eden_pipe.render.visibility.bake import bake
from eden_pipe.render.visibility.frame_light import FrameLights, ProbeLight
from eden_pipe.render.visibility.store import SkyVisibility
from eden_pipe.stages.render import make_sky
from tests.conftest import make_cfg
from tests.sky_scenes import (
    ROOF_HALF,
    ROOF_HEIGHT,
    UniformSky,
    closed_box,
    grid,
    hidden_fraction,
    parallel_rectangle_factor,
    rays_down_at,
    roofed_floor,
    uniform_settings,
)


@pytest.fixture(scope="module")
def roofed():
    mesh = roofed_floor()
    tracer = RayTracer(mesh, 1)
    vis = bake(
        mesh,
        tracer,
        np.random.default_rng(0),
        directions=64,
        spacing_m=0.02,
        rays=16,
        cell_m=0.1,
        cell_height_m=0.03,
        lightmap_cell_m=0.1,
        lightmap_rays=16,
    )
    yield mesh, tracer, vis
    tracer.close()


def test_sh_projection_of_a_uniform_sky_gives_unit_open_irradiance():
    table = np.ones((64, 128, 3), np.float32)
    coeffs = sh.project_latlong(table, block=2)
    assert np.allclose(coeffs[0], np.sqrt(4 * np.pi), rtol=1e-3) and np.allclose(coeffs[1:], 0, atol=5e-3)
    normals = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, -0.6, 0.8]])
    assert np.allclose(sh.open_transfer(normals) @ coeffs, 1.0, rtol=1e-3)


def test_sh_projection_recovers_a_sky_band_limited_to_order_4():
    """Bands 0-3 are orthonormal: a sky made of the sixteen functions projects back to its own
    coefficients (band 3 included: what holds a sunset's low light), so a transfer dotted with
    them lights exactly, whatever hides the sky."""
    height, width = 128, 256
    theta = (np.arange(height) + 0.5) / height * np.pi
    phi = (np.arange(width) + 0.5) / width * 2.0 * np.pi - np.pi
    t, p = np.meshgrid(theta, phi, indexing="ij")
    dirs = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1).reshape(-1, 3)
    coeffs = np.random.default_rng(4).normal(size=(sh.COUNT, 3))
    assert sh.COUNT == 16 and np.all(sh.BAND[9:] == 3)
    table = (sh.basis(dirs).astype(np.float64) @ coeffs).reshape(height, width, 3)
    assert np.allclose(sh.project_latlong(table, block=1), coeffs, atol=2e-3)
    # The clamped cosine has nothing in band 3: the open sky's transfer is order 3's.
    assert np.all(sh.open_transfer(np.array([[0.3, -0.4, np.sqrt(0.75)]]))[:, 9:] == 0)


def test_open_transfer_matches_the_ambient_irradiance_of_a_real_sky(tmp_path):
    """With nothing hiding the sky, the baked model's sky term is the sky's ambient irradiance/pi
    (order-3 SH against the sky's own quadrature: within a few per cent)."""
    for lighting in ("clear", "overcast", "sunset"):
        sky, _ = make_sky(make_cfg(tmp_path, [f"lighting={lighting}"]).lighting, 0)
        coeffs = EnvironmentMap(sky, 0.0).sh()
        normals = np.array([[0, 0, 1.0], [0.6, 0, 0.8], [0, 0.8, 0.6]])
        ours = sh.open_transfer(normals) @ coeffs
        theirs = sky.ambient_irradiance(normals) / np.pi
        assert np.all(np.abs(ours - theirs) / theirs < 0.05), (lighting, ours, theirs)


def test_bake_sees_the_open_sky_and_the_roof_hides_its_view_factor(roofed):
    mesh, tracer, vis = roofed
    sky = UniformSky()
    settings = uniform_settings(sky_visibility=vis)
    rng = np.random.default_rng(1)
    # Points within 8 cm of the roof's axis, where 1 - F varies by under 0.01: their mean averages the
    # per-face sampling noise of the bake out, so what is left is its bias.
    r, phi = 0.08 * np.sqrt(rng.random(60)), 2 * np.pi * rng.random(60)
    centre = np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros(60)], axis=1)
    far = np.array([[1.8, -1.7, 0.0], [-1.6, 1.8, 0.0]])
    shaded = {}
    for name, points in (("centre", centre), ("far", far)):
        o, d = rays_down_at(points)
        hits = tracer.intersect(o, d)
        shaded[name] = shade(tracer, mesh, hits, o, d, sky, settings, np.random.default_rng(0))["shading"]
    # Under a black roof nothing bounces back: the shading is the visible sky alone.
    expected = 1.0 - hidden_fraction(ROOF_HALF, ROOF_HEIGHT)
    assert abs(shaded["centre"].mean() - expected) < 0.03, (shaded["centre"].mean(), expected)
    # Far from the roof it hides only a little sky near the horizon: close to fully open.
    assert np.all(shaded["far"] > 0.9) and np.all(shaded["far"] <= 1.05), shaded["far"]


def test_ground_map_hides_the_sky_of_the_land_outside_the_garden():
    """Land outside the bake's box (the skirt, a few faces metres wide) gets its sky from the ground
    map: beside a black roof its shading is 1 - F point by point, though each face spans metres;
    beyond the map's reach it is open sky. Without the map (ground_rays=0) it would all be open."""
    roof = grid(-ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT, 4, albedo=0.0, flip=True)
    skirt = grid(-8.0, 8.0, -8.0, 8.0, 0.0, 2, albedo=0.2, semantic=labels.BACKGROUND)
    mesh = Mesh.concatenate([roof, skirt])
    sky = UniformSky()
    points = np.array(
        [[0.75, 0.0, 0.0], [0.0, -0.9, 0.0], [1.1, 0.6, 0.0], [-1.6, 0.2, 0.0], [2.5, -2.5, 0.0], [7.5, 7.0, 0.0]]
    )
    with RayTracer(mesh, 1) as tracer:
        shaded = {}
        for ground_rays in (1024, 0):
            vis = bake(
                mesh,
                tracer,
                np.random.default_rng(0),
                directions=16,
                spacing_m=0.05,
                rays=4,
                cell_m=0.1,
                cell_height_m=0.03,
                ground_cell_m=0.1,
                ground_reach_m=3.0,
                ground_rays=ground_rays,
            )
            faces = np.arange(mesh.n_faces)
            assert (len(vis.ground_faces) > 0) == (ground_rays > 0)
            for side in (False, True):  # the sides table marks both sides of exactly the map's faces
                marked = vis.on_ground_map(vis.sides_of(faces, np.full(len(faces), side))[1])
                assert np.array_equal(marked, np.isin(faces, vis.ground_faces))
            o, d = rays_down_at(points)
            hits = tracer.intersect(o, d)
            shaded[ground_rays] = shade(
                tracer, mesh, hits, o, d, sky, uniform_settings(sky_visibility=vis), np.random.default_rng(0)
            )["shading"][:, 1]
    expected = np.array(
        [1.0 - parallel_rectangle_factor(p, -ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT) for p in points]
    )
    expected[-1] = 1.0  # beyond the map's reach: open sky
    assert np.allclose(shaded[1024], expected, atol=0.02), (shaded[1024], expected)
    assert expected[0] < 0.85 and np.allclose(shaded[0], 1.0, atol=1e-3), shaded[0]


def test_reference_path_tracer_converges_to_the_view_factor(roofed):
    mesh, tracer, _ = roofed
    sky = UniformSky()
    o, d = rays_down_at(np.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.0]]))
    hits = tracer.intersect(o, d)
    settings = uniform_settings(mode="reference", reference_samples=4096, reference_bounces=4)
    out = reference_shade(tracer, mesh, hits, o, d, sky, settings, np.random.default_rng(3))
    expected = 1.0 - hidden_fraction(ROOF_HALF, ROOF_HEIGHT)
    # 4096 stratified samples of a binary visibility: noise well below 0.01.
    assert np.allclose(out["shading"], expected, atol=0.01), (out["shading"], expected)


@pytest.mark.parametrize("gap_m", [5e-4, 1e-4])
def test_reference_rays_do_not_step_over_a_leaf_closer_than_a_millimetre(gap_m):
    """A black sheet ``gap_m`` above the floor, 1 m wide, 30 m off the origin (where float32 rounds
    a hit point to about 4 um): below its middle the floor sees 1 - F of the sky, F the sheet's view
    factor (near 1). A fixed 1 mm start offset put the floor's rays above the sheet: the open sky."""
    offset = np.array([30.0, -20.0, 0.0], np.float32)
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 8, albedo=0.5)
    sheet = grid(-0.5, 0.5, -0.5, 0.5, gap_m, 2, albedo=0.0, flip=True)
    both = Mesh.concatenate([floor, sheet])
    mesh = Mesh(
        both.vertices + offset, both.faces, both.semantic, both.material, both.albedo, both.translucency, both.specular
    )
    with RayTracer(mesh, 1) as tracer:
        # Rays start inside the gap and look down at the floor.
        o = np.array([[0.0, 0.0, 0.5 * gap_m], [0.013, -0.021, 0.5 * gap_m]], np.float32) + offset
        d = np.tile(np.array([[0.0, 0.0, -1.0]], np.float32), (2, 1))
        hits = tracer.intersect(o, d)
        assert np.all(hits.prim < floor.n_faces) and np.all(hits.prim >= 0)
        settings = uniform_settings(mode="reference", reference_samples=256, reference_bounces=2)
        out = reference_shade(tracer, mesh, hits, o, d, UniformSky(), settings, np.random.default_rng(5))
    expected = 1.0 - hidden_fraction(0.5, gap_m)
    assert expected < 0.002
    assert np.all(out["shading"] < 0.01), out["shading"]


def test_default_sun_shadow_rays_do_not_start_past_a_board_half_a_millimetre_up():
    """The default's direct sun (render.shading.direct_sun) under a sheet 0.5 mm above the floor, 30 m
    off the origin, the sun straight above: shadowed. Its 1 mm start used to put the rays above it."""
    from eden_pipe.render.shading import ShadingSettings, direct_sun

    offset = np.array([30.0, -20.0, 0.0], np.float32)
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 8, albedo=0.5)
    sheet = grid(-0.5, 0.5, -0.5, 0.5, 5e-4, 2, albedo=0.0, flip=True)
    both = Mesh.concatenate([floor, sheet])
    mesh = Mesh(
        both.vertices + offset, both.faces, both.semantic, both.material, both.albedo, both.translucency, both.specular
    )

    class Sun(UniformSky):
        sun_irradiance = np.full(3, 2.0)
        sun_angular_radius = 0.0046
        casts_cloud_shadows = False

    points = np.array([[0.0, 0.0, 0.0], [0.2, -0.1, 0.0], [1.5, 1.5, 0.0]], np.float32) + offset
    normals = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (3, 1))
    with RayTracer(mesh, 1) as tracer:
        front, _ = direct_sun(tracer, points, normals, Sun(), ShadingSettings(), np.random.default_rng(0))
    assert np.all(front[:2] == 0.0) and np.allclose(front[2], 2.0 / np.pi, rtol=1e-3)


def test_reference_adds_bounce_light_from_a_white_roof_and_its_passes_compose():
    """A grey roof reflects floor light back down: more than the black roof's 1 - F, and the
    written passes still add up to the image (same formula as the default)."""
    mesh = roofed_floor(roof_albedo=0.8)
    with RayTracer(mesh, 1) as tracer:
        sky = UniformSky()
        o, d = rays_down_at(np.array([[0.0, 0.0, 0.0], [1.9, 1.9, 0.0]]))
        o = np.concatenate([o, np.array([[0, 0, 5.0]], np.float32)])
        d = np.concatenate([d, np.array([[0, 0, 1.0]], np.float32)])  # one ray to the sky
        hits = tracer.intersect(o, d)
        settings = uniform_settings(mode="reference", reference_samples=1024, reference_bounces=6)
        out = reference_shade(tracer, mesh, hits, o, d, sky, settings, np.random.default_rng(4))
        open_part = 1.0 - hidden_fraction(ROOF_HALF, ROOF_HEIGHT)
        assert np.all(out["shading"][0] > open_part + 0.05)
        parts = out["albedo"] * out["shading"] + out["glossy"] + out["translucency"] + out["background"]
        assert np.allclose(out["linear"], parts, rtol=1e-5, atol=1e-6)
        assert np.allclose(out["background"][2], 1.0) and np.all(out["albedo"][2] == 0)


@pytest.mark.parametrize("own_sun", [False, True])
def test_frame_light_is_made_per_probe_as_views_need_it_and_equals_the_whole_table(roofed, tmp_path, own_sun):
    """A frame's light is made for the probes its views see, each once; the rows are exactly those
    made for every probe at once (one row depends on its probe alone), under a sky with a sun."""
    _, _, vis = roofed
    sky, _ = make_sky(make_cfg(tmp_path, ["lighting=clear"]).lighting, 0)
    light_args = (
        EnvironmentMap(sky, 0.0).sh(),
        sh.basis(np.asarray(sky.sun_direction, np.float32)[None])[0],
        np.asarray(sky.sun_irradiance, np.float32),
    )
    whole = vis.frame_rows(np.arange(vis.n_probes), *light_args, own_sun=own_sun)
    terms = whole.terms()
    assert set(terms) == set(ProbeLight.TERMS if own_sun else ProbeLight.TERMS[:4])
    assert all(len(v) == vis.n_probes and v.flags.c_contiguous and np.all(np.isfinite(v)) for v in terms.values())
    assert np.any(whole.bounce_sun > 0)  # the sun's bounce is in the rows
    light = vis.frame_light(*light_args, own_sun=own_sun)
    rng = np.random.default_rng(3)
    seen = np.zeros(vis.n_probes, bool)

    def same(a, b):
        return a.terms().keys() == b.terms().keys() and all(
            np.array_equal(v, getattr(b, k)) for k, v in a.terms().items()
        )

    for _ in range(3):  # three "views": overlapping probe sets with repeats
        probes = rng.integers(0, vis.n_probes, 40)
        assert same(light.rows(probes), whole.take(probes))
        seen[probes] = True
        assert np.array_equal(light.slot >= 0, seen) and len(light.made) == seen.sum()  # each once, where needed
    assert same(light.span(2, 5), whole.take(np.arange(2, 7)))  # the ground map's nodes: made at once, the same rows


def test_frames_under_the_same_sky_share_one_light_that_grows_with_the_probes_seen(roofed, tmp_path):
    """A job's frames under exactly the same sky and sun share one FrameLight (FrameLights), a
    different sky gets its own, and the shared light's rows stay those of the whole table as its
    store grows past its first buffers."""
    _, _, vis = roofed
    sky, _ = make_sky(make_cfg(tmp_path, ["lighting=clear"]).lighting, 0)
    args = (
        EnvironmentMap(sky, 0.0).sh(),
        sh.basis(np.asarray(sky.sun_direction, np.float32)[None])[0],
        np.asarray(sky.sun_irradiance, np.float32),
    )
    other = (args[0] * np.float32(1.01),) + args[1:]
    pool = FrameLights(keep=2)
    light = pool.get(vis, *args)
    assert pool.get(vis, *(a.copy() for a in args)) is light  # equal inputs, not the same arrays
    assert pool.get(vis, *other) is not light and pool.get(vis, *args) is light  # two skies kept
    assert pool.get(vis, *args, own_sun=True) is not light
    whole = vis.frame_rows(np.arange(vis.n_probes), *args)
    light.FIRST_ROOM = 3  # grow several times over this small garden's probes
    rng = np.random.default_rng(5)
    for _ in range(6):
        probes = rng.integers(0, vis.n_probes, 7)
        got = light.rows(probes)
        assert all(np.array_equal(v, getattr(whole.take(probes), k)) for k, v in got.terms().items())
    made = np.flatnonzero(light.slot >= 0)
    assert len(light.made) == len(made) and all(
        np.array_equal(v[light.slot[made]], getattr(whole.take(made), k)) for k, v in light.made.terms().items()
    )


def test_baked_visibility_round_trips_through_its_file(roofed, tmp_path):
    _, _, vis = roofed
    vis.save(tmp_path / "v.npz")
    back = SkyVisibility.load(tmp_path / "v.npz")
    assert np.array_equal(back.face_probe, vis.face_probe)
    for key in SkyVisibility.FIELDS[1:]:
        assert np.allclose(getattr(back, key), getattr(vis, key), rtol=2e-3, atol=2e-3), key
    for key in Lightmaps.FIELDS:  # the roof's 0.0625 m^2 faces are wider than the 0.1 m cells: mapped
        mine, read = getattr(vis.lightmaps, key), getattr(back.lightmaps, key)
        assert len(mine) and np.array_equal(read, mine), key


@pytest.mark.parametrize(
    "override,words",
    [
        ("render.mode=fast", ["render.mode", "fast", "standard", "reference"]),
        ("render.reference_samples=0", ["render.reference_samples", "0", "> 0"]),
        ("render.sky_visibility.spacing_m=0", ["render.sky_visibility.spacing_m", "0", "> 0"]),
        ("render.sky_visibility.rays=-1", ["render.sky_visibility.rays", "-1", ">= 0"]),
        ("render.mirror_rays=1.5", ["render.mirror_rays", "1.5", "[0, 1]"]),
        ("render.pixel_sky_rays=-1", ["render.pixel_sky_rays", "-1", "0..64"]),
        ("render.pixel_sky_radius=17", ["render.pixel_sky_radius", "17", "0..16"]),
        ("render.sky_visibility.lightmap_cell_m=-0.1", ["render.sky_visibility.lightmap_cell_m", "-0.1", ">= 0"]),
        ("render.sky_visibility.gain_prior_rays=-2", ["render.sky_visibility.gain_prior_rays", "-2", ">= 0"]),
        ("render.sky_visibility.part_prior_hits=-1", ["render.sky_visibility.part_prior_hits", "-1", ">= 0"]),
        ("render.sky_visibility.prior_hits=0", ["render.sky_visibility.prior_hits", "0", "> 0"]),
    ],
)
def test_render_light_model_keys_are_checked(tmp_path, override, words):
    from eden_pipe.config import ConfigError, to_config, validate

    with pytest.raises(ConfigError) as err:
        validate(to_config(make_cfg(tmp_path, [override])))
    for word in words:
        assert word in str(err.value), (word, str(err.value))


@pytest.mark.slow
def test_bake_is_shared_by_lightings_and_skipped_when_unused(tmp_path):
    """One bake per garden: a second lighting reuses it; the reference mode and the open-sky model
    skip the stage."""
    from eden_pipe.pipeline import run_job
    from tests.conftest import TINY

    quiet = {"echo": lambda *_: None}
    first = run_job(make_cfg(tmp_path, TINY + ["lighting=overcast", "render.max_frames=1"]), **quiet)
    second = run_job(make_cfg(tmp_path, TINY + ["lighting=twilight", "render.max_frames=1"]), **quiet)
    assert not first.artifacts["sky_visibility"].cached and second.artifacts["sky_visibility"].cached
    assert second.artifacts["sky_visibility"].key == first.artifacts["sky_visibility"].key
    for override in ("render.sky_visibility.enabled=false", "render.mode=reference"):
        other = run_job(
            make_cfg(
                tmp_path,
                TINY
                + [
                    "lighting=overcast",
                    "render.max_frames=1",
                    override,
                    "render.reference_samples=2",
                    "render.reference_bounces=2",
                    "render.modalities=[rgb,depth,shading]",
                ],
            ),
            **quiet,
        )
        assert "sky_visibility" not in other.artifacts, override


def traced_visible_sky(tracer: RayTracer, points: np.ndarray, rays: int = 4096) -> np.ndarray:
    """(N,) the cosine-weighted visible fraction of the sky above floor ``points``, ``rays`` rays each."""
    from eden_pipe.render.pathtrace import cosine_directions

    rng = np.random.default_rng(1)
    out = []
    for p in points:
        dirs = cosine_directions(np.tile([[0.0, 0.0, 1.0]], (rays, 1)), rng.random(rays), rng.random(rays))
        out.append(1.0 - tracer.occluded(np.tile(p + [0.0, 0.0, 1e-3], (rays, 1)).astype(np.float32), dirs).mean())
    return np.array(out)


def shaded_by_bake(mesh: Mesh, tracer: RayTracer, points: np.ndarray, **bake_settings) -> np.ndarray:
    """(N,) the default's shading at floor ``points`` under the uniform sky, from a coarse bake."""
    vis = bake(
        mesh,
        tracer,
        np.random.default_rng(0),
        directions=32,
        spacing_m=0.05,
        rays=4,
        cell_m=0.1,
        cell_height_m=0.03,
        ground_rays=0,
        **bake_settings,
    )
    o, d = rays_down_at(points)
    return shade(
        tracer,
        mesh,
        tracer.intersect(o, d),
        o,
        d,
        UniformSky(),
        uniform_settings(sky_visibility=vis),
        np.random.default_rng(0),
    )["shading"][:, 1]


def test_camera_gain_gives_faces_the_sky_of_the_points_cameras_see():
    """A floor of two big faces, half of it inside a closed black box: the points inside see no
    sky and no camera sees them, so a face's average visible sky is not what its pixels see (the
    test point's face is a quarter inside: its average is about three quarters of the point's).
    With ``camera_views`` the bake measures the sky at the points that cameras standing on the
    floor hit, and the point gets about its true visible sky (traced with 4,096 cosine rays).
    ``gain_prior_rays`` pseudo-rays shrink that gain toward 1: a few leave it, very many undo it."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 1, albedo=0.0)  # two faces, each half inside the box
    mesh = Mesh.concatenate([floor, closed_box([-2.2, -2.2, -0.1], [0.0, 2.2, 0.5])])
    point = np.array([[1.2, 0.3, 0.0]])
    with RayTracer(mesh, 1) as tracer:
        true = traced_visible_sky(tracer, point)[0]
        shaded = {
            (views, prior): shaded_by_bake(
                mesh, tracer, point, camera_views=views, camera_rays=256, gain_prior_rays=prior
            )[0]
            for views, prior in ((0, 8.0), (400, 8.0), (400, 1e4), (400, 1e12))
        }
    assert 0.8 < true < 0.97, true
    assert true - shaded[0, 8.0] > 0.2, (shaded, true)
    assert abs(shaded[400, 8.0] - true) < 0.06, (shaded, true)
    assert shaded[0, 8.0] < shaded[400, 1e4] < shaded[400, 8.0], shaded
    assert shaded[400, 1e12] == pytest.approx(shaded[0, 8.0], rel=1e-6), shaded


def test_lightmap_grid_spans_a_face_and_blends_its_nodes_bilinearly():
    """A face 2 m long and 0.5 m across (open sky above) gets 4 x 1 steps along its long edge and
    across it with 0.5 m cells; every node sits on the face and sees the whole sky on its upper
    side, next to none on the lower (the floor under it; grazing rays pass its edge). Node values
    set by hand are read back exactly at the nodes and blended bilinearly between them."""
    tri = Mesh.from_arrays(
        np.array([[0.0, 0.0, 0.3], [2.0, 0.0, 0.3], [1.0, 0.5, 0.3]]),
        np.array([[0, 1, 2]]),
        semantic=labels.OBSTACLE,
        material="generic",
        albedo=0.5,
    )
    mesh = Mesh.concatenate([tri, grid(-3.0, 3.0, -3.0, 3.0, 0.0, 1, albedo=0.5)])
    with RayTracer(mesh, 1) as tracer:
        maps = bake_lightmaps(
            mesh,
            tracer,
            np.random.default_rng(0),
            np.array([0.5, 18.0, 18.0]),
            np.array([True, False, False]),
            cell_m=0.5,
            rays=64,
        )
    assert maps.faces.tolist() == [0] and maps.steps.tolist() == [[4, 1]] and len(maps.visible) == 10
    assert np.all(maps.visible[:, 0] == 1.0) and np.all(maps.visible[:, 1] < 0.1), maps.visible
    maps.visible[:, 0] = np.arange(10)  # node (i, j) holds i + 5 j
    points = np.array([[1.0, 0.5, 0.3], [0.75, 0.25, 0.3], [1.5, 0.0, 0.3]])  # nodes 0.5 m apart from (0, 0)
    got = maps.visible_at(np.zeros(3, np.int32), np.zeros(3, bool), points)
    assert np.allclose(got, [7.0, 1.5 + 5 * 0.5, 3.0], atol=1e-4), got


def test_lightmap_gives_a_large_face_the_sky_of_each_of_its_points():
    """A floor of two 8 m^2 faces beside a closed black wall 2 m tall: 0.3 m from the wall the
    floor sees 60 % of its sky, 1.7 m away 86 %; one value per face holds neither. With
    lightmaps (nodes 0.25 m apart, 256 rays each) the shading at both points is their visible sky
    traced with 4,096 cosine rays, within 0.04; without, one of them is off by more than 0.1."""
    floor = grid(-2.0, 2.0, -2.0, 2.0, 0.0, 1, albedo=0.0)
    mesh = Mesh.concatenate([floor, closed_box([-0.1, -2.0, -0.1], [0.1, 2.0, 2.0])])
    points = np.array([[0.4, 0.7, 0.0], [1.8, -0.4, 0.0]])
    with RayTracer(mesh, 1) as tracer:
        true = traced_visible_sky(tracer, points)
        shaded = {
            cell: shaded_by_bake(mesh, tracer, points, lightmap_cell_m=cell, lightmap_rays=256) for cell in (0.0, 0.25)
        }
    assert true[0] < 0.65 and true[1] > 0.85, true
    assert np.abs(shaded[0.0] - true).max() > 0.1, (shaded, true)
    assert np.abs(shaded[0.25] - true).max() < 0.04, (shaded, true)


def test_lightmap_skips_the_underside_of_the_ground_and_keeps_every_other_ray():
    """Two large faces, a paving slab (a terrain material) on the ground and a wooden board above
    it: the slab's underside (its side facing down) is not traced and holds 0, its top and both of
    the board's sides get exactly the values of a bake where the slab is wood and every side is
    traced (the same draws); that bake's slab underside sees the open sky below the ground."""

    def scene(material: str) -> Mesh:
        slab = Mesh.from_arrays(
            np.array([[0.0, 0.0, 0.01], [1.0, 0.0, 0.01], [0.0, 1.0, 0.01]]),
            np.array([[0, 1, 2]]),
            semantic=labels.PAVEMENT,
            material=material,
            albedo=0.4,
        )
        board = Mesh.from_arrays(
            np.array([[0.0, 0.0, 0.6], [0.0, 1.0, 0.6], [1.0, 0.0, 0.6]]),  # wound facing down
            np.array([[0, 1, 2]]),
            semantic=labels.OBSTACLE,
            material="wood",
            albedo=0.4,
        )
        return Mesh.concatenate([slab, board])

    maps = {}
    for material in ("pavement", "wood"):
        mesh = scene(material)
        with RayTracer(mesh, 1) as tracer:
            maps[material] = bake_lightmaps(
                mesh, tracer, np.random.default_rng(3), np.array([0.5, 0.5]), np.ones(2, bool), cell_m=0.25, rays=64
            )
    ground, traced = maps["pavement"], maps["wood"]
    slab = np.arange(ground.first[0], ground.first[1])
    board = np.arange(ground.first[1], len(ground.visible))
    assert np.all(ground.visible[slab, 1] == 0.0) and np.all(traced.visible[slab, 1] > 0.9)
    assert np.array_equal(ground.visible[slab, 0], traced.visible[slab, 0])
    assert np.array_equal(ground.visible[board], traced.visible[board])
    assert np.all(ground.visible[slab, 0] < 0.9) and np.all(ground.visible[slab, 0] > 0.0)


def test_the_sun_bounce_leaves_out_the_multi_bounce_factor_unless_asked():
    """Under a bright roof the floor's probes' bounce rays meet its underside, whose multi-bounce
    factor is well above 1 (its own rays meet the bright floor). The sun's bounce table is the sum
    without the factor, so it is smaller there than the sky's; with ``sun_multi_bounce`` it is the
    sky's table itself, as before it existed, and every other table is the same either way (the
    same rays)."""
    mesh = roofed_floor(roof_albedo=0.8)
    settings = dict(directions=32, spacing_m=0.04, rays=16, cell_m=0.2, cell_height_m=0.05, ground_rays=0)
    with RayTracer(mesh, 1) as tracer:
        single = bake(mesh, tracer, np.random.default_rng(4), **settings)
        multi = bake(mesh, tracer, np.random.default_rng(4), sun_multi_bounce=True, **settings)
    assert np.array_equal(multi.sun_bounce, multi.bounce)
    for key in ("face_probe", "exposure", "transfer", "normal", "bounce", "tint"):
        assert np.array_equal(getattr(single, key), getattr(multi, key)), key
    under_roof = np.flatnonzero(single.bounce[:, 0] > 1e-3)
    assert len(under_roof) > 10
    ratio = single.sun_bounce[under_roof, 0] / single.bounce[under_roof, 0]
    assert np.all(ratio <= 1 + 1e-6) and np.median(ratio) < 0.95, np.percentile(ratio, [0, 50, 100])


def test_fast_rays_rebuild_the_scene_after_the_sky_counts_and_camera_gain():
    """``fast_rays``: the lightmaps', bounce and ground map's rays go through a scene built again
    without Embree's robust flag; the bundles' counts and the camera gain before it are the robust
    scene's, bit for bit, and the tracer is left as the bake made it. The rest, the same rays
    through another triangle test, stays within a hair of the robust bake."""
    mesh = roofed_floor(roof_albedo=0.5)
    settings = dict(
        directions=32, spacing_m=0.04, rays=16, cell_m=0.2, cell_height_m=0.05, ground_rays=0, camera_views=40,
        camera_rays=256, lightmap_cell_m=0.05, lightmap_rays=32,
    )  # fmt: skip
    with RayTracer(mesh, 1) as robust, RayTracer(mesh, 1) as fast:
        slow = bake(mesh, robust, np.random.default_rng(6), **settings)
        quick = bake(mesh, fast, np.random.default_rng(6), fast_rays=True, **settings)
        assert robust.robust and not fast.robust
    for key in ("face_probe", "exposure", "transfer", "normal"):
        assert np.array_equal(getattr(slow, key), getattr(quick, key)), key
    assert len(slow.lightmaps.visible) > 10 and np.any(slow.bounce[:, 0] > 1e-3)
    for a, b in ((slow.bounce, quick.bounce), (slow.sun_bounce, quick.sun_bounce), (slow.tint, quick.tint),
                 (slow.lightmaps.visible, quick.lightmaps.visible)):  # fmt: skip
        assert np.abs(a - b).mean() <= 0.01 * np.abs(a).mean()
