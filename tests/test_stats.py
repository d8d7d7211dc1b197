"""eden_pipe.tools.stats on the tiny dataset: counts add up, figures are real PNGs."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from eden_pipe.tools import stats
from tests.tools_dataset import manifest, tiny_dataset

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    return tiny_dataset(tmp_path_factory)


@pytest.fixture(scope="module")
def result(dataset, tmp_path_factory):
    out = tmp_path_factory.mktemp("stats")
    return out, stats.compute_stats(dataset, out, progress=False)


def test_pixel_counts_sum_to_rows_times_pixels(dataset, result):
    out, _ = result
    rows = manifest(dataset)
    total = int((rows.width * rows.height).sum())
    assert total == len(rows) * 96 * 72
    classes = pd.read_csv(out / "class_pixels.csv")
    assert list(classes.class_id) == list(range(10)) and int(classes.pixels.sum()) == total
    depth = pd.read_csv(out / "depth_pixels.csv")
    assert int(depth.pixels.sum()) == total
    assert list(depth.bin[:2]) == ["[0,1)", "[1,2)"] and list(depth.bin[-2:]) == ["[10,inf)", "sky"]
    assert depth.pixels.iloc[-1] > 0  # the tiny garden shows sky
    share = pd.read_csv(out / "class_share.csv")
    assert len(share) == len(rows)
    np.testing.assert_allclose(share[list(classes.name)].sum(axis=1), 1.0, atol=1e-5)
    lum = pd.read_csv(out / "luminance_by_lighting.csv")
    assert list(lum.lighting) == sorted(rows.lighting.unique()) and (lum["mean"] > 0).all()


def test_figures_are_non_empty_pngs(dataset, result):
    out, res = result
    rows = manifest(dataset)
    names = ["class_pixels.png", "class_share.png", "depth_pixels.png", "luminance.png"]
    pairs = rows[["garden", "lighting"]].drop_duplicates().itertuples(index=False)
    names += [f"contact_{garden}_{lighting}.png" for garden, lighting in pairs]
    for name in names:
        data = (out / name).read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000, name
        assert name in res["files"]


def test_depth_histogram_bins_are_half_open():
    depth = np.array([0.0, 0.999, 1.0, 9.999, 10.0, 250.0, np.inf], np.float32)
    counts = stats.depth_histogram(depth)
    assert counts.tolist() == [2, 1, 0, 0, 0, 0, 0, 0, 0, 1, 2, 1]


def test_cli_with_sample(dataset, tmp_path):
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "eden_pipe.tools.stats",
            str(dataset),
            "--out",
            str(tmp_path),
            "--sample",
            "6",
            "--no-progress",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 0, proc.stderr
    assert int(pd.read_csv(tmp_path / "class_pixels.csv").pixels.sum()) == 6 * 96 * 72
    assert (tmp_path / "class_pixels.png").stat().st_size > 0
