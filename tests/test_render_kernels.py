"""The renderer's fast kernels agree with the plain numpy they replace.

vec.* (row dots, gathers, scatters, sign flips, integer powers), lut.sample
(cv2.remap table lookups), the shared-direction Embree query, the float-layer
writer on strided views, and the single-threaded kernel scope of the render stage.
"""

from __future__ import annotations

import itertools

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
    x = np.linspace(0.0, 1.0, 1001, dtype=np.float32)
    np.testing.assert_allclose(vec.power(x, exponent), x.astype(np.float64) ** exponent, rtol=2e-5, atol=1e-30)
    with pytest.raises(ValueError, match="exponent=0"):
        vec.power(x, 0)


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
