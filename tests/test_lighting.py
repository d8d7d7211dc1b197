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

ALL_LAYERS = "render.modalities=[rgb,semantic,instance,depth,normal,flow,albedo,shading,translucency,glossy,background,rgb_linear]"


@pytest.fixture(scope="module")
def lit(tmp_path_factory):
    """One tiny garden rendered under every scenario (geometry shared through the cache)."""
    root = tmp_path_factory.mktemp("lit")
    for lighting in ("clear", "overcast", "sunset", "twilight", "cloudy"):
        run_job(make_cfg(root, TINY + [f"lighting={lighting}", ALL_LAYERS]), echo=lambda *_: None)
    manifest = pd.read_csv(root / "dataset" / "manifest.csv", keep_default_na=False)
    return root / "dataset", manifest


def read(root, row, column):
    return formats.read_modality(root / row[column], column)


def test_linear_rgb_equals_the_sum_of_written_passes(lit):
    root, manifest = lit
    for _, row in manifest.iterrows():
        I = read(root, row, "rgb_linear").astype(np.float64)
        parts = (read(root, row, "albedo").astype(np.float64) * read(root, row, "shading")
                 + read(root, row, "glossy") + read(root, row, "translucency") + read(root, row, "background"))
        # E (emission) is zero in gardens. float32 files: agreement to float precision.
        assert np.allclose(I, parts, rtol=1e-5, atol=1e-6)


def test_png_is_the_exposed_srgb_of_the_linear_image(lit):
    root, manifest = lit
    row = manifest[manifest.lighting == "clear"].iloc[0]
    expected = np.round(linear_to_srgb(read(root, row, "rgb_linear") * row.exposure) * 255)
    assert np.abs(read(root, row, "rgb_left").astype(float) - expected).max() <= 1


def test_diffuse_shading_is_view_independent(lit):
    """The same surface points, shot from two cameras, get the same diffuse shading."""
    from eden_pipe.camera.rig import Intrinsics
    from eden_pipe.render.raytrace import RayTracer
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
        for samples, median_tol, mean_tol in ((0, 1e-4, 1e-4), (8, 0.1, 0.02)):
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


def test_cloud_shadows_move_between_frames(tmp_path):
    cfg = make_cfg(tmp_path, ["lighting=cloudy"])
    sky, _ = make_sky(cfg.lighting, 0)
    pts = np.stack(np.meshgrid(np.linspace(0, 10, 40), np.linspace(0, 10, 40)), -1).reshape(-1, 2)
    pts = np.c_[pts, np.zeros(len(pts))]
    t0, t1 = sky.cloud_transmittance(pts, 0.0), sky.cloud_transmittance(pts, 5.0)
    assert t0.min() < 0.9 and not np.allclose(t0, t1)
