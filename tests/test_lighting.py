"""The five lighting scenarios and the intrinsic passes, read back from written files."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from eden_pipe.io import formats
from eden_pipe.pipeline import run_job
from eden_pipe.render.shading import linear_to_srgb
from eden_pipe.stages.render import make_sky
from tests.conftest import TINY, make_cfg
from tests.tiny_dataset import ALL_MODALITIES


@pytest.fixture(scope="module")
def lit(tmp_path_factory):
    """One tiny garden rendered under every scenario (geometry shared through the cache)."""
    root = tmp_path_factory.mktemp("lit")
    for lighting in ("clear", "overcast", "sunset", "twilight", "cloudy", "night"):
        # Exact storage: the identities below hold to float32 precision (compact EXR: half precision,
        # checked by the validator's tests).
        run_job(
            make_cfg(root, TINY + [f"lighting={lighting}", ALL_MODALITIES, "render.storage=exact"]),
            echo=lambda *_: None,
        )
    manifest = pd.read_csv(root / "dataset" / "manifest.csv", keep_default_na=False)
    return root / "dataset", manifest


def read(root, row, column):
    return formats.read_modality(root / row[column], column)


def test_linear_rgb_equals_the_sum_of_written_passes(lit):
    root, manifest = lit
    for _, row in manifest.iterrows():
        linear = read(root, row, "rgb_linear").astype(np.float64)
        parts = (
            read(root, row, "albedo").astype(np.float64) * read(root, row, "shading")
            + read(root, row, "glossy")
            + read(root, row, "translucency")
            + read(root, row, "background")
        )
        # E (emission) is zero in gardens. float32 files: agreement to float precision.
        assert np.allclose(linear, parts, rtol=1e-5, atol=1e-6)


def test_png_is_the_exposed_srgb_of_the_linear_image(lit):
    root, manifest = lit
    row = manifest[manifest.lighting == "clear"].iloc[0]
    expected = np.round(linear_to_srgb(read(root, row, "rgb_linear") * row.exposure) * 255)
    assert np.abs(read(root, row, "rgb_left").astype(float) - expected).max() <= 1


def test_diffuse_shading_is_view_independent(lit):
    """The same surface points, shot from two cameras, get the same diffuse shading."""
    from eden_pipe.camera.rig import Intrinsics
    from eden_pipe.render.embree import RayTracer
    from eden_pipe.render.shading import ShadingSettings, shade
    from eden_pipe.render.view import primary_rays
    from eden_pipe.stages.scene import load_scene

    root, manifest = lit
    scene_dir = next((root.parent / "stages" / "scene").glob("*/scene.json")).parent
    art = type("A", (), {"path": scene_dir})
    scene, arrays = load_scene(art)
    cfg = make_cfg(root.parent, TINY)
    sky, _ = make_sky(cfg.lighting, scene["seed"])
    row_a, row_b = manifest[manifest.lighting == "clear"].iloc[[0, 6]].itertuples(index=False)

    def pose(r):
        from tests.test_job import pose_of

        return pose_of(r)

    intr = Intrinsics(row_a.width, row_a.height, row_a.fx, row_a.fy, row_a.cx, row_a.cy)
    with RayTracer(arrays.mesh) as tracer:
        o, d = primary_rays(intr, pose(row_a))
        hits = tracer.intersect(o, d)
        ok = np.nonzero(hits.hit)[0]
        points = o[ok] + d[ok] * hits.t[ok, None]
        centre_b = pose(row_b)[:3, 3]
        d_b = points - centre_b
        o_b = np.broadcast_to(centre_b, d_b.shape)
        hits_b = tracer.intersect(o_b, d_b)
        same = (hits_b.prim == hits.prim[ok]) & (np.abs(hits_b.t - 1.0) < 1e-3)
        n = hits.normal[ok]
        same &= np.sign(np.sum(n * d[ok], 1)) == np.sign(np.sum(n * d_b, 1))  # the same side of the face
        assert same.sum() > 500
        # Per-point noise falls as 1/sqrt(samples) and depends on the view (points in shade get most of
        # their light from indirect samples): 32 samples keep the 10 % median bound meaningful on any walk.
        for samples, median_tol, mean_tol in ((0, 1e-4, 1e-4), (32, 0.1, 0.02)):
            settings = ShadingSettings(indirect_samples=samples)
            a = shade(tracer, arrays.mesh, hits, o, d, sky, settings, np.random.default_rng(1))["shading"][ok][same]
            b = shade(tracer, arrays.mesh, hits_b, o_b, d_b, sky, settings, np.random.default_rng(2))["shading"][same]
            rel = np.abs(a - b).sum(1) / np.maximum((a + b).sum(1), 1e-9) * 2
            # Deterministic without indirect samples; with them, independent Monte Carlo
            # estimates of the same light agree up to sampling noise (and exactly on average).
            assert np.median(rel) < median_tol, samples
            assert abs(a.mean() - b.mean()) / a.mean() < mean_tol, samples


def test_overcast_has_no_sun_term(lit):
    root, manifest = lit
    cfg = make_cfg(root, TINY + ["lighting=overcast"])
    sky, _ = make_sky(cfg.lighting, 0)
    assert np.all(sky.sun_irradiance == 0)
    # Without a sun, shading is the sky's ambient irradiance alone: no cast shadows,
    # so shading depends on the normal only (same normal => same shading).
    row = manifest[manifest.lighting == "overcast"].iloc[0]
    shading = read(root, row, "shading")
    assert np.all(np.isfinite(shading))


def test_sunset_sun_is_red_shifted(tmp_path):
    cfg_clear = make_cfg(tmp_path, ["lighting=clear"])
    cfg_sunset = make_cfg(tmp_path, ["lighting=sunset"])
    for seed in range(3):
        clear, _ = make_sky(cfg_clear.lighting, seed)
        sunset, _ = make_sky(cfg_sunset.lighting, seed)
        rb = lambda s: s.sun_irradiance[0] / s.sun_irradiance[2]  # noqa: E731
        assert rb(sunset) > rb(clear)


def test_mean_luminance_order(lit):
    root, manifest = lit

    def mean_luminance(lighting):
        rows = manifest[manifest.lighting == lighting]
        values = [read(root, r, "rgb_left").astype(float) @ [0.2126, 0.7152, 0.0722] for _, r in rows.iterrows()]
        return float(np.mean(values))

    assert mean_luminance("twilight") < mean_luminance("overcast") < mean_luminance("clear")
    assert mean_luminance("night") < mean_luminance("twilight")


def test_lighting_json_records_the_drawn_sun_and_moon(lit):
    """The sun's intensity, size and colour are drawn per scenario and published (docs/lighting.md)."""
    import json

    from eden_pipe.lighting import SCENARIO_TABLE

    root, _ = lit
    for name in ("clear", "sunset", "night", "overcast"):
        data = json.loads(next(root.glob(f"*/{name}/lighting.json")).read_text())
        defaults = SCENARIO_TABLE[name].defaults
        for key, drawn in (
            ("sun_intensity", "sun_intensity"),
            ("sun_temperature_k", "sun_temperature_k"),
            ("sun_angular_diameter_deg", "sun_drawn_angular_diameter_deg"),
        ):
            lo, hi = defaults[key] if isinstance(defaults[key], list) else (defaults[key], defaults[key])
            assert lo - 1e-9 <= data[drawn] <= hi + 1e-9, (name, key)
        assert data["direct_light"] == {"night": "moon", "overcast": "none"}.get(name, "sun")
        assert (data["moon_phase"] is not None) == (name == "night")
        assert len(data["ambient_sh9_rgb"]) == 9 and data["scenery"] == "procedural"
        if data["direct_light"] != "none":
            assert data["sun_angular_diameter_deg"] == pytest.approx(data["sun_drawn_angular_diameter_deg"])
            assert sum(
                c * w for c, w in zip(data["sun_colour_rgb"], (0.2126, 0.7152, 0.0722), strict=True)
            ) == pytest.approx(1.0)


