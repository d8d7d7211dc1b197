"""Sky and sun: Preetham / CIE overcast / twilight radiance, sun colour, scale
convention, ambient lookup, cloud shadows, scenery and lighting sampling.
The lighting config checks are in test_lighting.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from eden_pipe.render.sky import (
    LUMA,
    SCENARIOS,
    LightingParams,
    Sky,
    clear_reference_irradiance,
    sample_lighting,
    zenith_chromaticity,
    zenith_luminance,
)


def params(
    scenario: str, elev_deg: float, turbidity: float = 2.5, cover: float = 0.0, az_deg: float = 30.0, **kw
) -> LightingParams:
    return LightingParams(scenario, math.radians(elev_deg), math.radians(az_deg), turbidity, cloud_cover=cover, **kw)


TYPICAL = {
    "clear": params("clear", 45.0, 2.5),
    "cloudy": params("cloudy", 40.0, 4.0, cover=0.45),
    "overcast": params("overcast", 45.0, 3.0, cover=1.0),
    "sunset": params("sunset", 3.0, 4.0),
    "twilight": params("twilight", -3.0, 2.5),
    "night": params("night", 35.0, 3.0, moon_phase=0.8),
}


@pytest.fixture(scope="module")
def skies() -> dict[str, Sky]:
    return {name: Sky(p, seed=5) for name, p in TYPICAL.items()}


def sphere_dirs(n: int = 3000) -> np.ndarray:
    """Fibonacci sphere plus the poles and exact horizon directions."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], -1)
    a = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
    horizon = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1)
    return np.concatenate([d, horizon, [[0, 0, 1.0], [0, 0, -1.0]]])


def dir_at(elev_deg: float, az_deg: float) -> np.ndarray:
    e, a = math.radians(elev_deg), math.radians(az_deg)
    return np.array([[math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)]])


def lum(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb) @ LUMA


def test_radiance_finite_nonnegative_everywhere(skies):
    d = sphere_dirs()
    for name, sky in skies.items():
        for t in (0.0, 7.5):
            L = sky.radiance(d, time=t)
            assert L.shape == (len(d), 3)
            assert np.all(np.isfinite(L)) and np.all(L >= 0.0), name
            assert np.all(lum(L[d[:, 2] < 0]) > 0.0), f"{name}: below-horizon radiance must not be black"
        E = sky.ambient_irradiance(d)
        assert np.all(np.isfinite(E)) and np.all(E >= 0.0), name
        mask, rgb = sky.scenery(d)
        assert mask.shape == (len(d),) and rgb.shape == (len(d), 3)
        assert np.all(np.isfinite(rgb)) and np.all(rgb >= 0.0), name
        assert np.all(lum(rgb[mask]) > 0.0), name
        assert sky.sun_direction.shape == (3,) and abs(np.linalg.norm(sky.sun_direction) - 1.0) < 1e-12
        assert math.isfinite(sky.exposure) and sky.exposure > 0.0
        assert abs(math.degrees(2 * sky.sun_angular_radius) - 0.53) < 0.01


def test_sun_direction_convention():
    sky = Sky(params("clear", 30.0, az_deg=90.0), seed=0)  # azimuth from +x toward +y
    np.testing.assert_allclose(sky.sun_direction, [0.0, math.cos(math.radians(30)), 0.5], atol=1e-12)


def test_zenith_luminance_and_chromaticity_values():
    # chi = (4/9 - 2/120)(pi - pi/2) = 0.671952; Yz = 3.1196 tan(chi) + 1.9882 = 4.4696 kcd/m^2
    assert zenith_luminance(math.pi / 4, 2.0) == pytest.approx(4.4696, abs=1e-3)
    # theta_s = 0 leaves the constant column: xz = .00394 T + .25886, yz = .00516 T + .26688
    assert zenith_chromaticity(0.0, 2.0) == pytest.approx((0.26674, 0.27720), abs=1e-6)


