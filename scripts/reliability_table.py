"""Every bad input and fault, run for real as subprocesses; writes docs/reliability.md.

    python scripts/reliability_table.py                  # all of it (about 5 minutes on 2 cores)
    python scripts/reliability_table.py --only bad       # the bad inputs (about 2 minutes)
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
import shutil
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

import yaml

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "scripts"))
# The rows, the job helpers and the faults, re-exported for tests/test_bad_inputs.py and tests/test_faults.py.
from reliability_faults import FaultResult, Faults, make_read_only, undo_read_only  # noqa: E402, F401
from reliability_inputs import BAD_INPUTS, POOL_ARG, BadInput  # noqa: E402
from reliability_jobs import (  # noqa: E402, F401
    HOOK,
    JOB,
    Run,
    count_files,
    differences,
    everything_under,
    fingerprint,
    finish,
    frames_done,
    job_env,
    job_paths,
    run,
    start,
    temporaries,
    wait_until,
)


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
                f"run in {same} of {len(faults)}** (every file under the dataset root but dataset.json: "
                "sha256 of its bytes, of a PNG's or EXR's decoded array)."
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