def test_cloud_shadows_move_between_frames(tmp_path):
    cfg = make_cfg(tmp_path, ["lighting=cloudy"])
    sky, _ = make_sky(cfg.lighting, 0)
    pts = np.stack(np.meshgrid(np.linspace(0, 10, 40), np.linspace(0, 10, 40)), -1).reshape(-1, 2)
    pts = np.c_[pts, np.zeros(len(pts))]
    t0, t1 = sky.cloud_transmittance(pts, 0.0), sky.cloud_transmittance(pts, 5.0)
    assert t0.min() < 0.9 and not np.allclose(t0, t1)


# --------------------------------------------------------------- lighting config checks
# One scenario table (eden_pipe.lighting.SCENARIO_TABLE) and one check (check_lighting):
# config.validate runs it before any stage, sample_lighting for direct callers.


def _cfg(name, **values):
    from eden_pipe.lighting import LightingConfig

    return LightingConfig.for_scenario(name, **values)


def test_every_scenario_default_passes_and_matches_the_shipped_yaml(tmp_path):
    from omegaconf import OmegaConf

    from eden_pipe.config import to_plain
    from eden_pipe.lighting import SCENARIO_TABLE, check_lighting

    for name, scenario in SCENARIO_TABLE.items():
        check_lighting(_cfg(name))
        shipped = OmegaConf.to_container(make_cfg(tmp_path, [f"lighting={name}"]).lighting)
        # The YAML is the scenario's defaults; keys it leaves out (images, rotation) keep the schema's.
        assert shipped == to_plain(_cfg(name)), name
        for key, value in scenario.defaults.items():
            assert shipped[key] == (list(value) if isinstance(value, list) else value), (name, key)


