"""What the benchmarks share: another revision's code in a worktree, a driver run in it, and a line
that says which machine the figures come from.

``render_throughput.py`` and ``bake_throughput.py`` time the working tree against a git revision,
each side in a process of its own running a small driver script (a string, so that it runs
inside the measured revision's tree). The driver prints its result as one ``RESULT {json}`` line.
"""

from __future__ import annotations

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def revision_tree(rev: str, root: Path, tool: str) -> tuple[Path, str]:
    """A detached worktree of ``rev`` under ``root`` (made once, reused): its path and full hash."""
    sha = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--verify", f"{rev}^{{commit}}"], capture_output=True, text=True
    )
    if sha.returncode:
        sys.exit(f"{tool}: --against {rev!r} is not a commit of this repository")
    full = sha.stdout.strip()
    tree = root / f"rev-{full[:12]}" / "code"
    if not (tree / ".git").exists():
        tree.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run(["git", "-C", str(REPO), "worktree", "add", "--detach", str(tree), full], check=True)
    return tree, full


def run_driver(driver: str, code_root: Path, payload: dict, tool: str, *, verbose: bool = False) -> dict:
    """``driver`` run with ``code_root``'s package first on the path and ``payload`` as its argument:
    the dict of its ``RESULT`` line (its other output echoed when ``verbose``)."""
    path = os.pathsep.join(filter(None, [str(code_root), os.environ.get("PYTHONPATH")]))
    proc = subprocess.run(
        [sys.executable, "-c", driver, json.dumps(payload)],
        cwd=code_root,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
    )
    if verbose:
        sys.stdout.write("".join(line + "\n" for line in proc.stdout.splitlines() if not line.startswith("RESULT ")))
    if proc.returncode:
        sys.exit(f"{tool}: the run in {code_root} failed:\n{proc.stderr[-4000:]}")
    line = next(line for line in proc.stdout.splitlines() if line.startswith("RESULT "))
    return json.loads(line[len("RESULT ") :])


def machine_line() -> str:
    """One line naming the machine's CPU, its cores, its widest vector ISA, the ray packets the native
    tracer traces there and the load average. The same code runs at different speeds, and traces
    8- or 16-ray packets (``embree_native.packet_lanes``), on an AVX2 and an AVX-512 CPU
    (docs/scale-out.md): figures from two machines are not comparable, only ratios from one run."""
    model, flags = platform.processor() or platform.machine(), set()
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            for line in cpuinfo:
                key, _, value = line.partition(":")
                if key.strip() == "model name" and value.strip():
                    model = value.strip()
                elif key.strip() == "flags":
                    flags = set(value.split())
                    break
    except OSError:
        pass
    isa = "AVX-512" if "avx512f" in flags else "AVX2" if "avx2" in flags else "no AVX2" if flags else "ISA unknown"
    packets = "native tracer packets unknown (older code)"  # a revision before the native tracer or its packet widths
    if str(REPO) not in sys.path:  # the working tree's package, as run_driver runs it, installed or not
        sys.path.insert(0, str(REPO))
    try:
        from eden_pipe.render import embree_native
    except ImportError:
        pass
    else:
        try:
            library = embree_native.load_library()
        except embree_native.NativeTracerError as exc:  # no native path on this machine
            packets = f"no native tracer ({exc})"
        else:
            device = library.lib.rtcNewDevice(library.ffi.NULL)
            lanes = getattr(embree_native, "packet_lanes", lambda lib, device: None)(library.lib, device)
            library.lib.rtcReleaseDevice(device)
            packets = f"native tracer packets of {lanes} rays" if lanes else packets
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else "unknown"
    return f"machine: {model}, {cores} cores, {isa}; {packets}; load average {load}"
