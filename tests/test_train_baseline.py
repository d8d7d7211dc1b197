"""scripts/train_baseline.py end to end on the shared TINY dataset: 2 training steps, table, predictions the CLI
scores alike; for the segmentation and the depth task."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pandas as pd
import pytest

from tests.conftest import REPO
from tests.tiny_dataset import tiny_root

pytest.importorskip("torch", reason="the baseline trains a torch network: pip install -e '.[test,test-torch]'")


def _script():
    spec = importlib.util.spec_from_file_location("train_baseline", REPO / "scripts" / "train_baseline.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_two_steps_end_to_end(tmp_path_factory, tmp_path):
    tb = _script()
    root = tiny_root(tmp_path_factory) / "dataset"
    split = str(pd.read_csv(root / "manifest.csv")["split"].iloc[0])  # one garden: train and test on its split
    lines = []
    out = tb.main(
        [
            "--dataset",
            str(root),
            "--train-split",
            split,
            "--test-split",
            split,
            "--steps",
            "2",
            "--batch-size",
            "2",
            "--size",
            "64x48",
            "--device",
            "cpu",
            "--pred-out",
            str(tmp_path / "pred"),
        ],
        echo=lines.append,
    )
    text = "\n".join(lines)
    assert "| test lighting | test images | train: all |" in text
    assert out["stats"]["all"]["steps"] == 2
    miou = out["results"]["all"]["all"]["miou"]
    assert 0.0 <= miou <= 1.0
    assert set(out["results"]["all"]) == {"clear", "all"}

    # the predictions follow the eval CLI's convention (at --size, so not at the dataset's resolution):
    # the CLI reads them and refuses the shape mismatch with a message naming the file
    from eden_pipe.eval.cli import EvalError, evaluate

    with pytest.raises(EvalError, match="prediction shape"):
        evaluate(root, tmp_path / "pred", split=split, task="semantic")


def test_predictions_score_the_same_with_the_cli(tmp_path_factory, tmp_path):
    tb = _script()
    root = tiny_root(tmp_path_factory) / "dataset"
    split = str(pd.read_csv(root / "manifest.csv")["split"].iloc[0])
    out = tb.main(
        [
            "--dataset",
            str(root),
            "--train-split",
            split,
            "--test-split",
            split,
            "--steps",
            "1",
            "--batch-size",
            "2",
            "--device",
            "cpu",
            "--pred-out",
            str(tmp_path / "pred"),
        ],
        echo=lambda *_: None,
    )
    from eden_pipe.eval.cli import main

    assert (
        main(
            [
                str(root),
                "--pred",
                str(tmp_path / "pred"),
                "--split",
                split,
                "--task",
                "semantic",
                "--out",
                str(tmp_path / "s.json"),
            ]
        )
        == 0
    )
    scores = json.loads((tmp_path / "s.json").read_text())
    assert scores["semantic"]["overall"]["miou"] == pytest.approx(out["results"]["all"]["all"]["miou"], abs=1e-12)


def test_depth_task_trains_and_scores_with_eden_pipe_eval(tmp_path_factory, tmp_path, monkeypatch):
    tb = _script()
    root = tiny_root(tmp_path_factory) / "dataset"
    manifest = pd.read_csv(root / "manifest.csv")
    split = str(manifest["split"].iloc[0])
    # every depth score is computed by eden_pipe.eval's DepthMeter: count the images it is given
    from eden_pipe.eval import metrics

    updates = []
    real_update = metrics.DepthMeter.update
    monkeypatch.setattr(
        metrics.DepthMeter, "update", lambda self, pred, gt, mask=None: updates.append(1) or real_update(self, pred, gt)
    )
    lines = []
    out = tb.main(
        [
            "--dataset",
            str(root),
            "--task",
            "depth",
            "--train-split",
            split,
            "--test-split",
            split,
            "--steps",
            "2",
            "--batch-size",
            "2",
            "--device",
            "cpu",
            "--pred-out",
            str(tmp_path / "pred"),
        ],
        echo=lines.append,
    )
    text = "\n".join(lines)
    images = len(manifest)
    assert out["stats"]["all"]["steps"] == 2
    assert len(updates) == images  # one DepthMeter update per test image
    result = out["results"]["all"]
    assert result["images"] == images and list(result["per_lighting"]) == ["clear"]
    assert f"train: all; depth ({images} images, 0 missing predictions)" in text
    assert "| lighting | images | abs rel | log10 | rms (m) | delta1 | delta2 | delta3 |" in text
    assert out["table"] in text
    overall = result["overall"]
    assert overall["pixels"] > 0 and overall["abs_rel"] > 0 and 0 <= overall["delta1"] <= overall["delta3"] <= 1

    # the written predictions are float32 metres at the depth paths; the eval CLI scores them identically
    rel = manifest["depth"].iloc[0]
    pred = np.load((tmp_path / "pred" / rel).with_suffix(".npy"))
    assert pred.dtype == np.float32 and pred.shape == (manifest["height"].iloc[0], manifest["width"].iloc[0])
    assert np.all(pred > 0)
    from eden_pipe.eval.cli import evaluate

    scores = evaluate(root, tmp_path / "pred", split=split, task="depth")["depth"]
    for key in ("abs_rel", "log10", "rms", "delta1", "delta2", "delta3", "pixels"):
        assert scores["overall"][key] == pytest.approx(overall[key], rel=1e-12)
        assert scores["per_lighting"]["clear"][key] == pytest.approx(result["per_lighting"]["clear"][key], rel=1e-12)


def test_unknown_task_is_refused(capsys):
    tb = _script()
    with pytest.raises(SystemExit) as err:
        tb.build_parser().parse_args(["--dataset", "x", "--task", "flow"])
    assert err.value.code == 2
    assert "--task: invalid choice: 'flow' (choose from 'segmentation', 'depth')" in capsys.readouterr().err
