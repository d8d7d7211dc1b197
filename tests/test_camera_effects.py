"""Camera effects (docs/design.md, Camera effects): the sensor model's statistics and geometry, the
rolling shutter's per-row poses (exactly those of rig.json), motion blur, the ground truth unchanged
through the pipeline, the validator, every key's bad values, and every effect off as before."""

from __future__ import annotations

import re

import numpy as np
import pytest

from eden_pipe.camera.rig import Intrinsics
from eden_pipe.camera.sensor import Sensor
from eden_pipe.colour import srgb_to_uint8

INTR = Intrinsics(160, 120, 150.0, 150.0, 79.5, 59.5)


def flat(value: float, intr: Intrinsics = INTR) -> np.ndarray:
    return np.full((intr.height, intr.width, 3), value)


# ------------------------------------------------------------------ sensor: noise statistics
@pytest.mark.parametrize("x", [0.05, 0.3, 0.8])
@pytest.mark.parametrize("gain", [1.0, 4.0])
def test_adc_mean_and_variance_match_shot_and_read_noise(x, gain):
    """A flat field's ADC values: mean black + x (white - black), variance from the model's shot and
    read noise (plus 1/12 DN^2 of rounding), each within 5 sampling standard errors."""
    sensor = Sensor(full_well_e=2000.0, read_noise_e=4.0, gain=gain, black_level=0.0625, bits=12)
    dn = sensor.digitise(flat(x), np.random.default_rng(1))
    n = dn.size
    scale = sensor.white_dn - sensor.black_dn  # DN per unit of x
    want_mean = sensor.black_dn + x * scale
    want_var = (sensor.noise_sigma(np.float64(x)) * scale) ** 2 + 1.0 / 12.0
    assert abs(dn.mean() - want_mean) < 5 * np.sqrt(want_var / n)
    # The sample variance's standard error for a near-normal variable: var * sqrt(2 / (n - 1)).
    assert abs(dn.var(ddof=1) - want_var) < 5 * want_var * np.sqrt(2.0 / (n - 1))


def test_black_level_keeps_the_dark_noise_and_the_isp_clips_it():
    """In the dark, the ADC's mean is the black level (noise both sides of it, none clipped at 0);
    without a black level half the read noise is clipped at 0 DN, which biases the mean up.
    Above the white point every value is the white level."""
    dark = flat(0.0)
    with_black = Sensor(read_noise_e=5.0, black_level=0.0625, bits=10)
    dn = with_black.digitise(dark, np.random.default_rng(2))
    assert abs(dn.mean() - with_black.black_dn) < 0.05 and dn.min() < with_black.black_dn
    no_black = Sensor(read_noise_e=5.0, black_level=0.0, bits=10)
    dn0 = no_black.digitise(dark, np.random.default_rng(2))
    assert dn0.min() == 0 and dn0.mean() > 0.1  # clipped at 0: a positive bias
    bright = with_black.digitise(flat(1.5), np.random.default_rng(3))
    assert np.all(bright == with_black.white_dn)
    assert np.all(with_black.to_display(bright) == 255) and np.all(with_black.to_display(dn) <= 10)


def test_low_bit_depth_quantises_to_its_levels():
    sensor = Sensor(read_noise_e=0.0, full_well_e=1e9, black_level=0.0, bits=2, tone_curve="gamma", gamma=1.0)
    ramp = np.linspace(0, 1, INTR.width)[None, :, None] * np.ones((INTR.height, 1, 3))
    out = sensor.apply(ramp, INTR, np.random.default_rng(0))
    assert set(np.unique(out)) == {0, 85, 170, 255}


