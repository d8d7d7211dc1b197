"""render=cycles: Blender Cycles (bpy) for the light, Embree for the labels (render/backends/cycles.py).

Runs where bpy imports (the ``[cycles]`` extra, or ``render.cycles.python`` pointing at an
interpreter with it: ``EDEN_CYCLES_PYTHON``); ``.ci/run`` installs it. Checked: the camera and
sky conventions against the Embree backend's own rays (the background of every sky pixel), the
shading of a floor under a black roof against its closed-form view factor, the translucency of a
leaf lit from behind against E * albedo * t / pi, the glossy lobe against the Embree backend's,
and, through the pipeline, that every label file is byte-identical to render=raytrace's and that
the validator's image-formation check passes.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from benchmarks.cycles_devices import write_job
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.config.schema import CyclesConfig, RenderConfig
from eden_pipe.models.mesh import Mesh
from eden_pipe.render.backends.cycles import CyclesBackend, check_available
from eden_pipe.render.shading import sky_and_background
from eden_pipe.render.view import primary_rays
from eden_pipe.scene.arrays import SceneArrays
from scripts.dataset_fingerprint import content_digest
from tests.sky_scenes import ROOF_HALF, ROOF_HEIGHT, UniformSky, grid, hidden_fraction, roofed_floor

PYTHON = os.environ.get("EDEN_CYCLES_PYTHON", "")
WHY_NOT = check_available(PYTHON)
pytestmark = pytest.mark.skipif(WHY_NOT is not None, reason=f"Cycles unavailable: {WHY_NOT}")


class GradientSky(UniformSky):
    """Radiance that names its direction (0.5 + 0.5 d): any mapping error shows."""

    casts_cloud_shadows = False

    def radiance(self, directions, time=0.0):
        return (0.5 + 0.5 * np.asarray(directions, np.float64)).astype(np.float32)


class DarkSky(UniformSky):
    casts_cloud_shadows = False

    def __init__(self, sun_irradiance=(0.0, 0.0, 0.0), sun_direction=(0.0, 0.0, 1.0), radiance=0.0):
        self.sun_irradiance = np.asarray(sun_irradiance, np.float64)
        self.sun_direction = np.asarray(sun_direction, np.float64)
        self.sun_angular_radius = 0.0046
        self.level = radiance

    def radiance(self, directions, time=0.0):
        return np.full((len(directions), 3), self.level, np.float32)


def backend(mesh: Mesh, sky, samples: int = 32) -> CyclesBackend:
    scene = SceneArrays(mesh, np.zeros(mesh.n_faces, np.uint16))
    cfg = RenderConfig(cycles=CyclesConfig(python=PYTHON, samples=samples, map_width=512))
    return CyclesBackend(scene, sky, cfg, modalities={"rgb", "shading"}, threads=2)


def look(at_from, forward, down) -> np.ndarray:
    """Camera-to-world pose (OpenCV: x right, y down, z forward)."""
    z, y = np.asarray(forward, float), np.asarray(down, float)
    pose = np.eye(4)
    pose[:3, 0], pose[:3, 1], pose[:3, 2], pose[:3, 3] = np.cross(y, z), y, z, at_from
    return pose


def test_sky_and_camera_conventions_match_the_embree_rays():
    mesh = roofed_floor(0.0)
    intr = Intrinsics(64, 48, 50.0, 50.0, 27.0, 20.0)  # principal point off centre: the shift is checked
    pose = look([-1.5, 0.0137, 0.3071], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0])  # no edge through a pixel centre
    sky = GradientSky()
    with backend(mesh, sky, samples=4) as be:
        out = be.render_view(
            be.frame(0.0), intr, pose, want={"rgb", "background", "albedo", "shading", "glossy", "translucency"}
        )
    _, d = primary_rays(intr, pose)
    expected = sky_and_background(sky, d).reshape(48, 64, 3)
    sky_px = ~np.isfinite(out["depth"])
    assert sky_px.sum() > 500
    err = np.abs(out["background"][sky_px] - expected[sky_px]).max(axis=1)
    # Bilinear lookups of a 512 x 256 map of a linear function: off only where a pixel sits beside
    # geometry (Cycles' 0.01 px filter still reaches it), never by a pixel's shift.
    assert np.median(err) < 1e-3 and np.mean(err < 1e-2) > 0.97
    hit = np.isfinite(out["depth"])
    assert np.all(out["background"][hit] == 0.0)
    assert np.all(out["albedo"][sky_px] == 0.0)
    ident = out["albedo"] * out["shading"] + out["glossy"] + out["translucency"] + out["background"]
    np.testing.assert_allclose(out["rgb_linear"], ident, rtol=1e-6, atol=1e-7)


def test_shading_under_a_black_roof_is_the_open_view_factor():
    sky = UniformSky()
    sky.casts_cloud_shadows = False  # type: ignore[attr-defined]
    intr = Intrinsics(16, 16, 400.0, 400.0, 7.5, 7.5)  # a narrow view of the floor below the roof's centre
    pose = look([0.0, 0.0, 0.3], [0.0, 0.0, -1.0], [0.0, -1.0, 0.0])
    with backend(roofed_floor(0.0), sky, samples=128) as be:
        out = be.render_view(be.frame(0.0), intr, pose, want={"rgb", "shading"})
    expected = 1.0 - hidden_fraction(ROOF_HALF, ROOF_HEIGHT)
    assert abs(float(out["shading"].mean()) - expected) < 0.01 * expected


def test_translucency_of_a_leaf_lit_from_behind():
    """A horizontal leaf (albedo 0.5, translucency 0.4) under a sun straight above, seen from below in
    a black world: shading (its lower side) 0, translucency E * 0.5 * 0.4 / pi."""
    leaf = grid(-1.0, 1.0, -1.0, 1.0, 1.0, 2, albedo=0.5)
    leaf = Mesh.from_arrays(
        leaf.vertices, leaf.faces, semantic=leaf.semantic, material="leaf", albedo=0.5, translucency=0.4
    )
    sky = DarkSky(sun_irradiance=(3.0, 3.0, 3.0))
    intr = Intrinsics(8, 8, 200.0, 200.0, 3.5, 3.5)
    pose = look([0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0])
    with backend(leaf, sky, samples=16) as be:
        out = be.render_view(be.frame(0.0), intr, pose, want={"rgb", "shading", "translucency"})
    np.testing.assert_allclose(out["translucency"].mean(axis=(0, 1)), 3.0 * 0.5 * 0.4 / np.pi, rtol=0.01)
    assert float(np.median(out["shading"])) == 0.0 and float(out["shading"].mean()) < 0.01 * 0.6 / np.pi


def glossy_floor() -> Mesh:
    """A black mirror-like floor 6 m wide: specular 1, albedo 0, a leaf's material (no terrain texture
    bumps its normal)."""
    floor = grid(-3.0, 3.0, -3.0, 3.0, 0.0, 4, albedo=0.0)
    return Mesh.from_arrays(
        floor.vertices, floor.faces, semantic=floor.semantic, material="leaf", albedo=0.0, specular=1
    )


def glossy_of_both(mesh: Mesh, sky, intr: Intrinsics, pose: np.ndarray, samples: int) -> tuple[np.ndarray, np.ndarray]:
    """One view's glossy layer (H, W, 3) from Cycles and from the Embree backend."""
    from eden_pipe.render.backends.raytrace import RaytraceBackend

    with backend(mesh, sky, samples=samples) as be:
        cycles = be.render_view(be.frame(0.0), intr, pose, want={"rgb", "glossy"})["glossy"]
    embree = RaytraceBackend(
        SceneArrays(mesh, np.zeros(mesh.n_faces, np.uint16)), sky, RenderConfig(), modalities={"glossy"}
    )
    try:
        fast = embree.render_view(embree.frame(0.0), intr, pose, want={"rgb", "glossy"})["glossy"]
    finally:
        embree.close()
    return cycles, fast


