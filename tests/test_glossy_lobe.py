"""The glossy sun lobe (``kernels.glossy_lobe``, ``shading.glossy_parts``): Cycles' Beckmann
microfacet BRDF, checked against its formulas in float64 and its closed forms (docs/realism.md,
Cycles: The glossy light). ``tests/test_cycles.py`` checks it against Cycles itself."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.render import vec
from tests.test_render_kernels import _bits_equal, _numpy_power


def _numpy_glossy_parts(n, d, front_sun, to_sun, alpha):
    """The glossy lobe as numpy spells it: Beckmann's D and Smith's height-correlated G with the rational
    Lambda (in float64), and the mirror and its Fresnel weight as float32 steps."""
    n64, d64, l64 = n.astype(np.float64), d.astype(np.float64), to_sun.astype(np.float64)
    h = l64[None] - d64
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    cos_h, cos_l, cos_v = (n64 * h).sum(1), n64 @ l64, -(n64 * d64).sum(1)

    def lam(c):
        s = alpha**2 * np.maximum((1.0 - c * c) / np.maximum(c * c, 1e-300), 0.0)
        a = 1.0 / np.sqrt(np.maximum(s, 1e-300))
        return np.where(s < 0.39, 0.0, ((0.396 * a - 1.259) * a + 1.0) / ((2.181 * a + 3.535) * a))

    valid = (cos_h > 0) & (cos_l > 0) & (cos_v > 0)
    c2 = np.where(valid, cos_h * cos_h, 1.0)
    beckmann = np.exp((1.0 - 1.0 / c2) / alpha**2) / (np.pi * alpha**2 * c2 * c2)
    brdf = beckmann / (1.0 + lam(cos_v) + lam(cos_l)) / np.where(valid, 4.0 * cos_v * cos_l, 1.0)
    lobe = np.where(valid, np.pi * brdf, 0.0)  # front_sun is E cos(l) / pi
    d_dot_n = vec.dot(d, n)
    mirror = d - (np.float32(2.0) * d_dot_n)[:, None] * n
    grazing = np.float32(1.0) - np.clip(-d_dot_n, 0.0, 1.0)
    fresnel = np.float32(0.04) + np.float32(0.96) * _numpy_power(grazing, 5)
    return front_sun * lobe[:, None], mirror, np.minimum(fresnel / np.float32(0.04), np.float32(2.0))


@pytest.mark.parametrize("front_dtype", [np.float32, np.float64])
def test_glossy_lobe_kernel_matches_the_beckmann_microfacet_brdf(front_dtype):
    """The kernel against the formulas in float64: the lobe to float32 rounding, the mirror and its weight
    bit for bit (they are float32 steps in both)."""
    from eden_pipe.render.shading import GLOSS_ALPHA, glossy_parts

    rng = np.random.default_rng(15)
    count = 20000
    n = vec.normalize(rng.normal(size=(count, 3)).astype(np.float32))
    d = vec.normalize(rng.normal(size=(count, 3)).astype(np.float32))
    d[::53] = -n[::53]  # head-on: no Fresnel gain
    front = rng.uniform(0.0, 3.0, (count, 3)).astype(front_dtype)
    front[::7] = 0.0  # in shadow
    to_sun = vec.normalize(np.array([[0.3, -0.5, 0.8]], np.float32))[0]
    near = np.arange(2, count, 11)  # sunlit faces seen near the sun's mirror, where the lobe is large
    n[near] *= np.sign(n[near] @ to_sun)[:, None]
    mirrored_sun = to_sun[None] - 2.0 * (n[near] @ to_sun)[:, None] * n[near]
    d[near] = vec.normalize((mirrored_sun + 0.2 * rng.normal(size=(len(near), 3))).astype(np.float32))
    d[1::57] = n[1::57]  # seen from behind: the clip's upper end, no lobe

    class Sky:
        sun_direction = to_sun

    got = glossy_parts(n, d, front, Sky())
    want = _numpy_glossy_parts(n, d, front, to_sun, GLOSS_ALPHA)
    assert got[0].dtype == np.result_type(front_dtype, np.float32)
    assert _bits_equal(got[1], want[1]) and _bits_equal(got[2], want[2])
    # float32 rounding, relative to the lobe's scale (exp of a large negative argument loses digits)
    np.testing.assert_allclose(got[0], want[0], rtol=2e-5, atol=1e-6 * float(want[0].max()))
    assert np.count_nonzero(got[0][near]) > 0.3 * len(near) * 3
    assert np.all(got[0][1::57] == 0.0) and np.all(got[2] <= 2.0) and np.all(got[2] >= 1.0)


def test_glossy_lobe_is_cycles_beckmann_brdf_in_closed_form():
    """At normal incidence the lobe is pi D(0) / 4 = 1 / (4 alpha^2); it is reciprocal in view and sun;
    and its directional albedo under a sun overhead (the lobe's energy over the hemisphere of views, times
    cos(v) / pi per unit front_sun) is below 1 and close to it at this roughness (Smith's G loses little)."""
    from eden_pipe.render.shading import GLOSS_ALPHA, glossy_parts

    class Overhead:
        sun_direction = np.array([0.0, 0.0, 1.0], np.float32)

    up = np.array([[0.0, 0.0, 1.0]], np.float32)
    peak = glossy_parts(up, -up, np.ones((1, 3), np.float32), Overhead())[0][0, 0]
    assert peak == pytest.approx(1.0 / (4.0 * GLOSS_ALPHA**2), rel=1e-6)

    rng = np.random.default_rng(3)
    a, b = (
        vec.normalize(rng.normal(size=(500, 3)) * [1, 1, 0] + [0, 0, 1.5]),
        vec.normalize(rng.normal(size=(500, 3)) * [1, 1, 0] + [0, 0, 1.5]),
    )
    normals = np.broadcast_to(up, (500, 3))
    lobes = []  # per unit front_sun the lobe is pi f, f the BRDF: the same with view and sun swapped
    for view, sun in ((a, b), (b, a)):
        per = [
            glossy_parts(normals[i : i + 1], -view[i : i + 1].astype(np.float32), np.ones((1, 3), np.float32), _Sun(s))
            for i, s in enumerate(sun)
        ]
        lobes.append(np.array([p[0][0, 0] for p in per]))
    np.testing.assert_allclose(lobes[0], lobes[1], rtol=1e-4)  # f(v, l) = f(l, v)

    # Directional albedo: E_v over the hemisphere of views (cosine-weighted) of lobe * cos(v) / pi.
    u1, u2 = rng.random(200000), rng.random(200000)
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    views = np.stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1 - u1)], 1).astype(np.float32)
    lobe = glossy_parts(np.broadcast_to(up, views.shape), -views, np.ones(views.shape, np.float32), Overhead())[0][:, 0]
    albedo = float(lobe.mean())  # cosine-distributed views: the mean of the lobe is its albedo
    assert 0.9 < albedo < 1.0


class _Sun:
    def __init__(self, direction):
        self.sun_direction = np.asarray(direction, np.float32)
