"""TinyRenderer (pybullet) as the oracle of the Embree backend, with the real pybullet and Embree.

Two independent renderers fed the same scene arrays and the same OpenCV cameras
must agree: z-depth within 1 % and the same semantic id on at least 99 % of the
non-edge pixels of garden views.

Edge pixels (defined once, in :func:`edge_mask`): a pixel is on a discontinuity
of an image when its 3x3 neighbourhood (cv2 dilate vs erode, i.e. max vs min)
spans

- two different semantic ids, or
- a depth jump: log z-depth varies by more than ``DEPTH_JUMP`` (5 %) inside the
  3x3 window, sky counting as a very large depth;

the edge mask is the union of the discontinuities of both images, dilated by
one more pixel (3x3), so an edge pixel lies within 2 px of a discontinuity in
either image. Those are the pixels where a one-pixel difference in
rasterisation rules, or sub-pixel geometry, can legitimately flip the answer.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pandas as pd
import pytest

from eden_pipe import labels
from eden_pipe.camera.rig import Intrinsics, look_rotation
from eden_pipe.config import to_config
from eden_pipe.io import formats
from eden_pipe.models.mesh import Mesh
from eden_pipe.pipeline import run_job
from eden_pipe.render.backends.tinyrenderer import TinyRendererBackend
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.rasterizer import TinyRenderer, gl_projection_matrix, gl_view_matrix, linearize_depth
from eden_pipe.render.view import render_view
from eden_pipe.scene.arrays import SceneArrays
from eden_pipe.stages.cache import StageCache
from eden_pipe.stages.model import run_model_stage
from eden_pipe.stages.scene import load_scene, run_scene_stage
from eden_pipe.stages.trajectory import load_poses, run_trajectory_stage
from eden_pipe.tools.validate import check_dataset
from tests.conftest import TINY, make_cfg

DEPTH_JUMP = 0.05  # relative depth change inside a 3x3 window that counts as a discontinuity
SKY_LOG_DEPTH = 20.0  # log z-depth given to sky pixels (e^20 m: beyond any garden)


# ------------------------------------------------------------------ metrics
def discontinuities(depth: np.ndarray, semantic: np.ndarray) -> np.ndarray:
    """Pixels whose 3x3 window spans two semantic ids or a relative depth jump above DEPTH_JUMP."""
    k = np.ones((3, 3), np.uint8)
    sem = semantic.astype(np.uint8)
    sem_edge = cv2.dilate(sem, k) != cv2.erode(sem, k)
    logz = np.where(np.isfinite(depth), np.log(np.maximum(depth, 1e-6)), SKY_LOG_DEPTH).astype(np.float32)
    depth_edge = (cv2.dilate(logz, k) - cv2.erode(logz, k)) > np.log1p(DEPTH_JUMP)
    return sem_edge | depth_edge


def edge_mask(a: dict, b: dict) -> np.ndarray:
    """Within 2 px of a depth or semantic discontinuity in either image (module doc)."""
    disc = discontinuities(a["depth"], a["semantic"]) | discontinuities(b["depth"], b["semantic"])
    return cv2.dilate(disc.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)


def agreement(a: dict, b: dict) -> dict:
    """Counts over the non-edge pixels of one view pair."""
    keep = ~edge_mask(a, b)
    za, zb = a["depth"][keep].astype(np.float64), b["depth"][keep].astype(np.float64)
    both_sky = ~np.isfinite(za) & ~np.isfinite(zb)
    with np.errstate(invalid="ignore"):
        close = both_sky | (np.abs(za - zb) <= 0.01 * np.where(np.isfinite(za), za, np.inf))
    finite = np.isfinite(za) & np.isfinite(zb)
    rel = np.abs(za[finite] - zb[finite]) / za[finite]
    return {
        "pixels": int(keep.size),
        "kept": int(keep.sum()),
        "depth_ok": int(close.sum()),
        "depth_tight": int(np.sum(rel < 1e-4)),
        "depth_finite": int(finite.sum()),
        "semantic_ok": int(np.sum(a["semantic"][keep] == b["semantic"][keep])),
        "instance_ok": int(np.sum(a["instance"][keep] == b["instance"][keep])),
    }


# ------------------------------------------------- camera conventions, exact
def test_projection_samples_opencv_pixel_centres_exactly():
    """Random triangles: TinyRenderer covers exactly the pixels whose centre (u, v) lies inside."""
    rng = np.random.default_rng(7)
    intr = Intrinsics(80, 60, 70.0, 75.0, 41.3, 28.6)
    pose = np.eye(4)
    pose[:3, :3] = look_rotation(0.4, -0.3)
    pose[:3, 3] = [1.0, 2.0, 1.5]
    v, u = np.mgrid[0 : intr.height, 0 : intr.width].astype(np.float64)
    mismatched = covered = 0
    for _ in range(12):
        uv = rng.uniform([3, 3], [intr.width - 3, intr.height - 3], size=(3, 2))
        z = rng.uniform(1.0, 6.0, size=3)
        cam = np.c_[(uv[:, 0] - intr.cx) / intr.fx * z, (uv[:, 1] - intr.cy) / intr.fy * z, z]
        world = cam @ pose[:3, :3].T + pose[:3, 3]
        mesh = Mesh.from_arrays(world, [[0, 1, 2]], semantic=labels.OBSTACLE, material="rock", albedo=[0.5, 0.5, 0.5])
        with TinyRenderer(SceneArrays(mesh, np.ones(1, np.uint16)), shade=False) as tiny:
            got = tiny.render(intr, pose)["hit"]
        # Inside test on the image-plane triangle (its edges are straight lines in the image).
        sides = [
            (uv[(i + 1) % 3, 0] - uv[i, 0]) * (v - uv[i, 1]) - (uv[(i + 1) % 3, 1] - uv[i, 1]) * (u - uv[i, 0])
            for i in range(3)
        ]
        inside = np.all([s >= 0 for s in sides], axis=0) | np.all([s <= 0 for s in sides], axis=0)
        # Pixels whose centre is within 1e-3 px of an edge are ambiguous to any rasteriser.
        lengths = [np.hypot(*(uv[(i + 1) % 3] - uv[i])) for i in range(3)]
        near_edge = (
            np.min([np.abs(s) / max(length, 1e-9) for s, length in zip(sides, lengths, strict=True)], axis=0) < 1e-3
        )
        mismatched += int(np.sum((got != inside) & ~near_edge))
        covered += int(inside.sum())
    assert covered > 1000
    assert mismatched == 0


def ground_plane_view(intr: Intrinsics, pitch_deg: float, height_m: float, lo: float, hi: float):
    """TinyRenderer's passes of the square ground plane z = 0 over [lo, hi]^2 seen by a camera at
    ``height_m`` pitched by ``pitch_deg``, and each pixel's exact z-depth on the unbounded plane
    (inf where its ray does not go down)."""
    pose = np.eye(4)
    pose[:3, :3] = look_rotation(0.3, np.deg2rad(pitch_deg))
    pose[:3, 3] = [2.0, 3.0, height_m]
    ground = Mesh.from_arrays(
        [[lo, lo, 0], [hi, lo, 0], [hi, hi, 0], [lo, hi, 0]],
        [[0, 1, 2], [0, 2, 3]],
        semantic=labels.GROUND,
        material="dirt",
        albedo=[0.3, 0.25, 0.2],
    )
    with TinyRenderer(SceneArrays(ground, np.zeros(2, np.uint16)), shade=False) as tiny:
        out = tiny.render(intr, pose)
    v, u = np.mgrid[0 : intr.height, 0 : intr.width].astype(np.float64)
    dirs = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1) @ pose[:3, :3].T
    with np.errstate(divide="ignore"):
        t = np.where(dirs[..., 2] < 0, -pose[2, 3] / dirs[..., 2], np.inf)  # z-depth: camera-frame z of dirs is 1
    return out, t


def test_depth_is_z_depth_on_a_tilted_plane():
    """Depth linearisation: a tilted ground plane's z-depth matches the analytic ray-plane value."""
    intr = Intrinsics(64, 48, 60.0, 60.0, 31.5, 23.5)
    out, t = ground_plane_view(intr, -35.0, 0.8, -20.0, 30.0)
    hit = out["hit"]
    assert hit.mean() > 0.4 and np.array_equal(hit, np.isfinite(t) & (t < 60))
    assert np.max(np.abs(out["depth"][hit] - t[hit]) / t[hit]) < 1e-4
    assert np.all(np.isinf(out["depth"][~hit])) and np.all(out["semantic"][~hit] == labels.BACKGROUND)


