"""Image-based lighting: panorama files and convention, ambient irradiance (table and SH9) against
brute-force integration, sun extraction, a render lit by a generated HDR map, and the config checks."""

from __future__ import annotations

import dataclasses
import json
import math

import cv2
import numpy as np
import pytest

from eden_pipe.errors import ConfigError
from eden_pipe.io.exr import write_exr
from eden_pipe.io.hdr import read_panorama, write_hdr
from eden_pipe.lighting import LightingConfig, check_lighting
from eden_pipe.render.sky import (
    LUMA,
    Sky,
    bake_panorama,
    build_sky,
    extract_sun,
    sample_lighting,
    sh9_irradiance,
    sh9_project_panorama,
)
from eden_pipe.render.sky.equirect import Panorama, pixel_directions, pixel_solid_angles


def random_normals(n: int, seed: int = 0) -> np.ndarray:
    v = np.random.default_rng(seed).normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def brute_force_irradiance(image: np.ndarray, normals: np.ndarray, rotation: float = 0.0) -> np.ndarray:
    """Sum over every pixel of the map: L max(n.d, 0) dw (exact pixel solid angles)."""
    h, w = image.shape[:2]
    dirs = pixel_directions(h, w, rotation)
    lw = image[..., :3].reshape(-1, 3).astype(np.float64) * pixel_solid_angles(h, w)[:, None]
    return np.clip(np.asarray(normals, np.float64) @ dirs.T, 0.0, None) @ lw


def model_sky(name: str, **values) -> Sky:
    return Sky(sample_lighting({"name": name, **values}, np.random.default_rng(1)), seed=3)


@pytest.fixture(scope="module")
def clear_map():
    """A clear Preetham sky with a 2 deg sun disc and the procedural scenery below, 512 x 256."""
    sky = model_sky("clear", sun_angular_diameter_deg=2.0)
    return sky, bake_panorama(sky, 512)


