"""Lighting realism: the default render against a converged path-traced reference, before and after.

On the default garden (seed 0), frame 0, the five left cameras at full
resolution (640 x 480), for each of the five lightings:

- before: today's default light model, Dind = the open sky everywhere
  (``render.sky_visibility.enabled=false``);
- after: the default, Dind from the garden's baked sky visibility and bounce
  (stage ``sky_visibility``, built or reused here; its time and size are
  reported apart, once per garden; glossy's mirror direction decided by the
  bake's guess along it and an any-hit ray for the ``mirror_rays`` share it is
  least sure of, ``render.glossy_mirror=predicted``); also with ``glossy_mirror``
  any_hit (an any-hit ray for every upward glossy pixel) and traced (a
  closest-hit ray);
- reference: ``render.mode=reference`` path tracing (``--samples`` paths per
  pixel and side, ``--bounces``), evaluated at ``--pixels`` random non-sky
  pixels of each view (the pixel-centre rays the default uses): the error
  metric is a mean over pixels, so a uniform pixel sample estimates it without
  bias at a fraction of the cost of whole reference images.

Errors: mean absolute error over the sampled pixels and channels of the linear
RGB (``linear``: I without exposure) and of the shading layer, relative to the
reference's mean there. Convergence: the reference is the mean of two
independent halves (different seeds); their difference, relative, is printed,
and half of it estimates the reference's own error (each half has twice the
variance of the whole). A view's latency: the full default modality stack of a left
camera (rgb, labels, depth, normal, forward flow with occlusion, albedo,
shading, translucency) timed before and after in the same run, alternating
which goes first (the other two glossy_mirror variants too); each view is rendered
``--repeats`` times, each time as part of a fresh frame, and its fastest render
counts (noise on a shared machine only adds time). Each variant's views make
the bake's per-probe light as they first need it (``visibility.frame_light.FrameLight``), inside
their timing: the five left views stand for one frame, whose right views (not
timed) would need few new probes, so this charges a frame's light to half its views.
That is a view's latency with both cores tracing its rays and one doing its
numpy work. A dataset's throughput is the render stage's: ``--job-frames``
(default 8) frames of each lighting through ``render_frames`` itself (two frame
threads of one Embree thread each on two cores, left and right views, every
file written), before and after in turn, in seconds a frame. Eight frames keep
both frame threads busy to the end, as in a job of a hundred frames; the
benchmark's own three-frame trajectory would leave one idle for its last frame.

    python benchmarks/realism.py [--pixels 1500] [--samples 2048] [--lightings clear,overcast]
        [--job-frames 8] [overrides ...]

2048 samples: at 256 the halves differed by 3-6 % (fireflies of the sun's bounce
and of light through leaves), which added about 0.006 to every error measured
against them; at 2048 by 1-2.5 %, about 1 % of reference error.

The last line is ``worst relative error vs reference: X`` (the worst after-error
over lightings and the two layers).
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.camera.rig import Intrinsics  # noqa: E402
from eden_pipe.config import make_cfg, to_config, to_plain  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.pathtrace import reference_shade  # noqa: E402
from eden_pipe.render.view import primary_rays, render_view  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402
from eden_pipe.stages.scene import load_scene  # noqa: E402
from eden_pipe.stages.sky_visibility import load_sky_visibility  # noqa: E402
from eden_pipe.stages.trajectory import load_poses  # noqa: E402

LIGHTINGS = ("clear", "cloudy", "overcast", "sunset", "twilight")
LEFT = {"rgb", "semantic", "instance", "depth", "normal", "flow", "albedo", "shading", "translucency"}
LAYERS = ("linear", "shading")


def relative_mae(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.abs(a - ref).mean() / max(ref.mean(), 1e-12))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--pixels", type=int, default=1500, help="sampled non-sky pixels per view")
    ap.add_argument("--samples", type=int, default=2048, help="reference paths per pixel and side")
    ap.add_argument("--bounces", type=int, default=6, help="reference bounces per path")
    ap.add_argument("--views", type=int, default=5, help="left cameras of the rig (frame 0)")
    ap.add_argument("--lightings", default=",".join(LIGHTINGS))
    ap.add_argument("--root", default=str(REPO / "outputs" / "bench_realism"), help="stage cache")
    ap.add_argument(
        "--repeats",
        type=int,
        default=2,
        help="timed renders of each view and variant; the fastest counts (a noisy machine only adds time)",
    )
    ap.add_argument(
        "--job-frames",
        type=int,
        default=8,
        help="frames of the render-stage throughput run per lighting and variant (0: skip it)",
    )
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden.seed=1")
    args = ap.parse_args()

    # The same views under every lighting (paired trajectories), as the issue measures.
    base = [
        "progress=false",
        "camera.trajectory.frames=[3,3]",
        "camera.trajectory.share_across_lightings=true",
        *args.overrides,
    ]
    cfg = to_config(make_cfg(Path(args.root), base))
    cache = StageCache(cfg.paths.stages, set())
    start = time.perf_counter()
    arts = run_stages(cfg, cache, through="trajectory")
    scene_art, traj = arts["scene"], arts["trajectory"]
    print(f"geometry: {time.perf_counter() - start:.1f} s")
    vis_art = run_stages(cfg, cache, through="sky_visibility")["sky_visibility"]
    bake = vis_art.marker()
    print(
        f"sky-visibility bake ({'cached' if vis_art.cached else 'built'}): {bake['faces']:,} faces, "
        f"{bake['probes']:,} probes, {bake['bake_seconds']:.1f} s tracing + {bake['bvh_seconds']:.1f} s BVH, "
        f"{bake['bytes'] / 2**20:.1f} MiB (once per garden; settings {to_plain(cfg.render.sky_visibility)})"
    )
    scene, arrays = load_scene(scene_art)
    vis = load_sky_visibility(vis_art)
    poses = load_poses(traj)
    intr = Intrinsics.from_config(cfg.camera)
    tracer = RayTracer(arrays.mesh)
    seed = scene.seed
    print(
        f"views: frame 0, left cameras 0..{args.views - 1}, {intr.width} x {intr.height}; reference at "
        f"{args.pixels} random non-sky pixels per view, {args.samples} samples (two halves of {args.samples // 2}), "
        f"{args.bounces} bounces"
    )

    # The sampled pixels: the same for every lighting.
    pick = []
    for k in range(args.views):
        o, d = primary_rays(intr, poses[0, k, 0])
        hit = np.nonzero(tracer.intersect(o, d).hit)[0]
        rng = rng_for(seed, "realism", "pixels", k)
        pick.append(np.sort(rng.choice(hit, min(args.pixels, len(hit)), replace=False)))

    rows, worst = [], 0.0
    variants = (
        "before",
        "after",
        "any_hit",
        "traced",
    )  # render.glossy_mirror: the default (predicted), any_hit, traced
    seconds = dict.fromkeys(variants, 0.0)
    views_timed = 0
    for lighting in args.lightings.split(","):
        lcfg = to_config(make_cfg(Path(args.root), base + [f"lighting={lighting}"]))
        sky, _ = make_sky(lcfg.lighting, seed)
        settings = frame_settings(lcfg.render, sky, 0.0, cloud_map_regions(arrays.mesh))

        def frame_variants(settings=settings) -> list:  # bound now: the loop rebinds settings per lighting
            """Each variant's settings for one frame: its own per-probe light, made as its views need it."""
            return [
                ("before", replace(settings, sky_visibility=None)),
                ("after", replace(settings, sky_visibility=vis)),
                ("any_hit", replace(settings, sky_visibility=vis, glossy_mirror="any_hit")),
                ("traced", replace(settings, sky_visibility=vis, glossy_mirror="traced")),
            ]

        frames = [frame_variants() for _ in range(max(1, args.repeats))]  # one frame per repeat
        got = {name: {layer: [] for layer in LAYERS} for name in variants + ("half1", "half2")}
        ref_seconds = 0.0
        for k in range(args.views):
            pose, pose_next = poses[0, k, 0], poses[1, k, 0]
            fastest = dict.fromkeys(variants, np.inf)
            for repeat, runs in enumerate(frames):
                for name, view_settings in runs if (k + repeat) % 2 == 0 else runs[::-1]:
                    t0 = time.perf_counter()
                    out = render_view(
                        tracer,
                        arrays,
                        intr,
                        pose,
                        sky,
                        want=LEFT | {"depth"},
                        pose_next=pose_next,
                        settings=view_settings,
                        rng=rng_for(seed, "render", lighting, 0, k, "left"),
                    )
                    fastest[name] = min(fastest[name], time.perf_counter() - t0)
                    if repeat == 0:
                        for layer in LAYERS:
                            got[name][layer].append(out[layer].reshape(-1, 3)[pick[k]])
            for name in variants:
                seconds[name] += fastest[name]
            views_timed += 1
            o, d = primary_rays(intr, pose)
            o, d = o[pick[k]], d[pick[k]]
            hits = tracer.intersect(o, d)
            t0 = time.perf_counter()
            for half in ("half1", "half2"):
                ref = reference_shade(
                    tracer,
                    arrays.mesh,
                    hits,
                    o,
                    d,
                    sky,
                    replace(
                        settings,
                        mode="reference",
                        reference_samples=max(1, args.samples // 2),
                        reference_bounces=args.bounces,
                    ),
                    rng_for(seed, "realism", "reference", lighting, k, half),
                    layers=("shading",),
                )
                for layer in LAYERS:
                    got[half][layer].append(ref[layer])
            ref_seconds += time.perf_counter() - t0
        cat = {name: {layer: np.concatenate(v) for layer, v in layers.items()} for name, layers in got.items()}
        row = {"lighting": lighting, "reference_seconds": ref_seconds}
        for layer in LAYERS:
            ref = 0.5 * (cat["half1"][layer] + cat["half2"][layer])
            row[f"{layer}_before"] = relative_mae(cat["before"][layer], ref)
            row[f"{layer}_after"] = relative_mae(cat["after"][layer], ref)
            row[f"{layer}_any_hit"] = relative_mae(cat["any_hit"][layer], ref)
            row[f"{layer}_traced"] = relative_mae(cat["traced"][layer], ref)
            row[f"{layer}_halves"] = relative_mae(cat["half1"][layer], cat["half2"][layer])
            row[f"{layer}_bias_before"] = float(cat["before"][layer].mean() / ref.mean() - 1)
            row[f"{layer}_bias_after"] = float(cat["after"][layer].mean() / ref.mean() - 1)
            worst = max(worst, row[f"{layer}_after"])
        rows.append(row)
        print(
            f"{lighting}: linear {row['linear_before']:.3f} -> {row['linear_after']:.3f} (glossy_mirror any_hit "
            f"{row['linear_any_hit']:.3f}, traced {row['linear_traced']:.3f}), "
            f"shading {row['shading_before']:.3f} -> {row['shading_after']:.3f} "
            f"(reference {ref_seconds:.0f} s)",
            flush=True,
        )

    print()
    print(
        "| lighting | linear RGB before | after | any_hit | traced | shading before | after | mean bias before | "
        "after | reference halves differ (linear / shading) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['lighting']} | {r['linear_before']:.3f} | {r['linear_after']:.3f} | {r['linear_any_hit']:.3f} | "
            f"{r['linear_traced']:.3f} | "
            f"{r['shading_before']:.3f} | {r['shading_after']:.3f} | {r['linear_bias_before']:+.3f} | "
            f"{r['linear_bias_after']:+.3f} | "
            f"{r['linear_halves']:.3f} / {r['shading_halves']:.3f} |"
        )
    print(
        "(errors: mean absolute error relative to the reference mean; bias: mean / reference mean - 1; the "
        "reference's own error is about half the halves' difference)"
    )
    rate = {name: views_timed / seconds[name] for name in variants}
    print(
        f"latency, one view at a time, full left-camera stack at {intr.width} x {intr.height}: before "
        f"{rate['before']:.3f} views/s, "
        f"after {rate['after']:.3f} views/s, after/before = {rate['after'] / rate['before']:.3f} "
        f"({views_timed} views each, fastest of {max(1, args.repeats)}, same run); "
        f"render.glossy_mirror=any_hit {rate['any_hit']:.3f} views/s, "
        f"{rate['any_hit'] / rate['before']:.3f} of before; traced {rate['traced']:.3f} views/s, "
        f"{rate['traced'] / rate['before']:.3f} of before"
    )
    if args.job_frames > 0:
        job = job_throughput(Path(args.root), base, args.lightings.split(","), args.job_frames, scene_art, vis_art)
        print(
            f"job throughput, the render stage (frame threads, left and right views, files written), "
            f"{args.job_frames} frames a lighting: "
            + ", ".join(f"{name} {b:.3f} -> {a:.3f} s a frame ({b / a:.3f})" for name, (b, a) in job.items())
            + f"; after/before = {sum(b for b, _ in job.values()) / sum(a for _, a in job.values()):.3f}"
        )
    print(
        f"bake amortised: {bake['bake_seconds'] + bake['bvh_seconds']:.1f} s per garden = "
        f"{(bake['bake_seconds'] + bake['bvh_seconds']) / (5 * 100 * 5):.3f} s per view of a five-lighting, "
        f"100-frame garden"
    )
    print(f"worst relative error vs reference: {worst:.3f}")


def job_throughput(root: Path, base: list[str], lightings: list[str], frames: int, scene_art, vis_art) -> dict:
    """{lighting: (before, after) seconds a frame} of the render stage itself (``render_frames``: its
    frame threads, left and right views, every file written) on a ``frames``-frame trajectory, before
    and after in turn (the order alternating by lighting). With as many frames a thread as this,
    both frame threads stay busy to the end, as in a job of a hundred frames; a run of three frames
    on two threads leaves one idle for its last third."""
    import tempfile

    from eden_pipe.stages.render import render_frames

    base = [o for o in base if not o.startswith("camera.trajectory.frames")] + [
        f"camera.trajectory.frames=[{frames},{frames}]"
    ]
    cfg = to_config(make_cfg(root, base))
    traj = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="trajectory")["trajectory"]  # geometry cached
    out = {}
    for i, lighting in enumerate(lightings):
        seconds = {}
        for name in ("before", "after") if i % 2 == 0 else ("after", "before"):
            overrides = (
                base + [f"lighting={lighting}"] + (["render.sky_visibility.enabled=false"] if name == "before" else [])
            )
            with tempfile.TemporaryDirectory(dir=root) as folder:
                facts = render_frames(
                    Path(folder),
                    to_config(make_cfg(root, overrides)),
                    scene_art,
                    traj,
                    False,
                    vis_art if name == "after" else None,
                )
            seconds[name] = facts["seconds_per_frame"]
        out[lighting] = (seconds["before"], seconds["after"])
    return out


if __name__ == "__main__":
    main()