@pytest.mark.parametrize("pitch_deg, height_m", [(-12.0, 1.0), (-5.0, 0.5)])
def test_depth_stays_within_the_backends_declared_error(pitch_deg, height_m):
    """On a ground plane seen from 1 to 70 m at 640 x 480, every pixel's z-depth is within
    ``TinyRendererBackend.depth_error`` of the exact ray-plane value (the allowance the validator's
    geometry check makes for this backend): its float32 z-buffer's steps grow as z^2."""
    intr = Intrinsics(640, 480, 640.0, 640.0, 319.5, 239.5)
    out, t = ground_plane_view(intr, pitch_deg, height_m, -40.0, 60.0)
    hit = out["hit"] & np.isfinite(t)
    assert hit.sum() > 100_000 and t[hit].max() > 60.0
    error = np.abs(out["depth"][hit] - t[hit])
    assert np.all(error <= TinyRendererBackend.depth_error(t[hit]))
    assert error.max() > 0.005  # millimetres far away: the allowance is needed, not idle


def test_gl_matrices_are_column_major_and_depth_inverts():
    intr = Intrinsics(640, 480, 640.0, 640.0, 320.0, 240.0)
    proj = np.array(gl_projection_matrix(intr, 0.01, 100.0)).reshape(4, 4).T
    assert proj[3, 2] == -1.0 and proj[0, 2] == 0.0 and np.isclose(proj[1, 2], 2.0 / 480)
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 3.0]
    view = np.array(gl_view_matrix(pose)).reshape(4, 4).T
    assert np.allclose(view @ [1.0, 2.0, 5.0, 1.0], [0.0, 0.0, -2.0, 1.0])  # 2 m ahead is -z in OpenGL
    z = np.array([0.05, 1.0, 7.5, 60.0])
    clip = proj @ np.c_[np.zeros((4, 2)), -z, np.ones(4)].T
    d = (clip[2] / clip[3] + 1.0) / 2.0
    assert np.allclose(linearize_depth(d, 0.01, 100.0), z, rtol=1e-9)


