"""The renderer's fast kernels agree with the plain numpy they replace.

vec.* (row dots, gathers, scatters, sign flips, integer powers), lut.sample
(cv2.remap table lookups), the shared-direction Embree query, the float-layer
writer on strided views, and the single-threaded kernel scope of the render stage.
"""

from __future__ import annotations

import itertools
import json

import cv2
import numpy as np
import pytest
from threadpoolctl import threadpool_info

from eden_pipe.io import formats
from eden_pipe.models.mesh import Mesh
from eden_pipe.render import lut, vec
from eden_pipe.render.embree import RayTracer
from eden_pipe.stages.render import single_threaded_kernels


@pytest.fixture
def rows():
    rng = np.random.default_rng(3)
    return rng.normal(size=(5000, 3)).astype(np.float32), rng.normal(size=(5000, 3)).astype(np.float32)


def test_dot_length_normalize_match_numpy(rows):
    a, b = rows
    np.testing.assert_allclose(vec.dot(a, b), np.sum(a * b, axis=1), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(vec.length(a), np.linalg.norm(a, axis=1), rtol=1e-6)
    unit = vec.normalize(a)
    np.testing.assert_allclose(unit, a / np.linalg.norm(a, axis=1, keepdims=True), rtol=1e-6, atol=1e-7)
    assert vec.dot(a, b).dtype == np.float32
    zero = vec.normalize(np.zeros((2, 3), np.float32))
    assert np.all(zero == 0.0)
    # float64 rows keep float64
    assert vec.dot(a.astype(np.float64), b.astype(np.float64)).dtype == np.float64


def test_facing_flips_exactly_the_rows_that_face_away(rows):
    n, d = rows
    flipped = vec.facing(n, d)
    expected = np.where((np.sum(n * d, axis=1) > 0)[:, None], -n, n)
    assert np.array_equal(flipped, expected)
    assert np.all(vec.dot(flipped, d) <= 0)


def test_gather_select_and_scatter_match_fancy_indexing(rows):
    a, b = rows
    rng = np.random.default_rng(4)
    index = rng.choice(len(a), 1200, replace=False)
    assert np.array_equal(vec.gather(a, index), a[index])
    mask = rng.random(len(a)) < 0.3
    assert np.array_equal(vec.select(mask, a, b), np.where(mask[:, None], a, b))
    expected = np.zeros((len(a), 3), np.float32)
    expected[index] = b[:1200]
    assert np.array_equal(vec.Scatter(index, len(a)).expand(b[:1200]), expected)


@pytest.mark.parametrize("exponent", [1, 2, 5, 60])
def test_integer_power_by_squaring(exponent):
    from eden_pipe.render import kernels

    x = np.linspace(0.0, 1.0, 1001, dtype=np.float32)
    np.testing.assert_allclose(kernels._power(x, exponent), x.astype(np.float64) ** exponent, rtol=2e-5, atol=1e-30)
    assert np.array_equal(kernels._power(x, exponent), _numpy_power(x, exponent))
    with pytest.raises(ValueError, match="positive integer"):
        kernels._power(x, 0)


def _numpy_power(x, exponent):
    """x ** exponent by repeated squaring in numpy: the products the glossy lobe's kernel makes."""
    result, base = None, x
    while exponent:
        if exponent & 1:
            result = base if result is None else result * base
        exponent >>= 1
        if exponent:
            base = base * base
    return result


def test_lut_bilinear_matches_manual_interpolation_and_wraps_the_seam():
    rng = np.random.default_rng(5)
    table = rng.random((7, 9, 3)).astype(np.float32)
    wrapped = lut.wrap_columns(table)
    x = rng.uniform(0.0, 9.0, 4000).astype(np.float32)  # the whole periodic range, seam included
    y = rng.uniform(0.0, 6.0, 4000).astype(np.float32)
    got = lut.sample(wrapped, x, y)
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x1, y1 = (x0 + 1) % 9, np.minimum(y0 + 1, 6)
    x0 %= 9
    manual = (table[y0, x0] * (1 - fx) + table[y0, x1] * fx) * (1 - fy) + (
        table[y1, x0] * (1 - fx) + table[y1, x1] * fx
    ) * fy
    # OpenCV quantises the weights to 1/32 of a texel.
    assert np.max(np.abs(got - manual)) < 1.0 / 32.0
    assert np.mean(np.abs(got - manual)) < 0.01
    nearest = lut.sample(wrapped, np.array([2.2, 3.7], np.float32), np.array([1.4, 4.6], np.float32), nearest=True)
    assert np.array_equal(nearest, table[[1, 5], [2, 4]])
    assert lut.sample(wrapped, np.zeros(0, np.float32), np.zeros(0, np.float32)).shape == (0, 3)


@pytest.mark.parametrize("period", [1, 64, 640, 2048])
def test_periodic_coordinates_are_numpys_remainder_bit_for_bit(period):
    rng = np.random.default_rng(period)
    p = np.float32(period)
    inside = (rng.uniform(-1.0, 1.0, 200_000) * period).astype(np.float32)
    edges = np.array([0.0, -0.0, -1e-45, 1e-45, -1e-30, np.nextafter(-p, 0), np.nextafter(p, 0), -0.5, 0.5], np.float32)
    # Within one period, where the fast form runs; then values that send it to numpy's own remainder.
    for x in (inside, edges, np.concatenate([inside, [np.float32(3.5 * period)]]), np.array([np.nan, 1.0], np.float32)):
        with np.errstate(invalid="ignore"):
            want = x % p
        got = lut.periodic(x, period)
        assert got.dtype == np.float32 and got.tobytes() == want.tobytes()
    assert np.all(np.signbit(lut.periodic(np.array([-0.0, 0.0], np.float32), period)) == [False, False])
    assert lut.periodic(np.zeros(0, np.float32), period).shape == (0,)


def test_lut_handles_more_points_than_one_remap_row_and_many_channels():
    table = np.arange(2 * 3 * 6, dtype=np.float32).reshape(2, 3, 6)
    n = lut.ROW * 3 + 17
    x = np.full(n, 1.0, np.float32)
    y = np.full(n, 1.0, np.float32)
    assert np.array_equal(lut.sample(table, x, y), np.broadcast_to(table[1, 1], (n, 6)))


def _box_mesh() -> Mesh:
    v = np.array([[0, 0, 1], [4, 0, 1], [4, 4, 1], [0, 4, 1]], np.float32)  # a roof over [0,4]^2 at z = 1
    return Mesh.from_arrays(v, [[0, 1, 2], [0, 2, 3]], semantic=7, material="rock", albedo=(0.5, 0.5, 0.5))


@pytest.mark.parametrize("threads", [1, 2])
def test_shared_direction_occlusion_equals_per_ray_directions(threads, monkeypatch):
    import eden_pipe.render.embree as embree

    monkeypatch.setattr(embree, "CHUNK", 64)  # several chunks through the pool
    rng = np.random.default_rng(6)
    origins = np.column_stack([rng.uniform(-2, 6, 500), rng.uniform(-2, 6, 500), np.zeros(500)]).astype(np.float32)
    up = np.array([[0.1, 0.2, 1.0]], np.float32)
    with RayTracer(_box_mesh(), threads=threads) as tracer:
        shared = tracer.occluded(origins, up)
        per_ray = tracer.occluded(origins, np.repeat(up, len(origins), axis=0))
    assert np.array_equal(shared, per_ray)
    under_roof = (
        (origins[:, 0] + 0.1 > 0) & (origins[:, 0] + 0.1 < 4) & (origins[:, 1] + 0.2 > 0) & (origins[:, 1] + 0.2 < 4)
    )
    inner = (origins[:, 0] > 0.05) & (origins[:, 0] < 3.85) & (origins[:, 1] > 0.05) & (origins[:, 1] < 3.75)
    assert np.all(shared[inner]) and not np.any(shared[~under_roof])


def test_ray_batches_are_cut_into_several_chunks_per_thread_with_the_same_answers(monkeypatch):
    """A batch below CHUNK rays per thread is cut into CHUNKS_PER_THREAD chunks per thread, which
    cover every ray once, and the answers equal one call on one thread."""
    import eden_pipe.render.embree as embree

    monkeypatch.setattr(embree, "MIN_SPLIT", 16)
    rng = np.random.default_rng(8)
    n = 500
    origins = np.column_stack([rng.uniform(-2, 6, n), rng.uniform(-2, 6, n), np.zeros(n)]).astype(np.float32)
    directions = rng.normal(size=(n, 3)).astype(np.float32)
    directions[:, 2] = np.abs(directions[:, 2]) + 0.1
    with RayTracer(_box_mesh(), threads=1) as one:
        alone_hit, alone_t = one.occluded(origins, directions), one.intersect(origins, directions).t
    with RayTracer(_box_mesh(), threads=2) as two:
        spans = []
        two.map_chunks(lambda a, b: spans.append((a, b)), n)
        assert len(spans) == embree.CHUNKS_PER_THREAD * 2
        assert sorted(spans)[0][0] == 0 and sorted(spans)[-1][1] == n
        assert all(b == c for (_, b), (c, _) in itertools.pairwise(sorted(spans)))
        assert np.array_equal(two.occluded(origins, directions), alone_hit)
        assert np.array_equal(two.intersect(origins, directions).t, alone_t)
    assert 0 < alone_hit.sum() < n


def test_float_layer_written_from_a_strided_view_reads_back_exactly(tmp_path):
    packed = np.random.default_rng(7).random((48, 64 * 15)).astype(np.float32).reshape(48 * 64, 15)
    view = packed[:, 3:6].reshape(48, 64, 3)  # how shade() hands layers over: a column slice
    assert not view.flags.c_contiguous
    formats.write_float(tmp_path / "albedo.npy", view)
    assert np.array_equal(formats.read_float(tmp_path / "albedo.npy"), view)


def test_single_threaded_kernels_scope_limits_blas_and_opencv_then_restores():
    cv2.setNumThreads(2)
    before_blas = [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"]
    with single_threaded_kernels():
        assert cv2.getNumThreads() == 1
        assert all(info["num_threads"] == 1 for info in threadpool_info() if info["user_api"] == "blas")
    assert cv2.getNumThreads() == 2
    assert [info["num_threads"] for info in threadpool_info() if info["user_api"] == "blas"] == before_blas


def test_backend_registry_is_lazy_and_declares_capabilities():
    import subprocess
    import sys

    # The config, the modality table, the registry and the backend classes load neither embreex, pybullet nor bpy.
    code = (
        "import sys; from eden_pipe import config, modalities; from eden_pipe.render import backends; "
        "backends.get('tinyrenderer'); backends.get('raytrace'); backends.get('cycles'); "
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('embreex', 'pybullet', 'bpy')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"

    from eden_pipe import modalities
    from eden_pipe.config import ConfigError, validate
    from eden_pipe.render import backends
    from tests.conftest import make_cfg

    assert backends.names() == ("raytrace", "tinyrenderer", "cycles")
    assert backends.get("raytrace").capabilities == frozenset(modalities.MODALITIES)
    assert backends.get("tinyrenderer").capabilities == {"rgb", "semantic", "instance", "depth"}
    assert backends.get("tinyrenderer").max_frame_threads == 1
    assert backends.get("cycles").capabilities == frozenset(modalities.MODALITIES)  # labels from its Embree pass
    assert backends.get("cycles").max_frame_threads == 1  # one Blender scene
    assert modalities.BY_NAME["depth"].backends == ("raytrace", "tinyrenderer", "cycles")
    assert modalities.BY_NAME["flow"].backends == ("raytrace", "cycles")
    cfg = make_cfg("/tmp", [])
    cfg.render.backend = "mitsuba"
    with pytest.raises(ConfigError, match="raytrace"):
        validate(cfg)


def test_worker_layout_respects_backend_thread_limits():
    from types import SimpleNamespace

    from eden_pipe.stages.render import worker_layout

    ray = SimpleNamespace(backend="raytrace", threads=4, workers=2)
    assert worker_layout(ray, 10) == (2, 2)
    assert worker_layout(SimpleNamespace(backend="raytrace", threads=4, workers=8), 3) == (3, 1)
    assert worker_layout(SimpleNamespace(backend="tinyrenderer", threads=4, workers=2), 10) == (1, 1)
    # A moving mesh (wind): three scenes a frame thread, so an automatic count stops at two.
    assert worker_layout(SimpleNamespace(backend="raytrace", threads=8, workers=0), 10, moving=True) == (2, 4)
    assert worker_layout(SimpleNamespace(backend="raytrace", threads=8, workers=4), 10, moving=True) == (4, 2)


# ------------------------------------------------------------------ compiled kernels against their numpy
# The numpy each kernel of eden_pipe.render.kernels replaced, kept here as its oracle: the kernels keep its
# operations, order and precision, so the results must be bit-identical (not merely close).
def _bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


def _numpy_leave(points, normals, dist):
    scale = np.abs(points).max(axis=1) + np.minimum(dist, np.float32(1e6))
    return points + normals * (np.float32(1e-5) + np.float32(4.0 * 2.0**-23) * scale)[:, None]


@pytest.mark.parametrize("dtypes", [(np.float32, np.float32), (np.float64, np.float32), (np.float32, np.float64)])
def test_leave_kernel_is_bit_identical_to_numpy(dtypes):
    from eden_pipe.render.offsets import leave

    rng = np.random.default_rng(11)
    points = (rng.normal(size=(4001, 3)) * rng.uniform(0.01, 300, (4001, 1))).astype(dtypes[0])
    normals = vec.normalize(rng.normal(size=(4001, 3))).astype(np.float32)
    dist = rng.uniform(0.0, 3e6, 4001).astype(dtypes[1])
    dist[::7] = 0.0
    got = leave(points, normals, dist)
    assert _bits_equal(got, _numpy_leave(points, normals, dist))
    # strided and broadcast inputs take the same path
    assert _bits_equal(leave(points[::2], normals[::2], dist[::2]), _numpy_leave(points[::2], normals[::2], dist[::2]))


def _numpy_sun(weight, back_weight, cloud, n_dirs, sun, steps):
    for idx, c, seen in steps:
        weight[idx] += np.where(seen & (c > 0), c, np.float32(0.0))
        back_weight[idx] += np.where(seen & (c < 0), -c, np.float32(0.0))
    scale = (cloud / (np.pi * n_dirs)).astype(np.float32)
    return (weight * scale)[:, None] * sun, (back_weight * scale)[:, None] * sun


@pytest.mark.parametrize("cloud_dtype", [np.float32, np.float64])
def test_sun_weights_and_light_kernels_are_bit_identical_to_numpy(cloud_dtype):
    from eden_pipe.render import kernels

    rng = np.random.default_rng(12)
    n, n_dirs = 3000, 4
    steps = []
    for _ in range(n_dirs):
        idx = np.sort(rng.choice(n, 2000, replace=False))
        c = rng.uniform(-1, 1, 2000).astype(np.float32)
        c[::50] = 0.0
        steps.append((idx, c, rng.random(2000) < 0.7))
    cloud = rng.uniform(0.2, 1.0, n).astype(cloud_dtype)
    sun = np.array([3.1, 2.9, 2.4], np.float32)
    expected = _numpy_sun(np.zeros(n, np.float32), np.zeros(n, np.float32), cloud, n_dirs, sun, steps)
    weight, back_weight = np.zeros(n, np.float32), np.zeros(n, np.float32)
    for idx, c, seen in steps:
        kernels.add_sun_fractions(weight, back_weight, idx, c, seen.astype(np.float32))
    got = kernels.sun_light(weight, back_weight, cloud, np.pi * n_dirs, sun)
    assert all(_bits_equal(g, e) for g, e in zip(got, expected, strict=True))


def _numpy_flow(intr, points, sky_dirs, hit, pose_other, eps):
    u0, v0 = intr.pixel_grid()
    rot, centre = pose_other[:3, :3], pose_other[:3, 3]
    u1, v1, z1 = intr.project(vec.select(hit, points - centre, sky_dirs) @ rot)
    flow = np.stack([u1 - u0.ravel(), v1 - v0.ravel()], axis=1).astype(np.float32)
    flow = np.where(np.isfinite(flow), flow, np.float32(0.0))
    inside = (z1 > 1e-9) & (u1 >= -0.5) & (u1 < intr.width - 0.5) & (v1 >= -0.5) & (v1 < intr.height - 0.5)
    check = np.nonzero(inside)[0]
    surface = hit[check]
    p = vec.gather(points, check).astype(np.float32)
    to_cam = centre.astype(np.float32) - p
    dist = vec.length(to_cam)
    unit = to_cam / np.maximum(dist, np.float32(1e-12))[:, None]
    nudge = np.float32(2.0 * eps) * np.maximum(np.float32(1.0), dist)
    origins = vec.select(surface, p + unit * nudge[:, None], np.broadcast_to(centre.astype(np.float32), p.shape))
    dirs = vec.select(surface, unit, vec.gather(sky_dirs, check).astype(np.float32))
    tmax = np.where(surface, dist * np.float32(1.0 - 2.0 * eps) - nudge, np.float32(3.0e37))
    return flow, inside, (origins, dirs, tmax)


def test_flow_kernels_are_bit_identical_to_numpy():
    from eden_pipe.camera.rig import Intrinsics, look_rotation
    from eden_pipe.render import kernels
    from eden_pipe.render.shading import EPS
    from eden_pipe.render.view import primary_rays

    intr = Intrinsics(64, 48, 50.0, 50.0, 31.5, 23.5)
    pose, other = np.eye(4), np.eye(4)
    pose[:3, :3], pose[:3, 3] = look_rotation(0.3, -0.2), [1.0, 2.0, 0.8]
    other[:3, :3], other[:3, 3] = look_rotation(0.45, -0.1), [1.3, 2.2, 0.8]
    origins, dirs = primary_rays(intr, pose)
    rng = np.random.default_rng(13)
    hit = rng.random(len(dirs)) < 0.8
    t = np.where(hit, rng.uniform(0.05, 80.0, len(dirs)).astype(np.float32), np.float32(np.inf))
    t[::97] = 1e-7  # points at the other camera's centre plane and behind it
    points = origins + dirs * np.where(hit, t, 0.0)[:, None]
    unit = vec.normalize(dirs)
    flow, inside, rays = _numpy_flow(intr, points, unit, hit, other, EPS)
    assert 0 < inside.sum() < len(inside)
    cam = kernels.flow_relative(points, unit, hit, other[:3, 3]) @ other[:3, :3]
    got_flow, got_inside = kernels.reproject(cam, intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height)
    assert _bits_equal(got_flow, flow) and np.array_equal(got_inside, inside)
    check = np.nonzero(inside)[0]
    got_rays = kernels.occlusion_rays(
        points, unit, hit, check, other[:3, 3], np.float32(2.0 * EPS), np.float32(1.0 - 2.0 * EPS), np.float32(3.0e37)
    )
    assert all(_bits_equal(g, e) for g, e in zip(got_rays, rays, strict=True))


def test_primary_hits_kernel_is_bit_identical_to_numpy():
    from eden_pipe.render import kernels

    rng = np.random.default_rng(14)
    n = 5000
    origins = np.ascontiguousarray(np.broadcast_to(rng.normal(size=3) * 10, (n, 3)))
    directions = rng.normal(size=(n, 3))
    directions[::101] = 0.0  # zero rows stay zero
    t = rng.uniform(0.1, 50, n).astype(np.float32)
    normal = vec.normalize(rng.normal(size=(n, 3)).astype(np.float32))
    idx = np.sort(rng.choice(n, 3500, replace=False))
    dirs_hit = vec.gather(directions, idx).astype(np.float32, copy=False)
    d = vec.normalize(dirs_hit)
    points = vec.gather(origins, idx).astype(np.float32, copy=False) + dirs_hit * t[idx, None]
    facing, behind = vec.facing_side(vec.gather(normal, idx), d)
    got = kernels.primary_hits(idx, origins, directions, t, normal)
    assert all(_bits_equal(g, e) for g, e in zip(got, (d, points, facing, behind), strict=True))


@pytest.mark.parametrize("wide", [False, True])
def test_compose_kernel_is_bit_identical_to_numpy(wide):
    """The image formation against its numpy, float32 terms and (reference renderer, indirect rays)
    float64 shading and back light."""
    from eden_pipe.render import kernels

    rng = np.random.default_rng(15)
    n_rays, n_hit = 4000, 2500
    idx = np.sort(rng.choice(n_rays, n_hit, replace=False))
    high = np.float64 if wide else np.float32
    albedo = rng.random((n_hit, 3)).astype(np.float32)
    trans = np.where(rng.random(n_hit) < 0.3, rng.random(n_hit), 0.0).astype(np.float32)
    spec = np.where(rng.random(n_hit) < 0.3, rng.random(n_hit), 0.0).astype(np.float32)
    back, gloss, shading = (rng.random((n_hit, 3)).astype(high) * 3 for _ in range(3))
    background = vec.Scatter(np.setdiff1d(np.arange(n_rays), idx), n_rays).expand(
        rng.random((n_rays - n_hit, 3)).astype(np.float32)
    )
    # shading.compose before the kernel
    translucency = (albedo * trans[:, None] * back).astype(np.float32)
    glossy = (spec[:, None] * gloss).astype(np.float32)
    shading32 = shading.astype(np.float32)
    linear_hit = albedo * shading32 + glossy + translucency
    scatter = vec.Scatter(idx, n_rays)
    expected = {
        "albedo": scatter.expand(albedo),
        "shading": scatter.expand(shading32),
        "glossy": scatter.expand(glossy),
        "translucency": scatter.expand(translucency),
        "linear": scatter.expand(linear_hit) + background,
    }
    source = np.full(n_rays, -1, np.int64)
    source[idx] = np.arange(n_hit)
    for asked in (kernels.COMPOSED_LAYERS, ("shading",), ()):
        linear, values = kernels.compose_layers(
            source, albedo, trans, back, spec, gloss, shading32, background,
            np.array([k in asked for k in kernels.COMPOSED_LAYERS]),
        )  # fmt: skip
        assert _bits_equal(linear, expected["linear"])
        for k in asked:
            assert _bits_equal(values[kernels.COMPOSED_LAYERS.index(k)], expected[k])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_normalize_kernel_is_bit_identical_to_numpy(dtype):
    """vec.normalize against its numpy: zero, tiny, NaN and infinite rows included."""
    rng = np.random.default_rng(17)
    a = (rng.normal(size=(3001, 3)) * rng.uniform(1e-3, 1e3, (3001, 1))).astype(dtype)
    a[0], a[1], a[2], a[3] = 0.0, 1e-35, np.nan, np.inf
    with np.errstate(invalid="ignore"):
        expected = a / np.maximum(np.sqrt((a * a) @ np.ones(3, dtype)), dtype(1e-30))[:, None]
        assert _bits_equal(vec.normalize(a), expected)
        assert _bits_equal(vec.normalize(a[::3]), expected[::3])  # strided rows


def _numpy_visible_at(maps, slot, back, points):
    origin, axis_a, axis_b, steps_a, steps_b, across, first = (np.take(t, slot, axis=0) for t in maps._terms)
    q = points.astype(np.float32, copy=False) - origin
    u = np.clip(vec.dot(axis_a, q), np.float32(0.0), steps_a)
    v = np.clip(vec.dot(axis_b, q), np.float32(0.0), steps_b)
    i = np.minimum(u, steps_a - 1).astype(np.int32)
    j = np.minimum(v, steps_b - 1).astype(np.int32)
    u -= i
    v -= j
    node = (first + j * across + i) * 2 + back
    row = 2 * across
    flat = maps.visible.ravel()
    out = np.take(flat, node) * ((1 - u) * (1 - v))
    out += np.take(flat, node + 2) * (u * (1 - v))
    out += np.take(flat, node + row) * ((1 - u) * v)
    out += np.take(flat, node + row + 2) * (u * v)
    return out


def test_lightmap_kernel_is_bit_identical_to_numpy():
    from eden_pipe.render.lightmap import Lightmaps

    rng = np.random.default_rng(18)
    steps = rng.integers(1, 17, (40, 2)).astype(np.int32)
    first = np.concatenate([[0], np.cumsum((steps[:, 0] + 1) * (steps[:, 1] + 1))[:-1]]).astype(np.int32)
    frame = np.concatenate([rng.normal(size=(40, 3)), rng.normal(size=(40, 6)) * 10], axis=1).astype(np.float32)
    n_nodes = int(first[-1] + (steps[-1, 0] + 1) * (steps[-1, 1] + 1))
    maps = Lightmaps(np.arange(40, dtype=np.int32), frame, steps, first, rng.random((n_nodes, 2)).astype(np.float32))
    slot = rng.integers(0, 40, 5000).astype(np.int32)
    back = rng.random(5000) < 0.5
    points = (np.take(frame[:, :3], slot, axis=0) + rng.normal(size=(5000, 3)) * 0.5).astype(np.float32)
    assert _bits_equal(maps.visible_at(slot, back, points), _numpy_visible_at(maps, slot, back, points))


def test_bake_light_kernels_are_bit_identical_to_numpy():
    """SkyVisibility.bounce_light and .irradiance against their numpy, with negative sky terms and
    zero exposures (whose -0.0 products numpy's maximum turns into +0.0)."""
    from eden_pipe.render.visibility.frame_light import ProbeLight
    from eden_pipe.render.visibility.store import SkyVisibility

    rng = np.random.default_rng(19)
    n = 4000

    def three(scale=1.0):
        return (rng.normal(size=(n, 3)) * scale).astype(np.float32)

    rows = ProbeLight(three(), rng.random(n).astype(np.float32), three(0.1), three(0.1))
    exposure = rng.uniform(0, 2, n).astype(np.float32)
    exposure[::5] = 0.0
    ambient, cloud = np.abs(three()), rng.random(n).astype(np.float32)
    for c in (cloud, None):
        if c is None:
            bounce = rows.bounce_sky.copy()
        else:
            bounce = np.multiply(rows.bounce_sun, c[:, None])
            bounce += rows.bounce_sky
        np.maximum(bounce, np.float32(0.0), out=bounce)
        assert _bits_equal(SkyVisibility.bounce_light(rows, c), bounce)
        light = ambient * rows.visible[:, None]
        light += rows.sky
        light *= exposure[:, None]
        np.maximum(light, np.float32(0.0), out=light)
        light += bounce
        assert _bits_equal(SkyVisibility.irradiance(rows, exposure, ambient, bounce), light)


# ------------------------------------------------------------------ the render stage's writer pool
class _PassesBackend:
    """A backend stand-in: deterministic passes per pose (what the writers get), no rays."""

    def frame(self, time):
        return time

    def render_view(self, state, intr, pose, *, want, rng=None, **_):
        h, w = intr.height, intr.width
        draw = np.random.default_rng(int(abs(pose[:3, 3]).sum() * 1000) + int(state * 100))
        out = {"depth": draw.uniform(0.5, 30.0, (h, w)).astype(np.float32)}
        out["rgb_linear"] = draw.random((h, w, 3)).astype(np.float32)
        out["semantic"] = draw.integers(0, 5, (h, w)).astype(np.uint8)
        out["albedo"] = draw.random((h, w, 3)).astype(np.float32)
        return {k: v for k, v in out.items() if k in want or k in ("depth", "rgb_linear")}


def _frame_renderer(folder, cfg_factory, writers):
    from types import SimpleNamespace

    from eden_pipe.stages.render import FrameRenderer

    cfg = cfg_factory(["camera.width=40", "camera.height=30", "camera.cx=20", "camera.cy=15"])
    poses = np.tile(np.eye(4), (3, 2, 2, 1, 1))
    poses[..., :3, 3] = np.random.default_rng(16).uniform(-5, 5, poses.shape[:3] + (3,))
    modalities = {"rgb", "depth", "semantic", "albedo"}
    sky = SimpleNamespace(exposure=1.3)
    return FrameRenderer(folder, cfg, _PassesBackend(), sky, poses, modalities, 0, writers)


def test_writer_pool_writes_the_same_files_and_marks_a_frame_after_them(tmp_path, cfg_factory):
    from concurrent.futures import ThreadPoolExecutor

    from eden_pipe.io import layout

    for name in ("alone", "pool"):
        (tmp_path / name).mkdir()
        layout.unfinished(tmp_path / name, 3)  # makes the marker folder
    alone = _frame_renderer(tmp_path / "alone", cfg_factory, None)
    with ThreadPoolExecutor(2) as writers:
        pooled = _frame_renderer(tmp_path / "pool", cfg_factory, writers)
        for f in (0, 1):
            alone.render(f)
            pooled.render(f)
            marker = layout.marker_path(tmp_path / "pool", f)
            assert marker.is_file()
            written = json.loads(marker.read_text())["files"]
            paths = [tmp_path / "pool" / rel for files in written.values() for rel in files.values()]
            assert marker.stat().st_mtime_ns >= max(p.stat().st_mtime_ns for p in paths)
    files = sorted(p.relative_to(tmp_path / "alone") for p in (tmp_path / "alone").rglob("*") if p.is_file())
    assert len(files) == 2 * (2 * 6 + 1)  # frames x (pairs x (rgb and depth left and right, semantic, albedo) + marker)
    for rel in files:
        if rel.parts[0] != layout.MARKERS:
            assert (tmp_path / "alone" / rel).read_bytes() == (tmp_path / "pool" / rel).read_bytes(), rel


def test_a_failed_write_in_the_pool_fails_the_frame_without_a_marker(tmp_path, cfg_factory, monkeypatch):
    from concurrent.futures import ThreadPoolExecutor

    from eden_pipe.io import layout

    real_write = layout.write_files

    def second_pair_fails(folder, files, data, options):
        if any(rel.startswith("cam1/") for rel in files.values()):
            raise OSError("disk full")
        real_write(folder, files, data, options)

    layout.unfinished(tmp_path, 3)
    monkeypatch.setattr(layout, "write_files", second_pair_fails)
    with ThreadPoolExecutor(1) as writers:
        with pytest.raises(OSError, match="disk full"):
            _frame_renderer(tmp_path, cfg_factory, writers).render(0)
    assert (tmp_path / "cam0" / "albedo" / "00000.exr").is_file()  # the first pair was written
    assert not layout.marker_path(tmp_path, 0).exists()