@pytest.mark.parametrize("name", ["clear", "cloudy", "overcast", "sunset", "twilight", "night"])
def test_check_lighting_enforces_each_scenarios_limits(name):
    from eden_pipe.errors import ConfigError
    from eden_pipe.lighting import DRAWN_KEYS, SCENARIO_TABLE, check_lighting

    s = SCENARIO_TABLE[name]
    keys = {
        "sun_elevation_deg": s.elevation_limits_deg,
        "turbidity": s.turbidity_limits,
        "cloud_cover": s.cloud_cover_limits,
        "sun_azimuth_deg": s.azimuth_limits_deg,
        "sun_intensity": s.intensity_limits,
        "sky_intensity": s.intensity_limits,
        "cloud_speed": s.cloud_speed_limits,
        "sun_angular_diameter_deg": (0.0, 10.0),
        "sun_temperature_k": (1667.0, 25000.0),
        "environment_rotation_deg": s.azimuth_limits_deg,
        "moon_phase": (0.0, 1.0),
    }
    assert set(keys) == set(DRAWN_KEYS)
    if name != "night":  # the moon's phase belongs to the night: elsewhere it must stay unset
        with pytest.raises(
            ConfigError,
            match=r"^invalid config: lighting\.moon_phase=0\.5; allowed: unset \(null\): "
            r"only scenario night uses it, not " + name + "$",
        ):
            check_lighting(_cfg(name, moon_phase=0.5))
        del keys["moon_phase"]
    for key, (lo, hi) in keys.items():
        check_lighting(_cfg(name, **{key: [lo, hi]}))  # the limits themselves are allowed
        check_lighting(_cfg(name, **{key: lo}))  # a scalar is a degenerate range
        for bad in ([lo - 0.25, hi], [lo, hi + 0.25], [hi, lo], lo - 0.25):
            if bad == [hi, lo] and lo == hi:
                continue
            with pytest.raises(ConfigError) as err:
                check_lighting(_cfg(name, **{key: bad}))
            msg = str(err.value)
            assert msg.startswith(f"invalid config: lighting.{key}="), msg
            assert f"within [{lo:g}, {hi:g}]" in msg and f"scenario {name}" in msg, msg


def test_preetham_and_overcast_need_the_sun_up_twilight_down():
    from eden_pipe.errors import ConfigError
    from eden_pipe.lighting import SCENARIO_TABLE, check_lighting

    for s in SCENARIO_TABLE.values():
        lo, hi = s.elevation_limits_deg
        if s.sky_model == "twilight":
            assert hi < 0 and not s.has_sun
        else:
            assert lo > 0  # night: the moon is up
        assert s.has_clouds == (s.sky_model == "preetham")
        assert s.direct_light == {"preetham": "sun", "night": "moon"}.get(s.sky_model, "none")
    with pytest.raises(
        ConfigError, match=r"lighting\.sun_elevation_deg='\[-5, 10\]'; allowed: .*\[0\.5, 90\] deg for scenario clear"
    ):
        check_lighting(_cfg("clear", sun_elevation_deg=[-5, 10]))
    with pytest.raises(ConfigError, match=r"lighting\.sun_elevation_deg='\[-3, 2\]'; allowed: .*scenario twilight"):
        check_lighting(_cfg("twilight", sun_elevation_deg=[-3, 2]))
    check_lighting(_cfg("twilight", sun_elevation_deg=[-12, -0.5]))