def test_groups_split_into_files_map_back_to_their_ids():
    """Two instances of two classes, one face per uploaded file: every body uid maps to its ids."""
    left = [[-9.0, -5.0, 3.0], [0.0, -5.0, 3.0], [0.0, 5.0, 3.0], [-9.0, 5.0, 3.0]]
    right = [[0.0, -5.0, 3.0], [9.0, -5.0, 3.0], [9.0, 5.0, 3.0], [0.0, 5.0, 3.0]]
    quads = [
        Mesh.from_arrays(v, [[0, 1, 2], [0, 2, 3]], semantic=sem, material="rock", albedo=[0.4, 0.4, 0.4])
        for v, sem in ((left, labels.OBSTACLE), (right, labels.TREE))
    ]
    mesh = Mesh.concatenate(quads)
    intr = Intrinsics(40, 20, 20.0, 20.0, 19.5, 9.5)
    with TinyRenderer(SceneArrays(mesh, np.array([3, 3, 8, 8], np.uint16)), max_file_faces=1) as tiny:
        out = tiny.render(intr, np.eye(4))
        assert tiny.n_bodies == 4 and tiny.n_groups == 2
    assert set(np.unique(out["instance"][:, :18]).tolist()) == {3} and set(
        np.unique(out["instance"][:, 22:]).tolist()
    ) == {8}
    assert np.all(out["semantic"][:, :18] == labels.OBSTACLE) and np.all(out["semantic"][:, 22:] == labels.TREE)
    assert np.allclose(out["depth"], 3.0)


# ------------------------------------------------------------- garden views
def garden_views(root, overrides: list[str], frames: int):
    """Build model -> scene -> trajectory through the pipeline's stage functions; return the scene and views."""
    cfg = to_config(make_cfg(root, TINY + overrides))
    cache = StageCache(cfg.paths.stages)
    model = run_model_stage(cfg.garden, cache)
    scene_art = run_scene_stage(cfg.garden, cfg.camera, model, cache)
    traj = run_trajectory_stage(cfg.camera, scene_art, model, cache, cfg.lighting.name)
    _, arrays = load_scene(scene_art)
    poses = load_poses(traj)
    views = [
        poses[f, k, side] for f in range(min(frames, len(poses))) for k in range(poses.shape[1]) for side in (0, 1)
    ]
    return arrays, Intrinsics.from_config(cfg.camera), views


def compare_backends(arrays, intr, views) -> dict:
    totals: dict[str, int] = {}
    with RayTracer(arrays.mesh) as tracer, TinyRenderer(arrays, shade=False) as tiny:
        for pose in views:
            ray = render_view(tracer, arrays, intr, pose, None, want={"semantic", "instance"})
            tin = tiny.render(intr, pose)
            for key, value in agreement(ray, tin).items():
                totals[key] = totals.get(key, 0) + value
    return totals


