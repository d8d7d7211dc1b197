"""Shard exports (eden_pipe.tools.shards) read back by their own libraries (webdataset, datasets) and streamed by
eden_pipe.data.EdenShards into the folder loader's tensors."""

from __future__ import annotations

import io
import json
import math
import tarfile
from pathlib import Path

import datasets
import numpy as np
import pytest
import webdataset as wds
from PIL import Image

from eden_pipe import modalities
from eden_pipe.data import shard_layout as layout
from eden_pipe.data.manifest_reader import load_manifest, row_intrinsics, row_pose
from eden_pipe.modalities import read_modality
from eden_pipe.tools import export as ex
from eden_pipe.tools import shards
from tests.tools_dataset import copy_dataset, tiny_dataset

try:  # the streaming reader is a torch IterableDataset; the exports and their read-back need no torch
    import torch
    from torch.utils.data import DataLoader

    from eden_pipe.data import EdenDataset, EdenShards
except ImportError:
    torch = None  # type: ignore[assignment]
needs_torch = pytest.mark.skipif(torch is None, reason="EdenShards is a torch dataset: pip install -e '.[test-torch]'")

# Every loader key of the tiny dataset (it has every modality), and the right camera.
MODALITIES = ["rgb", "semantic", "instance", "depth", "normal", "flow_fwd", "flow_bwd", "albedo", "shading"]
MODALITIES += ["translucency", "glossy", "background", "rgb_linear"]
SPLIT_OF_CAMERA = {0: "train", 1: "train", 2: "val", 3: "val", 4: "test"}


@pytest.fixture(scope="module")
def root(tmp_path_factory):
    """The tiny dataset with its rows spread over three splits (by camera), so exports are split-aware."""
    dst = copy_dataset(tiny_dataset(tmp_path_factory), tmp_path_factory.mktemp("split3") / "dataset")
    text = (dst / "manifest.csv").read_text().splitlines()
    header = text[0].split(",")
    cam, split = header.index("camera"), header.index("split")
    lines = [text[0]]
    for line in text[1:]:
        cells = line.split(",")
        cells[split] = SPLIT_OF_CAMERA[int(cells[cam])]
        lines.append(",".join(cells))
    (dst / "manifest.csv").write_text("\n".join(lines) + "\n")
    return dst


@pytest.fixture(scope="module")
def manifest(root):
    return load_manifest(root)


@pytest.fixture(scope="module")
def wds_out(root, tmp_path_factory):
    out = tmp_path_factory.mktemp("wds") / "shards"
    assert ex.main([str(root), "--format", "webdataset", "--out", str(out), "--shard-size", "3", "--seed", "7"]) == 0
    return out


@pytest.fixture(scope="module")
def hf_out(root, tmp_path_factory):
    out = tmp_path_factory.mktemp("hf") / "hf"
    assert ex.main([str(root), "--format", "hf", "--out", str(out), "--shard-size", "3", "--seed", "7"]) == 0
    return out


def key_of(row) -> tuple:
    return (str(row["garden"]), str(row["lighting"]), int(row["camera"]), int(row["frame"]))


def expected_order(root, split, seed=7) -> list[tuple]:
    """The documented order: the selection's (garden, lighting, camera, frame) order permuted by the seed."""
    return [key_of(r) for r in shards.split_order(ex.select_rows(root), split, seed).to_dict("records")]


def urls(out: Path, split: str) -> list[str]:
    return [str(p) for p in sorted(out.glob(f"{split}-*.tar"))]