@pytest.mark.parametrize("sun_off_vertical_deg", [0.0, 50.0])
def test_glossy_lobe_is_the_renderers_beckmann_lobe(sun_off_vertical_deg):
    """A glossy floor (specular 1, albedo 0) in a black world under a sun overhead or 50 degrees off
    vertical, seen around the sun's mirror: Cycles' glossy layer (a Beckmann Glossy BSDF of
    ``glossy_roughness(shading.GLOSS_ALPHA)``) equals the Embree backend's (the same microfacet lobe,
    ``kernels.glossy_lobe``) over the whole lobe, its shape away from normal incidence included. The
    normalised Blinn-Phong lobe the renderers had before (exponent 60) was 1.10 times this lobe's peak with
    the sun overhead and 0.43 of it with the sun 50 degrees off vertical (no 1 / (4 cos l cos v)); a GGX
    lobe of roughness 0.2 (alpha 0.04) peaks 17 times higher."""
    tilt = np.radians(sun_off_vertical_deg)
    floor = glossy_floor()
    sky = DarkSky(sun_irradiance=(3.0, 3.0, 3.0), sun_direction=(np.sin(tilt), 0.0, np.cos(tilt)))
    intr = Intrinsics(64, 64, 46.0, 46.0, 31.5, 31.5)  # +-35 degrees: the whole lobe
    forward, down = [np.sin(tilt), 0.0, -np.cos(tilt)], [-np.cos(tilt), 0.0, -np.sin(tilt)]
    pose = look([-np.sin(tilt), 0.0137, np.cos(tilt)], forward, down if tilt else [0.0, -1.0, 0.0])
    cycles, fast = (layer[..., 0] for layer in glossy_of_both(floor, sky, intr, pose, samples=64))
    lobe = fast > 0.15 * fast.max()
    assert lobe.sum() > 200
    ratio = cycles[lobe] / fast[lobe]
    assert abs(float(cycles.max() / fast.max()) - 1.0) < 0.04
    assert abs(float(np.median(ratio)) - 1.0) < 0.03 and 0.9 < float(ratio.min()) and float(ratio.max()) < 1.1
    assert abs(float(cycles.sum() / fast.sum()) - 1.0) < 0.03  # the lobe's energy


