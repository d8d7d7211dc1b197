"""scripts/train_baseline.py end to end on the shared TINY dataset: 2 training steps, table, predictions the CLI
scores alike."""

from __future__ import annotations

import importlib.util
import json

import pandas as pd
import pytest

from tests.conftest import REPO
from tests.tiny_dataset import tiny_root


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