def test_preetham_zenith_radiance_matches_formula_and_scale():
    p = params("clear", 45.0, 2.0)
    sky = Sky(p, seed=0)
    zen = sky.radiance(np.array([[0.0, 0.0, 1.0]]))[0]
    expected = zenith_luminance(math.pi / 4, 2.0)  # F(0, ts) / F(0, ts) = 1 at the zenith
    from eden_pipe.render.sky import K_SCALE

    assert lum(zen) == pytest.approx(K_SCALE * expected, rel=5e-3)
    x, y = zenith_chromaticity(math.pi / 4, 2.0)
    assert zen[2] > zen[0]  # a clear zenith is blue (x, y ~ 0.24)
    assert 0.2 < x < 0.3 and 0.2 < y < 0.3


def test_clear_sky_brighter_near_sun_than_opposite(skies):
    sky = skies["clear"]
    near = lum(sky.radiance(dir_at(45.0, 40.0)))[0]  # 10 deg from the sun
    opposite = lum(sky.radiance(dir_at(45.0, 210.0)))[0]
    assert near > 2.0 * opposite


def test_scale_convention_clear_sun_is_pi_at_60_deg():
    sky = Sky(params("clear", 60.0, 2.5), seed=0)
    assert lum(sky.sun_irradiance) == pytest.approx(math.pi, rel=1e-9)
    sun_h = lum(sky.sun_irradiance) * math.sin(math.radians(60.0))
    sky_h = lum(sky.ambient_irradiance(np.array([[0.0, 0.0, 1.0]]))[0])
    assert 0.1 < sky_h / sun_h < 0.4, sky_h / sun_h
    assert lum(sky.horizontal_irradiance) == pytest.approx(clear_reference_irradiance(), rel=0.01)


def test_overcast_cie_distribution_and_no_sun(skies):
    sky = skies["overcast"]
    assert np.all(sky.sun_irradiance == 0.0)
    zen = sky.radiance(np.array([[0.0, 0.0, 1.0]]))[0]
    hor = sky.radiance(np.array([[1.0, 0.0, 0.0]]))[0]
    assert zen[0] / hor[0] == pytest.approx(3.0, rel=1e-9)
    mid = sky.radiance(dir_at(30.0, 123.0))[0]
    assert mid[0] / zen[0] == pytest.approx((1 + 2 * 0.5) / 3, rel=1e-9)
    np.testing.assert_allclose(zen, zen[0])  # neutral white
    clear_same_sun = Sky(params("clear", 45.0, 2.5), seed=0)
    ratio = lum(sky.horizontal_irradiance) / lum(clear_same_sun.horizontal_irradiance)
    assert 0.25 <= ratio <= 0.4, ratio
    assert np.all(sky.cloud_transmittance(np.random.default_rng(0).uniform(0, 10, (50, 3))) == 1.0)


def test_twilight_dim_blue_no_sun_glow_toward_sun(skies):
    sky, clear = skies["twilight"], skies["clear"]
    assert np.all(sky.sun_irradiance == 0.0)
    up = np.array([[0.0, 0.0, 1.0]])
    e_tw = lum(sky.ambient_irradiance(up))[0]
    e_clear = lum(clear.horizontal_irradiance)
    assert 0.005 < e_tw / e_clear < 0.06, e_tw / e_clear
    E = sky.ambient_irradiance(up)[0]
    assert E[2] > 1.5 * E[0]  # bluish
    toward = lum(sky.radiance(dir_at(3.0, 30.0)))[0]
    away = lum(sky.radiance(dir_at(3.0, 210.0)))[0]
    assert toward > 1.5 * away
    assert np.all(sky.cloud_transmittance(np.zeros((4, 3))) == 1.0)


def test_sunset_sun_red_shifted(skies):
    sunset, clear = skies["sunset"].sun_irradiance, skies["clear"].sun_irradiance
    assert sunset[0] / sunset[2] > 3.0 * (clear[0] / clear[2])
    assert clear[0] / clear[2] > 1.0  # even the noon sun is slightly warm (Rayleigh)
    assert lum(sunset) < lum(clear)


