"""Running eden-pipe jobs for ``scripts/reliability_table.py`` and its tests, and looking at what they leave.

Holds the small job every row runs (:data:`JOB`), the fault hook's variable (:data:`HOOK`), the
subprocess helpers (:func:`run`, :func:`start`, :func:`finish`, :func:`wait_until`) with their
:class:`Run` result, and the on-disk checks (:func:`fingerprint` of a dataset root, file counts,
temporaries left behind, everything under a folder).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
from dataset_fingerprint import VOLATILE, content_digest  # noqa: E402  (VOLATILE: time or host)

# A coarse sky-visibility bake for small jobs that test the pipeline, not the light. The default's 14 mm
# bundles cost ~0.5M rays per direction, its camera gain 16M rays, the lightmaps of the small garden's soil
# 49M: a JOB with the default bake took 42-45 s on 2 quiet cores (the bake 34-37 s), with this one 11 s
# (the bake 3.2 s). docs/realism.md says what each key does; tests/conftest.py TINY takes it from here.
COARSE_BAKE = [
    "render.sky_visibility.directions=8",
    "render.sky_visibility.spacing_m=0.04",
    "render.sky_visibility.rays=2",
    "render.sky_visibility.camera_views=200",
    "render.sky_visibility.camera_rays=256",
    "render.sky_visibility.lightmap_rays=8",
]

# A tiny but complete job (as tests/conftest.py TINY, 6 frames so faults land mid-render).
JOB = [
    "garden=small",
    "camera.width=96",
    "camera.height=72",
    "camera.fx=96",
    "camera.fy=96",
    "camera.cx=48",
    "camera.cy=36",
    "camera.trajectory.frames=[6,6]",
    "garden.lawn.triangles_per_m2=1500",
    "progress=false",
    *COARSE_BAKE,
]
HOOK = "EDEN_PIPE_FAULT_ENOSPC_AFTER_BYTES"


# ------------------------------------------------------------------ running jobs
@dataclass
class Run:
    rc: int
    stdout: str
    stderr: str
    seconds: float

    @property
    def lines(self) -> list[str]:
        return [line for line in self.stderr.splitlines() if line.strip()]

    @property
    def message(self) -> str:
        return self.lines[-1] if self.lines else ""


def job_env(code: Path = REPO, extra: dict | None = None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in (HOOK, "HYDRA_FULL_ERROR")}
    env["PYTHONPATH"] = os.pathsep.join([str(code), env.get("PYTHONPATH", "")])
    return {**env, **(extra or {})}


def run(
    args: list[str], cwd: Path, *, code: Path = REPO, env: dict | None = None, preexec=None, timeout: float = 900
) -> Run:
    start = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "eden_pipe", *args],
        cwd=cwd,
        env=job_env(code, env),
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=preexec,
    )
    return Run(proc.returncode, proc.stdout, proc.stderr, time.perf_counter() - start)


def start(args: list[str], cwd: Path, *, env: dict | None = None) -> tuple[subprocess.Popen, float]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "eden_pipe", *args],
        cwd=cwd,
        env=job_env(REPO, env),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return proc, time.perf_counter()


def finish(proc: subprocess.Popen, t0: float, timeout: float = 900) -> Run:
    out, err = proc.communicate(timeout=timeout)
    return Run(proc.returncode, out, err, time.perf_counter() - t0)


def frames_done(stages: Path) -> int:
    return len(list(stages.glob("render/*/frames/*.json")))


def wait_until(predicate: Callable[[], bool], proc: subprocess.Popen, timeout: float = 600) -> None:
    end = time.monotonic() + timeout
    while not predicate():
        if proc.poll() is not None:
            raise RuntimeError(f"the job ended (rc {proc.returncode}) before the fault could be injected")
        if time.monotonic() > end:
            raise TimeoutError("the job never reached the point of the fault")
        time.sleep(0.05)


def job_paths(folder: Path) -> list[str]:
    return [f"paths.stages={folder}/stages", f"paths.dataset={folder}/dataset"]


# ------------------------------------------------------------------ what is on disk
def fingerprint(root: Path) -> dict[str, str]:
    """A digest of every file under a dataset root (VOLATILE ones left out): of a PNG's or EXR's
    decoded array, of any other file's bytes (``dataset_fingerprint.content_digest``)."""
    return {
        str(p.relative_to(root)): content_digest(p)
        for p in sorted(Path(root).rglob("*"))
        if p.is_file() and p.name not in VOLATILE
    }


def differences(found: dict[str, str], reference: dict[str, str], most: int = 5) -> str:
    """The files of two fingerprints that differ or are missing from either, up to ``most`` named."""
    names = sorted(n for n in found.keys() | reference.keys() if found.get(n) != reference.get(n))
    return ", ".join(names[:most]) + (f" and {len(names) - most} more" if len(names) > most else "")


def count_files(folder: Path) -> int:
    return sum(1 for p in Path(folder).rglob("*") if p.is_file()) if Path(folder).exists() else 0


def temporaries(*folders: Path) -> list[str]:
    """Half-written files or folders left behind (atomic writers' temporaries, unfinished builds)."""
    found = []
    for folder in folders:
        if Path(folder).exists():
            found += [str(p) for p in Path(folder).rglob(".*") if ".tmp" in p.name]
    return found


def everything_under(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in Path(folder).rglob("*"))
