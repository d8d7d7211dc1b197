"""Camera pairs per second for the full modality stack on the default garden.

One pair = one camera pair at one frame: the left camera with every modality
(rgb, semantic, instance, depth, normal, forward and backward flow with
occlusion, albedo, shading, translucency) plus the right camera's rgb and
depth, all written to disk. Geometry stages are built once (cached under the
root's stages/) and then only the render stage is timed, forced. The render
stage's one-off setup (scene load, BVH build) is reported apart from the
per-frame rate, and both are combined for a 100-frame job (the default).

Each measurement runs in a process of its own (so its peak RSS is its own).
``--against REV`` also measures git revision REV, checked out in a worktree
under the root, with a stage cache of its own (stage keys hold the code), back
to back with the working tree; ``--repeats N`` alternates the two N times and
keeps each side's best. The last line is then

    speedup vs REV: X (A pairs/s vs B pairs/s)

with A the working tree's rate and B the revision's. TinyRenderer renders the
first frame(s) of the same trajectory for a ratio against pybullet's renderer.

    python benchmarks/render_throughput.py [--frames 2] [--against ab818e1] [overrides ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from revisions import REPO, machine_line, revision_tree, run_driver

# Runs inside the measured revision's own tree: only APIs every revision since the bake has
# (``run_job``, ``make_cfg``, the render marker's ``seconds_per_frame`` and ``setup_seconds``).
DRIVER = r"""
import json, resource, sys, time
from pathlib import Path
try:
    from eden_pipe.config import make_cfg
except ImportError:  # older revisions kept it in the tests
    from tests.conftest import make_cfg
from eden_pipe.pipeline import run_job

args = json.loads(sys.argv[1])
root, base = Path(args["root"]), args["base"]
echo = print if args["verbose"] else (lambda *_: None)
start = time.perf_counter()
if args.get("warm", True):  # build what is missing, so the forced run below times the render alone
    run_job(make_cfg(root, base), echo=echo)
first = time.perf_counter() - start
result = run_job(make_cfg(root, base + ["force=[render]"]), echo=echo)
marker = result.artifacts["render"].marker()
out = {
    "first_run_s": first,
    "render_s": result.artifacts["render"].seconds,
    "seconds_per_frame": marker["seconds_per_frame"],
    "setup_seconds": marker["setup_seconds"],
    "frames": marker["frames"],
    "workers": marker.get("workers", 1),
    "faces": result.artifacts["scene"].marker()["faces"],
    "peak_rss_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}
print("RESULT " + json.dumps(out))
"""


def measure(code_root: Path, data_root: Path, base: list[str], verbose: bool) -> dict:
    """One job (geometry if missing, then the render stage forced) in a fresh process of ``code_root``'s code."""
    payload = {"root": str(data_root), "base": base, "verbose": verbose}
    return run_driver(DRIVER, code_root, payload, "render_throughput", verbose=verbose)


def pairs_per_second(result: dict) -> float:
    return 5.0 / result["seconds_per_frame"]  # five camera pairs per frame


def report(label: str, result: dict) -> None:
    per_frame = result["seconds_per_frame"]
    print(
        f"{label}: {pairs_per_second(result):.3f} pairs/s ({per_frame:.2f} s per frame of 5 pairs, "
        f"{result['workers']} frame threads); setup (scene load + BVH build) {result['setup_seconds']:.2f} s; "
        f"a 100-frame job {500 / (result['setup_seconds'] + 100 * per_frame):.3f} pairs/s; "
        f"peak RSS {result['peak_rss_mib']:.0f} MiB"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=2, help="frames to render (each = 5 camera pairs)")
    parser.add_argument("--against", metavar="REV", help="also measure this git revision, back to back")
    parser.add_argument("--repeats", type=int, default=1, help="alternate the two measurements this many times")
    parser.add_argument("--tiny-frames", type=int, default=1, help="frames for the TinyRenderer comparison (0 = skip)")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="cache and dataset folder")
    parser.add_argument("--quiet", action="store_true", help="no stage timings")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    print(machine_line())
    if args.frames < 1 or args.repeats < 1:
        parser.error(f"--frames and --repeats must be at least 1 (got {args.frames}, {args.repeats})")
    root = Path(args.root)
    steps = max(args.frames + 1, 2)
    base = ["progress=false", f"camera.trajectory.frames=[{steps},{steps}]", *args.overrides]
    work = [*base, f"render.max_frames={args.frames}"]
    against = revision_tree(args.against, root, "render_throughput") if args.against else None

    best: dict[str, dict] = {}
    for _ in range(args.repeats):
        sides = [("tree", REPO, root)]
        if against is not None:
            sides.insert(0, ("rev", against[0], root / f"rev-{against[1][:12]}"))
        for side, code, data in sides:
            result = measure(code, data, work, verbose=not args.quiet)
            if side not in best or result["seconds_per_frame"] < best[side]["seconds_per_frame"]:
                best[side] = result
    tree = best["tree"]
    print(f"scene faces: {tree['faces']:,}")
    if against is not None:
        report(f"revision {args.against} ({against[1][:12]})", best["rev"])
    report("working tree", tree)
    if args.tiny_frames:
        # The same views through pybullet's TinyRenderer (rgb, semantic, instance, depth), same cache.
        tiny = measure(
            REPO,
            root,
            [
                *base,
                f"render.max_frames={args.tiny_frames}",
                "render=tinyrenderer",
                f"paths.dataset={root}/dataset_tiny",
            ],
            verbose=False,
        )
        print(
            f"tinyrenderer (4 modalities): {pairs_per_second(tiny):.3f} pairs/s; "
            f"raytrace (all modalities) / tinyrenderer: {pairs_per_second(tree) / pairs_per_second(tiny):.2f}x"
        )
    if against is not None:
        a, b = pairs_per_second(tree), pairs_per_second(best["rev"])
        print(f"speedup vs {args.against}: {a / b:.2f} ({a:.3f} pairs/s vs {b:.3f} pairs/s)")


if __name__ == "__main__":
    main()
