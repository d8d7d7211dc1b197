"""eden_pipe.data.EdenDataset against the files it reads (TINY dataset)."""

from __future__ import annotations

import os

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="the loader is a torch Dataset: pip install -e '.[test,test-torch]'")

from eden_pipe.data import EdenDataset  # noqa: E402
from eden_pipe.data.manifest_reader import load_manifest, quaternion_to_rotation, rotation_to_quaternion  # noqa: E402
from eden_pipe.io.formats import read_modality  # noqa: E402
from tests.tiny_dataset import tiny_root  # noqa: E402

ALL = ["rgb", "semantic", "instance", "depth", "normal", "flow_fwd", "albedo"]


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    return tiny_root(tmp_path_factory) / "dataset"


@pytest.fixture(scope="module")
def manifest(root):
    return load_manifest(root)


def test_item_dtypes_units_and_values(root, manifest):
    ds = EdenDataset(root, ALL)
    assert len(ds) == int((manifest["flow_fwd"] != "").sum())  # rows without flow_fwd (last frame) left out
    item = ds[0]
    rec = ds.records[0]
    h, w = int(rec["height"]), int(rec["width"])
    read = lambda col: read_modality(root / rec[col], col)  # noqa: E731

    assert item["rgb"].dtype == torch.float32 and item["rgb"].shape == (3, h, w)
    np.testing.assert_allclose(item["rgb"].permute(1, 2, 0).numpy(), read("rgb_left") / 255.0, atol=1e-6)
    assert 0.0 <= float(item["rgb"].min()) and float(item["rgb"].max()) <= 1.0

    sem = read("semantic")
    assert item["semantic"].dtype == torch.int64 and item["semantic"].shape == (h, w)
    np.testing.assert_array_equal(item["semantic"].numpy(), np.where(sem == 0, 255, sem))
    assert item["instance"].dtype == torch.int64
    np.testing.assert_array_equal(item["instance"].numpy(), read("instance"))

    depth = read("depth")
    assert item["depth"].dtype == torch.float32 and item["depth"].shape == (1, h, w)
    assert item["depth_valid"].dtype == torch.bool
    np.testing.assert_array_equal(item["depth_valid"][0].numpy(), np.isfinite(depth))
    assert 0 < item["depth_valid"].float().mean() < 1  # sky is in view and invalid
    np.testing.assert_allclose(item["depth"][0].numpy()[np.isfinite(depth)], depth[np.isfinite(depth)])
    assert float(item["depth"][~item["depth_valid"]].abs().sum()) == 0.0

    n = item["normal"]
    assert n.dtype == torch.float32 and n.shape == (3, h, w)
    norms = n.norm(dim=0)[item["normal_valid"][0]]
    assert torch.allclose(norms, torch.ones_like(norms), atol=1e-3)

    flow, occ = read("flow_fwd"), read("occ_fwd")
    assert item["flow_fwd"].dtype == torch.float32 and item["flow_fwd"].shape == (2, h, w)
    np.testing.assert_array_equal(item["flow_fwd"].permute(1, 2, 0).numpy(), flow)
    np.testing.assert_array_equal(item["flow_fwd_valid"][0].numpy(), occ == 0)
    assert item["albedo"].shape == (3, h, w) and item["albedo"].dtype == torch.float32

    K = item["K"].numpy()
    assert item["K"].dtype == torch.float32
    np.testing.assert_allclose(K, [[rec["fx"], 0, rec["cx"]], [0, rec["fy"], rec["cy"]], [0, 0, 1]])
    pose = item["pose"].numpy().astype(np.float64)
    assert item["pose"].shape == (4, 4) and item["pose"].dtype == torch.float32
    np.testing.assert_allclose(pose[:3, 3], [rec["tx"], rec["ty"], rec["tz"]], atol=1e-5)
    np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-5)
    assert item["garden"] == rec["garden"] and item["frame"] == rec["frame"] and item["camera"] == rec["camera"]


def test_quaternion_roundtrip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        q = q if q[0] >= 0 else -q
        np.testing.assert_allclose(rotation_to_quaternion(quaternion_to_rotation(q)), q, atol=1e-9)


def _backproject(depth, valid, K, pose):
    v, u = np.nonzero(valid)
    d = depth[v, u]
    cam = np.stack([(u - K[0, 2]) / K[0, 0] * d, (v - K[1, 2]) / K[1, 1] * d, d], 1)
    return u, v, cam @ pose[:3, :3].T + pose[:3, 3]


def _project(points, K, pose):
    cam = (points - pose[:3, 3]) @ pose[:3, :3]
    return K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]