def test_exposed_brightness_order(skies):
    def exposed(name: str) -> float:
        s = skies[name]
        return lum(s.horizontal_irradiance) * s.exposure

    assert exposed("twilight") < exposed("overcast") < exposed("clear")
    assert exposed("twilight") < exposed("sunset") < exposed("clear")
    assert skies["twilight"].exposure > skies["overcast"].exposure > skies["clear"].exposure


def brute_force_irradiance(sky: Sky, normal: np.ndarray, n_u: int = 300, n_phi: int = 600) -> np.ndarray:
    """Integrate L (n.d)+ over the full sphere on a uniform (cos theta, phi) midpoint grid."""
    u = -1.0 + (np.arange(2 * n_u) + 0.5) / n_u  # cos theta in (-1, 1)
    phi = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
    U, P = np.meshgrid(u, phi, indexing="ij")
    r = np.sqrt(1.0 - U * U)
    d = np.stack([r * np.cos(P), r * np.sin(P), U], -1).reshape(-1, 3)
    cos = np.clip(d @ normal, 0.0, None)
    keep = cos > 0.0
    L = sky.radiance(d[keep])
    return (L * cos[keep, None]).sum(0) * (1.0 / n_u) * (2 * math.pi / n_phi)


@pytest.mark.parametrize("name", list(TYPICAL))
def test_ambient_up_matches_brute_force(skies, name):
    sky = skies[name]
    up = np.array([0.0, 0.0, 1.0])
    ref = brute_force_irradiance(sky, up)
    got = sky.ambient_irradiance(up[None])[0]
    np.testing.assert_allclose(got, ref, rtol=0.03)


@pytest.mark.parametrize("name", ["clear", "sunset", "twilight", "cloudy"])
def test_ambient_tilted_matches_brute_force(skies, name):
    sky = skies[name]
    n = np.array([math.sin(1.1) * math.cos(0.4), math.sin(1.1) * math.sin(0.4), math.cos(1.1)])
    ref = brute_force_irradiance(sky, n, 200, 400)
    got = sky.ambient_irradiance(n[None])[0]
    np.testing.assert_allclose(got, ref, rtol=0.03)


def test_cloud_shadows_move_and_clear_has_none(skies):
    rng = np.random.default_rng(1)
    pts = np.concatenate([rng.uniform(0, 10, (400, 2)), rng.uniform(0, 2, (400, 1))], axis=1)
    assert np.all(skies["clear"].cloud_transmittance(pts, 0.0) == 1.0)
    assert np.all(skies["sunset"].cloud_transmittance(pts, 3.0) == 1.0)
    cloudy = skies["cloudy"]
    series = np.stack([cloudy.cloud_transmittance(pts, t) for t in np.arange(0.0, 60.0, 4.0)])
    assert np.all((series >= 0.0) & (series <= 1.0))
    assert series.min() < 0.3 and series.max() > 0.99  # both shadow and sun over the run
    assert np.abs(series[1:] - series[:-1]).mean() > 1e-3  # shadows move with time
    same = Sky(TYPICAL["cloudy"], seed=5)
    np.testing.assert_array_equal(same.cloud_transmittance(pts, 2.0), cloudy.cloud_transmittance(pts, 2.0))
    still = Sky(params("cloudy", 40.0, 4.0, cover=0.45, cloud_speed=0.0), seed=5)
    np.testing.assert_array_equal(still.cloud_transmittance(pts, 0.0), still.cloud_transmittance(pts, 30.0))


