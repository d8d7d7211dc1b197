"""What each part of the render costs, for one default-garden view (one left camera, 640 x 480).

Geometry (model, scene, trajectory stages) is built once through the
pipeline's own stage chain (``run_stages``) and cached under outputs/bench/ (shared with
render_throughput.py); then ``render_view`` is timed in this process for:

- labels only: depth, semantic, instance, normal (pixel-centre rays);
- full stack: + forward/backward flow with occlusion + albedo, shading,
  translucency (the default modalities, as the render stage asks the left camera);
- full stack + rgb at the default samples (rgb_spp=1, indirect_samples=0);
- the same with indirect_samples=1, 2 and with rgb_spp=2, 4 (and both).

Ratios are to the labels-only time measured in the same process. Each case
runs ``--repeats`` times; the minimum is reported (the machine is shared).

    python benchmarks/shading_cost.py [--camera 0] [--repeats 1] [--lighting clear] [overrides ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.camera.rig import Intrinsics  # noqa: E402
from eden_pipe.config import make_cfg, to_config  # noqa: E402
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.shading import ShadingSettings  # noqa: E402
from eden_pipe.render.view import render_view  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402
from eden_pipe.stages.scene import load_scene  # noqa: E402
from eden_pipe.stages.trajectory import load_poses  # noqa: E402

LABELS = {"depth", "semantic", "instance", "normal"}
FULL = LABELS | {"flow", "albedo", "shading", "translucency"}
# (name, want, rgb_spp, indirect_samples)
CASES = [
    ("labels only", LABELS, 1, 0),
    ("full stack (no rgb)", FULL, 1, 0),
    ("full + rgb (spp 1, indirect 0)", FULL | {"rgb"}, 1, 0),
    ("full + rgb, indirect 1", FULL | {"rgb"}, 1, 1),
    ("full + rgb, indirect 2", FULL | {"rgb"}, 1, 2),
    ("full + rgb, spp 2", FULL | {"rgb"}, 2, 0),
    ("full + rgb, spp 4", FULL | {"rgb"}, 4, 0),
    ("full + rgb, spp 4, indirect 1", FULL | {"rgb"}, 4, 1),
]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--camera", type=int, default=0, help="camera pair of the rig (left camera)")
    ap.add_argument("--repeats", type=int, default=1)
    ap.add_argument("--lighting", default="clear")
    ap.add_argument(
        "--root", default=str(REPO / "outputs" / "bench"), help="cache folder (shared with render_throughput.py)"
    )
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden.seed=1")
    args = ap.parse_args()

    # frames=[3,3] as render_throughput.py's default (--frames 2): the same cached trajectory.
    cfg = to_config(
        make_cfg(
            Path(args.root),
            ["progress=false", "camera.trajectory.frames=[3,3]", f"lighting={args.lighting}", *args.overrides],
        )
    )
    start = time.perf_counter()
    arts = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="trajectory")
    scene_art, traj = arts["scene"], arts["trajectory"]
    states = ", ".join(f"{n} {'cached' if a.cached else 'built'}" for n, a in arts.items())
    print(f"geometry: {states} ({time.perf_counter() - start:.1f} s)")
    scene, arrays = load_scene(scene_art)
    poses = load_poses(traj)
    sky, _ = make_sky(cfg.lighting, scene["seed"])
    intr = Intrinsics.from_config(cfg.camera)
    frame, k = 1, args.camera  # frame 1 has both neighbours: forward and backward flow
    pose, pose_prev, pose_next = poses[frame, k, 0], poses[frame - 1, k, 0], poses[frame + 1, k, 0]
    print(
        f"garden {scene['garden_id']}: {json.loads((scene_art.path / 'scene.json').read_text())['faces']:,} faces, "
        f"{len(scene['instances'])} instances; frame {frame}, camera {k}, {intr.width}x{intr.height}, "
        f"lighting {args.lighting}, threads {int(cfg.render.threads) or 'all'}"
    )

    with RayTracer(arrays.mesh, int(cfg.render.threads)) as tracer:

        def render(want, spp, indirect):
            settings = ShadingSettings(
                indirect_samples=indirect,
                soft_shadow_samples=int(cfg.render.soft_shadow_samples),
                time=frame / float(cfg.camera.trajectory.fps),
            )
            t0 = time.perf_counter()
            render_view(
                tracer,
                arrays,
                intr,
                pose,
                sky,
                want=want,
                pose_next=pose_next,
                pose_prev=pose_prev,
                settings=settings,
                rng=rng_for(scene["seed"], "bench", frame, k),
                rgb_spp=spp,
            )
            return time.perf_counter() - t0

        render(LABELS, 1, 0)  # warm-up: Embree builds its BVH on the first query
        print(f"\n{'case':<32} {'seconds':>8} {'x labels':>9}")
        base = None
        for name, want, spp, indirect in CASES:
            seconds = min(render(want, spp, indirect) for _ in range(max(1, args.repeats)))
            base = base or seconds
            print(f"{name:<32} {seconds:>8.2f} {seconds / base:>9.2f}", flush=True)


if __name__ == "__main__":
    main()
