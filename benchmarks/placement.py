"""Placed / requested instances per pool over many default gardens, and the bases' clearance.

Builds only the model and scene stages of ``garden=default garden.seed=S`` for each seed
(the lawn is switched off: placement never looks at it, and it is the slowest part of a
garden's model stage), into a shared stage cache, so a rerun after a change to the scene
stage rebuilds scenes only. Prints one line per garden, then placed/requested per pool and
overall, the unplaced instances with their reasons, and the smallest gap between any two
bases found independently of the scene stage (pybullet closest points between the base
bodies in ``proxies.npz``; negative = overlap). ``--trajectory`` also plans each garden's
rig trajectory (first lighting) to show the rig still finds a free path.

    python benchmarks/placement.py [--seeds 50] [--root outputs/bench/placement] [--trajectory] [overrides ...]

Target (docs/placement.md): >= 98 % of requested instances placed over 50 default gardens, no two
bases closer than zero.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.config import make_cfg, to_config  # noqa: E402
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.scene.description import read_scene  # noqa: E402
from eden_pipe.scene.placement import scene_base_gap  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402


def timed(seconds: dict):
    """A ``run_stages`` step that records each stage's seconds in ``seconds``."""

    def step(name, fn, *args, **kwargs):
        start = time.perf_counter()
        art = fn(*args, **kwargs)
        seconds[name] = time.perf_counter() - start
        return art

    return step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=50, help="gardens: seeds 0 .. N-1")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench" / "placement"), help="stage cache folder")
    parser.add_argument("--trajectory", action="store_true", help="also plan each garden's trajectory")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden.trees.count=[17,17]")
    args = parser.parse_args()
    root = Path(args.root)
    totals: dict[str, dict[str, int]] = {"requested": {}, "placed": {}}  # per pool the sampler places
    unplaced, gaps = [], []
    start = time.perf_counter()
    for seed in range(args.seeds):
        cfg = to_config(
            make_cfg(root, ["garden=default", f"garden.seed={seed}", "garden.lawn.enabled=false", *args.overrides])
        )
        seconds: dict[str, float] = {}
        arts = run_stages(
            cfg,
            StageCache(cfg.paths.stages, set()),
            timed(seconds),
            through="trajectory" if args.trajectory else "scene",
        )
        scene_art = arts["scene"]
        scene = read_scene(scene_art)
        for key in totals:
            for pool, n in getattr(scene, key).items():
                totals[key][pool] = totals[key].get(pool, 0) + n
        unplaced += [dict(garden=scene.garden_id, **u) for u in scene.unplaced]
        gaps.append(scene_base_gap(scene_art.path))
        fence = next((i.type for i in scene.instances if i.pool == "fence"), "-")
        line = (
            f"{scene.garden_id:12s} model {seconds['model']:5.1f} s  scene {seconds['scene']:5.1f} s  "
            f"placed {sum(scene.placed.values()):3d}/{sum(scene.requested.values()):3d}  "
            f"fence {fence:14s} min base gap {gaps[-1]:+.3f} m"
        )
        if args.trajectory:
            line += f"  trajectory {arts['trajectory'].marker()['frames']} frames"
        print(line, flush=True)
    seconds = time.perf_counter() - start
    print(f"\n{'pool':10s} {'placed':>7s} {'requested':>9s} {'share':>7s}")
    for pool in totals["requested"]:
        p, r = totals["placed"][pool], totals["requested"][pool]
        print(f"{pool:10s} {p:7d} {r:9d} {100.0 * p / max(r, 1):6.1f}%")
    p, r = sum(totals["placed"].values()), sum(totals["requested"].values())
    print(f"{'overall':10s} {p:7d} {r:9d} {100.0 * p / max(r, 1):6.1f}%")
    print(f"smallest gap between two bases over all gardens: {min(gaps):+.3f} m (< 0 = overlap)")
    for u in unplaced:
        print("unplaced:", json.dumps(u))
    print(f"{args.seeds} gardens in {seconds:.0f} s")


if __name__ == "__main__":
    main()
