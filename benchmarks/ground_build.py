"""Time to build the default garden's ground: terrain mesh + the full lawn on every grass patch.

Exactly what the model stage does (eden_pipe.stages.model): ``build_terrain``
with the garden's terrain config, then ``build_lawn`` over every grass patch
with the recipe's lawn (species mix, freshness, trim, budget ...). Target:
<= 10 s per garden.

    python benchmarks/ground_build.py [--seeds 0,1,2,3] [overrides ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from omegaconf import OmegaConf  # noqa: E402

from tests.conftest import make_cfg  # noqa: E402  (composes conf/ exactly as the CLI does)

from eden_pipe.models.terrain import build_terrain  # noqa: E402
from eden_pipe.scene.recipe import sample_recipe  # noqa: E402
from eden_pipe.stages.model import build_lawn  # noqa: E402

TARGET_S = 10.0


def build_ground(garden: dict):
    """(terrain, terrain mesh, lawn mesh, seconds per step) as in run_model_stage."""
    recipe = sample_recipe(garden)
    t = garden["terrain"]
    t0 = time.perf_counter()
    terrain = build_terrain(garden["seed"], garden["size_m"], t["cells_per_m"], t["relief_m"], t["relief_scale_m"],
                            t["patch_types"], t["patch_weights"], tuple(t["types_per_garden"]))
    t1 = time.perf_counter()
    ground = terrain.mesh()
    t2 = time.perf_counter()
    lawn = build_lawn(terrain, recipe["lawn"], garden["seed"]) if recipe["lawn"] else None
    t3 = time.perf_counter()
    return terrain, ground, lawn, recipe["lawn"], (t1 - t0, t2 - t1, t3 - t2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0,1,2,3", help="comma-separated garden seeds")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden.lawn.triangles_per_m2=30000")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]

    # Warm-up (imports, species presets, noise tables) on a small garden, not timed.
    warm = OmegaConf.to_container(make_cfg(Path("/tmp/eden-bench"), ["garden=small"]).garden, resolve=True)
    build_ground(warm)

    print(f"{'seed':>4}  {'terrain types':<32} {'grass':>5}  {'terrain tris':>12}  {'lawn tris':>10}  "
          f"{'terrain s':>9}  {'mesh s':>6}  {'lawn s':>6}  {'total s':>7}")
    totals = []
    for seed in seeds:
        cfg = make_cfg(Path("/tmp/eden-bench"), [f"garden.seed={seed}", *args.overrides])
        garden = OmegaConf.to_container(cfg.garden, resolve=True)
        terrain, ground, lawn, lawn_cfg, (t_terrain, t_mesh, t_lawn) = build_ground(garden)
        total = t_terrain + t_mesh + t_lawn
        totals.append(total)
        n_grass = len(terrain.patches_of("grass"))
        print(f"{seed:>4}  {','.join(terrain.patch_types):<32} {n_grass:>5}  {ground.n_faces:>12,}  "
              f"{(lawn.n_faces if lawn else 0):>10,}  {t_terrain:>9.3f}  {t_mesh:>6.3f}  {t_lawn:>6.2f}  {total:>7.2f}")
        if lawn_cfg:
            mix = ", ".join(f"{s} {w:.2f}" for s, w in zip(lawn_cfg["species"], lawn_cfg["weights"]))
            print(f"      lawn: {mix}; {lawn_cfg['triangles_per_m2']}/m^2, trim {lawn_cfg['trim']:.2f}")
    worst = max(totals)
    print(f"\nworst {worst:.2f} s, mean {sum(totals) / len(totals):.2f} s per garden; target <= {TARGET_S:.0f} s: "
          f"{'OK' if worst <= TARGET_S else 'MISSED'}")


if __name__ == "__main__":
    main()