# ---------------------------------------------------------------------------- WebDataset
def test_webdataset_read_back_by_webdataset(root, manifest, wds_out):
    """Every row once, in its split's shards, members the stored files' bytes, metadata the manifest row."""
    index = json.loads((wds_out / layout.INDEX).read_text())
    by_key = {key_of(r): r for r in manifest.to_dict("records")}
    seen = []
    for split in ("train", "val", "test"):
        rows = manifest[manifest["split"] == split]
        assert index["splits"][split]["samples"] == len(rows)
        assert index["splits"][split]["shards"] == [Path(u).name for u in urls(wds_out, split)]
        assert len(urls(wds_out, split)) == math.ceil(len(rows) / 3)
        samples = list(wds.WebDataset(urls(wds_out, split), shardshuffle=False))
        order = []
        for sample in samples:
            meta = json.loads(sample["json"])
            rec = by_key[key_of(meta)]
            order.append(key_of(meta))
            assert meta["split"] == split
            assert sample["__key__"] == f"{rec['garden']}/{rec['lighting']}/cam{rec['camera']}/{rec['frame']:05d}"
            for column in modalities.PATH_COLUMNS:
                name = f"{column}.{Path(rec[column]).suffix[1:]}"
                if rec[column]:
                    assert sample[name] == (root / rec[column]).read_bytes(), name
                    assert meta[column] == rec[column]
                else:
                    assert not any(k.startswith(column + ".") for k in sample)
            for column in ("fx", "cx", "qw", "tx", "timestamp", "baseline", "exposure"):
                assert meta[column] == rec[column]
            assert np.array_equal(meta["pose"], row_pose(rec)) and np.array_equal(meta["K"], row_intrinsics(rec))
        assert order == expected_order(root, split)
        seen += order
    assert sorted(seen) == sorted(by_key)


def test_webdataset_decoder_reads_the_images(root, manifest, wds_out):
    """webdataset's own PNG decoder gives the pixels the modality table's reader gives."""
    by_key = {key_of(r): r for r in manifest.to_dict("records")}
    samples = list(wds.WebDataset(urls(wds_out, "train"), shardshuffle=False).decode("rgb8"))
    assert samples
    for sample in samples:
        rec = by_key[key_of(sample["json"])]
        assert np.array_equal(sample["rgb_left.png"], read_modality(root / rec["rgb_left"], "rgb_left"))


def test_shuffle_is_the_seed_s(root, manifest, tmp_path):
    """Same seed: the same bytes; another seed: the same samples in another order."""
    outs = {}
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        outs[name] = tmp_path / name
        ex.export(root, "webdataset", outs[name], shard_size="4", seed=seed)
    tars = {n: [p.read_bytes() for p in sorted(o.glob("*.tar"))] for n, o in outs.items()}
    assert tars["a"] == tars["b"]
    keys = {
        n: [json.loads(s["json"])["frame"] for s in wds.WebDataset(urls(o, "train"), shardshuffle=False)]
        for n, o in outs.items()
    }
    assert keys["a"] != keys["c"] and sorted(keys["a"]) == sorted(keys["c"])
    assert expected_order(root, "train", 3) != sorted(expected_order(root, "train", 3))


def test_byte_sized_shards(root, tmp_path):
    """A byte size closes a shard before the sample that would pass it (tar blocks counted)."""
    limit = 100_000
    out = tmp_path / "bytes"
    facts = ex.export(root, "webdataset", out, shard_size="100KB")
    assert facts["train"]["shards"] > 1
    for tar in out.glob("*.tar"):
        with tarfile.open(tar) as fh:
            members = fh.getmembers()
        blocks = sum(512 + math.ceil(m.size / 512) * 512 for m in members)
        one_sample = len({m.name.split(".")[0] for m in members}) == 1
        assert blocks <= limit or one_sample


# ---------------------------------------------------------------------------- Hugging Face
def test_hf_read_back_by_datasets(root, manifest, hf_out):
    dd = datasets.load_from_disk(str(hf_out))
    assert isinstance(dd, datasets.DatasetDict) and set(dd) == {"train", "val", "test"}
    by_key = {key_of(r): r for r in manifest.to_dict("records")}
    images = {c for c, f in dd["train"].features.items() if isinstance(f, datasets.Image)}
    # PNGs Pillow reads exactly are images; 16-bit three-channel PNGs and EXR are bytes.
    assert {"rgb_left", "semantic", "instance", "depth", "occ_fwd"} <= images
    assert not images & {"normal", "flow_fwd", "albedo"}
    for split, part in dd.items():
        assert len(part) == int((manifest["split"] == split).sum())
        assert len(list((hf_out / split).glob("*.arrow"))) == math.ceil(len(part) / 3)
        order = []
        for row in part:
            rec = by_key[key_of(row)]
            order.append(key_of(row))
            assert row["split"] == split and row["fx"] == rec["fx"] and row["qx"] == rec["qx"]
            assert np.array_equal(row["pose"], row_pose(rec))
            rgb = np.asarray(row["rgb_left"].convert("RGB"))
            assert np.array_equal(rgb, read_modality(root / rec["rgb_left"], "rgb_left"))
            assert np.array_equal(np.asarray(row["semantic"]), read_modality(root / rec["semantic"], "semantic"))
            assert row["albedo"] == (root / rec["albedo"]).read_bytes()
            assert row["normal_path"] == rec["normal"]
            if not rec["flow_bwd"]:
                assert row["flow_bwd"] is None and row["flow_bwd_path"] == ""
        assert order == expected_order(root, split)


