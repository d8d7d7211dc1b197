"""Scale-out through the real command line: Hydra launchers and concurrent jobs on one stage cache.

The fast suite keeps one test here (two concurrent jobs on one cache); the
launcher sweeps are ``slow`` and skip when their plugin is not installed
(``pip install -e ".[scale]"``, ``".[ray]"``).
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from eden_pipe.data.manifest_reader import load_manifest
from eden_pipe.modalities import read_modality
from eden_pipe.stages.manifest import PATH_COLUMNS
from tests.conftest import REPO, TINY

STAGE_LINE = re.compile(r"\[eden-pipe\] (model|scene|trajectory|render|manifest)\s+(built|cached)")


def tiny_cli(root: Path) -> list[str]:
    """TINY as CLI overrides, every path under ``root``."""
    return [
        *TINY,
        f"paths.stages={root}/stages",
        f"paths.dataset={root}/dataset",
        f"hydra.run.dir={root}/runs/${{now:%H-%M-%S-%f}}",
        f"hydra.sweep.dir={root}/multirun",
    ]


def env() -> dict:
    out = dict(os.environ)
    out["PYTHONPATH"] = str(REPO) + os.pathsep + out.get("PYTHONPATH", "")
    return out


def cli(args: list[str], cwd: Path, timeout: int = 600) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [sys.executable, "-m", "eden_pipe", *args], cwd=cwd, env=env(), capture_output=True, text=True, timeout=timeout
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc


def check_dataset(root: Path, gardens: int, lightings: int) -> pd.DataFrame:
    """One merged manifest with every job's rows, every listed file present and decodable."""
    manifest = load_manifest(root / "dataset")  # every path column, '' where a job did not list it
    rows_per_job = 4 * 5  # TINY: 4 frames x 5 camera pairs
    assert len(manifest) == gardens * lightings * rows_per_job
    assert manifest.groupby(["garden", "lighting"]).size().eq(rows_per_job).all()
    assert manifest["garden"].nunique() == gardens and manifest["lighting"].nunique() == lightings
    assert manifest.groupby("garden")["split"].nunique().eq(1).all()  # splits are by garden
    assert not manifest.duplicated(["garden", "lighting", "frame", "camera"]).any()
    for column in PATH_COLUMNS:  # decoded by the modality table's reader, whatever the storage mode
        for rel in manifest[column]:
            if rel:
                assert read_modality(root / "dataset" / rel, column).shape[:2] == (72, 96), rel
    return manifest


def check_cache(root: Path) -> None:
    """Every artifact finished exactly once: a marker, no temporary or trash folders left behind."""
    stages = root / "stages"
    leftovers = [p for p in stages.glob("*/*") if p.name.startswith((".tmp-", ".trash-"))]
    assert not leftovers, leftovers
    for folder in stages.glob("*/*"):
        if folder.is_dir():
            assert (folder / "DONE.json").is_file(), folder


# ---------------------------------------------------------------- fast: locks
def test_concurrent_jobs_share_one_cache_and_build_geometry_once(tmp_path):
    """Same garden, two lightings, two processes started together on one cache."""
    args = [*tiny_cli(tmp_path), "render.modalities=[semantic,instance,depth]"]  # label passes only: quick
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "eden_pipe", *args, f"lighting={lighting}"],
            cwd=tmp_path,
            env=env(),
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        for lighting in ("clear", "sunset")
    ]
    outputs = [p.communicate(timeout=300)[0] for p in procs]
    assert [p.returncode for p in procs] == [0, 0], "\n".join(o[-2000:] for o in outputs)
    status = [dict(STAGE_LINE.findall(o)) for o in outputs]
    # The lighting is not part of the geometry keys: one job builds, the other waits on the lock and reuses.
    for stage in ("model", "scene"):
        assert sorted(s[stage] for s in status) == ["built", "cached"], (stage, status)
    for stage in ("trajectory", "render", "manifest"):  # a random walk per lighting (EDEN)
        assert [s[stage] for s in status] == ["built", "built"], (stage, status)
    # Each model was built once, inside the single garden build, and nothing else was built.
    model_dir = tmp_path / "stages" / "model"
    gardens = sorted(model_dir.glob("garden-*/DONE.json"))
    assert len(gardens) == 1 and json.loads(gardens[0].read_text())["models_cached"] == 0
    listed = set(json.loads((gardens[0].parent / "models.json").read_text()).values())
    built = {p.name for p in model_dir.iterdir() if p.is_dir() and not p.name.startswith(("garden-", "."))}
    assert listed == built and len(built) > 0
    check_cache(tmp_path)
    manifest = check_dataset(tmp_path, gardens=1, lightings=2)
    # Same geometry, a walk of its own under each lighting (camera.trajectory.share_across_lightings=false).
    clear, sunset = (manifest[manifest.lighting == name].reset_index(drop=True) for name in ("clear", "sunset"))
    assert not np.allclose(clear[["tx", "ty", "tz"]], sunset[["tx", "ty", "tz"]])


# ------------------------------------------------------------ slow: launchers
def installed(module: str) -> bool:
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:  # the parent package (hydra_plugins) is missing too
        return False


def needs(module: str):
    return pytest.mark.skipif(not installed(module), reason=f"{module} not installed")


@pytest.mark.slow
@needs("hydra_plugins.hydra_joblib_launcher")
def test_joblib_multirun_merges_one_manifest(tmp_path):
    """2 gardens x 2 lightings on 2 joblib workers -> one merged manifest with all 80 rows."""
    proc = cli(
        [
            "-m",
            "hydra/launcher=eden_joblib",
            "hydra.launcher.n_jobs=2",
            "render.threads=1",
            "garden.seed=0,1",
            "lighting=clear,sunset",
            *tiny_cli(tmp_path),
        ],
        tmp_path,
    )
    assert "80 rows merged" in proc.stdout + proc.stderr
    check_dataset(tmp_path, gardens=2, lightings=2)
    check_cache(tmp_path)
    assert len(list((tmp_path / "stages" / "model").glob("garden-*/DONE.json"))) == 2
    assert len(list((tmp_path / "stages" / "render").glob("*/DONE.json"))) == 4


@pytest.mark.slow
@needs("hydra_plugins.hydra_submitit_launcher")
def test_submitit_local_multirun(tmp_path):
    """The SLURM code path without a cluster: submitit's local executor, 1 garden x 2 lightings."""
    proc = cli(
        [
            "-m",
            "hydra/launcher=eden_submitit_local",
            "render.threads=1",
            "garden.seed=3",
            "lighting=cloudy,overcast",
            *tiny_cli(tmp_path),
        ],
        tmp_path,
    )
    assert "40 rows merged" in proc.stdout + proc.stderr
    check_dataset(tmp_path, gardens=1, lightings=2)
    check_cache(tmp_path)
    logs = list((tmp_path / "multirun" / ".submitit").glob("*/*_log.out"))
    assert len(logs) == 2 and all("Job completed successfully" in p.read_text() for p in logs)


@pytest.mark.slow
@needs("hydra_plugins.hydra_ray_launcher")
def test_ray_local_multirun(tmp_path):
    """Ray on a local instance (only where the [ray] extra is installed)."""
    proc = cli(
        [
            "-m",
            "hydra/launcher=eden_ray",
            "render.threads=1",
            "garden.seed=0",
            "lighting=clear,twilight",
            *tiny_cli(tmp_path),
        ],
        tmp_path,
    )
    assert "40 rows merged" in proc.stdout + proc.stderr
    check_dataset(tmp_path, gardens=1, lightings=2)
