"""Every bad input and fault, run for real as subprocesses; writes docs/reliability.md.

    python scripts/reliability_table.py                  # all of it (about 15 minutes on 2 cores)
    python scripts/reliability_table.py --only bad       # the bad inputs (about 4 minutes)
    python scripts/reliability_table.py --only faults    # the faults
    python scripts/reliability_table.py --out docs/reliability.md

A bad input must stop before any work: exit 2, one line on stderr, no file or folder
written (the job runs in an empty folder; the dataset root and stage cache are the
defaults under it). A fault is injected into a real job of the small garden at 96x72
with 6 frames (:data:`JOB`); the table records what the program did, the time to failure,
the files left (dataset root, stage cache, temporaries) and whether a rerun completed
with files identical to an uninterrupted run (every file under the dataset root hashed,
as ``scripts/dataset_fingerprint.py`` does).

``tests/test_bad_inputs.py`` runs a sample of :data:`BAD_INPUTS`; ``tests/test_faults.py``
runs the faults through the same helpers.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
from dataset_fingerprint import VOLATILE  # noqa: E402  (files that record time or host)
from reliability_inputs import BAD_INPUTS, POOL_ARG, BadInput  # noqa: E402  (the rows; BAD_INPUTS re-exported)

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
    """sha256 of every file under a dataset root (VOLATILE ones left out)."""
    return {
        str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(Path(root).rglob("*"))
        if p.is_file() and p.name not in VOLATILE
    }


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


# ------------------------------------------------------------------ bad inputs (rows: reliability_inputs.py)
class Inputs:
    """Where a case's input files go (never inside the job's folder), and the code the job runs:
    preset cases run a copy of the package whose conf/species holds the user's preset."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.folder.mkdir(parents=True, exist_ok=True)
        self._copy: Path | None = None

    def package_copy(self) -> Path:
        if self._copy is None:
            self._copy = self.folder / "code"
            shutil.copytree(REPO / "eden_pipe", self._copy / "eden_pipe", ignore=shutil.ignore_patterns("__pycache__"))
            shutil.copytree(REPO / "conf", self._copy / "conf")
        return self._copy


def prepare(case: BadInput, inputs: Inputs) -> tuple[list[str], Path]:
    """The case's full argument list and the code root it runs."""
    args = list(case.args)
    code = REPO
    if case.setup:
        args += case.setup(inputs)
    if case.preset:
        kind, shipped, edit = case.preset
        code = inputs.package_copy()
        folder = code / "conf" / "species" / kind
        preset = yaml.safe_load((folder / f"{shipped}.yaml").read_text())
        edit(preset)
        (folder / "user_preset.yaml").write_text(yaml.safe_dump(preset, sort_keys=False))
        # only the user's preset in its pool, so that pool certainly draws it
        args += [f"{POOL_ARG[kind]}=[user_preset]"] + (
            [] if kind == "grass" else [f"{POOL_ARG[kind].rsplit('.', 1)[0]}.count=[1,1]"]
        )
    return args, code


@dataclass
class BadResult:
    case: BadInput
    run: Run
    written: list[str]

    @property
    def stopped_cleanly(self) -> bool:
        missing = [w for w in self.case.words if w not in self.run.message]
        return (
            self.run.rc == 2
            and len(self.run.lines) == 1
            and self.run.message.startswith("eden-pipe: ")
            and not missing
            and not self.written
        )


def run_bad_input(case: BadInput, workdir: Path, inputs: Inputs) -> BadResult:
    """Run one bad input in the empty folder ``workdir`` (default paths: everything would land there)."""
    workdir.mkdir(parents=True, exist_ok=True)
    args, code = prepare(case, inputs)
    flags = [a for a in args if a.startswith("--")]  # Hydra's options go before the overrides
    result = run([*flags, *JOB, *[a for a in args if a not in flags]], workdir, code=code)
    written = everything_under(workdir)
    if case.preset:  # leave the copy's species folder as it was for the next case
        (code / "conf" / "species" / case.preset[0] / "user_preset.yaml").unlink()
    return BadResult(case, result, written)


