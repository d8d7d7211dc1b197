"""Where one camera pair's time goes: rays by caller, the shading arithmetic, the encoders.

Renders frames of the default garden (cached under the root, as
render_throughput.py) with one frame thread and one Embree thread, and times:
every ``RayTracer.intersect``/``occluded`` call by the function that made it
and the view (left: every modality; right: rgb and depth), each column's
encoder and write, and the rest of each view (numpy/numba arithmetic). A
cProfile of the same run names the arithmetic's largest functions.
Figures are per camera pair (milliseconds).

    python benchmarks/pair_profile.py [--frames 1] [overrides ...]
    PYTHONPATH=/path/to/REV-worktree python benchmarks/pair_profile.py --root ROOT   # another revision's code
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path[:0] = [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]  # another tree first

try:
    from eden_pipe.config import make_cfg
except ImportError:  # a revision from before make_cfg moved into the package (PYTHONPATH=its tree)
    from tests.conftest import make_cfg  # type: ignore[no-redef]
from eden_pipe.io import layout  # noqa: E402
from eden_pipe.modalities import COLUMNS  # noqa: E402
from eden_pipe.pipeline import run_job  # noqa: E402
from eden_pipe.render.backends.raytrace import RaytraceBackend  # noqa: E402

try:
    from eden_pipe.render.embree import RayTracer
except ImportError:  # a revision from before the tracer moved (ab818e1: render.raytrace)
    from eden_pipe.render.raytrace import RayTracer  # type: ignore[no-redef]

sys.path.append(str(Path(__file__).resolve().parent))
from revisions import machine_line  # noqa: E402

TIMES: defaultdict[str, float] = defaultdict(float)
COUNTS: defaultdict[str, int] = defaultdict(int)
STATE = threading.local()


def timed_tracer(method):
    def wrapper(self, origins, *args, **kwargs):
        caller = sys._getframe(1).f_code.co_name
        start = time.perf_counter()
        try:
            return method(self, origins, *args, **kwargs)
        finally:
            seconds = time.perf_counter() - start
            key = f"rays {method.__name__} from {caller} ({getattr(STATE, 'view', '?')})"
            TIMES[key] += seconds
            COUNTS[key] += len(origins)
            STATE.rays = getattr(STATE, "rays", 0.0) + seconds

    return wrapper


def timed_view(method):
    def wrapper(self, state, intr, pose, *, want, **kwargs):
        STATE.view = "left" if "semantic" in want else "right"
        STATE.rays = 0.0
        start = time.perf_counter()
        out = method(self, state, intr, pose, want=want, **kwargs)
        TIMES[f"arithmetic ({STATE.view})"] += time.perf_counter() - start - STATE.rays
        return out

    return wrapper


def timed_write(folder, files, data, options):
    for column, rel in files.items():
        start = time.perf_counter()
        COLUMNS[column].write(Path(folder) / rel, data[column], options)
        TIMES[f"write {column}"] += time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=1, help="frames to render (each = 5 camera pairs)")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="cache and dataset folder")
    parser.add_argument("--top", type=int, default=15, help="cProfile rows to print")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    print(machine_line())
    root = Path(args.root)
    steps = max(args.frames + 1, 2)
    base = [
        "progress=false",
        f"camera.trajectory.frames=[{steps},{steps}]",
        f"render.max_frames={args.frames}",
        "render.workers=1",
        "render.threads=1",
        *args.overrides,
    ]
    run_job(make_cfg(root, base), echo=lambda *_: None)  # geometry and bake, untimed
    RayTracer.intersect = timed_tracer(RayTracer.intersect)  # type: ignore[method-assign]
    RayTracer.occluded = timed_tracer(RayTracer.occluded)  # type: ignore[method-assign]
    RaytraceBackend.render_view = timed_view(RaytraceBackend.render_view)  # type: ignore[method-assign]
    layout.write_files = timed_write
    profile = cProfile.Profile()
    profile.enable()
    result = run_job(make_cfg(root, [*base, "force=[render]"]), echo=lambda *_: None)
    profile.disable()
    marker = result.artifacts["render"].marker()
    pairs = 5 * marker["frames"]
    per_pair = marker["seconds_per_frame"] / 5
    print(f"{pairs} pairs, {per_pair * 1000:.0f} ms per pair (setup {marker['setup_seconds']:.1f} s apart)")
    print("| part | ms per pair | rays per pair |")
    print("|---|---|---|")
    for key in sorted(TIMES, key=lambda k: -TIMES[k]):
        rays = f"{COUNTS[key] / pairs:,.0f}" if key in COUNTS else ""
        print(f"| {key} | {TIMES[key] / pairs * 1000:.0f} | {rays} |")
    accounted = sum(TIMES.values()) / pairs
    print(f"| rest (frame setup, derived passes, markers) | {(per_pair - accounted) * 1000:.0f} | |")
    print(f"\ncProfile, top {args.top} by own time (profiler overhead included):")
    stats = pstats.Stats(profile)
    stats.sort_stats("tottime").print_stats(args.top)


if __name__ == "__main__":
    main()
