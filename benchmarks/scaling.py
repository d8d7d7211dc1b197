"""Camera pairs per second on one machine against frame threads per job and jobs at once.

For each (jobs J, frame threads T) in the grid, J render jobs of one garden run
concurrently, each with ``render.workers=T`` and ``render.threads=T`` (one
Embree thread per frame thread). Each job follows a trajectory of its own (its
step count differs by one from the next job's, so the jobs' render stages have
distinct cache keys and do not wait on each other's lock); the garden's model,
scene and bake are built once beforehand and shared. Per cell it prints the
summed steady rate (each job's frames / its frame time: setup excluded) and the
wall-clock rate over the whole batch (setup included).

    python benchmarks/scaling.py --jobs 1,2 --threads 1,2 --frames 4 [overrides ...]

The table in docs/scale-out.md comes from this script.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))

from render_throughput import DRIVER  # noqa: E402  (one job in a process of its own)
from revisions import machine_line  # noqa: E402


def start_job(root: Path, overrides: list[str]) -> subprocess.Popen:
    """One job whose render stage is forced (what it needs upstream is built first, untimed)."""
    payload = json.dumps({"root": str(root), "base": overrides, "verbose": False, "warm": False})
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    return subprocess.Popen(
        [sys.executable, "-c", DRIVER, payload],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def finish(proc: subprocess.Popen) -> dict:
    out, err = proc.communicate()
    if proc.returncode:
        sys.exit(f"scaling: a job failed:\n{err[-4000:]}")
    line = next(line for line in out.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def job_overrides(base: list[str], frames: int, job: int, threads: int, render_frames: int | None = None) -> list[str]:
    steps = frames + 1 + job
    return [
        *base,
        f"camera.trajectory.frames=[{steps},{steps}]",
        f"render.max_frames={frames if render_frames is None else render_frames}",
        f"render.workers={threads}",
        f"render.threads={threads}",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", default="1,2", help="comma-separated numbers of concurrent jobs")
    parser.add_argument("--threads", default="1,2", help="comma-separated frame threads per job")
    parser.add_argument("--cells", help="JxT pairs instead of the grid, e.g. 1x16,2x8,4x4,16x1")
    parser.add_argument("--frames", type=int, default=4, help="frames per job (5 pairs each)")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="cache and dataset folder")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    print(machine_line())
    try:
        if args.cells:
            cells = [tuple(int(n) for n in cell.split("x", 1)) for cell in args.cells.split(",")]
        else:
            cells = [(int(j), int(t)) for j in args.jobs.split(",") for t in args.threads.split(",")]
    except ValueError:
        parser.error(
            f"--jobs/--threads take integers and --cells JxT pairs (got {args.jobs}, {args.threads}, {args.cells})"
        )
    if min([n for cell in cells for n in cell] + [args.frames]) < 1 or any(len(cell) != 2 for cell in cells):
        parser.error("--jobs, --threads, --cells and --frames take positive integers")
    root = Path(args.root)
    base = ["progress=false", *args.overrides]
    # The garden's geometry and bake once, untimed (each job's trajectory is built in its own run,
    # before its render stage: seconds, outside the frame times).
    finish(start_job(root, job_overrides(base, args.frames, 0, os.cpu_count() or 1, render_frames=1)))
    print(f"{args.frames} frames (x 5 pairs) per job")
    print(
        "| jobs | frame threads per job | cores asked | pairs/s (steady, summed) | pairs/s (wall, with setup) "
        "| s per frame per job | peak RSS per job (MiB) |"
    )
    print("|---|---|---|---|---|---|---|")
    for n_jobs, n_threads in cells:
        procs = [start_job(root, job_overrides(base, args.frames, j, n_threads)) for j in range(n_jobs)]
        results = [finish(p) for p in procs]
        steady = sum(5.0 / r["seconds_per_frame"] for r in results)
        # The render stages overlap; the longest one (its setup included) bounds the batch.
        forced = max(r["render_s"] for r in results)
        per_frame = sum(r["seconds_per_frame"] for r in results) / n_jobs
        rss = max(r["peak_rss_mib"] for r in results)
        print(
            f"| {n_jobs} | {n_threads} | {n_jobs * n_threads} | {steady:.2f} | "
            f"{n_jobs * args.frames * 5 / forced:.2f} | {per_frame:.2f} | {rss:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