def test_clouds_in_sky_drift_and_whiten(skies):
    cloudy, clear = skies["cloudy"], Sky(params("cloudy", 40.0, 4.0, cover=0.0), seed=5)
    d = sphere_dirs(2000)
    d = d[d[:, 2] > 0.3]
    a, b = cloudy.radiance(d, 0.0), cloudy.radiance(d, 20.0)
    assert np.abs(a - b).max() > 1e-3
    # Clouds grey the blue sky: lower blue/red ratio than the cloud-free sky.
    c = clear.radiance(d)
    assert (a[:, 2] / a[:, 0]).mean() < (c[:, 2] / c[:, 0]).mean()


def test_scenery_is_a_seeded_function_of_direction():
    a = Sky(TYPICAL["clear"], seed=3)
    d = sphere_dirs(4000)
    mask, rgb = a.scenery(d)
    assert mask[d[:, 2] < 0].all()  # the distant ground fills below the horizon
    assert not mask[d[:, 2] > math.sin(math.radians(15))].any()
    assert mask[(d[:, 2] >= 0)].any()  # some silhouette rises above the horizon
    # Pure function of direction: batch order and vector length do not matter.
    perm = np.random.default_rng(0).permutation(len(d))
    m2, rgb2 = a.scenery(2.5 * d[perm])
    np.testing.assert_array_equal(m2, mask[perm])
    np.testing.assert_allclose(rgb2, rgb[perm], rtol=1e-12, atol=1e-15)
    # Deterministic per seed, different across seeds; silhouette independent of the lighting.
    m3, rgb3 = Sky(TYPICAL["clear"], seed=3).scenery(d)
    np.testing.assert_array_equal(m3, mask)
    np.testing.assert_array_equal(rgb3, rgb)
    m4, _ = Sky(TYPICAL["clear"], seed=4).scenery(d)
    assert (m4 != mask).any()
    m5, rgb5 = Sky(TYPICAL["twilight"], seed=3).scenery(d)
    np.testing.assert_array_equal(m5, mask)
    assert lum(rgb5[mask]).mean() < lum(rgb[mask]).mean()  # lit by the scenario


def test_sample_lighting_draws_within_ranges_and_is_deterministic():
    cfg = dict(
        name="clear",
        sun_elevation_deg=[35, 60],
        sun_azimuth_deg=[0, 360],
        turbidity=[2, 3],
        sun_intensity=1.0,
        sky_intensity=1.0,
        cloud_cover=[0, 0],
        cloud_speed=1.0,
    )
    p = sample_lighting(cfg, np.random.default_rng(7))
    assert p.scenario == "clear"
    assert math.radians(35) <= p.sun_elevation <= math.radians(60)
    assert 2 <= p.turbidity <= 3 and p.cloud_cover == 0.0 and p.sun_intensity == 1.0
    assert p == sample_lighting(cfg, np.random.default_rng(7))
    for name in SCENARIOS:  # defaults alone give a valid sky
        q = sample_lighting({"name": name}, np.random.default_rng(0))
        assert q.scenario == name
        Sky(q, seed=0)
    assert sample_lighting({"name": "twilight"}, np.random.default_rng(0)).sun_elevation < 0


def test_sample_lighting_checks_its_config_with_check_lighting():
    """Direct callers get the one check (eden_pipe.lighting.check_lighting), not a render-time crash."""
    from eden_pipe.errors import ConfigError

    with pytest.raises(ConfigError, match=r"lighting\.turbidity='\[12, 15\]'.*scenario clear"):
        sample_lighting({"name": "clear", "turbidity": [12, 15]}, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="sun_elevaton_deg"):
        sample_lighting({"name": "clear", "sun_elevaton_deg": [30, 40]}, np.random.default_rng(0))


def test_sample_lighting_reads_typed_and_dict_configs_alike():
    from omegaconf import OmegaConf

    from eden_pipe.lighting import LightingConfig

    typed = OmegaConf.structured(LightingConfig.for_scenario("cloudy"))
    draws = [
        sample_lighting(c, np.random.default_rng(3))
        for c in (
            typed,
            LightingConfig.for_scenario("cloudy"),
            {"name": "cloudy"},
            OmegaConf.create({**OmegaConf.to_container(typed)}),
        )
    ]
    assert all(d == draws[0] for d in draws)