def test_mirror_light_with_the_renderers_fresnel_weight():
    """The same glossy floor under a sky whose radiance names its direction, no sun, seen obliquely:
    Cycles' glossy layer is the sky along each pixel's mirror direction times the renderer's Fresnel
    weight (1 head-on, up to 2 at grazing), as the Embree backend's glossy layer is, pixel by pixel."""
    floor = glossy_floor()
    sky = GradientSky()
    intr = Intrinsics(48, 36, 30.0, 30.0, 23.5, 17.5)
    pose = look([0.0137, 0.0, 0.6], [0.0, 0.8, -0.6], [0.0, 0.6, 0.8])  # 37 degrees down, no edge on a pixel centre
    cycles, fast = glossy_of_both(floor, sky, intr, pose, samples=4)
    _, d = primary_rays(intr, pose)
    grazing = 1.0 - np.abs(d[:, 2] / np.linalg.norm(d, axis=1))
    weight = np.minimum(1.0 + 24.0 * grazing**5, 2.0).reshape(36, 48)
    assert weight.min() < 1.01 and weight.max() > 1.5  # both ends of the weight
    np.testing.assert_allclose(cycles, fast, rtol=0.02)


@pytest.mark.slow  # about 3 minutes on 2 cores: 40 Cycles renders of the small garden
def test_pipeline_labels_identical_to_raytrace_and_validated(tmp_path, tmp_path_factory):
    """The tiny dataset again with render=cycles (its stages reused): every label file identical to
    render=raytrace's (decoded arrays: scripts/dataset_fingerprint.content_digest), and the cycles dataset passes
    ``validate`` (the identity checked from the written layers)."""
    from eden_pipe.pipeline import run_job
    from eden_pipe.tools.validate import main as validate
    from tests.conftest import TINY, make_cfg
    from tests.tiny_dataset import ALL_MODALITIES, tiny_root

    tiny = tiny_root(tmp_path_factory)
    overrides = TINY + [
        ALL_MODALITIES,
        "render=cycles",
        "render.cycles.samples=2",
        "render.cycles.map_width=128",
        f"paths.stages={tiny}/stages",
        f"paths.dataset={tmp_path}/dataset",
    ]
    if PYTHON:
        overrides.append(f"render.cycles.python={PYTHON}")
    run_job(make_cfg(None, overrides), echo=lambda *_: None)
    cycles, raytrace = tmp_path / "dataset", tiny / "dataset"
    same, differ = [], []
    for path in sorted(cycles.rglob("*")):
        rel = path.relative_to(cycles)
        column = rel.parts[-2] if len(rel.parts) >= 2 else ""
        if path.is_file() and column in {"semantic", "instance", "depth", "depth_right", "normal", "flow_fwd"}:
            (same if content_digest(path) == content_digest(raytrace / rel) else differ).append(str(rel))
    assert len(same) == 4 * 5 * 6 - 5 and not differ  # the last frame has no forward flow
    assert validate([str(cycles)]) == 0


