"""Time to build the default garden's ground: terrain mesh + the full lawn on every grass patch.

Exactly what the model stage does (eden_pipe.stages.model): the terrain its
config builds (``TerrainConfig.build``), then ``build_lawn`` over every grass
patch with the recipe's lawn (species mix, freshness, trim, budget ...).
Target: <= 10 s per garden.

    python benchmarks/ground_build.py [--seeds 0,1,2,3] [overrides ...]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.config import GardenConfig, make_cfg, to_config  # noqa: E402
from eden_pipe.scene.recipe import sample_recipe  # noqa: E402
from eden_pipe.stages.model import build_lawn  # noqa: E402

TARGET_S = 10.0


def garden_config(overrides: list[str]) -> GardenConfig:
    return to_config(make_cfg(Path("/tmp/eden-bench"), overrides)).garden


def build_ground(garden: GardenConfig):
    """(terrain, terrain mesh, lawn mesh, the recipe's lawn, seconds per step) as in run_model_stage."""
    recipe = sample_recipe(garden)
    t0 = time.perf_counter()
    terrain = garden.terrain.build(garden.seed, garden.size_m)
    t1 = time.perf_counter()
    ground = terrain.mesh()
    t2 = time.perf_counter()
    lawn = build_lawn(terrain, recipe.lawn, garden.seed) if recipe.lawn else None
    t3 = time.perf_counter()
    return terrain, ground, lawn, recipe.lawn, (t1 - t0, t2 - t1, t3 - t2)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0,1,2,3", help="comma-separated garden seeds")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden.lawn.triangles_per_m2=30000")
    args = ap.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]

    # Warm-up (imports, species presets, noise tables) on a small garden, not timed.
    build_ground(garden_config(["garden=small"]))

    print(
        f"{'seed':>4}  {'terrain types':<32} {'grass':>5}  {'terrain tris':>12}  {'lawn tris':>10}  "
        f"{'terrain s':>9}  {'mesh s':>6}  {'lawn s':>6}  {'total s':>7}"
    )
    totals = []
    for seed in seeds:
        garden = garden_config([f"garden.seed={seed}", *args.overrides])
        terrain, ground, lawn, lawn_draw, (t_terrain, t_mesh, t_lawn) = build_ground(garden)
        total = t_terrain + t_mesh + t_lawn
        totals.append(total)
        n_grass = len(terrain.patches_of("grass"))
        print(
            f"{seed:>4}  {','.join(terrain.patch_types):<32} {n_grass:>5}  {ground.n_faces:>12,}  "
            f"{(lawn.n_faces if lawn else 0):>10,}  {t_terrain:>9.3f}  {t_mesh:>6.3f}  {t_lawn:>6.2f}  {total:>7.2f}"
        )
        if lawn_draw:
            # One weight per species (sample_recipe draws them together).
            mix = ", ".join(f"{s} {w:.2f}" for s, w in zip(lawn_draw.species, lawn_draw.weights, strict=True))
            print(f"      lawn: {mix}; {lawn_draw.triangles_per_m2}/m^2, trim {lawn_draw.trim:.2f}")
    worst = max(totals)
    print(
        f"\nworst {worst:.2f} s, mean {sum(totals) / len(totals):.2f} s per garden; target <= {TARGET_S:.0f} s: "
        f"{'OK' if worst <= TARGET_S else 'MISSED'}"
    )


if __name__ == "__main__":
    main()