@pytest.mark.parametrize("name", SCENARIOS)
def test_shipped_lighting_configs_build_a_sky(name):
    yaml = pytest.importorskip("yaml")
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "conf" / "lighting" / f"{name}.yaml"
    if not path.exists():
        pytest.skip(f"{path} not present")
    cfg = yaml.safe_load(path.read_text())
    p = sample_lighting(cfg, np.random.default_rng(0))
    assert p.scenario == name
    sky = Sky(p, seed=0)
    assert np.all(np.isfinite(sky.radiance(sphere_dirs(200))))


def test_cloud_shadow_map_matches_exact_transmittance(skies):
    from eden_pipe.render.sky import CloudShadowMap

    sky = skies["cloudy"]
    rng = np.random.default_rng(11)
    garden = np.column_stack([rng.uniform(0, 20, 20000), rng.uniform(0, 20, 20000), rng.uniform(0, 5, 20000)])
    far = np.column_stack([rng.uniform(-60, 80, 5000), rng.uniform(-60, 80, 5000), np.zeros(5000)])
    outside = np.array([[500.0, 500.0, 0.0], [-300.0, 40.0, 2.0]])  # beyond every table: evaluated exactly
    regions = [((0, 0, 0), (20, 20, 5), 0.2), ((-60, -60, 0), (80, 80, 5), 0.5)]
    for t in (0.0, 4.0):
        cmap = CloudShadowMap(sky, t, regions)
        for pts, tol in ((garden, 0.005), (far, 0.03)):
            exact = sky.cloud_transmittance(pts, t)
            got = cmap.transmittance(pts)
            assert np.max(np.abs(got - exact)) < tol and np.mean(np.abs(got - exact)) < tol / 10
            assert exact.min() < 0.5 < exact.max(), "the sample must cross cloud shadow edges"
        np.testing.assert_allclose(cmap.transmittance(outside), sky.cloud_transmittance(outside, t), rtol=1e-6)
    clear = CloudShadowMap(skies["clear"], 0.0, regions)
    assert np.all(clear.transmittance(garden) == 1.0) and not clear.tables


def numpy_cloud_transmittance(cmap, points):
    """``CloudShadowMap.transmittance`` as numpy computed it, table by table: the compiled pass must
    give these bits."""
    from eden_pipe.render import lut

    pts = np.asarray(points).reshape(-1, 3)
    sun = cmap.sky.sun_direction
    wide = pts.astype(np.float64)
    layer = wide[:, :2] + sun[None, :2] * ((250.0 - wide[:, 2]) / sun[2])[:, None]  # CLOUD_ALTITUDE 250 m
    assert np.array_equal(layer, cmap.sky.cloud_layer_xy(pts))
    out = np.empty(len(pts), np.float32)
    todo = np.arange(len(pts))
    for origin, spacing, table in cmap.tables:
        f = (layer[todo] - origin) / spacing
        ny, nx = table.shape[:2]
        inside = (f[:, 0] >= 0) & (f[:, 0] <= nx - 1) & (f[:, 1] >= 0) & (f[:, 1] <= ny - 1)
        idx = todo[inside]
        noise = lut.sample(table, f[inside, 0].astype(np.float32), f[inside, 1].astype(np.float32))[:, 0]
        out[idx] = cmap.sky.transmittance_of_noise(noise)
        todo = todo[~inside]
    if len(todo):
        out[todo] = cmap.sky.layer_transmittance(layer[todo], cmap.time)
    return out


