"""Compiled copies of numpy's own steps agree with numpy to the bit.

vec.take (numpy's take for gathers of items, (P, 3) rows and one-word rows), sh.basis and
sh.along (the SH functions at directions, and a table's rows evaluated along them: einsum's
order), embree.unit_normals (Embree's normals over their length), a view's hit points, the
blocked mirror's radiance, a frame light's rows and the pair's share lookup.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.camera.rig import Intrinsics
from eden_pipe.render import kernels, pixel_sky, sh, vec
from eden_pipe.render.embree import unit_normals
from eden_pipe.render.visibility.frame_light import ProbeLight
from eden_pipe.render.visibility.store import MIN_BLOCKED, SkyVisibility


def _bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a.view(np.uint8), b.view(np.uint8))


@pytest.mark.parametrize("dtype", [np.float32, np.float64, np.int32, np.int64, np.uint8, np.uint16, np.bool_])
def test_take_is_numpys_take(dtype):
    """vec.take (and gather, Scatter) against np.take(axis=0): the compiled 1-D and (P, 3) copies,
    negative indices, empty and strided inputs, other widths through numpy, and the same error
    for an index outside the table."""
    rng = np.random.default_rng(23)
    table = (rng.normal(size=(1000, 3)) * 100).astype(dtype)
    for a in (table, table[:, 0].copy(), table[:, :2].copy(), table[::2], table[:, 1]):
        for index in (
            rng.integers(-len(a), len(a), 5000),
            rng.integers(0, len(a), 700).astype(np.int32),
            np.zeros(0, np.int64),
            rng.integers(0, len(a), (4, 3)),
        ):
            assert _bits_equal(vec.take(a, index), np.take(a, index, axis=0))
        for outside in (len(a), -len(a) - 1):
            with pytest.raises(IndexError):
                vec.take(a, np.array([0, outside, 1]))
    index = rng.integers(0, 1000, 300)
    assert _bits_equal(vec.gather(table, index), table[index])
    scatter = vec.Scatter(np.array([5, 2, 7]), 9)
    expected = np.zeros((9, 3), dtype)
    expected[[5, 2, 7]] = table[:3]
    assert _bits_equal(scatter.expand(table[:3]), expected)


def _numpy_sh_basis(directions):
    """``sh.basis`` as whole-array numpy (numpy's weakly typed scalars: float32 throughout)."""
    x, y, z = np.asarray(directions, np.float32).T.copy()
    xx, yy, zz = x * x, y * y, z * z
    rows = [
        np.full_like(x, 0.282095),
        0.488603 * y,
        0.488603 * z,
        0.488603 * x,
        1.092548 * x * y,
        1.092548 * y * z,
        0.315392 * (3.0 * z * z - 1.0),
        1.092548 * x * z,
        0.546274 * (x * x - y * y),
        0.590044 * y * (3.0 * xx - yy),
        2.890611 * x * y * z,
        0.457046 * y * (5.0 * zz - 1.0),
        0.373176 * z * (5.0 * zz - 3.0),
        0.457046 * x * (5.0 * zz - 1.0),
        1.445306 * z * (xx - yy),
        0.590044 * x * (xx - 3.0 * yy),
    ]
    return np.stack(rows).T  # column-major, as sh.basis returns it


def test_sh_basis_and_along_are_numpys_to_the_bit():
    """sh.basis against whole-array numpy (float64 and float32 directions, strided rows, odd
    values), and sh.along against the einsum of the gathered rows it replaces."""
    rng = np.random.default_rng(29)
    d = rng.normal(size=(20001, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[:2], d[2] = 0.0, [1e20, -1e20, 3.0]
    with np.errstate(over="ignore", invalid="ignore"):
        for directions in (d, d.astype(np.float32), d[::3], np.asfortranarray(d)):
            ours, numpy_ = sh.basis(directions), _numpy_sh_basis(directions)
            assert ours.strides == numpy_.strides
            assert _bits_equal(np.ascontiguousarray(ours), np.ascontiguousarray(numpy_))
    d = d[3:]
    table = (rng.normal(size=(5000, sh.COUNT)) * rng.uniform(1e-4, 1.0, (5000, 1))).astype(np.float32)
    for n in (len(d), 63, 1, 0):
        rows = rng.integers(0, len(table), n)
        for directions in (d[:n], d[:n].astype(np.float32)):
            expected = np.einsum("ij,ij->i", np.take(table, rows, axis=0), _numpy_sh_basis(directions))
            assert _bits_equal(sh.along(table, rows, directions), expected)
    with pytest.raises(ValueError, match="float32"):
        sh.along(table.astype(np.float64), rows, d[:n])


def test_unit_normals_are_numpys_to_the_bit():
    """Embree's normals scaled as numpy scales them: zero rows stay zero, tiny and huge rows too."""
    rng = np.random.default_rng(31)
    ng = (rng.normal(size=(30001, 3)) * rng.uniform(1e-20, 1e15, (30001, 1))).astype(np.float32)
    ng[:3], ng[3] = 0.0, 1e-35
    length = np.sqrt((ng * ng) @ np.ones(3, np.float32))
    expected = ng * (np.float32(1.0) / np.maximum(length, np.float32(1e-30)))[:, None]
    assert _bits_equal(unit_normals(ng), expected)
    assert _bits_equal(unit_normals(ng[::7]), expected[::7])


def test_hit_points_and_blocked_radiance_are_numpys_to_the_bit():
    """view's hit points (float64 rays, float32 distances, misses at the origin) and the mean
    radiance behind a blocked mirror (visible fractions outside [0, 1], NaN and near 1 included)."""
    rng = np.random.default_rng(37)
    origins = np.broadcast_to(rng.normal(size=3), (4001, 3)).copy()
    dirs = rng.normal(size=(4001, 3))
    t = rng.uniform(0.1, 80.0, 4001).astype(np.float32)
    hit = rng.random(4001) < 0.8
    t[~hit] = np.inf
    expected = origins + dirs * np.where(hit, t, 0.0)[:, None]
    assert _bits_equal(kernels.hit_points(origins, dirs, t, hit), expected)
    bounce = rng.uniform(0.0, 2.0, (500, 3)).astype(np.float32)
    visible = rng.uniform(-0.2, 1.2, 500).astype(np.float32)
    visible[:3] = np.nan, 1.0, 0.96
    index = rng.integers(0, 500, 3000)
    with np.errstate(invalid="ignore"):
        clipped = np.clip(visible[index], np.float32(0.0), np.float32(1.0))
        expected = bounce[index] / np.maximum(np.float32(1.0) - clipped, np.float32(MIN_BLOCKED))[:, None]
        assert _bits_equal(SkyVisibility.blocked_radiance(bounce, visible, index), expected)
    with pytest.raises(IndexError):
        SkyVisibility.blocked_radiance(bounce, visible, np.array([500]))


@pytest.mark.parametrize("own_sun", [False, True])
def test_probe_light_rows_taken_in_one_pass_are_each_terms(own_sun):
    """ProbeLight.take's one pass gives every term's own np.take, as contiguous arrays."""
    rng = np.random.default_rng(41)
    light = ProbeLight.empty(own_sun)
    terms = {k: rng.normal(size=(300,) + v.shape[1:]).astype(np.float32) for k, v in light.terms().items()}
    light = ProbeLight(**terms)
    index = rng.integers(-300, 300, 2000).astype(np.int32)
    taken = light.take(index)
    for k, v in terms.items():
        got = getattr(taken, k)
        assert got.flags.c_contiguous and _bits_equal(got, np.take(v, index, axis=0))
    with pytest.raises(IndexError):
        light.take(np.array([300]))


def test_share_lookup_is_the_numpy_projection_to_the_bit():
    """SkyShare.lookup's compiled steps after the camera-frame product against numpy's: points behind
    the camera, outside the image, on pixel edges (rint's ties to even) and on other face sides."""
    intr = Intrinsics(64, 48, 60.0, 61.0, 31.5, 23.5)
    pose = np.eye(4)
    pose[:3, 3] = [0.3, -0.2, 0.1]
    rng = np.random.default_rng(43)
    share = pixel_sky.SkyShare(pose, intr, rng.integers(-1, 4, 64 * 48), rng.random(64 * 48).astype(np.float32))
    cam = np.column_stack([rng.uniform(-1.2, 1.2, (5000, 2)), rng.uniform(-1.0, 3.0, 5000)])
    cam[:50, 0] = (np.arange(50) % 8 + 0.5 - intr.cx) / intr.fx * cam[:50, 2]  # u exactly between pixels
    points = cam @ pose[:3, :3].T + pose[:3, 3]
    sides = rng.integers(-1, 4, 5000)
    u, v, _ = intr.project((points - pose[:3, 3]) @ pose[:3, :3])
    u, v = np.rint(u), np.rint(v)
    inside = (u >= 0) & (u < intr.width) & (v >= 0) & (v < intr.height)
    pixel = np.where(inside, v * intr.width + u, 0).astype(np.int64)
    same = inside & (np.take(share.side, pixel) == sides)
    expected = np.where(same, np.take(share.factor, pixel), np.float32(np.nan)).astype(np.float32)
    assert _bits_equal(share.lookup(points, sides), expected)
