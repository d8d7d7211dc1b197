"""eden_pipe.tools.export: every format read back by an independent reader and compared to the source."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from eden_pipe import labels
from eden_pipe.data.manifest_reader import load_manifest, row_intrinsics, row_pose
from eden_pipe.io.formats import read_modality
from eden_pipe.tools import export as ex
from tests.tiny_dataset import tiny_root
from tests.tools_dataset import copy_dataset


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    return tiny_root(tmp_path_factory)


@pytest.fixture(scope="module")
def root(base):
    return base / "dataset"


@pytest.fixture(scope="module")
def rows(root):
    return ex.select_rows(root)


def read(root, rec, col):
    return read_modality(root / rec[col], col)


def quat_rot(w, x, y, z):
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


# ------------------------------------------------------------------ 3DRMS
def test_3drms(root, base, rows, tmp_path):
    out = tmp_path / "3drms"
    facts = ex.export_3drms(root, out, rows, stages=base / "stages", points=20000)
    assert facts["images"] == 2 * len(rows) and len(facts["ply"]) == 1
    for rec in rows.to_dict("records")[::3]:
        k, f = int(rec["camera"]), int(rec["frame"])
        h, w = int(rec["height"]), int(rec["width"])
        for vcam, right in ((2 * k, False), (2 * k + 1, True)):
            stem = out / rec["garden"] / rec["lighting"] / f"vcam_{vcam}" / f"vcam_{vcam}_f{f:05d}"
            rgb = cv2.imread(f"{stem}_undist.png")[..., ::-1]
            np.testing.assert_array_equal(rgb, read(root, rec, "rgb_right" if right else "rgb_left"))
            dmap = np.fromfile(f"{stem}_dmap.bin", dtype=">f4").reshape((h, w), order="F")
            depth = read(root, rec, "depth_right" if right else "depth")
            np.testing.assert_array_equal(dmap, np.where(np.isfinite(depth), depth, 0))
            vals = [float(t) for t in open(f"{stem}_cam.txt").read().split()]
            assert len(vals) == 11
            fx, fy, cx, cy = vals[:4]
            assert (fx, fy, cx, cy) == (rec["fx"], rec["fy"], rec["cx"], rec["cy"])
            w2c = np.eye(4)
            w2c[:3, :3], w2c[:3, 3] = quat_rot(*vals[4:8]), vals[8:]
            np.testing.assert_allclose(np.linalg.inv(w2c), row_pose(rec, right=right), atol=1e-6)
            gtr = Path(f"{stem}_gtr.png")
            if right:
                assert not gtr.exists()  # labels are rendered for the left camera only
            else:
                with Image.open(gtr) as img:
                    assert img.mode == "P"
                    np.testing.assert_array_equal(np.asarray(img), read(root, rec, "semantic"))
                    pal = np.asarray(img.getpalette(), np.uint8).reshape(-1, 3)[:10]
                    np.testing.assert_array_equal(pal, labels.COLORS)

    # semantic point cloud: independent PLY parse; label frequencies follow the mesh's per-class area
    ply = out / "small-s0" / "small-s0_semantic.ply"
    raw = ply.read_bytes()
    head, body = raw.split(b"end_header\n", 1)
    head = head.decode()
    assert "binary_little_endian" in head and "property uchar label" in head
    n = int(head.split("element vertex ")[1].split()[0])
    dt = np.dtype(
        [
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("r", "u1"),
            ("g", "u1"),
            ("b", "u1"),
            ("label", "u1"),
            ("instance", "<u2"),
        ]
    )
    pts = np.frombuffer(body, dt)
    assert n == len(pts) == 20000
    geo = np.load(next((base / "stages" / "scene").glob("*/geometry.npz")))
    v, faces, sem = geo["vertices"].astype(np.float64), geo["faces"], geo["semantic"]
    xyz = np.stack([pts["x"], pts["y"], pts["z"]], 1)
    assert np.all(xyz >= v.min(0) - 1e-4) and np.all(xyz <= v.max(0) + 1e-4)
    a, b_, c = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    area = 0.5 * np.linalg.norm(np.cross(b_ - a, c - a), axis=1)
    expected = np.bincount(sem, weights=area, minlength=10) / area.sum()
    got = np.bincount(pts["label"], minlength=10) / n
    np.testing.assert_allclose(got, expected, atol=0.02)
    np.testing.assert_array_equal(np.stack([pts["r"], pts["g"], pts["b"]], 1), labels.COLORS[pts["label"]])


def test_3drms_without_geometry(root, rows, tmp_path, capsys):
    # A dataset published before the scene mesh was (no <garden>/geometry.ply) and no stage cache.
    old = copy_dataset(root, tmp_path / "old")
    for ply in old.glob("*/geometry.ply"):
        ply.unlink()
    facts = ex.export_3drms(old, tmp_path / "o", rows[rows["camera"] == 0], stages=tmp_path / "nothing", points=10)
    assert facts["ply"] == [] and "skipping its semantic point cloud" in capsys.readouterr().err
    assert not list((tmp_path / "o").rglob("*.ply"))


# ------------------------------------------------------------------- COCO
def test_coco(root, rows, tmp_path):
    from pycocotools.coco import COCO

    facts = ex.export_coco(root, tmp_path / "coco", rows, name="all")
    coco = COCO(facts["json"])
    cats = {c["id"]: c["name"] for c in coco.loadCats(coco.getCatIds())}
    assert cats == {i: labels.NAMES[i] for i in range(1, 9)}
    assert len(coco.getImgIds()) == len(rows) and len(coco.getAnnIds()) > 0
    by_key = {(r["garden"], r["lighting"], int(r["camera"]), int(r["frame"])): r for r in rows.to_dict("records")}
    for img in coco.loadImgs(coco.getImgIds()):
        rec = by_key[(img["garden"], img["lighting"], img["camera"], img["frame"])]
        inst, sem = read(root, rec, "instance").astype(np.int64), read(root, rec, "semantic")
        np.testing.assert_array_equal(
            cv2.imread(str(tmp_path / "coco" / img["file_name"]))[..., ::-1], read(root, rec, "rgb_left")
        )
        anns = coco.loadAnns(coco.getAnnIds(imgIds=img["id"]))
        seen = set()
        for ann in anns:
            mask = coco.annToMask(ann).astype(bool)
            np.testing.assert_array_equal(mask, inst == ann["eden_instance_id"])
            assert ann["area"] == mask.sum()
            counts = np.bincount(sem[mask], minlength=10)
            counts[[0, 9]] = 0
            assert ann["category_id"] == counts.argmax()
            seen.add(ann["eden_instance_id"])
        # every instance with a labelled (non-void, non-background) pixel is annotated
        for i in set(np.unique(inst)) - {0}:
            s = sem[inst == i]
            assert (i in seen) == bool(np.any((s != 0) & (s != 9)))


# ------------------------------------------------------------- KITTI flow
def test_kitti_flow(root, rows, tmp_path):
    out = tmp_path / "kitti"
    facts = ex.export_kitti_flow(root, out, rows)
    index = list(csv.DictReader(open(out / "index.csv")))
    assert facts["pairs"] == len(index) == int((rows["flow_fwd"] != "").sum())
    m = load_manifest(root)
    for entry in index[::4]:
        rec = m[(m.camera == int(entry["camera"])) & (m.frame == int(entry["frame"]))].iloc[0]
        nxt = m[(m.camera == int(entry["camera"])) & (m.frame == int(entry["frame"]) + 1)].iloc[0]
        name = entry["id"]
        # devkit formula on raw OpenCV (BGR) decoding: u = R, v = G, valid = B
        for sub, occluded_ok in (("flow_occ", True), ("flow_noc", False)):
            img = cv2.imread(str(out / sub / f"{name}_10.png"), cv2.IMREAD_UNCHANGED).astype(np.float64)
            assert img.dtype == np.float64 and img.shape[2] == 3
            u, v, valid = (img[..., 2] - 2**15) / 64.0, (img[..., 1] - 2**15) / 64.0, img[..., 0] > 0
            flow = read(root, rec, "flow_fwd")
            occ = read(root, rec, "occ_fwd") > 0
            expect_valid = np.ones_like(occ) if occluded_ok else ~occ
            expect_valid &= np.all(np.abs(flow) < 511, axis=-1)
            np.testing.assert_array_equal(valid, expect_valid)
            np.testing.assert_allclose(u[valid], flow[..., 0][valid], atol=1 / 128 + 1e-6)
            np.testing.assert_allclose(v[valid], flow[..., 1][valid], atol=1 / 128 + 1e-6)
        disp = cv2.imread(str(out / "disp_occ_0" / f"{name}_10.png"), cv2.IMREAD_UNCHANGED)
        assert disp.dtype == np.uint16 and disp.ndim == 2
        depth = read(root, rec, "depth")
        ok = disp > 0
        np.testing.assert_array_equal(ok, np.isfinite(depth))
        np.testing.assert_allclose(disp[ok] / 256.0, rec["fx"] * rec["baseline"] / depth[ok], atol=1 / 512 + 1e-6)
        np.testing.assert_array_equal(
            cv2.imread(str(out / "image_2" / f"{name}_11.png"))[..., ::-1], read(root, nxt, "rgb_left")
        )
        np.testing.assert_array_equal(
            cv2.imread(str(out / "image_3" / f"{name}_10.png"))[..., ::-1], read(root, rec, "rgb_right")
        )


# ------------------------------------------------------------- nerfstudio
def test_nerfstudio(root, rows, tmp_path):
    facts = ex.export_nerfstudio(root, tmp_path / "ns", rows)
    (path,) = facts["scenes"]
    data = json.loads(open(path).read())
    scene = Path(path).parent
    assert data["camera_model"] == "OPENCV" and data["w"] == 96 and data["h"] == 72
    assert len(data["frames"]) == 2 * len(rows)
    rec0 = rows.iloc[0]
    K = row_intrinsics(rec0)
    by_file = {f["file_path"]: f for f in data["frames"]}
    rng = np.random.default_rng(0)
    for rec in rows.to_dict("records")[::5]:
        for tag, right in (("l", False), ("r", True)):
            fr = by_file[f"images/cam{int(rec['camera'])}{tag}_{int(rec['frame']):05d}.png"]
            np.testing.assert_array_equal(
                cv2.imread(str(scene / fr["file_path"]))[..., ::-1],
                read(root, rec, "rgb_right" if right else "rgb_left"),
            )
            mm = cv2.imread(str(scene / fr["depth_file_path"]), cv2.IMREAD_UNCHANGED)
            assert mm.dtype == np.uint16
            depth = mm.astype(np.float64) * 0.001  # nerfstudio's depth_unit_scale_factor
            src = read(root, rec, "depth_right" if right else "depth")
            np.testing.assert_array_equal(mm > 0, np.isfinite(src))
            c2w = np.array(fr["transform_matrix"])
            j, i = np.nonzero(mm > 0)
            pick = rng.choice(len(i), size=min(50, len(i)), replace=False)
            i, j = i[pick], j[pick]
            # nerfstudio: pixel (i, j)'s centre at (i+0.5, j+0.5); camera looks down -z, y up
            d = depth[j, i]
            dirs = np.stack(
                [(i + 0.5 - data["cx"]) / data["fl_x"], -(j + 0.5 - data["cy"]) / data["fl_y"], -np.ones_like(d)], 1
            )
            world = (dirs * d[:, None]) @ c2w[:3, :3].T + c2w[:3, 3]
            # project with the source manifest's OpenCV pose and K: the same pixel
            pose = row_pose(rec, right=right)
            cam = (world - pose[:3, 3]) @ pose[:3, :3]
            u, v = K[0, 0] * cam[:, 0] / cam[:, 2] + K[0, 2], K[1, 1] * cam[:, 1] / cam[:, 2] + K[1, 2]
            np.testing.assert_allclose(u, i, atol=1e-6)
            np.testing.assert_allclose(v, j, atol=1e-6)
            np.testing.assert_allclose(cam[:, 2], src[j, i], atol=6e-4)  # mm quantisation


def test_cli(root, tmp_path):
    out = tmp_path / "cli"
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "eden_pipe.tools.export",
            str(root),
            "--format",
            "nerfstudio",
            "--out",
            str(out),
            "--lighting",
            "clear",
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stderr
    assert (out / "small-s0" / "clear" / "transforms.json").is_file()
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "eden_pipe.tools.export",
            str(root),
            "--format",
            "coco",
            "--out",
            str(out),
            "--lighting",
            "none",
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode != 0 and "no manifest rows" in res.stderr