def test_cloud_shadow_map_lookup_is_numpys_bit_for_bit(skies):
    """Float32 points in the finer table, the coarser one, on the finer one's edges and beyond both:
    the same values as the lookup written in numpy, to the bit."""
    from eden_pipe.render.sky import CloudShadowMap

    sky = skies["cloudy"]
    rng = np.random.default_rng(12)
    regions = [((0, 0, 0), (20, 20, 5), 0.2), ((-60, -60, 0), (80, 80, 5), 0.5)]
    cmap = CloudShadowMap(sky, 2.0, regions)
    origin, spacing, table = cmap.tables[0]
    ny, nx = table.shape[:2]
    # points whose layer crossing lies on the finer table's first and last texel columns and rows
    edge_xy = origin + spacing * np.array([[0.0, 3.0], [nx - 1.0, 5.0], [4.0, 0.0], [6.0, ny - 1.0]])
    s = sky.sun_direction
    edges = np.column_stack([edge_xy - s[None, :2] * (250.0 / s[2]), np.zeros(4)])
    pts = np.vstack(
        [
            np.column_stack([rng.uniform(0, 20, 5000), rng.uniform(0, 20, 5000), rng.uniform(0, 5, 5000)]),
            np.column_stack([rng.uniform(-60, 80, 2000), rng.uniform(-60, 80, 2000), np.zeros(2000)]),
            [[500.0, 500.0, 0.0], [-300.0, 40.0, 2.0]],
            edges,
        ]
    ).astype(np.float32)
    got = cmap.transmittance(pts)
    assert np.array_equal(got, numpy_cloud_transmittance(cmap, pts))
    assert np.array_equal(
        cmap.transmittance(pts.astype(np.float64)), numpy_cloud_transmittance(cmap, pts.astype(np.float64))
    )
    assert 0.5 < got.max() and got.min() < 0.5


def test_cloud_shadow_map_skips_oversized_tables_and_stays_exact():
    from eden_pipe.render.sky import CloudShadowMap

    low_sun = Sky(params("cloudy", 1.0, 4.0, cover=0.45), seed=5)  # 1 deg: the footprint smears out
    regions = [((-60, -60, 0), (80, 80, 30), 0.2)]
    cmap = CloudShadowMap(low_sun, 0.0, regions)
    assert not cmap.tables
    pts = np.array([[1.0, 2.0, 0.5], [10.0, 3.0, 4.0]])
    np.testing.assert_allclose(cmap.transmittance(pts), low_sun.cloud_transmittance(pts, 0.0), rtol=1e-6)


# ------------------------------------------------------- the sampled sun (docs/lighting.md)
def _cct(rgb: np.ndarray) -> float:
    """Correlated colour temperature of a linear sRGB colour (McCamy's formula)."""
    from eden_pipe.render.sky import XYZ_TO_SRGB

    X, Y, Z = np.linalg.solve(XYZ_TO_SRGB, np.asarray(rgb, float))
    x, y = X / (X + Y + Z), Y / (X + Y + Z)
    n = (x - 0.3320) / (0.1858 - y)
    return 449 * n**3 + 3525 * n**2 + 6823.3 * n + 5520.33


def test_sun_intensity_size_and_colour_are_drawn_within_each_scenarios_ranges():
    from eden_pipe.lighting import SCENARIO_TABLE

    for name, scenario in SCENARIO_TABLE.items():
        d = scenario.defaults
        for seed in range(20):
            p = sample_lighting({"name": name}, np.random.default_rng(seed))
            for key, value in (
                ("sun_intensity", p.sun_intensity),
                ("sun_temperature_k", p.sun_temperature),
                ("sun_angular_diameter_deg", math.degrees(p.sun_angular_diameter)),
            ):
                lo, hi = (d[key], d[key]) if not isinstance(d[key], list) else d[key]
                assert lo - 1e-9 <= value <= hi + 1e-9, (name, key, value)
            if seed < 2:  # the sky takes the drawn size (two draws a scenario: a sky costs 0.1-0.6 s)
                sky = Sky(p, seed=0)
                assert sky.sun_angular_radius == pytest.approx(p.sun_angular_diameter / 2)
        assert (p.moon_phase is not None) == (name == "night")
    # The older keys keep their draws: the new ones are drawn after them.
    p = sample_lighting({"name": "clear"}, np.random.default_rng(5))
    rng = np.random.default_rng(5)
    assert p.sun_elevation == pytest.approx(math.radians(rng.uniform(35, 60)))
    assert p.sun_azimuth == pytest.approx(math.radians(rng.uniform(0, 360)))


