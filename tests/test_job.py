"""End-to-end properties of one small job, run once with the real pybullet and Embree."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eden_pipe import labels
from eden_pipe.camera.rig import quaternion_to_rotation
from eden_pipe.config import to_config
from eden_pipe.io import formats
from eden_pipe.pipeline import run_job
from eden_pipe.stages.cache import StageCache
from eden_pipe.stages.model import run_model_stage
from eden_pipe.stages.scene import run_scene_stage
from eden_pipe.stages.trajectory import load_poses, run_trajectory_stage
from tests.conftest import TINY, make_cfg

EXACT = ["render.storage=exact"]


def snapshot(root: Path) -> dict[str, tuple[int, int]]:
    """(inode, mtime_ns) of every file under root."""
    out = {}
    for path in root.rglob("*"):
        if path.is_file():
            st = path.stat()
            out[str(path.relative_to(root))] = (st.st_ino, st.st_mtime_ns)
    return out


@pytest.fixture(scope="module")
def job(tmp_path_factory):
    root = tmp_path_factory.mktemp("job")
    # Exact storage (float32 layers, .flo flow): these tests hold the renderer to its own precision;
    # compact files are checked within their format's precision by test_io and the validator's tests.
    cfg = make_cfg(root, TINY + EXACT)
    lines: list[str] = []
    result = run_job(cfg, echo=lines.append)
    manifest = pd.read_csv(root / "dataset" / "manifest.csv", keep_default_na=False)
    return root, cfg, result, lines, manifest


def pose_of(row) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quaternion_to_rotation([row.qw, row.qx, row.qy, row.qz])
    m[:3, 3] = [row.tx, row.ty, row.tz]
    return m


def K_of(row) -> np.ndarray:
    return np.array([[row.fx, 0, row.cx], [0, row.fy, row.cy], [0, 0, 1.0]])


def test_manifest_rows_columns_and_files(job):
    root, _, result, lines, manifest = job
    assert len(manifest) == 4 * 5
    assert list(manifest.columns[:21]) == [
        "garden",
        "seed",
        "lighting",
        "frame",
        "timestamp",
        "camera",
        "split",
        "width",
        "height",
        "fx",
        "fy",
        "cx",
        "cy",
        "baseline",
        "qw",
        "qx",
        "qy",
        "qz",
        "tx",
        "ty",
        "tz",
    ]
    assert set(manifest["split"]) <= {"train", "val", "test"} and manifest["split"].nunique() == 1
    render = result.artifacts["render"].marker()  # timings kept apart: one-off setup, then per frame
    assert render["setup_seconds"] > 0 and render["seconds_per_frame"] > 0 and render["rendered"] == 4
    for column in (
        "rgb_left",
        "rgb_right",
        "semantic",
        "instance",
        "depth",
        "normal",
        "albedo",
        "shading",
        "translucency",
    ):
        for rel in manifest[column]:
            assert (root / "dataset" / rel).is_file(), rel
    # Flow is undefined at the ends of the trajectory: empty path there, a file elsewhere.
    assert (manifest["flow_bwd"] == "").sum() == 5 and (manifest["flow_fwd"] == "").sum() == 5
    assert [line.split()[1] for line in lines[:6]] == [
        "model",
        "scene",
        "trajectory",
        "sky_visibility",
        "render",
        "manifest",
    ]


def test_forward_and_backward_flow_match_depth_reprojection(job):
    root, _, _, _, manifest = job
    data = root / "dataset"
    errors = []
    for direction, step in (("fwd", 1), ("bwd", -1)):
        for row in manifest.itertuples():
            path = getattr(row, f"flow_{direction}")
            if not path:
                continue
            other = manifest[(manifest.frame == row.frame + step) & (manifest.camera == row.camera)].iloc[0]
            depth = formats.read_depth(data / row.depth)
            flow = formats.read_flo(data / path)
            occ = formats.read_mask(data / getattr(row, f"occ_{direction}"))
            K = K_of(row)
            v, u = np.mgrid[0 : row.height, 0 : row.width].astype(np.float64)
            valid = np.isfinite(depth) & (occ == 0)
            z = depth[valid]
            cam = np.stack([(u[valid] - K[0, 2]) / K[0, 0] * z, (v[valid] - K[1, 2]) / K[1, 1] * z, z], axis=1)
            p0, p1 = pose_of(row), pose_of(other)
            world = cam @ p0[:3, :3].T + p0[:3, 3]
            cam1 = (world - p1[:3, 3]) @ p1[:3, :3]
            proj = cam1 @ K.T
            expected = proj[:, :2] / proj[:, 2:3] - np.stack([u[valid], v[valid]], axis=1)
            errors.append(np.linalg.norm(flow[valid] - expected, axis=1))
            assert valid.mean() > 0.3  # most of the view is visible geometry
    err = np.concatenate(errors)
    assert np.median(err) < 0.01


def test_sky_flow_is_rotation_only(job):
    root, _, _, _, manifest = job
    row = manifest[manifest.flow_fwd != ""].iloc[0]
    other = manifest[(manifest.frame == row.frame + 1) & (manifest.camera == row.camera)].iloc[0]
    depth = formats.read_depth(root / "dataset" / row.depth)
    flow = formats.read_flo(root / "dataset" / row.flow_fwd)
    sky = ~np.isfinite(depth)
    assert sky.any()
    K = K_of(row)
    v, u = np.mgrid[0 : row.height, 0 : row.width].astype(np.float64)
    d = np.stack([(u[sky] - K[0, 2]) / K[0, 0], (v[sky] - K[1, 2]) / K[1, 1], np.ones(sky.sum())], 1)
    R = pose_of(other)[:3, :3].T @ pose_of(row)[:3, :3]
    p = (d @ R.T) @ K.T
    expected = p[:, :2] / p[:, 2:3] - np.stack([u[sky], v[sky]], 1)
    assert np.median(np.linalg.norm(flow[sky] - expected, axis=1)) < 1e-3


def test_right_depth_is_left_shifted_by_disparity(job):
    root, _, _, _, manifest = job

    def agreement(shift: float) -> float:
        """Share of left pixels whose depth the right image shows ``shift`` disparities to the left."""
        agree, total = 0, 0
        for row in manifest.itertuples():
            left = formats.read_depth(root / "dataset" / row.depth)
            right = formats.read_depth(root / "dataset" / row.depth_right)
            v, u = np.mgrid[0 : row.height, 0 : row.width]
            ok = np.isfinite(left)
            ur = np.round(u - shift * row.fx * row.baseline / np.where(ok, left, 1.0)).astype(int)
            ok &= (ur >= 0) & (ur < row.width)
            zl = left[ok]
            agree += int(np.sum(np.abs(right[v[ok], ur[ok]] - zl) / zl < 0.01))
            total += len(zl)
        assert total > 0
        return agree / total

    # Occlusions (foliage close to the rig) keep some pixels from agreeing, how many depends on the
    # view; the true disparity must still explain most pixels and clearly more than a wrong one.
    true = agreement(1.0)
    assert true > 0.8 and true > max(agreement(0.0), agreement(-1.0), agreement(2.0)) + 0.1


def test_semantic_ids_and_palette(job):
    root, _, _, _, manifest = job
    seen = set()
    for rel in manifest["semantic"]:
        ids = formats.read_semantic(root / "dataset" / rel)
        assert ids.max() <= 9
        seen |= set(np.unique(ids).tolist())
        pal = formats.read_palette(root / "dataset" / rel)
        assert np.array_equal(pal[:10], labels.COLORS)
    assert labels.BACKGROUND in seen and labels.GRASS in seen | {labels.GROUND, labels.PAVEMENT}


def test_instance_ids_are_listed_in_scene_json(job):
    root, _, result, _, manifest = job
    scene = json.loads((result.artifacts["scene"].path / "scene.json").read_text())
    known = {0} | {i["id"] for i in scene["instances"]}
    for rel in manifest["instance"]:
        assert set(np.unique(formats.read_instance(root / "dataset" / rel)).tolist()) <= known
    for inst in scene["instances"]:
        assert {"id", "class", "type", "transform", "bbox_min", "bbox_max"} <= set(inst)


def test_normals_are_unit_and_face_the_camera(job):
    root, _, _, _, manifest = job
    row = manifest.iloc[0]
    n = formats.read_normal(root / "dataset" / row.normal)
    depth = formats.read_depth(root / "dataset" / row.depth)
    valid = np.isfinite(depth)
    length = np.linalg.norm(n[valid], axis=1)
    assert np.allclose(length, 1.0, atol=1e-3)
    v, u = np.mgrid[0 : row.height, 0 : row.width]
    rays = np.stack([(u - row.cx) / row.fx, (v - row.cy) / row.fy, np.ones_like(u, float)], -1)[valid]
    assert np.all(np.sum(rays * n[valid], axis=1) <= 1e-3)
    assert np.all(n[~valid] == 0)


def test_identical_rerun_is_cached_and_rewrites_nothing(job):
    root, cfg, _, _, _ = job
    before = snapshot(root)
    lines: list[str] = []
    result = run_job(cfg, echo=lines.append)
    assert all(a.cached for a in result.artifacts.values())
    assert all(" cached " in line for line in lines[:5])
    assert snapshot(root) == before


def test_lighting_change_reuses_geometry_with_its_own_trajectory(job):
    """As in EDEN, each lighting of a garden gets its own random walk; model and scene are built once."""
    root, _, first, _, _ = job
    cfg = make_cfg(root, TINY + EXACT + ["lighting=sunset"])
    result = run_job(cfg, echo=lambda *_: None)
    built = {name for name, a in result.artifacts.items() if not a.cached}
    assert built == {"trajectory", "render", "manifest"}
    clear, sunset = load_poses(first.artifacts["trajectory"]), load_poses(result.artifacts["trajectory"])
    assert clear.shape == sunset.shape and not np.allclose(clear[:, :, :, :3, 3], sunset[:, :, :, :3, 3])
    merged = pd.read_csv(root / "dataset" / "manifest.csv", keep_default_na=False)
    assert set(merged["lighting"]) == {"clear", "sunset"} and len(merged) == 40
    a, b = (merged[merged.lighting == name].reset_index(drop=True) for name in ("clear", "sunset"))
    assert not np.allclose(a[["tx", "ty", "tz"]], b[["tx", "ty", "tz"]])
    # Each job folder publishes its own walk.
    for name, poses in (("clear", clear), ("sunset", sunset)):
        rig = json.loads((root / "dataset" / "small-s0" / name / "rig.json").read_text())
        np.testing.assert_allclose(rig["cameras"][0]["poses"], poses[:, 0, 0], atol=1e-9)


def geometry_and_walk(root, overrides):
    cfg = to_config(make_cfg(root, TINY + EXACT + overrides))
    cache = StageCache(cfg.paths.stages)
    model = run_model_stage(cfg.garden, cache)
    scene = run_scene_stage(cfg.garden, cfg.camera, model, cache)
    return model, scene, run_trajectory_stage(cfg.camera, scene, model, cache, cfg.lighting.name)


def test_shared_trajectory_gives_every_lighting_the_same_poses(job):
    root = job[0]
    share = ["camera.trajectory.share_across_lightings=true"]
    walks = {}
    for lighting in ("clear", "sunset", "twilight"):
        model, scene, walks[lighting] = geometry_and_walk(root, share + [f"lighting={lighting}"])
        assert model.cached and scene.cached  # the geometry keys never see the lighting or the option
    assert not walks["clear"].cached and walks["sunset"].cached and walks["twilight"].cached
    assert walks["clear"].key == walks["sunset"].key == walks["twilight"].key
    assert json.loads((walks["clear"].path / "trajectory.json").read_text())["lighting"] is None


def test_trajectory_lengths_are_drawn_per_lighting_within_the_range(job):
    root = job[0]
    lengths = {}
    for lighting in ("clear", "cloudy", "overcast", "sunset", "twilight"):
        _, _, walk = geometry_and_walk(root, ["camera.trajectory.frames=[3,9]", f"lighting={lighting}"])
        lengths[lighting] = len(load_poses(walk))
        assert json.loads((walk.path / "trajectory.json").read_text())["lighting"] == lighting
        assert walk.marker()["frames"] == lengths[lighting]
    assert all(3 <= n <= 9 for n in lengths.values()) and len(set(lengths.values())) > 1, lengths
    # The same draw again: the length and walk are seeded from garden and lighting, nothing else.
    _, _, again = geometry_and_walk(root, ["camera.trajectory.frames=[3,9]", "lighting=cloudy", "force=[trajectory]"])
    assert len(load_poses(again)) == lengths["cloudy"]


def test_interrupted_render_resumes_at_frame_granularity(job):
    _, cfg, result, _, _ = job
    render_dir = result.artifacts["render"].path
    # Simulate a crash during frame 3: its marker and the completion marker never got written.
    (render_dir / "DONE.json").unlink()
    (render_dir / "frames" / "00003.json").unlink()
    kept = (render_dir / "frames" / "00001.json").stat().st_mtime_ns
    result2 = run_job(cfg, echo=lambda *_: None)
    art = result2.artifacts["render"]
    assert not art.cached and art.marker()["rendered"] == 1
    assert (render_dir / "frames" / "00001.json").stat().st_mtime_ns == kept
    assert result2.artifacts["scene"].cached


def test_force_recomputes_a_stage(job):
    root, _, _, _, _ = job
    cfg = make_cfg(root, TINY + EXACT + ["force=[trajectory]"])
    result = run_job(cfg, echo=lambda *_: None)
    assert not result.artifacts["trajectory"].cached
    assert result.artifacts["scene"].cached and result.artifacts["render"].cached


def test_same_seed_gives_the_same_dataset(job, tmp_path):
    """The same files, the same pixels in every image and the same bytes in every other file. An
    image's bytes are not compared: ISA-L's deflate, from the writer threads, now and then gives
    another valid stream of the same rows (docs/design.md, File formats)."""
    from scripts.dataset_fingerprint import content_digest

    root, _, _, _, _ = job
    other = tmp_path / "again"
    run_job(make_cfg(other, TINY + EXACT), echo=lambda *_: None)
    a = root / "dataset" / "small-s0" / "clear"
    b = other / "dataset" / "small-s0" / "clear"
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files and files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in files:
        assert content_digest(a / rel) == content_digest(b / rel), rel