def test_cycles_devices_benchmark_times_and_compares_devices(tmp_path):
    """benchmarks/cycles_devices.py run: a job written by its ``write_job`` rendered on the CPU and on
    ``auto`` in one worker; with the same seed the two agree within Cycles' own noise (where auto finds
    no GPU it is the CPU, and the images are the same pixel for pixel)."""
    mesh = roofed_floor(0.3)
    light = np.full((16, 32, 3), 0.8, np.float32)
    world = {
        "light_map": light,
        "camera_map": light,
        "sun_direction": np.array([0.3, 0.2, 0.93]) / np.linalg.norm([0.3, 0.2, 0.93]),
        "sun_irradiance": np.array([2.0, 1.9, 1.7]),
        "sun_angular_radius": 0.0046,
    }
    poses = np.stack([look([-1.5, y, 0.3071], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]) for y in (0.0137, 0.4)])
    job = tmp_path / "job.npz"
    meta = {"garden": "roofed floor", "seed": 0, "lighting": "sun", "faces": int(mesh.n_faces)}
    write_job(
        job,
        {k: getattr(mesh, k) for k in ("vertices", "faces", "albedo", "translucency", "specular")},
        world,
        Intrinsics(64, 48, 50.0, 50.0, 27.0, 20.0),
        poses,
        meta,
    )
    script = Path(__file__).resolve().parents[1] / "benchmarks" / "cycles_devices.py"
    res = subprocess.run(
        [
            sys.executable,
            str(script),
            "run",
            str(job),
            "--samples",
            "8",
            "--views",
            "2",
            "--threads",
            "2",
            "--python",
            PYTHON,
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 0, res.stdout + res.stderr
    lines = res.stdout.strip().splitlines()
    noise = float(re.search(r"relative error (\S+) \(the noise\)", res.stdout).group(1))
    error = float(re.search(r"auto vs cpu, same seed: relative error (\S+)", res.stdout).group(1))
    assert noise > 1e-3 and error <= noise
    backend_name = re.search(r"^auto \(([^)]+)\)", res.stdout, re.M).group(1)
    if backend_name == "CPU":
        assert error == 0.0
    timing = r"[\d.]+ x \([\d.]+ s vs [\d.]+ s a view, 64 x 48, 8 samples\)"
    assert re.fullmatch(
        rf"cycles auto \({re.escape(backend_name)}\) vs cpu: {timing}",
        lines[-1],
    ), lines[-1]


def test_worker_names_its_device_and_ends_with_its_parent(tmp_path):
    """The worker answers ``settings`` with the device Cycles renders on, and exits when its parent is
    killed in the middle of a render (the socket loop, which would notice, is not reached until the
    render ends: a GPU's first one can take minutes)."""
    import signal
    import time

    script = (
        "import time\n"
        "import numpy as np\n"
        "from eden_pipe.config.schema import CyclesConfig\n"
        "from eden_pipe.render.backends.cycles import CyclesProcess, plain, worker_settings\n"
        "from tests.sky_scenes import roofed_floor\n"
        f"p = CyclesProcess({PYTHON!r})\n"
        "m = roofed_floor(0.3)\n"
        "p.call('scene', {k: getattr(m, k) for k in ('vertices', 'faces', 'albedo', 'translucency', 'specular')})\n"
        "sky = np.full((16, 32, 3), 0.8, np.float32)\n"
        "p.call('world', {'light_map': sky, 'camera_map': sky, 'sun_direction': np.array([0.0, 0.0, 1.0]),"
        " 'sun_irradiance': np.zeros(3), 'sun_angular_radius': 0.0046})\n"
        "facts = p.call('settings', worker_settings(CyclesConfig(samples=1 << 24), 1))\n"
        "pose = np.diag([1.0, -1.0, -1.0, 1.0]); pose[2, 3] = 0.3\n"
        "view = dict(width=64, height=48, fx=50.0, fy=50.0, cx=31.5, cy=23.5, pose=pose,"
        f" paths=[{str(tmp_path / 'a.exr')!r}, {str(tmp_path / 'b.exr')!r}])\n"
        "p.conn.send(('view', plain(view)))  # a render of 16 M samples a pixel: busy for hours\n"
        "print(p.proc.pid, facts, flush=True)\n"
        "time.sleep(600)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True)
    worker = None
    try:
        pid_text, facts = parent.stdout.readline().split(" ", 1)
        worker = int(pid_text)
        assert facts.strip() == "{'device': 'CPU', 'names': []}"
        time.sleep(2.0)  # into the render
        assert running(worker)  # while its parent is
        parent.send_signal(signal.SIGKILL)
        parent.wait()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            if not running(worker):
                worker = None
                break
            time.sleep(0.2)
        assert worker is None, "the Cycles worker outlived its killed parent by 10 s"
    finally:
        if parent.poll() is None:
            parent.kill()
        if worker is not None:
            os.kill(worker, signal.SIGKILL)


def running(pid: int) -> bool:
    """Whether process ``pid`` runs (a zombie, exited but not yet reaped by whoever adopted it, does not)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except FileNotFoundError:
        return False
    return stat.rsplit(")", 1)[1].split()[0] != "Z"
