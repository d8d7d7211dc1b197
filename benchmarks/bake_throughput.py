"""The sky-visibility bake (stage ``sky_visibility``) on the default garden: its time, how much of it
the rays take, and its peak memory; with ``--against REV``, a git revision back to back.

Each measurement bakes in a process of its own (its peak RSS its own: scene, BVH and bake, as in the
stage), from the stage cache's scene under ``--root`` (built there first if missing). It reports the
bake's wall and CPU seconds, the seconds inside ``RayTracer.intersect``/``occluded`` (the rays, with
the tracer's own bookkeeping) and the rest, and the process's peak RSS; then each phase of the bake
(probes, bundles, camera gain, lightmaps, bounce rays and transfer, ground map) with its wall, CPU and
ray seconds and the RSS at its end (``VmRSS``; ``VmHWM``: the peak so far). ``--against REV`` checks REV
out in a worktree under the root and alternates the two sides ``--repeats`` times (the machine is
shared: take the best of each side), then compares every table of the two bakes bit for bit.

    python benchmarks/bake_throughput.py [--against 8c1128a] [--repeats 2] [overrides ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from revisions import REPO, machine_line, revision_tree, run_driver

# Run in a fresh process of the side's code (PYTHONPATH): bake once, print one RESULT line.
DRIVER = r"""
import json, resource, sys, time
from pathlib import Path
import numpy as np
from eden_pipe.config import make_cfg, to_config
from eden_pipe.pipeline import run_stages
from eden_pipe.rng import rng_for
from eden_pipe.scene.description import read_scene
from eden_pipe.stages.cache import StageCache
from eden_pipe.stages.scene import load_scene
from eden_pipe.stages.sky_visibility import bake_settings
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.visibility import bake as bake_module

def memory():
    fields = dict(line.split(":", 1) for line in open("/proc/self/status"))
    return {k: int(fields[k].split()[0]) / 1024 for k in ("VmRSS", "VmHWM")}

phases, rays = [], [0.0]
def timed_phase(name, fn):
    def run(*a, **k):
        wall, cpu, traced = time.perf_counter(), time.process_time(), rays[0]
        out = fn(*a, **k)
        phases.append({"phase": name, "wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
                       "rays": rays[0] - traced, **memory()})
        return out
    return run
for name in ("face_frames", "assign_probes", "sky_hits", "face_sky_table", "camera_gain", "bake_lightmaps",
             "bounce_rays", "bounce_transfer", "ground_map"):
    if not hasattr(bake_module, name):  # a revision from before the phase existed
        continue
    setattr(bake_module, name, timed_phase(name, getattr(bake_module, name)))

args = json.loads(sys.argv[1])
cfg = to_config(make_cfg(Path(args["root"]), args["base"]))
arts = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="scene")
_, arrays = load_scene(arts["scene"])
start = time.perf_counter()
tracer = RayTracer(arrays.mesh, int(cfg.render.threads))
bvh = time.perf_counter() - start
for name in ("intersect", "occluded"):
    def timed(*a, _query=getattr(tracer, name), **k):
        begin = time.perf_counter()
        out = _query(*a, **k)
        rays[0] += time.perf_counter() - begin
        return out
    setattr(tracer, name, timed)
wall, cpu = time.perf_counter(), time.process_time()
vis = bake_module.bake(arrays.mesh, tracer, rng_for(read_scene(arts["scene"]).seed, "sky_visibility"),
           **bake_settings(cfg.render, cfg.camera))
wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
tracer.close()
tables = {k: np.asarray(getattr(vis, k)) for k in ("face_probe", "exposure", "transfer", "normal", "bounce",
                                                   "sun_bounce", "tint", "ground_faces", "ground_grid", "face_sky")
          if hasattr(vis, k)}  # a revision from before the sun's own bounce has none
tables.update({f"lightmap_{k}": getattr(vis.lightmaps, k) for k in ("faces", "frame", "steps", "first", "visible")})
np.savez(args["tables"], **tables)
print("RESULT " + json.dumps({
    "wall": wall, "cpu": cpu, "rays": rays[0], "bvh": bvh, "faces": int(arrays.mesh.n_faces),
    "probes": int(vis.n_probes), "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    "phases": phases,
}))
"""


def report(label: str, result: dict) -> None:
    print(
        f"{label}: bake {result['wall']:.1f} s ({result['cpu']:.1f} s CPU), rays {result['rays']:.1f} s, "
        f"the rest {result['wall'] - result['rays']:.1f} s; BVH {result['bvh']:.1f} s; "
        f"peak RSS {result['peak_rss_mib']:.0f} MiB ({result['faces']:,} faces, {result['probes']:,} probes)"
    )
    for p in result.get("phases", []):  # absent from revisions before the breakdown
        print(
            f"    {p['phase']:<16} {p['wall']:6.1f} s ({p['cpu']:6.1f} s CPU, rays {p['rays']:6.1f} s), "
            f"RSS {p['VmRSS']:5.0f} MiB, peak so far {p['VmHWM']:5.0f} MiB"
        )


def differing_tables(a: Path, b: Path) -> list[str]:
    """The names of the tables whose bytes (dtype and shape included) differ between two bakes."""
    with np.load(a) as x, np.load(b) as y:
        names = sorted(set(x.files) | set(y.files))
        return [
            k
            for k in names
            if k not in x.files
            or k not in y.files
            or x[k].dtype != y[k].dtype
            or x[k].shape != y[k].shape
            or x[k].tobytes() != y[k].tobytes()
        ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--against", metavar="REV", help="also measure this git revision, alternating")
    parser.add_argument("--repeats", type=int, default=1, help="alternate the two measurements this many times")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="stage cache folder")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    print(machine_line())
    root = Path(args.root)
    base = ["progress=false", *args.overrides]
    sides = [("this tree", REPO)]
    if args.against:
        tree, full = revision_tree(args.against, root, "bake_throughput")
        sides.insert(0, (f"revision {args.against} ({full[:12]})", tree))
    best: dict[str, dict] = {}
    for _ in range(max(1, args.repeats)):
        for side, (label, code) in enumerate(sides):
            payload = {"root": str(root), "base": base, "tables": str(root / f"bake-tables-{side}.npz")}
            result = run_driver(DRIVER, code, payload, "bake_throughput")
            report(label, result)
            if label not in best or result["wall"] < best[label]["wall"]:
                best[label] = result
    if args.against:
        print("best of each:")
        for label, _ in sides:
            report(f"  {label}", best[label])
        before, after = (best[label] for label, _ in sides)
        print(
            f"bake speedup vs {args.against}: {before['wall'] / after['wall']:.2f}x wall, "
            f"{before['cpu'] / after['cpu']:.2f}x CPU; peak RSS {before['peak_rss_mib']:.0f} -> "
            f"{after['peak_rss_mib']:.0f} MiB"
        )
        differ = differing_tables(root / "bake-tables-0.npz", root / "bake-tables-1.npz")
        print("tables: bit-identical" if not differ else f"tables that differ: {', '.join(differ)}")


if __name__ == "__main__":
    main()
