"""python -m eden_pipe.eval: ground truth scores perfectly, corruptions score what metrics.py computes, missing
files fail."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from eden_pipe.eval.cli import main
from eden_pipe.eval.metrics import DepthMeter, SegmentationMeter
from eden_pipe.io.formats import read_modality, write_semantic
from eden_pipe.pipeline import run_job
from tests.conftest import TINY, make_cfg

LIGHTINGS = ("clear", "sunset")


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("evalds")
    for light in LIGHTINGS:
        run_job(
            make_cfg(
                root,
                TINY
                + [
                    f"lighting={light}",
                    "render.max_frames=2",
                    "render.modalities=[rgb,semantic,depth]",
                    "++split.overrides={small-s0: test}",
                ],
            ),
            echo=lambda *_: None,
        )
    return root / "dataset"


def _rows(root: Path) -> pd.DataFrame:
    df = pd.read_csv(root / "manifest.csv", keep_default_na=False)
    return df[df["split"] == "test"]


def _copy_gt(root: Path, dest: Path) -> Path:
    for rec in _rows(root).to_dict("records"):
        for col in ("semantic", "depth"):
            (dest / rec[col]).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy(root / rec[col], dest / rec[col])
    return dest


def test_ground_truth_scores_perfectly(dataset, tmp_path, capsys):
    pred = _copy_gt(dataset, tmp_path / "pred")
    out = tmp_path / "scores.json"
    assert main([str(dataset), "--pred", str(pred), "--out", str(out)]) == 0
    scores = json.loads(out.read_text())
    n = len(_rows(dataset))
    assert n == 2 * 2 * 5  # lightings x frames x camera pairs
    assert scores["semantic"]["images"] == n and scores["depth"]["images"] == n
    assert scores["semantic"]["overall"]["miou"] == 1.0
    assert scores["depth"]["overall"]["abs_rel"] == 0.0 and scores["depth"]["overall"]["delta1"] == 1.0
    assert sorted(scores["semantic"]["per_lighting"]) == sorted(LIGHTINGS)
    for light in LIGHTINGS:
        assert scores["semantic"]["per_lighting"][light]["miou"] == 1.0
        assert scores["depth"]["per_lighting"][light]["rms"] == 0.0
    printed = capsys.readouterr().out
    assert "| **overall** |" in printed and "| clear |" in printed and "| sunset |" in printed


def test_corrupted_prediction_matches_metrics(dataset, tmp_path):
    rng = np.random.default_rng(0)
    pred = tmp_path / "pred"
    seg_all, dep_all = SegmentationMeter(), DepthMeter()
    seg_clear = SegmentationMeter()
    for i, rec in enumerate(_rows(dataset).to_dict("records")):
        sem = read_modality(dataset / rec["semantic"], "semantic").astype(np.int64)
        bad = sem.copy()
        flip = rng.random(sem.shape) < 0.3
        bad[flip] = rng.integers(0, 10, size=int(flip.sum()))
        target = pred / rec["semantic"]
        target.parent.mkdir(parents=True, exist_ok=True)
        if i % 2:  # palette PNG (as the dataset writes) or grayscale PNG: both are ids
            write_semantic(target, bad.astype(np.uint8))
        else:
            Image.fromarray(bad.astype(np.uint8), mode="L").save(target)
        gt_d = read_modality(dataset / rec["depth"], "depth")
        noisy = np.where(np.isfinite(gt_d), gt_d, 5.0) * rng.uniform(0.7, 1.3, size=gt_d.shape)
        dtarget = (pred / rec["depth"]).with_suffix(".npy")  # float metres instead of the PNG
        dtarget.parent.mkdir(parents=True, exist_ok=True)
        np.save(dtarget, noisy.astype(np.float32))
        seg_all.update(bad, sem)
        dep_all.update(noisy.astype(np.float32), gt_d)
        if rec["lighting"] == "clear":
            seg_clear.update(bad, sem)
    out = tmp_path / "scores.json"
    assert main([str(dataset), "--pred", str(pred), "--out", str(out)]) == 0
    scores = json.loads(out.read_text())
    want_s, want_d = seg_all.compute(), dep_all.compute()
    assert scores["semantic"]["overall"]["miou"] == pytest.approx(want_s["miou"], abs=1e-12)
    assert 0.1 < want_s["miou"] < 0.95
    for name, v in want_s["iou"].items():
        got = scores["semantic"]["overall"]["iou"][name]
        assert (got is None and np.isnan(v)) or got == pytest.approx(v, abs=1e-12)
    assert scores["semantic"]["per_lighting"]["clear"]["miou"] == pytest.approx(seg_clear.compute()["miou"], abs=1e-12)
    for k in ("abs_rel", "log10", "rms", "delta1"):
        assert scores["depth"]["overall"][k] == pytest.approx(want_d[k], rel=1e-9)
    assert scores["depth"]["overall"]["abs_rel"] > 0.05


def test_missing_prediction_fails_naming_the_file(dataset, tmp_path):
    pred = _copy_gt(dataset, tmp_path / "pred")
    victim = _rows(dataset).iloc[3]["semantic"]
    (pred / victim).unlink()
    proc = subprocess.run(
        [sys.executable, "-m", "eden_pipe.eval", str(dataset), "--pred", str(pred), "--task", "semantic"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode != 0
    assert str(pred / victim) in proc.stderr
    out = tmp_path / "s.json"
    assert main([str(dataset), "--pred", str(pred), "--task", "semantic", "--allow-missing", "--out", str(out)]) == 0
    scores = json.loads(out.read_text())
    assert scores["semantic"]["missing"] == 1 and scores["semantic"]["missing_files"] == [victim]
    assert scores["semantic"]["images"] == len(_rows(dataset)) - 1
    assert "depth" not in scores


def test_filters_lighting_and_subsample(dataset, tmp_path):
    pred = _copy_gt(dataset, tmp_path / "pred")
    out = tmp_path / "s.json"
    assert main([str(dataset), "--pred", str(pred), "--lighting", "sunset", "--task", "depth", "--out", str(out)]) == 0
    scores = json.loads(out.read_text())
    assert list(scores["depth"]["per_lighting"]) == ["sunset"] and scores["depth"]["images"] == 10
    # no test_subsample column yet: asking for it is an error; with the column, only its rows count
    assert main([str(dataset), "--pred", str(pred), "--subsample"]) == 2
    sub = tmp_path / "sub"
    shutil.copytree(dataset, sub)
    df = pd.read_csv(sub / "manifest.csv", keep_default_na=False)
    df["test_subsample"] = (np.arange(len(df)) % 3 == 0).astype(int)
    df.to_csv(sub / "manifest.csv", index=False)
    assert main([str(sub), "--pred", str(pred), "--subsample", "--out", str(out)]) == 0
    want = int(((df["split"] == "test") & (df["test_subsample"] == 1)).sum())
    assert json.loads(out.read_text())["semantic"]["images"] == want