def test_noise_is_deterministic_per_generator():
    sensor = Sensor()
    image = np.random.default_rng(5).uniform(0, 1, (INTR.height, INTR.width, 3))
    a = sensor.apply(image, INTR, np.random.default_rng(7))
    b = sensor.apply(image, INTR, np.random.default_rng(7))
    c = sensor.apply(image, INTR, np.random.default_rng(8))
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_noiseless_sensor_is_the_srgb_png():
    """With no noise, a deep ADC and no black level, the sensor's PNG is sRGB(exposure * I) to 1 level."""
    sensor = Sensor(full_well_e=1e12, read_noise_e=0.0, black_level=0.0, bits=16)
    image = np.random.default_rng(5).uniform(0, 1.2, (INTR.height, INTR.width, 3))
    got = sensor.apply(image, INTR, np.random.default_rng(0)).astype(int)
    assert np.abs(got - srgb_to_uint8(image).astype(int)).max() <= 1


@pytest.mark.parametrize("curve", ["srgb", "gamma", "filmic"])
def test_tone_curves_fix_black_and_white_and_rise(curve):
    sensor = Sensor(tone_curve=curve)
    y = np.linspace(0, 1, 256)
    out = sensor.tone(y).astype(int)
    assert out[0] == 0 and out[-1] == 255 and np.all(np.diff(out) >= 0)


# ------------------------------------------------------------------ sensor: optics geometry
def test_cos4_vignetting_is_one_at_the_centre_and_cos4_off_axis():
    intr = Intrinsics(101, 81, 50.0, 50.0, 50.0, 40.0)
    falloff = Sensor(vignetting="cos4").relative_illumination(intr)
    assert falloff[40, 50] == 1.0
    theta = np.arctan(50.0 / 50.0)  # pixel (u=100, v=40): 50 px off axis at f = 50 px, 45 degrees
    assert falloff[40, 100] == pytest.approx(np.cos(theta) ** 4, rel=1e-12)
    assert falloff[0, 0] == pytest.approx(np.cos(np.arctan(np.hypot(50, 40) / 50.0)) ** 4, rel=1e-12)


def test_polynomial_vignetting_known_radius():
    intr = Intrinsics(101, 81, 50.0, 50.0, 50.0, 40.0)
    sensor = Sensor(vignetting="polynomial", vignetting_k1=-0.3, vignetting_k2=0.1)
    falloff = sensor.relative_illumination(intr)
    assert falloff[40, 50] == 1.0
    assert falloff[40, 75] == pytest.approx(1 - 0.3 * 0.25 + 0.1 * 0.0625, rel=1e-12)  # r = 25/50


def test_lateral_chromatic_aberration_moves_red_and_blue_radially():
    """A white dot 40 px right of the principal point: green stays, red lands at 40 (1 + ca_red) px and
    blue at 40 (1 + ca_blue) px (the centroid of its resampled spot); the centre pixel is unchanged."""
    intr = Intrinsics(201, 101, 100.0, 100.0, 100.0, 50.0)
    image = np.zeros((101, 201, 3))
    image[50, 140] = 1.0
    image[50, 100] = 0.5
    sensor = Sensor(ca_red=0.05, ca_blue=-0.025)
    out = sensor.aberrate(image, intr)
    assert np.array_equal(out[..., 1], image[..., 1])
    assert np.all(out[50, 100] == 0.5)
    for channel, scale in ((0, 0.05), (2, -0.025)):
        row = out[50, 120:, channel]  # the dot's spot, away from the centre pixel's
        centroid = 120 + np.sum(row * np.arange(len(row))) / row.sum()
        assert centroid == pytest.approx(100 + 40 * (1 + scale), abs=0.05)


# ------------------------------------------------------------------ sensor: the validator's check
def test_validator_accepts_the_sensor_png_and_rejects_another_sensors():
    """The validator's sensor check passes a PNG made by camera.json's sensor from the composite and fails
    one made with 16x the gain (4x the noise) or without the vignetting the file declares."""
    from eden_pipe.tools.camera_check import check_rgb_sensor
    from eden_pipe.tools.consistency import Layer
    from eden_pipe.tools.validate import Report

    intr = INTR
    row = {"width": intr.width, "height": intr.height, "fx": intr.fx, "fy": intr.fy, "cx": intr.cx, "cy": intr.cy}
    composite = np.random.default_rng(3).uniform(0, 0.5, (intr.height, intr.width, 3)).astype(np.float32)
    linear = Layer(composite, np.zeros_like(composite))
    declared = Sensor(full_well_e=3000.0, read_noise_e=3.0, vignetting="cos4", ca_red=0.002)
    exposure = 1.5
    results = {}
    for name, used in (
        ("same", declared),
        ("noisier", Sensor(**{**declared.__dict__, "gain": 16.0})),
        ("no vignetting", Sensor(**{**declared.__dict__, "vignetting": "none"})),
    ):
        png = used.apply(composite * np.float32(exposure), intr, np.random.default_rng(4))
        report = Report()
        check_rgb_sensor(report, "rgb.png", row, png, linear, exposure, declared.facts())
        results[name] = report.ok and report.checks == {"rgb": 1}
    assert results == {"same": True, "noisier": False, "no vignetting": False}


