"""Each pixel's visible sky as the render estimates it, against many traced rays (tuning views).

For choosing ``render.pixel_sky_rays`` and ``render.pixel_sky_radius`` (docs/realism.md, Each
pixel's own sky) on the realism protocol's *tuning* views only (``benchmarks/realism.py``,
``PROTOCOLS["tuning"]``: garden 0, frame 0, the five left cameras): each variant renders the views'
full left stack, and at a seeded sample of the pixels lit through a probe (no lightmap, not on the
ground map) its cosine-weighted visible fraction (the probe's times the exposure, as the render
reads it) is compared with ``--truth-rays`` stratified cosine rays traced from the pixel's own hit
point. Per class: the mean absolute error relative to the truth's mean, and the bias. The bake's
own value (before any pixel rays) is the first column; each variant's view time beside it.

    python benchmarks/pixel_sky.py k2=render.pixel_sky_rays=2 k4=render.pixel_sky_rays=4,render.pixel_sky_radius=6
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.realism import PROTOCOLS, lighting_overrides, render_left  # noqa: E402
from benchmarks.realism_sources import Captured, load_garden, visible_sky  # noqa: E402
from eden_pipe import labels  # noqa: E402
from eden_pipe.config import make_cfg, to_config  # noqa: E402
from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("variants", nargs="+", help="NAME=OVERRIDE[,OVERRIDE...]")
    ap.add_argument("--lighting", default="overcast")
    ap.add_argument("--pixels", type=int, default=600, help="sampled pixels a view")
    ap.add_argument("--truth-rays", type=int, default=256, help="traced rays a sampled pixel")
    ap.add_argument("--root", default=str(REPO / "outputs" / "bench_realism"), help="realism.py's stage cache")
    args = ap.parse_args()
    variants = {v.split("=", 1)[0]: v.split("=", 1)[1].split(",") for v in args.variants}
    protocol = PROTOCOLS["tuning"]
    root = Path(args.root)
    captured = Captured()
    (seed,) = protocol.seeds
    gbase = ["progress=false", "camera.trajectory.share_across_lightings=true", f"garden.seed={seed}"]
    cfg, arrays, vis, poses, intr = load_garden(root, gbase)
    regions = cloud_map_regions(arrays.mesh)
    columns: dict[str, list[np.ndarray]] = {}
    seconds = dict.fromkeys(variants, 0.0)
    with RayTracer(arrays.mesh) as tracer:
        for frame in protocol.frame_indices(len(poses)):
            for camera in range(poses.shape[1]):
                pick = None
                for name, overrides in variants.items():
                    lcfg = to_config(
                        make_cfg(root, gbase + lighting_overrides(args.lighting, root, protocol) + overrides)
                    )
                    sky, _ = make_sky(lcfg.lighting, seed)
                    settings = frame_settings(lcfg.render, sky, frame / float(cfg.camera.trajectory.fps), regions, vis)
                    start = time.perf_counter()
                    render_left(tracer, arrays, intr, poses, frame, camera, sky, settings, seed, args.lighting)
                    seconds[name] += time.perf_counter() - start
                    b = captured.last
                    if pick is None:
                        side = b.side_exposure
                        own = np.flatnonzero((side >= 0) & np.isfinite(side))
                        rng = rng_for(seed, "pixel_sky", frame, camera)
                        pick = np.sort(rng.choice(own, size=min(args.pixels, len(own)), replace=False))
                        at = (b.s.points[pick], b.s.n[pick], b.s.prim[pick])
                        columns.setdefault("truth", []).append(visible_sky(tracer, *at, args.truth_rays, rng))
                        columns.setdefault("class", []).append(arrays.mesh.semantic[b.s.prim[pick]])
                        bake = np.clip(b.rows.visible[pick] * captured.bake_exposure[pick], 0, 1)
                        columns.setdefault("bake", []).append(bake)
                    estimate = np.clip(b.rows.visible[pick] * b.exposure[pick], 0, 1)
                    columns.setdefault(name, []).append(estimate)
                print(f"frame {frame} camera {camera}", flush=True)
    c = {name: np.concatenate(parts) for name, parts in columns.items()}
    views = len(columns["truth"])
    names = ["bake", *variants]
    print(f"\n{args.lighting}: visible sky vs {args.truth_rays} traced rays, relative MAE (bias)")
    print("| class | pixels | " + " | ".join(names) + " |")
    print("|---|---|" + "---|" * len(names))
    for cls in [None, *np.unique(c["class"])]:
        m = np.ones(len(c["class"]), bool) if cls is None else c["class"] == cls
        if m.sum() < 20:
            continue
        truth = c["truth"][m]
        cells = [
            f"{np.abs(c[n][m] - truth).sum() / truth.sum():.3f} ({c[n][m].sum() / truth.sum() - 1:+.1%})" for n in names
        ]
        print(f"| {'all' if cls is None else labels.NAMES[cls]} | {int(m.sum())} | " + " | ".join(cells) + " |")
    print("seconds a view: " + ", ".join(f"{name} {s / views:.3f}" for name, s in seconds.items()))


if __name__ == "__main__":
    main()