# ------------------------------------------------------------------ faults
@dataclass
class FaultResult:
    name: str
    injected: str
    run: Run
    files_left: str
    clean: bool  # no temporaries, no half file under a final name
    rerun: Run | None = None
    identical: bool | None = None
    note: str = ""


class Faults:
    """Each method injects one fault into a fresh job folder and reruns it; ``reference`` is the
    fingerprint of an uninterrupted run of the same job."""

    def __init__(self, base: Path):
        self.base = base
        self._reference: dict | None = None
        self._primed: Path | None = None

    def folder(self, name: str) -> Path:
        path = self.base / name
        shutil.rmtree(path, ignore_errors=True)
        path.mkdir(parents=True)
        return path

    @property
    def reference(self) -> dict:
        if self._reference is None:
            folder = self.folder("reference")
            done = run([*JOB, *job_paths(folder)], folder)
            assert done.rc == 0, done.stderr[-2000:]
            self._reference = fingerprint(folder / "dataset")
        return self._reference

    def primed(self, name: str) -> Path:
        """A folder whose stage cache already holds the job's model, scene and trajectory (copied)."""
        if self._primed is None:
            self._primed = self.folder("primed")
            done = run([*JOB, *job_paths(self._primed), "render.max_frames=1", "render.modalities=[rgb]"], self._primed)
            assert done.rc == 0, done.stderr[-2000:]
            shutil.rmtree(self._primed / "dataset")
            for rendered in (self._primed / "stages").glob("*"):
                if rendered.name in ("render", "manifest"):
                    shutil.rmtree(rendered)
        folder = self.folder(name)
        shutil.copytree(self._primed / "stages", folder / "stages")
        return folder

    def _finish(
        self,
        name: str,
        injected: str,
        folder: Path,
        failed: Run,
        *,
        env_fix: dict | None = None,
        fix: Callable[[], None] | None = None,
        note: str = "",
    ) -> FaultResult:
        stages, dataset = folder / "stages", folder / "dataset"
        left = temporaries(stages, dataset)
        files = f"dataset {count_files(dataset)}, stages {count_files(stages)}, temporaries {len(left)}"
        if fix:
            fix()
        rerun = run([*JOB, *job_paths(folder)], folder, env=env_fix)
        identical = rerun.rc == 0 and fingerprint(dataset) == self.reference
        return FaultResult(name, injected, failed, files, not left, rerun, identical, note)

    # ---- disk full and file-size limits
    def disk_full_hook(self) -> FaultResult:
        folder = self.primed("disk_full_hook")
        failed = run([*JOB, *job_paths(folder)], folder, env={HOOK: "800000"})
        return self._finish(
            "disk full mid-render (ENOSPC)",
            f"{HOOK}=800000: writes fail past 800 kB",
            folder,
            failed,
            note=f"{frames_done(folder / 'stages')} of 6 frames finished before the disk filled",
        )

    def file_size_limit(self) -> FaultResult:
        folder = self.folder("file_size_limit")

        def limit() -> None:
            signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # EFBIG instead of a kill
            resource.setrlimit(resource.RLIMIT_FSIZE, (2**20, 2**20))

        failed = run([*JOB, *job_paths(folder)], folder, preexec=limit)
        return self._finish(
            "file larger than allowed (EFBIG)", "ulimit -f 1 MB (RLIMIT_FSIZE): the scene file fails", folder, failed
        )

    def tmpfs_full(self) -> FaultResult | None:
        """A real full filesystem: a tmpfs just larger than the primed cache (needs root and mount)."""
        folder = self.primed("tmpfs_full")
        mount = folder / "disk"
        mount.mkdir()
        used = sum(p.stat().st_size for p in (folder / "stages").rglob("*") if p.is_file())
        size = used + 1_500_000
        if (
            subprocess.run(
                ["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(mount)], capture_output=True
            ).returncode
            != 0
        ):
            return None
        try:
            shutil.move(str(folder / "stages"), str(mount / "stages"))
            paths = [f"paths.stages={mount}/stages", f"paths.dataset={mount}/dataset"]
            refused = run([*JOB, *paths], folder)
            failed = run([*JOB, *paths, "paths.check_free_space=false"], folder)
            left = temporaries(mount)
            files = (
                f"dataset {count_files(mount / 'dataset')}, stages {count_files(mount / 'stages')}, "
                f"temporaries {len(left)}"
            )
            subprocess.run(["mount", "-o", "remount,size=512m", str(mount)], check=True)
            rerun = run([*JOB, *paths], folder)
            identical = rerun.rc == 0 and fingerprint(mount / "dataset") == self.reference
            note = (
                f"without paths.check_free_space=false the job was refused before any work: rc {refused.rc}, "
                f"`{refused.message}`; {frames_done(mount / 'stages')} frames done before ENOSPC"
            )
            return FaultResult(
                "filesystem full mid-render (tmpfs)",
                f"a {size / 1e6:.1f} MB tmpfs, stage cache on it",
                failed,
                files,
                not left,
                rerun,
                identical,
                note,
            )
        finally:
            subprocess.run(["umount", "-l", str(mount)], capture_output=True)

    # ---- signals
    def signal_mid_render(self, sig: int) -> FaultResult:
        name = signal.Signals(sig).name
        folder = self.primed(f"signal_{name}")
        proc, t0 = start([*JOB, *job_paths(folder)], folder)
        wait_until(lambda: frames_done(folder / "stages") >= 2, proc)
        proc.send_signal(sig)
        failed = finish(proc, t0)
        return self._finish(f"{name} mid-render", f"{name} after 2 of 6 frames", folder, failed)

    def signal_mid_scene(self) -> FaultResult:
        folder = self.folder("sigterm_scene")
        proc, t0 = start([*JOB, *job_paths(folder)], folder)
        wait_until(lambda: any((folder / "stages" / "scene").glob(".tmp-*")), proc)
        proc.send_signal(signal.SIGTERM)
        failed = finish(proc, t0)
        return self._finish("SIGTERM while the scene is built", "SIGTERM during the scene stage", folder, failed)

    # ---- a damaged stage cache
    def damaged_cache(self, what: str) -> FaultResult:
        folder = self.folder(f"damaged_{what}")
        first = run([*JOB, *job_paths(folder)], folder)
        assert first.rc == 0, first.stderr[-2000:]
        stages = folder / "stages"
        if what == "truncated_npz":
            target = next(stages.glob("scene/*/geometry.npz"))
            target.write_bytes(target.read_bytes()[: target.stat().st_size // 2])
            injected = "scene geometry.npz cut to half its size"
        elif what == "missing_frame_file":
            target = next(stages.glob("render/*/cam0/rgb_left/00001.png"))
            target.unlink()
            injected = "one rendered PNG deleted under a completed render"
        elif what == "truncated_poses":
            target = next(stages.glob("trajectory/*/poses.npy"))
            target.write_bytes(target.read_bytes()[:100])
            injected = "trajectory poses.npy cut to 100 bytes"
        else:  # garbage marker
            target = next(stages.glob("model/garden-*/DONE.json"))
            target.write_text("{not json")
            injected = "the garden model's DONE.json overwritten with garbage"
        rerun = run([*JOB, *job_paths(folder)], folder)
        identical = rerun.rc == 0 and fingerprint(folder / "dataset") == self.reference
        rebuilt = [line for line in rerun.stdout.splitlines() if "damaged" in line]
        return FaultResult(
            f"damaged cache: {what.replace('_', ' ')}",
            injected,
            rerun,
            f"dataset {count_files(folder / 'dataset')}",
            not temporaries(stages),
            None,
            identical,
            "; ".join(rebuilt) or "not detected",
        )

    # ---- the dataset folder
    def dataset_removed(self) -> FaultResult:
        folder = self.primed("dataset_removed")
        (folder / "dataset").mkdir()
        (folder / "dataset" / "old.txt").write_text("an older file\n")
        proc, t0 = start([*JOB, *job_paths(folder)], folder)
        wait_until(lambda: frames_done(folder / "stages") >= 2, proc)
        shutil.rmtree(folder / "dataset")
        done = finish(proc, t0)
        identical = done.rc == 0 and fingerprint(folder / "dataset") == self.reference
        return FaultResult(
            "dataset folder removed mid-job",
            "rm -r of the dataset root after 2 of 6 frames",
            done,
            f"dataset {count_files(folder / 'dataset')}",
            not temporaries(folder),
            None,
            identical,
            "publishing recreates the root: the job completes",
        )

    def dataset_read_only(self) -> FaultResult | None:
        folder = self.primed("dataset_read_only")
        dataset = folder / "dataset"
        dataset.mkdir()
        proc, t0 = start([*JOB, *job_paths(folder)], folder)
        wait_until(lambda: frames_done(folder / "stages") >= 2, proc)
        how = make_read_only(dataset)
        if how is None:
            proc.kill()
            proc.wait()
            return None
        failed = finish(proc, t0)
        return self._finish(
            "dataset folder made read-only mid-job",
            f"{how} after 2 of 6 frames",
            folder,
            failed,
            fix=lambda: undo_read_only(dataset, how),
        )

    def dataset_replaced_by_file(self) -> FaultResult:
        folder = self.primed("dataset_file")
        proc, t0 = start([*JOB, *job_paths(folder)], folder)
        wait_until(lambda: frames_done(folder / "stages") >= 2, proc)
        (folder / "dataset").write_text("a file where the dataset folder goes\n")
        failed = finish(proc, t0)
        return self._finish(
            "dataset root replaced by a file mid-job",
            "a file written at the dataset path",
            folder,
            failed,
            fix=lambda: (folder / "dataset").unlink(),
        )

    # ---- two gardens at once
    def concurrent_gardens(self) -> FaultResult:
        folder = self.folder("concurrent")
        seq = self.folder("concurrent_reference")
        for seed in (0, 1):
            done = run([*JOB, *job_paths(seq), f"garden.seed={seed}"], seq)
            assert done.rc == 0, done.stderr[-2000:]
        procs = [
            start(
                [
                    *JOB,
                    f"paths.stages={folder}/stages-{seed}",
                    f"paths.dataset={folder}/dataset",
                    f"garden.seed={seed}",
                ],
                folder,
            )
            for seed in (0, 1)
        ]
        runs = [finish(p, t0) for p, t0 in procs]
        import pandas as pd

        rows = (
            len(pd.read_csv(folder / "dataset" / "manifest.csv"))
            if (folder / "dataset" / "manifest.csv").is_file()
            else 0
        )
        identical = all(r.rc == 0 for r in runs) and fingerprint(folder / "dataset") == fingerprint(seq / "dataset")
        merged = Run(max(r.rc for r in runs), "", "\n".join(r.stderr for r in runs), max(r.seconds for r in runs))
        return FaultResult(
            "two gardens sweeping into one root at once",
            "seeds 0 and 1 as two processes",
            merged,
            f"root manifest {rows} rows (2 x 6 frames x 5 pairs = 60)",
            not temporaries(folder),
            None,
            identical,
            "compared with the two jobs run one after the other",
        )

    def sigkill(self) -> FaultResult:
        folder = self.primed("sigkill")
        proc, t0 = start([*JOB, *job_paths(folder)], folder)
        wait_until(lambda: frames_done(folder / "stages") >= 2, proc)
        proc.kill()
        failed = finish(proc, t0)
        return self._finish(
            "SIGKILL mid-render",
            "SIGKILL after 2 of 6 frames (no handler can run)",
            folder,
            failed,
            note="temporaries of the frames in flight may stay (hidden, never published)",
        )

    def all(self) -> list[FaultResult]:
        steps = [
            self.disk_full_hook,
            self.file_size_limit,
            self.tmpfs_full,
            lambda: self.signal_mid_render(signal.SIGTERM),
            lambda: self.signal_mid_render(signal.SIGINT),
            self.signal_mid_scene,
            self.sigkill,
            lambda: self.damaged_cache("truncated_npz"),
            lambda: self.damaged_cache("missing_frame_file"),
            lambda: self.damaged_cache("truncated_poses"),
            lambda: self.damaged_cache("garbage_marker"),
            self.dataset_removed,
            self.dataset_read_only,
            self.dataset_replaced_by_file,
            self.concurrent_gardens,
        ]
        results = []
        for step in steps:
            result = step()
            if result is not None:
                results.append(result)
                print(
                    f"fault: {result.name}: rc {result.run.rc}, identical after rerun: {result.identical}",
                    file=sys.stderr,
                )
        return results


def make_read_only(folder: Path) -> str | None:
    """Make ``folder`` read-only for this user: chmod when not root, else a read-only bind mount."""
    if os.geteuid() != 0:
        folder.chmod(0o555)
        return "chmod 555"
    ok = subprocess.run(["mount", "--bind", str(folder), str(folder)], capture_output=True).returncode == 0
    ok = ok and subprocess.run(["mount", "-o", "remount,ro,bind", str(folder)], capture_output=True).returncode == 0
    return "a read-only bind mount" if ok else None


def undo_read_only(folder: Path, how: str) -> None:
    if how.startswith("chmod"):
        folder.chmod(0o755)
    else:
        subprocess.run(["umount", str(folder)], check=True)


# ------------------------------------------------------------------ the table
def _cell(text: str, limit: int = 220) -> str:
    text = " ".join(str(text).split()).replace("|", "\\|")
    return text if len(text) <= limit else text[: limit - 3] + "..."


def markdown(bad: list[BadResult], faults: list[FaultResult]) -> str:
    out = [
        "# Reliability: bad inputs and faults",
        "",
        "Generated by `python scripts/reliability_table.py`: every row ran for real as a subprocess,",
        f"on the small garden at 96x72 with 6 frames (`{' '.join(JOB)}`).",
        "",
        "## What the program does",
        "",
        (
            "- **Before any stage** (`eden_pipe/preflight.py: check_job`, from the Hydra callback before Hydra makes a "
            "folder, and again in `run_job`): unknown keys (allowed keys derived from the config dataclasses, "
            "did-you-mean by `difflib`), every value against its key's domain (`config.validate`: declared once per "
            "key beside its default in `eden_pipe/config/schema.py`), `paths.stages` and `paths.dataset` writable "
            "(a temporary file in the folder or its nearest existing parent), the species/asset presets the garden "
            "will draw (keys, value forms, their loaders), and free disk space: bytes per row from the modality "
            "table (`FileFormat.pixel_bytes` x width x height, in the storage mode) x camera pairs x frames still "
            "to render (found in the stage cache with a lookup-only `StageCache`), plus the garden's meshes when "
            "not cached. `paths.check_free_space=false` skips the space check. Hydra's own composition errors "
            "(`cli_errors.py`) give the same one line. A key set in a user's garden file names that file."
        ),
        (
            "- **Exit status**: 0 done; 2 bad input, nothing written; 74 an I/O failure mid-job (disk full, "
            "read-only, a folder removed or replaced); 130 SIGINT; 143 SIGTERM; 1 a bug (traceback)."
        ),
        (
            "- **Mid-job**: every file goes through `io.atomic` (temporary name, then rename), frames have markers, "
            "whole artifacts are built in a temporary folder, so a failure or signal leaves no half file under a "
            "final name; queued frames are dropped on the first failure or signal, running ones finish. Library "
            "errors that hide the filesystem's errno (OpenEXR's RuntimeError, numpy's short write) become the "
            "OSError they are."
        ),
        (
            "- **Damaged cache**: each `DONE.json` records its artifact's file count, bytes and a digest of (path, "
            "size); reuse re-lists the folder (one `stat` per file, no reads) and rebuilds a damaged artifact "
            "(a render artifact is re-rendered whole). Bit flips that keep sizes are not detected (that would read "
            "every byte on every reuse)."
        ),
        (
            f"- **Fault hook**: `{HOOK}=N` (tests only, off by default) makes writes through `io.atomic` fail "
            "with ENOSPC once the process has written N bytes."
        ),
        "",
    ]
    if bad:
        stopped = sum(r.stopped_cleanly for r in bad)
        out += [
            "## Bad inputs",
            "",
            (
                f"**{stopped} of {len(bad)} stopped before any work with exit 2, one line on stderr and no file or "
                f"folder written.** Time to failure is the whole command (Python and Hydra start-up included)."
            ),
            "",
            "| # | kind | input | exit | message (stderr, one line) | time (s) | files written |",
            "|---|---|---|---|---|---|---|",
        ]
        for i, r in enumerate(bad, 1):
            shown = " ".join(r.case.args) or r.case.label
            if r.case.preset:
                shown = f"conf/species/{r.case.preset[0]}/user_preset.yaml: {r.case.label}"
            elif r.case.setup:
                shown = f"{r.case.label} ({' '.join(r.case.args) or 'file written by the case'})"
            lines = "" if len(r.run.lines) == 1 else f" ({len(r.run.lines)} lines)"
            out.append(
                f"| {i} | {r.case.kind} | `{_cell(shown, 90)}` | {r.run.rc} | {_cell(r.run.message)}{lines} | "
                f"{r.run.seconds:.1f} | {len(r.written) or 'none'} |"
            )
        out.append("")
    if faults:
        same = sum(bool(f.identical) for f in faults)
        out += [
            "## Faults",
            "",
            (
                f"**{len(faults)} faults; after each, a rerun completed with a dataset identical to an uninterrupted "
                f"run in {same} of {len(faults)}** (sha256 of every file under the dataset root but dataset.json)."
            ),
            "Exit status: 74 an I/O failure, 130 SIGINT, 143 SIGTERM, -9 killed (SIGKILL cannot be handled).",
            "",
            (
                "| fault | injected | exit | message | time to failure (s) | files left | no temporaries | "
                "rerun exit | rerun identical | note |"
            ),
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for f in faults:
            rerun_rc = f.rerun.rc if f.rerun else "(the run above)"
            out.append(
                f"| {f.name} | {_cell(f.injected, 90)} | {f.run.rc} | {_cell(f.run.message)} | {f.run.seconds:.1f} "
                f"| {f.files_left} | {'yes' if f.clean else 'NO'} | {rerun_rc} | "
                f"{'yes' if f.identical else 'NO'} | {_cell(f.note, 160)} |"
            )
        out.append("")
    return "\n".join(out)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--only", choices=["bad", "faults"])
    ap.add_argument("--out", type=Path, default=REPO / "docs" / "reliability.md")
    args = ap.parse_args(argv)
    bad: list[BadResult] = []
    faults: list[FaultResult] = []
    with tempfile.TemporaryDirectory(prefix="eden-reliability-") as tmp:
        tmp = Path(tmp)
        if args.only in (None, "bad"):
            inputs = Inputs(tmp / "inputs")
            for i, case in enumerate(BAD_INPUTS):
                result = run_bad_input(case, tmp / f"bad{i:02d}", inputs)
                bad.append(result)
                print(
                    f"bad {i:2d} {'ok ' if result.stopped_cleanly else 'BAD'} rc={result.run.rc} "
                    f"{result.run.seconds:4.1f}s {result.run.message[:150]}",
                    file=sys.stderr,
                )
        if args.only in (None, "faults"):
            faults = Faults(tmp / "faults").all()
    args.out.write_text(markdown(bad, faults))
    print(f"wrote {args.out}", file=sys.stderr)
    return 0 if all(r.stopped_cleanly for r in bad) and all(f.identical for f in faults) else 1


if __name__ == "__main__":
    sys.exit(main())
