"""Regenerate docs/gallery/realism/: one default-garden view under the five lightings, four ways.

Per lighting, side by side: before (the open sky as Dind everywhere:
``render.sky_visibility.enabled=false``), after (the default: the garden's
baked sky visibility and bounce, glossy's mirror direction decided by the
bake's guess along it, an any-hit ray where it is least sure), any_hit
(``render.glossy_mirror=any_hit``: an any-hit ray for every upward glossy
pixel), and the path-traced reference
(``render.mode=reference``). Same view (seed 0, frame 0, left camera of pair
0), at reduced resolution (``--width``, intrinsics scaled) so the reference
finishes in minutes on two cores; each panel is exposed with the lighting's
own exposure. Writes ``realism.png``: one row per lighting. Geometry and the bake come from the stage cache under
``outputs/realism/`` (shared with ``benchmarks/realism.py --root outputs/realism``).

    python scripts/gallery_realism.py [--width 192] [--samples 128]
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.realism import LIGHTINGS, Unclouded  # noqa: E402
from eden_pipe.camera.rig import Intrinsics  # noqa: E402
from eden_pipe.config import make_cfg, to_config  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.shading import srgb_to_uint8  # noqa: E402
from eden_pipe.render.view import render_view  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402
from eden_pipe.stages.scene import load_scene  # noqa: E402
from eden_pipe.stages.sky_visibility import load_sky_visibility  # noqa: E402
from eden_pipe.stages.trajectory import load_poses  # noqa: E402


def label(image: np.ndarray, text: str) -> np.ndarray:
    out = image.copy()
    cv2.putText(out, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=192, help="image width (height and intrinsics scale with it)")
    ap.add_argument("--samples", type=int, default=128, help="reference paths per pixel and side")
    ap.add_argument("--cycles-samples", type=int, default=128, help="Cycles paths per pixel and render")
    ap.add_argument("--cycles-python", default="", help="render.cycles.python")
    ap.add_argument("--no-cycles", action="store_true")
    ap.add_argument("--camera", type=int, default=0)
    ap.add_argument("--root", default=str(ROOT / "outputs" / "bench_realism"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "realism"))
    args = ap.parse_args()
    base = ["progress=false", "camera.trajectory.share_across_lightings=true", "garden.seed=0"]
    cfg = to_config(make_cfg(Path(args.root), base))
    arts = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="sky_visibility")
    vis = load_sky_visibility(arts["sky_visibility"])
    scene, arrays = load_scene(arts["scene"])
    pose = load_poses(arts["trajectory"])[0, args.camera, 0]
    full = Intrinsics.from_config(cfg.camera)
    s = args.width / full.width
    intr = Intrinsics(
        args.width,
        int(round(full.height * s)),
        full.fx * s,
        full.fy * s,
        (full.cx + 0.5) * s - 0.5,
        (full.cy + 0.5) * s - 0.5,
    )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    cycles = None
    if not args.no_cycles:
        from benchmarks.realism import cycles_settings
        from eden_pipe.render.backends.cycles import CyclesProcess, layers_from_passes, world_maps

        cycles = CyclesProcess(args.cycles_python)
        mesh = arrays.mesh
        cycles.call("scene", {k: getattr(mesh, k) for k in ("vertices", "faces", "albedo", "translucency", "specular")})
        cycles.call("settings", cycles_settings(args.cycles_samples, 1))
    with RayTracer(arrays.mesh) as tracer:
        for lighting in LIGHTINGS[:5]:
            lcfg = to_config(make_cfg(Path(args.root), base + [f"lighting={lighting}"]))
            sky, _ = make_sky(lcfg.lighting, scene.seed)
            settings = replace(
                frame_settings(lcfg.render, sky, 0.0, cloud_map_regions(arrays.mesh)), clouds=Unclouded()
            )
            panels = []
            for name, variant in (
                ("fast", replace(settings, sky_visibility=vis)),
                ("reference", replace(settings, mode="reference", reference_samples=args.samples)),
            ):
                view = render_view(
                    tracer,
                    arrays,
                    intr,
                    pose,
                    sky,
                    want={"rgb", "depth"},
                    settings=variant,
                    rng=rng_for(scene.seed, "gallery", "realism", lighting, name),
                )
                panels.append(label(srgb_to_uint8(view["rgb_linear"] * sky.exposure), f"{lighting}: {name}"))
                print(f"{lighting} {name} done", flush=True)
            if cycles is not None:
                cycles.call("world", world_maps(sky, settings, 0.0, 1024))
                passes, _ = cycles.render(intr, pose)
                linear = layers_from_passes(passes)["linear"]
                panels.append(label(srgb_to_uint8(linear * sky.exposure), f"{lighting}: Cycles"))
                print(f"{lighting} Cycles done", flush=True)
            rows.append(np.concatenate(panels, axis=1))
    if cycles is not None:
        cycles.close()
    cv2.imwrite(str(out / "realism.png"), cv2.cvtColor(np.concatenate(rows, axis=0), cv2.COLOR_RGB2BGR))
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
