"""The faults of ``scripts/reliability_table.py``: each injected into a real job, then rerun.

:class:`Faults` holds one method per fault (disk full through the hook, a file-size limit, a full
tmpfs, signals mid-render and mid-scene, SIGKILL, damaged stage-cache artifacts, the dataset folder
removed, read-only or replaced by a file, concurrent gardens); each returns a :class:`FaultResult`
whose rerun is compared with an uninterrupted run of the same job. :func:`make_read_only` and
:func:`undo_read_only` make a folder read-only for the current user and back.
``tests/test_faults.py`` runs the faults through the same helpers.
"""

from __future__ import annotations

import os
import resource
import shutil
import signal
import subprocess
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from reliability_jobs import (
    HOOK,
    JOB,
    Run,
    count_files,
    differences,
    fingerprint,
    finish,
    frames_done,
    job_paths,
    run,
    start,
    temporaries,
    wait_until,
)


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
        found = fingerprint(dataset)
        identical = rerun.rc == 0 and found == self.reference
        if rerun.rc == 0 and not identical:
            note = "; ".join(filter(None, [note, f"differs from the reference: {differences(found, self.reference)}"]))
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