# ------------------------------------------------------------------ files and convention
def test_equirect_convention_lookup_and_rotation():
    h, w = 64, 128
    dirs = pixel_directions(h, w)
    centre = dirs.reshape(h, w, 3)[h // 2, w // 2]
    assert centre[0] > 0.98 and abs(centre[1]) < 0.2  # the centre column looks along +x
    quarter_left = dirs.reshape(h, w, 3)[h // 2, w // 4]
    assert quarter_left[1] > 0.98  # +y a quarter width to the left
    assert dirs.reshape(h, w, 3)[0, 0, 2] > 0.98  # row 0: the zenith
    np.testing.assert_allclose(pixel_solid_angles(h, w).sum(), 4 * math.pi, rtol=1e-12)
    image = np.random.default_rng(0).uniform(0, 5, (h, w, 3)).astype(np.float32)
    # Texel centres give the texels (to float32 rounding of the coordinates).
    np.testing.assert_allclose(Panorama(image).lookup(dirs), image.reshape(-1, 3), atol=1e-4)
    # Rotating by +90 deg brings the map's +x to world +y.
    turned = Panorama(image, math.radians(90.0))
    np.testing.assert_allclose(
        turned.lookup(pixel_directions(h, w, math.radians(90.0))), image.reshape(-1, 3), atol=1e-4
    )
    np.testing.assert_allclose(
        turned.lookup(np.array([[0.0, 1.0, 0.0]])), Panorama(image).lookup(np.array([[1.0, 0.0, 0.0]]))
    )


def test_panoramas_read_back_from_hdr_exr_and_png(tmp_path, clear_map):
    _, image = clear_map
    write_hdr(tmp_path / "sky.hdr", image)
    write_exr(tmp_path / "sky.exr", image, half=False)
    hdr, exr = read_panorama(tmp_path / "sky.hdr"), read_panorama(tmp_path / "sky.exr")
    np.testing.assert_array_equal(exr, image)
    assert hdr.dtype == np.float32 and hdr.shape == image.shape
    # RGBE: three 8-bit mantissas share the exponent of the pixel's largest channel.
    assert np.all(np.abs(hdr - image) <= 0.01 * image.max(axis=2, keepdims=True) + 1e-9)
    # An 8-bit RGBA PNG: sRGB decoded to linear, alpha kept.
    rgba = np.zeros((4, 8, 4), np.uint8)
    rgba[..., 0], rgba[..., 3] = 255, 255
    rgba[2:, :, 3] = 0
    cv2.imwrite(str(tmp_path / "scenery.png"), rgba[..., [2, 1, 0, 3]])
    png = read_panorama(tmp_path / "scenery.png")
    assert png.shape == (4, 8, 4)
    np.testing.assert_allclose(png[0, 0], [1.0, 0.0, 0.0, 1.0])
    assert np.all(png[2:, :, 3] == 0)


@pytest.mark.parametrize(
    "key, make, words",
    [
        ("environment", lambda d: str(d / "missing.hdr"), ["cannot read", "missing.hdr"]),
        ("environment", lambda d: _write_raw(d / "bad.hdr", b"not an image"), ["not a valid .hdr image"]),
        ("environment", lambda d: _write_array(d / "square.exr", np.ones((16, 16, 3))), ["16x16", "twice as wide"]),
        ("environment", lambda d: _write_png(d / "ldr.png"), ["of type .hdr, .pic, .exr"]),
        ("scenery", lambda d: str(d / "nowhere.png"), ["cannot read"]),
    ],
)
def test_bad_image_files_fail_the_check_in_one_line(tmp_path, key, make, words):
    value = make(tmp_path)
    with pytest.raises(ConfigError) as err:
        check_lighting(LightingConfig.for_scenario("clear", **{key: value}))
    msg = str(err.value)
    assert msg.startswith(f"invalid config: lighting.{key}=") and "\n" not in msg
    assert "allowed: the path of a readable equirectangular image (width = 2 x height)" in msg
    for w in words:
        assert w in msg, (w, msg)


def test_environment_sun_mode_is_checked():
    with pytest.raises(
        ConfigError,
        match=r"^invalid config: lighting\.environment_sun='brightest'; "
        r"allowed: one of auto, none, explicit$",
    ):
        check_lighting(LightingConfig.for_scenario("clear", environment_sun="brightest"))


def _write_raw(path, data: bytes) -> str:
    path.write_bytes(data)
    return str(path)


def _write_array(path, array) -> str:
    write_exr(path, array, half=False)
    return str(path)


def _write_png(path) -> str:
    cv2.imwrite(str(path), np.zeros((8, 16, 3), np.uint8))
    return str(path)


# ------------------------------------------------------------------ ambient irradiance
def test_sh9_is_exact_for_linear_radiance_and_close_on_a_sky():
    """SH9 holds the l <= 1 bands exactly: a map L(d) = a + b.d has E(n) = pi a + 2 pi / 3 b.n."""
    h, w = 128, 256
    dirs = pixel_directions(h, w)
    a, b = np.array([1.0, 0.5, 0.2]), np.array([[0.3, -0.2, 0.6], [0.1, 0.1, 0.1], [0.0, 0.2, -0.1]])
    image = (a[None, :] + dirs @ b.T).reshape(h, w, 3)  # b rows per channel, |b| < a: positive everywhere
    n = random_normals(200)
    coeffs = sh9_project_panorama(image)
    np.testing.assert_allclose(sh9_irradiance(coeffs, n), math.pi * a + (2 * math.pi / 3) * n @ b.T, rtol=1e-4)


def test_sh9_and_table_irradiance_against_brute_force(clear_map, tmp_path):
    """Measured on the clear map without its sun (the errors are printed with -s)."""
    _, image = clear_map
    _, rest = extract_sun(image)
    n = random_normals(300, seed=1)
    ref = brute_force_irradiance(rest, n) @ LUMA
    sh = sh9_irradiance(sh9_project_panorama(rest), n) @ LUMA
    sh_err = np.abs(sh - ref) / ref
    up = n[:, 2] > 0
    print(
        f"SH9 vs brute force: mean {sh_err.mean():.4f}, max (upward normals) {sh_err[up].max():.4f}, "
        f"max (all) {sh_err.max():.4f}"
    )
    assert sh_err.mean() < 0.01 and sh_err[up].max() < 0.02
    # The renderer's table (exact convolution of the map averaged to 128 x 64, bilinear over normals).
    # (A sun left in the map, environment_sun=none, is smeared over the table's 5.6 deg steps of
    # normal: up to ~9 % off near its terminator. Extracted, it is exact: the next test.)
    path_sky = _environment_sky_from(rest, "none", tmp=tmp_path)
    table = path_sky.ambient_irradiance(n) @ LUMA / path_sky.scale
    t_err = np.abs(table - ref) / ref
    print(
        f"ambient table vs brute force: mean {t_err.mean():.5f}, max (upward) {t_err[up].max():.5f}, "
        f"max (all) {t_err.max():.5f}"
    )
    assert t_err.mean() < 0.002 and t_err[up].max() < 0.005 and t_err.max() < 0.02


_MAPS: dict = {}


def _environment_sky_from(image: np.ndarray, mode: str, tmp, scenario: str = "clear", rotation: float = 0.0) -> object:
    """An EnvironmentSky of ``image`` written as an EXR (float32) under ``scenario``, in the folder ``tmp``
    (a test's tmp_path, so that pytest removes it)."""
    from pathlib import Path

    folder = Path(tmp)
    path = folder / f"map{len(_MAPS)}.exr"
    _MAPS[str(path)] = True
    write_exr(path, image, half=False)
    # sun_intensity 1: the extracted sun as the map holds it (the scenario's range would scale it).
    params = sample_lighting(
        {
            "name": scenario,
            "environment": str(path),
            "environment_sun": mode,
            "sun_intensity": 1.0,
            "environment_rotation_deg": math.degrees(rotation),
        },
        np.random.default_rng(2),
    )
    return build_sky(params, seed=3)


# ------------------------------------------------------------------ sun extraction
@pytest.mark.parametrize("rotation_deg", [0.0, 137.0])
def test_extract_sun_recovers_a_known_sun(clear_map, rotation_deg):
    sky, image = clear_map
    rotation = math.radians(rotation_deg)
    found, rest = extract_sun(image, rotation)
    truth = (
        np.array([[math.cos(rotation), -math.sin(rotation), 0], [math.sin(rotation), math.cos(rotation), 0], [0, 0, 1]])
        @ sky.sun_direction
    )
    angle = math.degrees(math.acos(min(1.0, float(found.direction @ truth))))
    energy = found.irradiance / sky.sun_irradiance - 1.0
    diameter = math.degrees(2 * found.angular_radius)
    print(
        f"sun: direction error {angle:.4f} deg, energy error {np.abs(energy).max():.4f}, diameter {diameter:.3f} "
        f"deg (true 2)"
    )
    assert angle < 0.05 and np.all(np.abs(energy) < 0.01) and abs(diameter - 2.0) < 0.1
    # Removed, not counted twice: the map's total irradiance is the rest's plus the sun's.
    up = np.array([[0.0, 0.0, 1.0]])
    np.testing.assert_allclose(
        brute_force_irradiance(rest, up)[0] + found.irradiance * found.direction[2],
        brute_force_irradiance(image, up)[0],
        rtol=1e-3,
    )
    assert (rest @ LUMA).max() < 0.05 * (image @ LUMA).max()


def test_no_sun_is_found_in_an_overcast_map():
    image = bake_panorama(model_sky("overcast"), 256)
    found, rest = extract_sun(image)
    assert found is None and rest is image


# ------------------------------------------------------------------ rendering with a map
def _patch_scene():
    """Two quads: one facing up at z = 0, one tilted 60 deg toward +x, far apart (no mutual shadowing
    from the sun at the test's elevations, and each sees the whole sky above it)."""
    from eden_pipe.models.mesh import Mesh

    flat = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    c, s = math.cos(math.radians(60)), math.sin(math.radians(60))
    tilt = np.array([[-c, -1, -s], [c, -1, s], [c, 1, s], [-c, 1, -s]], np.float32) * [1, 1, -1] + [20, 0, 0]
    v = np.concatenate([flat, tilt])
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return Mesh.from_arrays(v, f, semantic=7, material="rock", albedo=(0.5, 0.5, 0.5))


def _shade_patches(sky, mesh):
    """Shading of rays straight down onto each quad's centre region (a real Embree render)."""
    from eden_pipe.render.embree import RayTracer
    from eden_pipe.render.shading import ShadingSettings, shade

    xy = np.stack(np.meshgrid(np.linspace(-0.3, 0.3, 5), np.linspace(-0.3, 0.3, 5)), -1).reshape(-1, 2)
    origins = np.concatenate([np.c_[xy, np.full(len(xy), 5.0)], np.c_[xy + [20, 0], np.full(len(xy), 5.0)]])
    dirs = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    with RayTracer(mesh) as tracer:
        hits = tracer.intersect(origins.astype(np.float32), dirs.astype(np.float32))
        assert hits.hit.all()
        out = shade(
            tracer,
            mesh,
            hits,
            origins,
            dirs,
            sky,
            ShadingSettings(indirect_samples=0),
            np.random.default_rng(0),
            layers=("shading",),
        )
        normals = np.asarray(hits.normal, np.float64)
    normals *= np.sign(normals[:, 2:3])  # the side facing the camera (up)
    return out["shading"].astype(np.float64), normals


def test_render_ambient_matches_the_maps_irradiance(clear_map, tmp_path):
    """A patch lit by a sun-free map (environment_sun=none) is shaded by the map's cosine-weighted
    irradiance / pi; lit by the map with its sun (auto), by the whole map's, sun included."""
    _, image = clear_map
    _, sunless = extract_sun(image)
    mesh = _patch_scene()
    sky = _environment_sky_from(sunless, "none", tmp=tmp_path)
    shading, normals = _shade_patches(sky, mesh)
    expected = brute_force_irradiance(sunless, normals) * sky.scale / math.pi
    err = np.abs(shading - expected) / expected
    print(f"render vs map irradiance (sun-free map): max error up {err[:25].max():.5f}, tilted {err[25:].max():.5f}")
    assert err[:25].max() < 0.003 and err[25:].max() < 0.01
    # Sun extracted from the map: ambient (rest of the map) + sun = the whole map's irradiance.
    sky = _environment_sky_from(image, "auto", tmp=tmp_path)
    assert sky.extracted is not None
    shading, normals = _shade_patches(sky, mesh)
    expected = brute_force_irradiance(image, normals) * sky.scale / math.pi
    err = np.abs(shading - expected) / expected
    print(f"render vs map irradiance (sun extracted): max error up {err[:25].max():.5f}, tilted {err[25:].max():.5f}")
    assert err.max() < 0.01


def test_environment_scale_follows_the_scenario_and_sun_modes(clear_map, tmp_path):
    _, image = clear_map
    auto = _environment_sky_from(image, "auto", tmp=tmp_path)
    # Scaled to the illuminance of the scenario's sky model at the drawn values.
    reference = Sky(dataclasses.replace(auto.params, environment=None), auto.seed)
    total = auto.sky_horizontal_irradiance + auto.sun_irradiance / auto.params.sun_intensity * auto.sun_direction[2]
    np.testing.assert_allclose(total @ LUMA, reference.horizontal_irradiance @ LUMA, rtol=1e-3)
    none = _environment_sky_from(image, "none", tmp=tmp_path)
    assert np.all(none.sun_irradiance == 0) and none.direct_light == "none"
    explicit = _environment_sky_from(image, "explicit", tmp=tmp_path)
    reference = Sky(dataclasses.replace(explicit.params, environment=None), explicit.seed)
    np.testing.assert_allclose(explicit.sun_irradiance, reference.sun_irradiance)
    np.testing.assert_allclose(
        explicit.sky_horizontal_irradiance @ LUMA, reference.sky_horizontal_irradiance @ LUMA, rtol=1e-3
    )
    # A night map renders as dark as the night: the scenario sets the level.
    night = _environment_sky_from(image, "auto", scenario="night", tmp=tmp_path)
    assert night.horizontal_irradiance @ LUMA < 0.02 * (auto.horizontal_irradiance @ LUMA)
    # Below the horizon the map itself is the background (no procedural scenery by default).
    mask, _ = auto.scenery(np.array([[1.0, 0.0, -0.5]]))
    assert not mask.any()
    facts = json.loads(json.dumps(auto.facts()))
    assert facts["environment"]["sun_found"]["pixels"] > 0 and len(facts["ambient_sh9_rgb"]) == 9


def test_scenery_panorama_with_alpha_covers_only_its_mask(tmp_path):
    h, w = 64, 128
    rgba = np.zeros((h, w, 4), np.float32)
    rgba[..., :3] = 0.5
    rgba[h // 2 - 4 :, :, 3] = 1.0  # scenery up to ~11 deg above the horizon, and everything below
    path = tmp_path / "scenery.exr"
    write_exr(path, rgba, half=False)
    sky = Sky(sample_lighting({"name": "clear", "scenery": str(path)}, np.random.default_rng(0)), seed=0)
    d = np.array([[1.0, 0.0, 0.1], [1.0, 0.0, 0.6], [0.0, 1.0, -0.3]])
    mask, rgb = sky.scenery(d)
    assert mask.tolist() == [True, False, True]
    np.testing.assert_allclose(rgb[0], 0.5 * sky.horizontal_irradiance / math.pi, rtol=1e-5)
    assert sky.facts()["scenery"]["path"] == str(path)


def test_environment_job_end_to_end_records_and_keys_the_map(tmp_path, clear_map):
    """A tiny job lit by an .hdr map: lighting.json names the file and its hash, and a changed file
    changes the render key."""
    from eden_pipe.pipeline import run_job
    from eden_pipe.stages.render import render_key
    from tests.conftest import TINY, make_cfg

    _, image = clear_map
    env = tmp_path / "garden_sky.hdr"
    write_hdr(env, image)
    cfg = make_cfg(
        tmp_path,
        TINY
        + [
            "lighting=clear",
            f"lighting.environment={env}",
            "render.max_frames=1",
            "camera.pairs=1",
            "render.modalities=[rgb,shading]",
        ],
    )
    result = run_job(cfg, echo=lambda *_: None)
    lighting = json.loads(next((tmp_path / "dataset").glob("*/clear/lighting.json")).read_text())
    from eden_pipe.io.hdr import file_sha256

    assert lighting["environment"]["path"] == str(env) and lighting["environment"]["sha256"] == file_sha256(env)
    assert lighting["environment"]["sun_found"] is not None and lighting["direct_light"] == "sun"
    key = render_key(cfg, result.artifacts["scene"], result.artifacts["trajectory"])
    write_hdr(env, image * 1.5)
    assert render_key(cfg, result.artifacts["scene"], result.artifacts["trajectory"]) != key