def test_sun_colour_temperature_tint_and_the_atmosphere():
    from eden_pipe.render.sky import temperature_tint

    np.testing.assert_allclose(temperature_tint(5778), [1, 1, 1], atol=1e-12)  # the model's white
    for t in (2500, 4500, 6500, 9000):
        assert lum(temperature_tint(t)) == pytest.approx(1.0)  # colour only
    warm, cool = temperature_tint(4000), temperature_tint(8000)
    assert warm[0] > 1 > warm[2] and cool[2] > 1 > cool[0]
    clear = Sky(params("clear", 60.0, 2.5, sun_temperature=5778.0), seed=0)
    assert clear.sun_irradiance @ LUMA == pytest.approx(math.pi)  # the scale convention holds
    # Clear noon stays near white, sunset is warm, the night's moon bluish.
    for seed in range(10):
        noon = Sky(sample_lighting({"name": "clear", "sun_elevation_deg": 60}, np.random.default_rng(seed)), 0)
        assert 5000 < _cct(noon.sun_irradiance) < 6600
        sunset = Sky(sample_lighting({"name": "sunset"}, np.random.default_rng(seed)), 0)
        assert _cct(sunset.sun_irradiance) < 3800
        moon = Sky(sample_lighting({"name": "night"}, np.random.default_rng(seed)), 0)
        assert _cct(moon.sun_irradiance) > 6500 and moon.sun_irradiance[2] > moon.sun_irradiance[0]


# --------------------------------------------------------------- night
def test_night_moon_phase_law_and_brightness_order():
    from eden_pipe.render.sky import moon_phase_factor

    assert moon_phase_factor(1.0) == pytest.approx(1.0)
    assert 0.07 < moon_phase_factor(0.5) < 0.11  # a half moon gives ~9 % of the full moon's light
    assert moon_phase_factor(0.0) < 1e-3
    full = Sky(params("night", 40.0, 3.0, moon_phase=1.0), seed=0)
    half = Sky(params("night", 40.0, 3.0, moon_phase=0.5), seed=0)
    np.testing.assert_allclose(half.sun_irradiance, full.sun_irradiance * moon_phase_factor(0.5))
    twilight = Sky(params("twilight", -6.0, 3.0), seed=0)
    assert full.horizontal_irradiance @ LUMA < twilight.horizontal_irradiance @ LUMA
    assert full.exposure <= 16.0 and full.exposure > twilight.exposure


def test_night_sky_glow_is_warm_at_the_horizon_and_dim_above():
    sky = Sky(params("night", 30.0, 3.0, moon_phase=0.0), seed=0)  # new moon: the glow alone
    horizon, zenith = sky.radiance(dir_at(1.0, 200.0))[0], sky.radiance(dir_at(89.0, 0.0))[0]
    assert lum(horizon) > 5 * lum(zenith) and horizon[0] > horizon[2]
    brighter = Sky(params("night", 30.0, 3.0, moon_phase=0.0, sky_intensity=2.0), seed=0)
    # (the new moon still lights the sky with 3e-4 of the full moon: not exactly twice)
    np.testing.assert_allclose(brighter.radiance(dir_at(1.0, 200.0))[0], 2 * horizon, rtol=1e-3)
    # Moonlit sky: the Preetham sky of the moon, blue, brightest near the moon.
    moonlit = Sky(params("night", 30.0, 3.0, moon_phase=1.0, sky_intensity=1e-9), seed=0)
    near, far = moonlit.radiance(dir_at(35.0, 30.0))[0], moonlit.radiance(dir_at(35.0, 210.0))[0]
    assert lum(near) > lum(far) and far[2] > far[0]