# ------------------------------------------------------------------ rolling shutter: per-row poses
def walk(n: int = 4, fps: float = 10.0) -> np.ndarray:
    """(n, 4, 4) poses of a camera turning 0.2 rad about z and moving 0.05 m along x per frame."""
    from eden_pipe.camera.rig import look_rotation

    poses = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        poses[i, :3, :3] = look_rotation(0.2 * i, -0.1)
        poses[i, :3, 3] = [0.05 * i, 1.0, 0.8]
    return poses


def rotation_angle(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation between two poses (or rotations)."""
    return float(np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1)))


def test_pose_interpolation_hits_the_frames_and_slerps_between():
    from eden_pipe.camera.shutter import poses_at

    poses, fps = walk(), 10.0
    got = poses_at(poses, fps, 1, np.array([0.0, 0.1, -0.1, 0.05, 0.025]))
    assert np.array_equal(got[0], poses[1]) and np.array_equal(got[1], poses[2]) and np.array_equal(got[2], poses[0])
    half = got[3]  # halfway from frame 1 to 2: half the rotation, the translations' mean
    assert np.allclose(half[:3, 3], (poses[1, :3, 3] + poses[2, :3, 3]) / 2, atol=1e-15)
    assert rotation_angle(poses[1, :3, :3], half[:3, :3]) == pytest.approx(0.5 * rotation_angle(poses[1], poses[2]))
    assert rotation_angle(half[:3, :3], poses[2, :3, :3]) == pytest.approx(0.5 * rotation_angle(poses[1], poses[2]))
    quarter = got[4]
    assert rotation_angle(poses[1, :3, :3], quarter[:3, :3]) == pytest.approx(0.25 * rotation_angle(poses[1], poses[2]))
    assert np.allclose(quarter[:3, :3] @ quarter[:3, :3].T, np.eye(3), atol=1e-14)


def test_pose_interpolation_extrapolates_past_the_ends():
    from eden_pipe.camera.shutter import poses_at

    poses, fps = walk(3), 10.0
    after = poses_at(poses, fps, 2, np.array([0.05]))[0]  # half a frame past the last: constant velocity
    assert np.allclose(after[:3, 3], poses[2, :3, 3] + 0.5 * (poses[2, :3, 3] - poses[1, :3, 3]), atol=1e-15)
    assert rotation_angle(poses[2, :3, :3], after[:3, :3]) == pytest.approx(0.5 * rotation_angle(poses[1], poses[2]))
    before = poses_at(poses, fps, 0, np.array([-0.05]))[0]
    assert np.allclose(before[:3, 3], poses[0, :3, 3] - 0.5 * (poses[1, :3, 3] - poses[0, :3, 3]), atol=1e-15)
    single = poses_at(poses[:1], fps, 0, np.array([-0.05, 0.05]))
    assert np.array_equal(single, np.stack([poses[0], poses[0]]))


def test_rolling_shutter_rows_span_the_readout_and_the_middle_row_is_the_frame():
    from eden_pipe.camera.shutter import exposure_poses, poses_at, row_offsets

    poses, fps, height, readout = walk(), 10.0, 121, 0.03
    rows = exposure_poses(poses, fps, 1, height, readout)[0]
    assert rows.shape == (height, 4, 4)
    assert np.array_equal(rows[60], poses[1])  # mid-exposure row: the published pose, exactly
    assert np.array_equal(rows[0], poses_at(poses, fps, 1, np.array([-readout / 2]))[0])
    assert np.array_equal(rows[-1], poses_at(poses, fps, 1, np.array([readout / 2]))[0])
    assert row_offsets(height, readout)[[0, 60, 120]].tolist() == [-0.015, 0.0, 0.015]
    assert np.all(exposure_poses(poses, fps, 1, height, 0.0)[0] == poses[1])  # global shutter
    blurred = exposure_poses(poses, fps, 1, 5, 0.0, exposure_s=0.04, samples=4)
    offsets = [-0.015, -0.005, 0.005, 0.015]
    assert np.array_equal(blurred[:, 0], poses_at(poses, fps, 1, np.array(offsets)))


# ------------------------------------------------------------------ rendering over the exposure
@pytest.fixture(scope="module")
def ground_backend():
    """The raytrace backend on a ground plane under the clear sky, and one frame's shading state."""
    from eden_pipe import labels
    from eden_pipe.config import make_cfg
    from eden_pipe.models.mesh import Mesh
    from eden_pipe.render.backends.raytrace import RaytraceBackend
    from eden_pipe.scene.arrays import SceneArrays
    from eden_pipe.stages.render import make_sky

    cfg = make_cfg(None, ["render.sky_visibility.enabled=false"])
    ground = Mesh.from_arrays(
        [[-20, -20, 0], [30, -20, 0], [30, 30, 0], [-20, 30, 0]],
        [[0, 1, 2], [0, 2, 3]],
        semantic=labels.GROUND,
        material="dirt",
        albedo=[0.3, 0.25, 0.2],
    )
    sky, _ = make_sky(cfg.lighting, 0)
    backend = RaytraceBackend(SceneArrays(ground, np.zeros(2, np.uint16)), sky, cfg.render, modalities={"rgb"})
    yield backend, backend.frame(0.0)
    backend.close()


class RecordingTracer:
    """A tracer that records the rays and hits of every ``intersect`` and forwards to the real one."""

    def __init__(self, tracer):
        self.tracer, self.calls = tracer, []

    def intersect(self, origins, dirs, **kw):
        hits = self.tracer.intersect(origins, dirs, **kw)
        self.calls.append((origins.copy(), dirs.copy(), hits.t.copy()))
        return hits

    def __getattr__(self, name):
        return getattr(self.tracer, name)


def test_rolling_shutter_render_casts_each_row_from_its_published_pose(ground_backend):
    """Every row of the rendered RGB is traced from exposure_poses' pose of that row: its rays are
    primary_rays of that pose, and their hits on the ground are the analytic ray-plane depths."""
    from eden_pipe.camera.shutter import exposure_poses, sample_offsets
    from eden_pipe.render.exposure import ExposureScene, render_exposed_rgb
    from eden_pipe.render.view import primary_rays

    backend, state = ground_backend
    intr = Intrinsics(48, 31, 40.0, 40.0, 23.5, 15.0)
    poses = walk()
    poses[:, 2, 3] = [0.8, 1.0, 1.3, 1.5]  # rising too: rows see the ground from different heights
    pose_samples = exposure_poses(poses, 10.0, 1, intr.height, readout_s=0.08)
    row_poses = pose_samples[0]
    tracer = RecordingTracer(backend.tracer)
    rgb = render_exposed_rgb(
        lambda t: ExposureScene(tracer, backend.scene.mesh, state),
        intr,
        pose_samples,
        sample_offsets(0.0, 1),
        backend.sky,
        np.random.default_rng(0),
    )
    assert rgb.shape == (intr.height, intr.width, 3) and np.isfinite(rgb).all()
    origins, dirs, t = tracer.calls[0]
    w, checked = intr.width, 0
    for r in range(intr.height):
        o, d = primary_rays(intr, row_poses[r])
        rows = slice(r * w, (r + 1) * w)
        assert np.array_equal(origins[rows], o[rows])
        assert np.allclose(dirs[rows], d[rows], rtol=0, atol=1e-15)
        with np.errstate(divide="ignore"):
            analytic = np.where(d[rows, 2] < 0, -row_poses[r, 2, 3] / d[rows, 2], np.inf)  # z-depth on z = 0
        near = analytic < 15.0  # on the plane (it reaches 20 m or more from the camera)
        checked += int(near.sum())
        assert np.allclose(t[rows][near], analytic[near], rtol=1e-5)
    assert checked > intr.width * intr.height / 3


def test_exposure_of_one_sample_at_the_frame_is_the_sharp_render(ground_backend):
    """With no readout and no blur the exposure render is the sharp render's RGB bit for bit."""
    from eden_pipe.camera.shutter import exposure_poses, sample_offsets

    backend, state = ground_backend
    intr = Intrinsics(48, 32, 40.0, 40.0, 23.5, 15.5)
    poses = walk()
    sharp = backend.render_view(state, intr, poses[1], want={"rgb"}, rng=np.random.default_rng(3))["rgb_linear"]
    exposed = backend.render_exposed(
        state,
        intr,
        exposure_poses(poses, 10.0, 1, intr.height, 0.0),
        sample_offsets(0.0, 8),
        rng=np.random.default_rng(3),
    )
    assert np.array_equal(exposed, sharp)


def test_motion_blur_averages_the_sub_frame_renders(ground_backend):
    """The blurred RGB is the mean of the renders at each sub-frame pose (the callback's scene at
    each sample's offset), and differs from the sharp frame."""
    from eden_pipe.camera.shutter import exposure_poses, sample_offsets

    backend, state = ground_backend
    intr = Intrinsics(48, 32, 40.0, 40.0, 23.5, 15.5)
    poses = walk()
    samples = exposure_poses(poses, 10.0, 1, intr.height, 0.0, exposure_s=0.05, samples=3)
    blurred = backend.render_exposed(state, intr, samples, sample_offsets(0.05, 3), rng=np.random.default_rng(3))
    each = [
        backend.render_exposed(state, intr, samples[j : j + 1], np.zeros(1), rng=np.random.default_rng(3))
        for j in range(3)
    ]
    assert np.allclose(blurred, np.mean(each, axis=0), rtol=1e-6, atol=1e-7)
    assert not np.allclose(blurred, each[1])


# ------------------------------------------------------------------ through the pipeline
def dataset_files(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def effect_jobs(tmp_path_factory):
    """A tiny job clean, with the sensor, and with sensor, rolling shutter and blur; one stage cache."""
    from eden_pipe.pipeline import run_job
    from tests.conftest import TINY, make_cfg

    stages = tmp_path_factory.mktemp("stages")
    variants = {
        "clean": [],
        "sensor": ["camera.sensor.enabled=true", "camera.sensor.vignetting=cos4", "camera.sensor.ca_red=0.003"],
        "all": [
            "camera.sensor.enabled=true",
            "camera.sensor.tone_curve=filmic",
            "camera.readout_s=0.03",
            "camera.exposure_s=0.02",
            "camera.blur_samples=2",
        ],
    }
    roots = {}
    for name, overrides in variants.items():
        root = tmp_path_factory.mktemp(name)
        run_job(make_cfg(root, TINY + [f"paths.stages={stages}", *overrides]), echo=lambda *_: None)
        roots[name] = (root / "dataset", TINY + [f"paths.stages={stages}", *overrides])
    return roots


def test_effects_change_only_the_rgb_pngs_and_publish_camera_json(effect_jobs):
    """The ground truth (labels, depth, normals, flow, layers) is the clean render's, byte for byte."""
    import json

    clean = dataset_files(effect_jobs["clean"][0])
    assert not any(name.endswith("camera.json") for name in clean)
    for name in ("sensor", "all"):
        files = dataset_files(effect_jobs[name][0])
        images = {k for k in clean if "/cam" in k and k.endswith((".png", ".npy", ".exr", ".flo"))}
        rgb = {k for k in images if "/rgb_left/" in k or "/rgb_right/" in k}
        assert rgb and len(images) > 2 * len(rgb)
        assert all(files[k] == clean[k] for k in images - rgb)
        assert all(files[k] != clean[k] for k in rgb)
        (camera_json,) = [k for k in files if k.endswith("camera.json")]
        published = json.loads(files[camera_json])
        assert (published["sensor"]["bits"], published["sensor"]["white_dn"], published["sensor"]["black_dn"]) == (
            10,
            1023,
            64,
        )
    published = json.loads(dataset_files(effect_jobs["all"][0])["small-s0/clear/camera.json"])
    assert (published["readout_s"], published["exposure_s"], published["blur_samples"]) == (0.03, 0.02, 2)


@pytest.mark.parametrize("name", ["sensor", "all"])
def test_validate_passes_with_the_effects_and_says_what_it_skipped(effect_jobs, name):
    from eden_pipe.tools.validate import check_dataset

    report = check_dataset(effect_jobs[name][0], progress=False)
    assert report.ok, report.lines()
    skipped = dict(report.not_run.keys())  # (check, reason) -> rows: check -> reason
    if name == "sensor":
        assert report.checks["rgb"] > 0 and "rgb" not in skipped
    else:
        assert "rgb" not in report.checks and "rolling shutter or motion blur" in skipped["rgb"]


def test_rendering_again_gives_the_same_bytes(effect_jobs, tmp_path):
    """The noise and the exposure's shading samples are seeded per frame and view: a re-render (a new
    dataset root, the render stage forced) writes the same files."""
    from eden_pipe.pipeline import run_job
    from tests.conftest import make_cfg

    root, overrides = effect_jobs["all"]
    first = dataset_files(root)
    run_job(make_cfg(tmp_path, [*overrides, "force=[render]"]), echo=lambda *_: None)
    again = dataset_files(tmp_path / "dataset")
    images = [k for k in first if "/cam" in k]
    assert images and all(again[k] == first[k] for k in images)


def test_shutter_and_blur_need_a_backend_that_renders_them():
    from eden_pipe.preflight import PreflightError, check_job
    from tests.conftest import TINY, make_cfg

    for key in ("camera.readout_s=0.01", "camera.exposure_s=0.01"):
        cfg = make_cfg(None, [*TINY, "render=tinyrenderer", key, "paths.check_free_space=false"])
        with pytest.raises(PreflightError, match=r"camera\.readout_s and camera\.exposure_s need a backend"):
            check_job(cfg)


def test_the_traced_row_poses_are_exposure_poses_of_rig_json_exactly(effect_jobs):
    """A user's exposure_poses of rig.json's poses and camera.json's keys are exactly the poses the
    render stage hands the backend, for every view of a frame."""
    import json

    from eden_pipe.camera.shutter import exposure_poses
    from eden_pipe.config import to_config
    from eden_pipe.stages.render import FrameRenderer
    from tests.conftest import make_cfg

    root, overrides = effect_jobs["all"]
    cfg = to_config(make_cfg(root.parent, overrides))
    rig = json.loads((root / "small-s0" / "clear" / "rig.json").read_text())
    camera = json.loads((root / "small-s0" / "clear" / "camera.json").read_text())
    poses = np.array([[c["poses"] for c in rig["cameras"][2 * k : 2 * k + 2]] for k in range(5)]).transpose(
        2, 0, 1, 3, 4
    )
    exact = poses + np.random.default_rng(0).normal(0, 1e-11, poses.shape)  # the stage's unrounded poses

    from eden_pipe.render.backends import Backend

    class Recorder(Backend):  # render_exposed_views: the interface's, view by view
        def __init__(self):
            self.calls = []

        def render_exposed(self, state, intr, pose_samples, sample_offsets, *, rng, rgb_spp=1):
            self.calls.append(pose_samples)
            return np.zeros((intr.height, intr.width, 3), np.float32)

    backend = Recorder()
    renderer = FrameRenderer(root, cfg, backend, None, exact, {"rgb"}, seed=0)
    blank = np.zeros((rig["height"], rig["width"], 3), np.float32)
    frame, pair = 2, 3
    renderer.expose(None, {"left": {"rgb_linear": blank}, "right": {"rgb_linear": blank}}, frame, pair)
    for side, traced in enumerate(backend.calls):
        mine = exposure_poses(
            np.array(rig["cameras"][2 * pair + side]["poses"]),
            camera["fps"],
            frame,
            rig["height"],
            camera["readout_s"],
            camera["exposure_s"],
            camera["blur_samples"],
        )
        assert mine.shape == (2, rig["height"], 4, 4) and np.array_equal(traced, mine)
    assert len(backend.calls) == 2


# ------------------------------------------------------------------ configuration
EFFECT_KEYS = ["camera.readout_s", "camera.exposure_s", "camera.blur_samples"]


def effect_bad_values() -> list[tuple[str, object]]:
    """Every camera-effect key and each value its domain (config.schema) gives as outside it."""
    from eden_pipe.config import EdenConfig, schema_items
    from eden_pipe.config.domains import Where

    default = EdenConfig()
    cases = []
    for item in schema_items():
        if item.domain is None or not (item.key in EFFECT_KEYS or item.key.startswith("camera.sensor.")):
            continue
        where = Where(item.key, item.kind, default.camera.sensor if "sensor" in item.key else default.camera)
        cases += [(item.key, value) for value in item.domain.outside(where)]
    return cases


def test_every_effect_key_has_bad_values_to_try():
    keys = {key for key, _ in effect_bad_values()}
    assert keys >= {*EFFECT_KEYS, "camera.sensor.full_well_e", "camera.sensor.bits", "camera.sensor.tone_curve"}
    assert len(keys) == len(EFFECT_KEYS) + 12  # every sensor key but the enabled switch


@pytest.mark.parametrize(("key", "value"), effect_bad_values(), ids=lambda v: str(v))
def test_a_bad_effect_value_is_rejected_naming_key_value_and_allowed(key, value):
    from eden_pipe.config import make_cfg, validate
    from eden_pipe.errors import ConfigError

    shown = f"'{value}'" if isinstance(value, str) else ("inf" if value == np.inf else repr(value))
    with pytest.raises(ConfigError, match=rf"invalid config: {re.escape(key)}=.*; allowed: "):
        validate(make_cfg(None, [f"{key}={shown}"]))


def test_with_every_effect_off_the_png_key_and_metadata_are_as_before():
    """Off by default: the PNG is srgb_to_uint8(exposure * rgb_linear) as before, expose adds nothing,
    the render key gets no part and no camera.json is written (the whole dataset's byte-identity with
    the revision before is scripts/dataset_fingerprint.py's: only config.yaml differs)."""
    from types import SimpleNamespace

    from eden_pipe.config import make_cfg, to_config
    from eden_pipe.stages.describe import camera_effects_metadata
    from eden_pipe.stages.render import FrameRenderer, camera_effects_key

    cfg = to_config(make_cfg(None, []))
    assert camera_effects_key(cfg.camera) == [] and camera_effects_metadata(cfg) is None
    renderer = FrameRenderer(None, cfg, None, SimpleNamespace(exposure=1.7), np.zeros((3, 5, 2, 4, 4)), {"rgb"}, 0)
    linear = np.random.default_rng(0).uniform(0, 1, (4, 5, 3)).astype(np.float32)
    views = {"left": {"rgb_linear": linear}}
    renderer.expose(None, views, 1, 0)
    assert set(views["left"]) == {"rgb_linear"}
    assert np.array_equal(renderer.display_rgb(views["left"], 1, 0, "left"), srgb_to_uint8(linear * 1.7))


def test_a_rerun_without_effects_removes_camera_json(effect_jobs):
    """Publishing the clean job into a dataset that held a job with effects drops its camera.json."""
    from eden_pipe.pipeline import run_job
    from tests.conftest import TINY, make_cfg

    root, overrides = effect_jobs["sensor"]
    stages = next(o for o in overrides if o.startswith("paths.stages="))
    assert (root / "small-s0" / "clear" / "camera.json").is_file()
    run_job(make_cfg(root.parent, [*TINY, stages]), echo=lambda *_: None)
    assert not (root / "small-s0" / "clear" / "camera.json").exists()
