"""Each pixel's visible sky as the render estimates it, against many traced rays (tuning views).

For choosing ``render.pixel_sky_rays`` and ``render.pixel_sky_radius`` (docs/realism.md, Each
pixel's own sky) on the realism protocol's *tuning* views only (``benchmarks/realism.py``,
``PROTOCOLS["tuning"]``: garden 0, frame 0, the five left cameras): each variant renders the views'
full left stack, and at a seeded sample of the pixels lit through a probe (no lightmap, not on the
ground map) its cosine-weighted visible fraction (the probe's times the exposure, as the render
reads it) is compared with ``--truth-rays`` stratified cosine rays traced from the pixel's own hit
point. Per class: the mean absolute error relative to the truth's mean, and the bias. The bake's
own value (before any pixel rays) is the first column; each variant's view time beside it. A
variant that changes the bake (``render.sky_visibility.*``, e.g. ``shadow_maps=true``: each pixel's
sky from the bundles' depth maps) renders with a bake of its own.

With ``--right`` the pixels are the right cameras' (rgb and depth, as the render stage draws them):
each variant renders the left stack, then the right view twice, tracing every pixel's own rays
(``NAME``) and taking the left's factors where it sees the same face side (``NAME +left``, as the
render stage does); the times are the right view's. ``--job-frames N`` then times the render stage
itself (every file of a pair written, frame threads) on an N-frame trajectory of ``--job-garden``
(default 101) under clear, today's default against each variant as the stage runs it and with its
right views tracing their own rays, in turn, ``--job-rounds`` times, the order reversed each round.

    python benchmarks/pixel_sky.py k2=render.pixel_sky_rays=2 k4=render.pixel_sky_rays=4,render.pixel_sky_radius=6
    python benchmarks/pixel_sky.py --pixels 1000 today=render.pixel_sky_rays=0 \
        maps=render.sky_visibility.shadow_maps=true
    python benchmarks/pixel_sky.py --right --job-frames 4 k4=render.pixel_sky_rays=4
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.realism import PROTOCOLS, lighting_overrides, render_left, variant_bakes  # noqa: E402
from benchmarks.realism_report import job_throughput  # noqa: E402
from benchmarks.realism_sources import Captured, load_garden, visible_sky  # noqa: E402
from eden_pipe import labels  # noqa: E402
from eden_pipe.config import make_cfg, to_config  # noqa: E402
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.render import pixel_sky  # noqa: E402
from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.view import PIXEL_SKY, render_view  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402


def nothing_shared(share, points, sides):
    """``SkyShare.lookup`` finding nothing: every right pixel traces its own rays."""
    return np.full(len(points), np.nan, np.float32)


def stage_seconds(root: Path, garden: int, frames: int, rounds: int, variants: dict) -> dict[str, float]:
    """{name: the render stage's mean seconds a frame} (``realism_report.job_throughput``) for today's
    default, each variant, and each with its right views tracing their own rays (``NAME alone``), in
    turn, the order reversed each round."""
    base = ["progress=false", "camera.trajectory.share_across_lightings=true", f"garden.seed={garden}"]
    runs = {"today": ([], pixel_sky.SkyShare.lookup)}
    for name, overrides in variants.items():
        runs[name] = (overrides, pixel_sky.SkyShare.lookup)
        runs[f"{name} alone"] = (overrides, nothing_shared)
    seconds: dict[str, list[float]] = {name: [] for name in runs}
    lookup = pixel_sky.SkyShare.lookup
    try:
        for r in range(rounds):
            for name in list(runs) if r % 2 == 0 else list(runs)[::-1]:
                overrides, lookup_of_run = runs[name]
                pixel_sky.SkyShare.lookup = lookup_of_run  # type: ignore[method-assign]
                run = job_throughput(root, base, ["clear"], frames, {name: overrides}, [["lighting=clear"]])
                seconds[name].append(run[name])
                print(f"render stage, round {r}, {name}: {run[name]:.3f} s a frame", flush=True)
    finally:
        pixel_sky.SkyShare.lookup = lookup
    return {name: float(np.mean(s)) for name, s in seconds.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("variants", nargs="+", help="NAME=OVERRIDE[,OVERRIDE...]")
    ap.add_argument("--lighting", default="overcast")
    ap.add_argument("--pixels", type=int, default=600, help="sampled pixels a view")
    ap.add_argument("--truth-rays", type=int, default=256, help="traced rays a sampled pixel")
    ap.add_argument("--root", default=str(REPO / "outputs" / "bench_realism"), help="realism.py's stage cache")
    ap.add_argument("--right", action="store_true", help="the right cameras' pixels, alone and taking the left's")
    ap.add_argument("--job-frames", type=int, default=0, help="render-stage timing frames (0: none)")
    ap.add_argument("--job-garden", type=int, default=101, help="the garden the render stage is timed on")
    ap.add_argument("--job-rounds", type=int, default=2, help="render-stage timing rounds")
    args = ap.parse_args()
    variants = {v.split("=", 1)[0]: v.split("=", 1)[1].split(",") for v in args.variants}
    protocol = PROTOCOLS["tuning"]
    root = Path(args.root)
    captured = Captured()
    (seed,) = protocol.seeds
    gbase = ["progress=false", "camera.trajectory.share_across_lightings=true", f"garden.seed={seed}"]
    cfg, arrays, vis, poses, intr = load_garden(root, gbase)
    regions = cloud_map_regions(arrays.mesh)
    garden = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="sky_visibility")["sky_visibility"]
    bakes = variant_bakes(root, gbase, variants, garden, vis)

    columns: dict[str, list[np.ndarray]] = {}
    names = [f"{n}{tail}" for n in variants for tail in (("", " +left") if args.right else ("",))]
    first = next(iter(variants))
    taken_pixels = [0, 0]  # right pixels lit through a probe: taking the left's factor, all
    seconds = dict.fromkeys(names, 0.0)
    with RayTracer(arrays.mesh) as tracer:
        for frame in protocol.frame_indices(len(poses)):
            for camera in range(poses.shape[1]):
                picks: dict = {}

                def record(column: str, frame: int = frame, camera: int = camera, picks: dict = picks) -> None:
                    """The visible fraction the last render used at the view's sampled pixels (drawn on
                    its first render)."""
                    b = captured.last
                    if not picks:
                        side = b.side_exposure
                        own = np.flatnonzero((side >= 0) & np.isfinite(side))
                        rng = rng_for(seed, "pixel_sky", frame, camera)
                        picks["pick"] = pick = np.sort(rng.choice(own, size=min(args.pixels, len(own)), replace=False))
                        at = (b.s.points[pick], b.s.n[pick], b.s.prim[pick])
                        columns.setdefault("truth", []).append(visible_sky(tracer, *at, args.truth_rays, rng))
                        columns.setdefault("class", []).append(arrays.mesh.semantic[b.s.prim[pick]])
                        bake = np.clip(b.rows.visible[pick] * captured.bake_exposure[pick], 0, 1)
                        columns.setdefault("bake", []).append(bake)
                    pick = picks["pick"]
                    estimate = np.clip(b.rows.visible[pick] * b.exposure[pick], 0, 1)
                    columns.setdefault(column, []).append(estimate)

                for name, overrides in variants.items():
                    lcfg = to_config(
                        make_cfg(root, gbase + lighting_overrides(args.lighting, root, protocol) + overrides)
                    )
                    sky, _ = make_sky(lcfg.lighting, seed)
                    settings = frame_settings(
                        lcfg.render, sky, frame / float(cfg.camera.trajectory.fps), regions, bakes[name]
                    )
                    start = time.perf_counter()
                    left = render_left(tracer, arrays, intr, poses, frame, camera, sky, settings, seed, args.lighting)
                    if not args.right:
                        seconds[name] += time.perf_counter() - start
                        record(name)
                        continue
                    for column, partner in ((name, None), (f"{name} +left", left)):
                        start = time.perf_counter()
                        render_view(
                            tracer, arrays, intr, poses[frame, camera, 1], sky, want={"rgb", "depth"},
                            settings=settings, rng=rng_for(seed, "render", args.lighting, frame, camera, "right"),
                            partner=partner,
                        )  # fmt: skip
                        seconds[column] += time.perf_counter() - start
                        record(column)
                    if name == first:  # which right pixels took the left's factor (the same for every k)
                        b = captured.last
                        sides = b.s.prim.astype(np.int64) * 2 + b.s.back_side
                        found = np.isfinite(left[PIXEL_SKY].lookup(b.s.points, sides))
                        side = b.side_exposure
                        columns.setdefault("taken", []).append(found[picks["pick"]])
                        taken_pixels[0] += int(np.count_nonzero(found & (side >= 0) & np.isfinite(side)))
                        taken_pixels[1] += int(np.count_nonzero((side >= 0) & np.isfinite(side)))
                print(f"frame {frame} camera {camera}", flush=True)
    c = {name: np.concatenate(parts) for name, parts in columns.items()}
    views = len(columns["truth"])
    names = ["bake", *names]
    where = f"{args.lighting}, right cameras" if args.right else args.lighting
    print(f"\n{where}: visible sky vs {args.truth_rays} traced rays, relative MAE (bias)")
    print("| class | pixels | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    rows = [("all", np.ones(len(c["class"]), bool))]
    rows += [(labels.NAMES[cls], c["class"] == cls) for cls in np.unique(c["class"])]
    if args.right:
        rows += [("taking the left's", c["taken"]), ("tracing", ~c["taken"])]
    for row, m in rows:
        if m.sum() < 20:
            continue
        truth = c["truth"][m]
        cells = [
            f"{np.abs(c[n][m] - truth).sum() / truth.sum():.3f} ({c[n][m].sum() / truth.sum() - 1:+.1%})" for n in names
        ]
        print(f"| {row} | {int(m.sum())} | " + " | ".join(cells) + " |")
    if args.right:
        share = taken_pixels[0] / max(taken_pixels[1], 1)
        print(f"right pixels lit through a probe taking the left's factor: {share:.3f}")
    print("seconds a view: " + ", ".join(f"{name} {s / views:.3f}" for name, s in seconds.items()))
    if args.job_frames > 0:
        stage = stage_seconds(root, args.job_garden, args.job_frames, args.job_rounds, variants)
        print(
            "render stage, seconds a frame (rate against today's): "
            + ", ".join(f"{name} {s:.3f} ({stage['today'] / s:.3f})" for name, s in stage.items())
        )


if __name__ == "__main__":
    main()