def test_pairs_poses_agree_with_flow(root):
    """(t, t+1) pairs: the poses, K and depth reproduce the rendered forward flow (pose convention check)."""
    ds = EdenDataset(root, ["depth"], pairs=True, cameras=[0])
    assert len(ds) == 3 and all(k in ds[0] for k in ("flow_fwd", "flow_fwd_valid", "next_pose", "next_depth"))
    item = ds[1]
    assert ds.next_records[1]["frame"] == item["frame"] + 1
    K, pose, nxt = (item[k].numpy().astype(np.float64) for k in ("K", "pose", "next_pose"))
    valid = (item["depth_valid"][0] & item["flow_fwd_valid"][0]).numpy()
    u, v, pts = _backproject(item["depth"][0].numpy().astype(np.float64), valid, K, pose)
    u1, v1 = _project(pts, K, nxt)
    flow = item["flow_fwd"].numpy()
    # depth is stored in millimetres: allow the quantisation's reprojection error
    assert np.median(np.abs(u1 - u - flow[0, v, u])) < 0.02 and np.median(np.abs(v1 - v - flow[1, v, u])) < 0.02


def test_stereo_right_camera(root):
    ds = EdenDataset(root, ["rgb", "depth"], stereo=True)
    item = ds[0]
    pose, right, b = item["pose"].double(), item["pose_right"].double(), float(item["baseline"])
    assert b == pytest.approx(float(ds.records[0]["baseline"]))
    torch.testing.assert_close(right[:3, 3], pose[:3, 3] + b * pose[:3, 0])
    assert item["rgb_right"].shape == item["rgb"].shape and item["depth_right"].shape == item["depth"].shape
    # the right depth sees the left depth's points at the left pixel minus the disparity fx*b/z
    K = item["K"].numpy().astype(np.float64)
    valid = item["depth_valid"][0].numpy()
    u, v, pts = _backproject(item["depth"][0].numpy().astype(np.float64), valid, K, pose.numpy())
    ur, vr = _project(pts, K, right.numpy())
    np.testing.assert_allclose(vr, v, atol=1e-3)
    np.testing.assert_allclose(u - ur, K[0, 0] * b / item["depth"][0].numpy()[v, u], atol=1e-3)


def test_filters(root, manifest):
    assert len(EdenDataset(root, ["rgb"])) == len(manifest)
    assert len(EdenDataset(root, ["rgb"], cameras=[0, 2])) == int(manifest["camera"].isin([0, 2]).sum())
    split = manifest["split"].iloc[0]
    assert len(EdenDataset(root, ["rgb"], split=split, lighting="clear", garden=manifest["garden"].iloc[0])) == len(
        manifest
    )
    assert len(EdenDataset(root, ["rgb"], lighting="no-such-lighting")) == 0
    with pytest.raises(ValueError, match="test_subsample"):
        EdenDataset(root, ["rgb"], subsample=True)
    with pytest.raises(ValueError, match="unknown modality"):
        EdenDataset(root, ["lidar"])


def test_subsample_column(root, manifest, tmp_path):
    """A manifest with a bool test_subsample column: subsample=True keeps its true rows."""
    other = tmp_path / "ds"
    other.mkdir()
    for entry in os.listdir(root):
        if entry != "manifest.csv":
            os.symlink(root / entry, other / entry)
    m = manifest.copy()
    m["test_subsample"] = m["frame"] % 2 == 0
    m.to_csv(other / "manifest.csv", index=False)
    ds = EdenDataset(other, ["rgb"], subsample=True)
    assert len(ds) == int(m["test_subsample"].sum()) and all(r["frame"] % 2 == 0 for r in ds.records)
    assert len(EdenDataset(other, ["rgb"], subsample="test_subsample", cameras=0)) == 2


def test_ignore_index_configurable(root):
    item = EdenDataset(root, ["semantic"], ignore_index=-100)[0]
    assert int(item["semantic"].min()) >= -100 and 0 not in item["semantic"].unique().tolist()


def test_dataloader_two_workers(root):
    ds = EdenDataset(root, ["rgb", "semantic", "depth", "flow"], stereo=True, pairs=True)
    loader = torch.utils.data.DataLoader(ds, batch_size=4, num_workers=2, shuffle=False)
    batch = next(iter(loader))
    assert batch["rgb"].shape == (4, 3, 72, 96) and batch["next_rgb"].shape == (4, 3, 72, 96)
    assert batch["semantic"].dtype == torch.int64 and batch["depth_valid"].dtype == torch.bool
    assert batch["K"].shape == (4, 3, 3) and batch["pose"].shape == (4, 4, 4) and batch["baseline"].shape == (4,)
    assert isinstance(batch["garden"], list) and len(batch["garden"]) == 4
    torch.testing.assert_close(batch["rgb"][1], ds[1]["rgb"])
