"""Bad input through the real command line: one clear message, non-zero exit, nothing written."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

BAD = [
    # (override, words the message must contain)
    ("garden.trees.count=[17,5]", ["garden.trees.count", "17", "lo <= hi"]),
    ("garden.obstacles.count=[-1,3]", ["garden.obstacles.count", "-1", ">= 0"]),
    ("garden.trees.types=[quaking_aspen,baobab]", ["garden.trees.types", "baobab", "quaking_aspen"]),
    ("render.depth_format=exr", ["render.depth_format", "exr", "png16"]),
    ("render.glossy_mirror=mirror", ["render.glossy_mirror", "mirror", "any_hit"]),
    ("lighting.sun_elevation_deg=[60,30]", ["lighting.sun_elevation_deg", "60", "lo <= hi"]),
    ("camera.trajectory.frames=[1,4]", ["camera.trajectory.frames", "[1, 4]", ">= 2"]),
    ("camera.trajectory.min_steps=1", ["camera.trajectory.min_steps", "1", ">= 2"]),  # the deprecated alias
    ("garden.fences.probability=1.5", ["garden.fences.probability", "1.5", "[0, 1]"]),
    ("force=[rendr]", ["force", "rendr", "render"]),
    ("garden.seed=-3", ["garden.seed", "-3", ">= 0"]),
    ("+garden.tress.count=[5,6]", ["garden.tress", "did you mean garden.trees?"]),  # unknown keys (docs/reliability.md)
    ("paths.dataset=/proc/forbidden", ["paths.dataset", "/proc"]),  # checked before any stage
]

HYDRA_BAD = [
    ("garden.colour=red", "colour"),  # unknown key (structured config)
    ("camera.width=wide", "width"),  # wrong type
    ("lighting=midnight", "midnight"),  # unknown option in a config group
]


def run_cli(args, cwd):
    # This checkout's eden_pipe, whatever the cwd (the job runs in an empty temporary folder).
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")])}
    return subprocess.run(
        [sys.executable, "-m", "eden_pipe", *args], cwd=cwd, capture_output=True, text=True, timeout=900, env=env
    )


@pytest.mark.parametrize("override,words", BAD, ids=[b[0] for b in BAD])
def test_semantic_errors_name_key_value_and_allowed(tmp_path, override, words):
    proc = run_cli([override], tmp_path)
    assert proc.returncode != 0
    message = proc.stderr.strip().splitlines()[-1]
    for word in words:
        assert word in message, (word, message)
    assert list(tmp_path.iterdir()) == [], "bad input must not create any folder"


@pytest.mark.parametrize("override,word", HYDRA_BAD, ids=[b[0] for b in HYDRA_BAD])
def test_schema_errors_fail_at_startup(tmp_path, override, word):
    proc = run_cli([override], tmp_path)
    assert proc.returncode == 2  # Hydra's composition errors too: one line, as the checks give
    assert len(proc.stderr.strip().splitlines()) == 1 and proc.stderr.startswith("eden-pipe: invalid config: ")
    assert word in proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_bad_input_keeps_an_existing_dataset_intact(tmp_path):
    dataset = tmp_path / "outputs" / "dataset"
    dataset.mkdir(parents=True)
    (dataset / "manifest.csv").write_text("garden\nkept\n")
    proc = run_cli(["garden.trees.count=[3,1]"], tmp_path)
    assert proc.returncode != 0
    assert (dataset / "manifest.csv").read_text() == "garden\nkept\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["outputs"]
    assert sorted(p.name for p in (tmp_path / "outputs").iterdir()) == ["dataset"]


@pytest.mark.slow
def test_small_garden_through_the_cli(tmp_path):
    """The README's preview command: a small garden, a short trajectory, every modality."""
    proc = run_cli(["garden=small", "camera.trajectory.frames=[10,10]", "progress=false"], tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    import pandas as pd

    manifest = pd.read_csv(tmp_path / "outputs" / "dataset" / "manifest.csv", keep_default_na=False)
    assert len(manifest) == 10 * 5 and set(manifest.garden) == {"small-s0"}
    assert "[eden-pipe] render     built" in proc.stdout


@pytest.mark.slow
def test_default_garden_through_the_cli(tmp_path):
    """The quick-start job on the default garden (two frames of it, to keep CI time bounded)."""
    proc = run_cli(["render.max_frames=2", "progress=false"], tmp_path)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert (tmp_path / "outputs" / "dataset" / "default-s0" / "clear" / "cam4" / "rgb_left" / "00001.png").is_file()
