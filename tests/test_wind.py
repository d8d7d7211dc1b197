"""Wind-blown foliage (docs/design.md, "Wind"): the deformation, the movable tracer, exact flow of the
moved surface, the dynamic mask and motion layers, the validator's checks and still air unchanged.

The flow oracle here is independent of the renderer: brute-force ray-triangle intersection in numpy
against the mesh as the deformation places it at each frame's time, barycentric coordinates carried to
the next frame's vertices, projected through the next pose.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from eden_pipe import labels
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.config import make_cfg
from eden_pipe.errors import ConfigError
from eden_pipe.models.bush import build_bush_model
from eden_pipe.models.mesh import MATERIALS, Mesh
from eden_pipe.pipeline import run_job
from eden_pipe.preflight import check_job
from eden_pipe.render import wind
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.view import Motion, render_view
from eden_pipe.scene.arrays import SceneArrays
from eden_pipe.stages.render import render_key
from eden_pipe.tools.validate import check_dataset
from tests.conftest import TINY

BREEZE = wind.WindParams(speed_mps=6.0, direction_deg=30.0, gust_strength=0.4)


def toy_garden(seed: int = 3) -> tuple[Mesh, np.ndarray]:
    """A ground quad (rigid) and a 'tree' of 60 leaf triangles 0.3-2 m up on a trunk-like column."""
    rng = np.random.default_rng(seed)
    ground = np.array([[-3, -3, 0], [3, -3, 0], [3, 3, 0], [-3, 3, 0]], np.float32)
    centres = np.column_stack([rng.uniform(-0.6, 0.6, 60), rng.uniform(-0.6, 0.6, 60), rng.uniform(0.3, 2.0, 60)])
    leaves = (centres[:, None, :] + rng.normal(0, 0.12, (60, 3, 3))).reshape(-1, 3).astype(np.float32)
    base = np.array([[0, 0, 0.0], [0.05, 0, 0.0], [0, 0.05, 0.0]], np.float32)  # fixes the tree's base at z = 0
    vertices = np.concatenate([ground, leaves, base])
    faces = np.concatenate([[[0, 1, 2], [0, 2, 3]], 4 + np.arange(180).reshape(60, 3), [[184, 185, 186]]])
    n = len(faces)
    semantic = np.full(n, labels.TREE, np.uint8)
    semantic[:2] = labels.GROUND
    material = np.full(n, MATERIALS["leaf"], np.uint8)
    material[:2] = MATERIALS["dirt"]
    instance = np.where(semantic == labels.TREE, 1, 0).astype(np.uint16)
    return Mesh(vertices, faces.astype(np.int32), semantic, material, (0.4, 0.5, 0.3)), instance


def look_at(eye, target) -> np.ndarray:
    """Camera-to-world pose, OpenCV axes (x right, y down, z forward), world Z up."""
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    pose = np.eye(4)
    pose[:3, :3] = np.column_stack([x, np.cross(z, x), z])
    pose[:3, 3] = eye
    return pose


def brute_force_hits(vertices, faces, origins, dirs):
    """(t, face, barycentric (b1, b2)) of the nearest hit of each ray, numpy Moller-Trumbore in float64."""
    tri = vertices[faces].astype(np.float64)
    a, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    p = np.cross(dirs[:, None, :], e2[None])
    det = np.einsum("fk,nfk->nf", e1, p)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / det
        s = origins[:, None, :] - a[None]
        u = np.einsum("nfk,nfk->nf", s, p) * inv
        q = np.cross(s, e1[None])
        v = np.einsum("nk,nfk->nf", dirs, q) * inv
        t = np.einsum("fk,nfk->nf", e2, q) * inv
    ok = (np.abs(det) > 1e-12) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-6)
    t = np.where(ok, t, np.inf)
    face = np.argmin(t, axis=1)
    rows = np.arange(len(origins))
    return t[rows, face], face, np.stack([u[rows, face], v[rows, face]], 1)


# ------------------------------------------------------------------ the deformation
def test_rigid_parts_never_move_and_positions_depend_on_time_alone():
    mesh, instance = toy_garden()
    field = wind.WindField.build(mesh, instance, BREEZE, seed=5)
    ground = np.unique(mesh.faces[:2])
    later, earlier = field.positions(2.0), field.positions(0.7)
    again = field.positions(2.0)  # after another time: no state carried between calls
    assert np.array_equal(later, again)
    assert np.array_equal(later[ground], mesh.vertices[ground])  # rigid: never written, bit for bit
    leaves = np.unique(mesh.faces[2:-1])
    assert np.all(np.linalg.norm(later[leaves] - earlier[leaves], axis=1) > 0)
    base = mesh.faces[-1]
    assert np.abs(later[base] - mesh.vertices[base]).max() < 1e-3  # the plant's foot stays put
    other = wind.WindField.build(mesh, instance, BREEZE, seed=6)  # another garden seed: other plant phases
    assert not np.array_equal(other.positions(2.0), later)


def test_drag_grows_with_the_square_of_the_speed():
    mesh, instance = toy_garden()
    slow = wind.WindField.build(mesh, instance, wind.WindParams(3.0, 30.0, 0.4), seed=5)
    fast = wind.WindField.build(mesh, instance, wind.WindParams(6.0, 30.0, 0.4), seed=5)
    # Same gust phase: the gust field travels at the wind speed, so compare where it does not lag.
    slow.params, fast.params = wind.WindParams(3.0, 30.0, 0.0), wind.WindParams(6.0, 30.0, 0.0)
    d_slow = slow.positions(1.3).astype(np.float64) - mesh.vertices
    d_fast = fast.positions(1.3).astype(np.float64) - mesh.vertices
    moved = np.abs(d_slow).max(axis=1) > 1e-4
    assert moved.sum() > 100
    assert np.allclose(d_fast[moved], 4.0 * d_slow[moved], rtol=0, atol=2e-6)
    assert wind.WindParams(40.0, 0.0, 0.0).amplitude == wind.WindParams(wind.MAX_SPEED_MPS, 0.0, 0.0).amplitude


def test_the_fast_sine_is_within_its_stated_error():
    from numba import njit

    x = np.linspace(-5000.0, 5000.0, 400001)
    values = njit(lambda a: np.array([wind._sin(v) for v in a]))(x)
    assert np.abs(values - np.sin(x)).max() < 4e-6


def test_surface_motion_is_exact_for_an_affine_motion_and_zero_on_rigid_faces():
    rng = np.random.default_rng(1)
    now = rng.normal(size=(30, 3)).astype(np.float32)
    faces = np.arange(30, dtype=np.int32).reshape(10, 3)
    A = np.eye(3) + rng.normal(0, 0.05, (3, 3))
    shift = np.array([0.01, -0.02, 0.005])
    other = (now.astype(np.float64) @ A.T + shift).astype(np.float32)
    other[:3] = now[:3]  # face 0 does not move
    prim = np.array([0, 1, 2, 5, 9, 4])
    bary = rng.dirichlet(np.ones(3), len(prim))
    points = np.einsum("nk,nkd->nd", bary, now[faces[prim]].astype(np.float64))
    hit = np.array([True, True, True, True, True, False])
    delta = wind.surface_motion(points, prim, hit, faces, now, other)
    want = np.einsum("nk,nkd->nd", bary, other[faces[prim]].astype(np.float64)) - points
    assert np.array_equal(delta[0], np.zeros(3)) and np.array_equal(delta[5], np.zeros(3))
    assert np.allclose(delta[1:5], want[1:5], rtol=0, atol=1e-9)


# ------------------------------------------------------------------ the movable tracer
def test_a_refitted_scene_gives_the_hits_of_a_scene_built_on_the_moved_mesh():
    hedge = build_bush_model("hedge_privet", 0).mesh
    field = wind.WindField.build(hedge, np.ones(hedge.n_faces, np.uint16), BREEZE, seed=2)
    moved = field.positions(1.7)
    v, u = np.meshgrid(np.linspace(-0.45, 0.45, 45), np.linspace(-0.6, 0.6, 62), indexing="ij")
    dirs = np.stack([u.ravel(), np.ones(u.size), -v.ravel() - 0.1], 1).astype(np.float32)
    origins = np.broadcast_to(np.float32([0.1, -3.0, 1.0]), dirs.shape).copy()
    fresh_mesh = Mesh(moved, hedge.faces, hedge.semantic, hedge.material, hedge.albedo)
    for path in ("native", "embreex"):
        with RayTracer(hedge, 1, path, movable=True) as movable, RayTracer(fresh_mesh, 1, path) as fresh:
            before = movable.intersect(origins, dirs, image=(45, 62))
            field.move(1.7, movable.vertices)
            movable.refit()
            got, want = movable.intersect(origins, dirs, image=(45, 62)), fresh.intersect(origins, dirs, image=(45, 62))
            assert 0.2 < want.hit.mean() < 0.95
            assert np.array_equal(got.prim, want.prim) and np.array_equal(got.t, want.t), path
            assert not np.array_equal(before.t, got.t)  # the refit moved what the rays see


# ------------------------------------------------------------------ the view
def test_flow_follows_each_moved_surface_point_exactly():
    mesh, instance = toy_garden()
    field = wind.WindField.build(mesh, instance, BREEZE, seed=5)
    intr = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    pose = look_at(np.array([0.3, -2.5, 1.3]), [0, 0, 1.0])
    pose_next = look_at(np.array([0.36, -2.45, 1.31]), [0.02, 0, 1.0])
    times = {"now": 1.0, "next": 1.1}
    tracers = {k: RayTracer(mesh, 1, "native", movable=True) for k in times}
    for k, t in times.items():
        field.move(t, tracers[k].vertices)
        tracers[k].refit()
    motion = Motion(mesh.faces, tracers["now"].vertices, tracers["next"], None)
    scene = SceneArrays(mesh, instance)
    out = render_view(
        tracers["now"], scene, intr, pose, None, want={"flow", "dynamic"}, pose_next=pose_next, motion=motion
    )
    # The oracle: the same rays, numpy intersection against the mesh at each time.
    u, v = intr.pixel_grid()
    dirs = intr.camera_rays(u, v).reshape(-1, 3) @ pose[:3, :3].T
    origins = np.broadcast_to(pose[:3, 3], dirs.shape)
    now, nxt = (tracers[k].vertices.astype(np.float64) for k in ("now", "next"))
    t, face, (b) = brute_force_hits(now, mesh.faces, origins, dirs)
    hit = np.isfinite(t)
    w = np.column_stack([1 - b.sum(1), b])
    moved_point = np.einsum("nk,nkd->nd", w, nxt[mesh.faces[face]])
    cam = (moved_point - pose_next[:3, 3]) @ pose_next[:3, :3]
    px, py, _ = intr.project(cam)
    want = np.stack([px - u.ravel(), py - v.ravel()], 1)
    leaf = hit & (face >= 2)
    assert leaf.sum() > 300 and (hit & (face < 2)).sum() > 300
    flow = out["flow_fwd"].reshape(-1, 2)
    assert np.abs(flow[leaf] - want[leaf]).max() < 2e-3  # float32 hit points; px
    # Moving pixels are marked, rigid ones are not, and the motion layer is the point's displacement.
    dynamic = out["dynamic"].ravel()
    assert np.array_equal(dynamic.astype(bool), leaf)
    displacement = (moved_point[leaf] - (origins + dirs * t[:, None])[leaf]) @ pose[:3, :3]
    assert np.abs(out["motion_fwd"].reshape(-1, 3)[leaf] - displacement).max() < 1e-5
    assert np.all(out["motion_fwd"].reshape(-1, 3)[~leaf] == 0)
    # The ground's flow is the camera's reprojection alone, as without wind.
    static = RayTracer(mesh, 1, "native")
    rigid = render_view(static, scene, intr, pose, None, want={"flow"}, pose_next=pose_next)
    t_rest, face_rest, _ = brute_force_hits(mesh.vertices.astype(np.float64), mesh.faces, origins, dirs)
    ground = hit & (face < 2) & np.isfinite(t_rest) & (face_rest < 2)  # ground in both (leaves moved)
    assert ground.sum() > 300
    assert np.array_equal(flow[ground], rigid["flow_fwd"].reshape(-1, 2)[ground])
    for tracer in (*tracers.values(), static):
        tracer.close()


# ------------------------------------------------------------------ the job
@pytest.fixture(scope="module")
def windy(tmp_path_factory):
    """One tiny job under a breeze and the same job in still air, sharing their stage cache."""
    root = tmp_path_factory.mktemp("wind")
    base = [*TINY, "render.max_frames=4"]
    run_job(make_cfg(root, [*base, "lighting.wind_mps=6", f"paths.dataset={root}/windy"]))
    run_job(make_cfg(root, [*base, f"paths.dataset={root}/still"]))
    return root


def test_a_windy_dataset_validates_with_its_motion(windy):
    report = check_dataset(windy / "windy", progress=False)
    assert report.ok, report.lines()
    assert report.checks.get("dynamic") == 20 and report.motion
    rigid = np.concatenate(report.motion["rigid"])
    moving = np.concatenate(report.motion["moving"])
    assert len(moving) > 1000 and np.median(rigid) < 0.01 and np.median(moving) < 0.02
    assert any(line.startswith("wind flow: ") for line in report.lines())
    manifest = (windy / "windy" / "manifest.csv").read_text().splitlines()[0].split(",")
    assert manifest[-3:] == ["dynamic", "motion_fwd", "motion_bwd"]
    facts = json.loads(next((windy / "windy").glob("*/*/lighting.json")).read_text())["wind"]
    assert facts["speed_mps"] == 6.0 and 0 <= facts["direction_deg"] <= 360


def test_still_air_lists_no_wind_columns_and_keeps_its_render_key(windy, tmp_path):
    header = (windy / "still" / "manifest.csv").read_text().splitlines()[0].split(",")
    assert "dynamic" not in header and "motion_fwd" not in header
    assert "wind" not in json.loads(next((windy / "still").glob("*/*/lighting.json")).read_text())
    assert check_dataset(windy / "still", progress=False).ok

    class Art:
        key = "k"

    keys = {
        render_key(make_cfg(tmp_path, [*TINY, *extra]), Art(), Art())
        for extra in ([], ["lighting.gust_strength=0.9"], ["lighting.wind_direction_deg=10"])
    }
    assert len(keys) == 1  # without wind, the wind's other keys change nothing
    assert render_key(make_cfg(tmp_path, [*TINY, "lighting.wind_mps=2"]), Art(), Art()) not in keys


def test_wind_is_checked_before_any_work(tmp_path):
    with pytest.raises(ConfigError, match=r"lighting.wind_mps=-1.*allowed"):
        check_job(make_cfg(tmp_path, [*TINY, "lighting.wind_mps=-1"]))
    with pytest.raises(ConfigError, match=r"lighting.wind_mps=3 with render.backend=tinyrenderer.*raytrace"):
        check_job(make_cfg(tmp_path, [*TINY, "lighting.wind_mps=3", "render=tinyrenderer"]))


def test_a_merged_manifest_leaves_the_wind_columns_empty_on_still_rows(windy, tmp_path):
    import pandas as pd

    dataset = tmp_path / "merged"
    base = [*TINY, "render.max_frames=4", f"paths.dataset={dataset}"]
    run_job(make_cfg(windy, base))  # still air, cached
    run_job(make_cfg(windy, [*base, "lighting=overcast", "lighting.wind_mps=[3, 6]"]))
    rows = pd.read_csv(dataset / "manifest.csv", keep_default_na=False)
    assert list(rows.columns[-3:]) == ["dynamic", "motion_fwd", "motion_bwd"]
    still, windy_rows = rows[rows["lighting"] == "clear"], rows[rows["lighting"] == "overcast"]
    assert (still["dynamic"] == "").all() and (windy_rows["dynamic"] != "").all()
    job_header = (dataset / still["garden"].iloc[0] / "clear" / "manifest.csv").read_text().splitlines()[0]
    assert "dynamic" not in job_header  # each job's own manifest as it was
    assert check_dataset(dataset, progress=False).ok


def test_frames_are_the_same_whatever_order_and_thread_render_them(windy):
    """The deformation is a function of time: a job cut to two frames (one frame per thread) writes the
    files the four-frame job (two frames per thread, scenes refitted in turn) wrote for them: the same
    pixels in every image, the same bytes in every other file. (An image's bytes can differ: ISA-L
    once deflated the same rows of a flow PNG to another valid stream, docs/design.md, File formats.)"""
    from scripts.dataset_fingerprint import content_digest as digest

    short = run_job(
        make_cfg(windy, [*TINY, "render.max_frames=2", "lighting.wind_mps=6", f"paths.dataset={windy}/short"])
    )
    long = run_job(
        make_cfg(windy, [*TINY, "render.max_frames=4", "lighting.wind_mps=6", f"paths.dataset={windy}/windy"])
    )
    a, b = short.artifacts["render"].path, long.artifacts["render"].path
    files = sorted(p.relative_to(a) for p in a.glob("cam*/*/0000[01].*"))
    assert len(files) > 50 and {f.suffix for f in files} >= {".png", ".exr"}
    assert {str(f): digest(a / f) for f in files} == {str(f): digest(b / f) for f in files}


def test_wind_with_the_camera_effects_validates(windy):
    """Wind with a rolling shutter, motion blur and the sensor: the RGB over the exposure sees the mesh
    at the frame's time; the ground truth is the sharp frame's, and the dataset validates."""
    overrides = [
        *TINY,
        "render.max_frames=4",
        "lighting.wind_mps=6",
        "camera.readout_s=0.02",
        "camera.exposure_s=0.01",
        "camera.blur_samples=2",
        "camera.sensor.enabled=true",
        f"paths.dataset={windy}/effects",
    ]
    run_job(make_cfg(windy, overrides))
    report = check_dataset(windy / "effects", progress=False)
    assert report.ok, report.lines()
    assert report.checks.get("dynamic") == 20
    sharp, exposed = (windy / name / "manifest.csv" for name in ("windy", "effects"))
    a = sharp.read_text().splitlines()[1].split(",")
    b = exposed.read_text().splitlines()[1].split(",")
    assert a == b  # the same rows and files: only the RGB's pixels differ


def test_motion_blur_moves_a_scene_of_its_own_to_each_sub_frame_time():
    from eden_pipe.render.backends.raytrace import MovingScenes

    mesh, instance = toy_garden()
    field = wind.WindField.build(mesh, instance, BREEZE, seed=5)
    scenes = MovingScenes(mesh, field, 1, "native", frame_threads=1, blur=True)
    try:
        ring = scenes.at([1.0, 1.1, 0.9])
        first = scenes.exposure_at(1.02)
        assert first not in ring.values()  # the ring's three stay where the frame needs them
        assert np.array_equal(first.vertices, field.positions(1.02))
        assert scenes.exposure_at(1.02) is first and np.array_equal(ring[1.1].vertices, field.positions(1.1))
        assert np.array_equal(scenes.exposure_at(0.98).vertices, field.positions(0.98))
    finally:
        scenes.close()


def test_the_torch_loader_gives_the_dynamic_mask_and_the_motion(windy):
    pytest.importorskip("torch")
    from eden_pipe.data.dataset import EdenDataset
    from eden_pipe.modalities import read_modality

    assert len(EdenDataset(windy / "still", modalities=["dynamic"])) == 0  # rows without the file are left out
    ds = EdenDataset(windy / "windy", modalities=["dynamic", "motion_fwd", "flow_fwd"])
    assert len(ds) == 15  # the last frame has no forward flow
    item, row = ds[0], ds.records[0]
    mask = read_modality(windy / "windy" / row["dynamic"], "dynamic")
    assert not item["dynamic"].dtype.is_floating_point and item["dynamic"].shape == (1, *mask.shape)
    assert np.array_equal(item["dynamic"][0].numpy(), mask == 1) and mask.any()
    assert item["motion_fwd"].shape == (3, *mask.shape)