@pytest.mark.parametrize(
    "name, values, words",
    [
        ("clear", {"sun_elevation_deg": [60, 35]}, ["lighting.sun_elevation_deg='[60, 35]'", "lo <= hi", "allowed"]),
        ("clear", {"turbidity": [1.0, 3.0]}, ["lighting.turbidity='[1, 3]'", "allowed", "1.7"]),
        ("clear", {"turbidity": [12, 15]}, ["lighting.turbidity='[12, 15]'", "[1.7, 10]", "scenario clear"]),
        ("cloudy", {"cloud_cover": [0.5, 1.5]}, ["lighting.cloud_cover='[0.5, 1.5]'", "allowed"]),
        ("clear", {"sun_intensity": "bright"}, ["lighting.sun_intensity='bright'", "allowed"]),
        ("clear", {"cloud_speed": -1}, ["lighting.cloud_speed=-1", "allowed"]),
        ("clear", {"turbidity": [2, 3, 4]}, ["lighting.turbidity='[2, 3, 4]'", "allowed"]),
        ("clear", {"turbidity": None}, ["lighting.turbidity=None", "allowed"]),
    ],
)
def test_check_lighting_messages(name, values, words):
    from eden_pipe.errors import ConfigError
    from eden_pipe.lighting import LightingConfig, check_lighting

    with pytest.raises(ConfigError) as err:
        check_lighting(LightingConfig(name=name, **values))
    msg = str(err.value)
    assert msg.startswith("invalid config: ") and "\n" not in msg
    for w in words:
        assert w in msg, (w, msg)


def test_check_lighting_rejects_unknown_scenarios_and_keys():
    from omegaconf import OmegaConf

    from eden_pipe.errors import ConfigError
    from eden_pipe.lighting import LightingConfig, check_lighting

    with pytest.raises(
        ConfigError, match=r"lighting\.name='foggy'; allowed: one of clear, cloudy, overcast, sunset, twilight, night"
    ):
        check_lighting(LightingConfig(name="foggy"))
    with pytest.raises(ConfigError, match=r"lighting\.name='foggy'"):
        check_lighting(OmegaConf.create({"name": "foggy"}))
    with pytest.raises(ConfigError, match=r"lighting\.sun_elevaton_deg=.*allowed: one of the keys"):
        LightingConfig.for_scenario("clear", sun_elevaton_deg=[30, 40])


def test_validate_uses_check_lighting(tmp_path):
    from eden_pipe.config import ConfigError, validate

    cfg = make_cfg(tmp_path, TINY + ["lighting=sunset", "lighting.turbidity=[12,15]"])
    with pytest.raises(
        ConfigError, match=r"^invalid config: lighting\.turbidity='\[12, 15\]'; allowed: .*scenario sunset$"
    ):
        validate(cfg)


@pytest.mark.parametrize(
    "overrides, key",
    [
        (["lighting.turbidity=[12,15]"], "lighting.turbidity"),
        (["lighting=clear", "lighting.sun_elevation_deg=[-5,10]"], "lighting.sun_elevation_deg"),
    ],
)
def test_bad_lighting_fails_at_startup_through_the_cli(tmp_path, overrides, key):
    """These once passed the start-up check and died in render with a traceback."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": str(repo) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    out = {name: tmp_path / name for name in ("s", "d", "r")}
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "eden_pipe",
            "garden=small",
            *overrides,
            f"paths.stages={out['s']}",
            f"paths.dataset={out['d']}",
            f"hydra.run.dir={out['r']}",
        ],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"eden-pipe: invalid config: {key}="), proc.stderr
    assert "Traceback" not in proc.stdout + proc.stderr
    assert not any(p.exists() for p in out.values()) and list(cwd.iterdir()) == []