# ---------------------------------------------------------------------------- EdenShards
@needs_torch
@pytest.mark.parametrize("fmt", ["webdataset", "hf"])
def test_stream_equals_the_folder(root, wds_out, hf_out, fmt):
    """Every key of every item: the folder loader's tensor, dtype and value, for the same row."""
    source = wds_out if fmt == "webdataset" else hf_out
    for split in ("train", "test"):
        folder = EdenDataset(root, MODALITIES, split=split, stereo=True)
        by_key = {key_of(r): i for i, r in enumerate(folder.records)}
        items = list(EdenShards(source, MODALITIES, split=split, stereo=True))
        assert sorted(key_of(i) for i in items) == sorted(by_key)
        for item in items:
            ref = folder[by_key[key_of(item)]]
            assert set(item) == set(ref)
            for key, value in ref.items():
                if isinstance(value, torch.Tensor):
                    assert value.dtype == item[key].dtype and torch.equal(value, item[key]), key
                elif key != "index":
                    assert value == item[key], key


@needs_torch
def test_stream_workers_read_each_sample_once(root, wds_out):
    stream = EdenShards(wds_out, ["rgb", "depth"], split="train")
    frames = [
        (int(c), int(f))
        for b in DataLoader(stream, batch_size=2, num_workers=2)
        for c, f in zip(b["camera"], b["frame"], strict=True)
    ]
    rows = EdenDataset(root, ["rgb", "depth"], split="train").records
    assert sorted(frames) == sorted((int(r["camera"]), int(r["frame"])) for r in rows)


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("text", ["0", "-3", "1.5", "abc", "10XB", "0KB", ""])
def test_bad_shard_size(text):
    with pytest.raises(ValueError, match=r"--shard-size .*positive sample count"):
        shards.parse_shard_size(text)


def test_shard_size_forms():
    assert shards.parse_shard_size("12") == shards.ShardSize(samples=12)
    assert shards.parse_shard_size("500MB") == shards.ShardSize(bytes=500_000_000)
    assert shards.parse_shard_size("1GiB") == shards.ShardSize(bytes=2**30)
    assert shards.parse_shard_size("1.5kb") == shards.ShardSize(bytes=1500)


def test_bad_arguments(root, tmp_path, capsys):
    with pytest.raises(ValueError, match="--seed -1"):
        ex.export(root, "webdataset", tmp_path / "a", seed=-1)
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "x").write_text("x")
    with pytest.raises(ValueError, match="must be a new or empty folder"):
        ex.export(root, "hf", tmp_path / "full")
    with pytest.raises(SystemExit):
        ex.main([str(root), "--format", "webdataset", "--out", str(tmp_path / "b"), "--shard-size", "lots"])
    assert "--shard-size 'lots'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        ex.main([str(root), "--format", "coco", "--out", str(tmp_path / "c"), "--shard-size", "3"])
    assert "--shard-size applies to the shard formats" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


@needs_torch
def test_stream_rejects(root, wds_out):
    with pytest.raises(ValueError, match="not a shard export"):
        EdenShards(root, split="train")
    with pytest.raises(ValueError, match=r"split 'valid'.*holds the splits test, train, val"):
        EdenShards(wds_out, split="valid")
    with pytest.raises(ValueError, match="unknown modality 'colour'"):
        EdenShards(wds_out, ["colour"], split="train")


def test_hf_image_rule_is_pillow_s():
    """Pillow reads a 16-bit three-channel PNG as 8 bits (why such columns are bytes, not datasets.Image)."""
    import cv2

    array = (np.arange(4 * 3 * 3).reshape(4, 3, 3) * 1000).astype(np.uint16)
    png = cv2.imencode(".png", array)[1].tobytes()
    assert np.asarray(Image.open(io.BytesIO(png))).dtype == np.uint8
    assert not shards.hf_image_column("normal", ["a/normal/00000.png"])
    assert shards.hf_image_column("depth", ["a/depth/00000.png"])
    assert not shards.hf_image_column("depth", ["a/depth/00000.npy"])