def check(totals: dict) -> None:
    kept = totals["kept"]
    assert kept >= 0.3 * totals["pixels"], totals  # not vacuous (grass blades make many depth edges)
    assert totals["depth_ok"] >= 0.99 * kept, totals
    assert totals["semantic_ok"] >= 0.99 * kept, totals
    # Both sample the same pixel-centre rays, so depth agrees far better than 1 % almost everywhere:
    # a half-pixel shift of either camera model fails this (the 1 % bound alone misses a shift along x).
    assert totals["depth_tight"] >= 0.9 * totals["depth_finite"], totals
    # Instances can legitimately z-fight where two instances overlap coplanarly (fence panels
    # meeting at a garden corner), so they get a looser bound.
    assert totals["instance_ok"] >= 0.97 * kept, totals


RES_160 = ["camera.width=160", "camera.height=120", "camera.fx=160", "camera.fy=160", "camera.cx=80", "camera.cy=60"]


@pytest.fixture(scope="module")
def garden_root(tmp_path_factory):
    """One stage cache for this module's small-garden tests (geometry built once)."""
    return tmp_path_factory.mktemp("oracle")


def test_raytrace_and_tinyrenderer_agree_on_garden_views(garden_root):
    """Small garden, 160 x 120 px, the left cameras of all 5 pairs over 2 frames (10 views)."""
    arrays, intr, views = garden_views(garden_root, RES_160, frames=2)
    check(compare_backends(arrays, intr, views[::2]))


def test_tinyrenderer_backend_through_the_pipeline(garden_root):
    """``render=tinyrenderer``: the render stage writes its passes with the usual writers and layout;
    the modalities it cannot make have empty manifest paths."""
    cfg = make_cfg(garden_root, TINY + RES_160 + ["render=tinyrenderer", "render.max_frames=1"])
    assert cfg.render.backend == "tinyrenderer"
    result = run_job(cfg, echo=lambda *_: None)
    data = garden_root / "dataset"
    manifest = pd.read_csv(data / "manifest.csv", keep_default_na=False)
    assert len(manifest) == 5 and result.artifacts["render"].marker()["frames"] == 1
    scene = json.loads((result.artifacts["scene"].path / "scene.json").read_text())
    for row in manifest.itertuples():
        for column in ("rgb_left", "rgb_right"):
            assert formats.read_rgb(data / getattr(row, column)).shape == (120, 160, 3)
        sem = formats.read_semantic(data / row.semantic)
        inst = formats.read_instance(data / row.instance)
        depth = formats.read_depth(data / row.depth)
        assert sem.shape == inst.shape == depth.shape == formats.read_depth(data / row.depth_right).shape == (120, 160)
        assert np.all(sem[~np.isfinite(depth)] == labels.BACKGROUND) and np.isfinite(depth).mean() > 0.3
        assert set(np.unique(inst).tolist()) <= {0} | {i["id"] for i in scene["instances"]}
        for column in ("normal", "flow_fwd", "flow_bwd", "occ_fwd", "occ_bwd", "albedo", "shading", "translucency"):
            assert getattr(row, column) == ""
    # The same views from the Embree backend: depth files agree (both written as uint16 millimetres).
    ray_cfg = make_cfg(
        garden_root,
        TINY
        + RES_160
        + ["render.max_frames=1", "render.modalities=[semantic,depth]", "paths.dataset=" + str(garden_root / "ray")],
    )
    run_job(ray_cfg, echo=lambda *_: None)
    ray = pd.read_csv(garden_root / "ray" / "manifest.csv", keep_default_na=False)
    za = np.stack([formats.read_depth(data / rel) for rel in manifest.depth])
    zb = np.stack([formats.read_depth(garden_root / "ray" / rel) for rel in ray.depth])
    both = np.isfinite(za) & np.isfinite(zb)
    assert np.mean(np.isfinite(za) == np.isfinite(zb)) > 0.99
    assert np.mean(np.abs(za[both] - zb[both]) <= 0.002 + 0.01 * zb[both]) > 0.97
    # The dataset validates: the geometry check allows the rasteriser's z-buffer steps
    # (``TinyRendererBackend.depth_error``), which grow with z^2, on top of the depth file's 0.5 mm.
    report = check_dataset(data, progress=False)
    assert report.ok, report.lines()
    assert report.checks["geometry"] == 5


@pytest.mark.slow
def test_raytrace_and_tinyrenderer_agree_at_full_resolution(tmp_path):
    """Small garden with its full lawn density at EDEN's 640 x 480: both cameras of 5 pairs x 2 frames."""
    res = [
        "camera.width=640",
        "camera.height=480",
        "camera.fx=640",
        "camera.fy=640",
        "camera.cx=320",
        "camera.cy=240",
        "garden.lawn.triangles_per_m2=4000",
    ]
    arrays, intr, views = garden_views(tmp_path, res, frames=2)
    check(compare_backends(arrays, intr, views))
