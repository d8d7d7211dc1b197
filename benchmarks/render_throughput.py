"""Images per second for the full modality stack on the default garden.

One "image" = one camera pair at one frame: the left camera with every
modality (rgb, semantic, instance, depth, normal, forward and backward flow
with occlusion, albedo, shading, translucency) plus the right camera's rgb and
depth, all written to disk. Geometry stages are built once (cached under
outputs/bench/) and then only the render stage is timed, forced. The render
stage's one-off setup (scene load, BVH build) is reported apart from the
per-frame rate, and both are combined for a 100-frame job (the default).
TinyRenderer then renders the first frame(s) of the same trajectory; the ratio
compares per-frame rates.

    python benchmarks/render_throughput.py [--frames 2] [overrides ...]
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.config import make_cfg  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.pipeline import run_job  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=2, help="frames to render (each = 5 camera pairs)")
    parser.add_argument("--tiny-frames", type=int, default=1, help="frames for the TinyRenderer comparison (0 = skip)")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="cache and dataset folder")
    parser.add_argument(
        "--tracer-rounds",
        type=int,
        default=0,
        help="then render again with render.tracer=embreex and =native, alternating, this many times each",
    )
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    root = Path(args.root)
    base = [
        "progress=false",
        f"camera.trajectory.frames=[{max(args.frames + 1, 2)},{max(args.frames + 1, 2)}]",
        *args.overrides,
    ]
    start = time.perf_counter()
    run_job(make_cfg(root, base + [f"render.max_frames={args.frames}"]), echo=print)
    print(f"first run (geometry + render): {time.perf_counter() - start:.1f} s")
    result = run_job(make_cfg(root, base + [f"render.max_frames={args.frames}", "force=[render]"]), echo=print)
    render = result.artifacts["render"]
    marker = render.marker()
    frames = marker["frames"]
    images = frames * 5
    print("stage timings of the first run are above (model, scene, trajectory, render, manifest)")
    print(f"scene faces: {result.artifacts['scene'].marker()['faces']:,}")
    per_frame = marker["seconds_per_frame"]
    rate = 5 / per_frame
    print(f"raytrace setup (scene load + BVH build, once per job): {marker['setup_seconds']:.2f} s")
    print(
        f"raytrace frames: {images} images in {frames * per_frame:.2f} s -> {rate:.3f} images/s "
        f"({per_frame:.2f} s per frame of 5 pairs, {marker.get('workers', 1)} frame threads)"
    )
    print(
        f"raytrace render stage including setup: {images / render.seconds:.3f} images/s over {frames} frames; "
        f"a 100-frame job: {500 / (marker['setup_seconds'] + 100 * per_frame):.3f} images/s"
    )
    own = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak RSS of this process (one job): {own:.0f} MiB")
    if args.tracer_rounds:
        compare_tracers(root, base + [f"render.max_frames={args.frames}", "force=[render]"], args.tracer_rounds)
    if args.tiny_frames:
        # The same views through pybullet's TinyRenderer (rgb, semantic, instance, depth), same run.
        tiny = run_job(
            make_cfg(
                root,
                base
                + [
                    f"render.max_frames={args.tiny_frames}",
                    "render=tinyrenderer",
                    f"paths.dataset={root}/dataset_tiny",
                    "force=[render]",
                ],
            ),
            echo=lambda *_: None,
        )
        t_marker = tiny.artifacts["render"].marker()
        t_rate = 5 / t_marker["seconds_per_frame"]
        print(
            f"tinyrenderer: setup {t_marker['setup_seconds']:.2f} s; {t_marker['frames'] * 5} images at "
            f"{t_marker['seconds_per_frame']:.2f} s per frame -> {t_rate:.3f} images/s"
        )
        print(f"ratio raytrace (all modalities) / tinyrenderer (4 modalities), per frame: {rate / t_rate:.2f}x")


def compare_tracers(root: Path, overrides: list[str], rounds: int) -> None:
    """The render stage again per render.tracer path (docs/design.md, Ray tracing), interleaved: the
    best setup (scene load + BVH build) and per-frame time of each, and their ratio."""
    best: dict[str, list[float]] = {}
    for _ in range(rounds):
        for tracer in ("embreex", "native"):
            result = run_job(make_cfg(root, overrides + [f"render.tracer={tracer}"]), echo=lambda *_: None)
            marker = result.artifacts["render"].marker()
            setup, per_frame = marker["setup_seconds"], marker["seconds_per_frame"]
            print(f"render.tracer={tracer}: setup {setup:.2f} s, {per_frame:.2f} s per frame")
            old = best.get(tracer, [float("inf")] * 2)
            best[tracer] = [min(old[0], setup), min(old[1], per_frame)]
    (s_old, f_old), (s_new, f_new) = best["embreex"], best["native"]
    print(
        f"best of {rounds}: embreex setup {s_old:.2f} s, {f_old:.2f} s per frame; native setup {s_new:.2f} s, "
        f"{f_new:.2f} s per frame; per-frame speed-up {f_old / f_new:.2f}x, setup {s_old / s_new:.2f}x"
    )


if __name__ == "__main__":
    main()
