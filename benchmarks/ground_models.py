"""Benchmark: a full 10 x 10 m lawn (100 patches of 1 x 1 m) and every asset type.

    python benchmarks/ground_models.py [--budget 20000] [--seeds 5] [--species a,b,c --weights 0.6,0.3,0.1]

Prints build time and triangle counts. Target: terrain + grass for the whole
garden <= 10 s, so the lawn alone should be well under that.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eden_pipe.models import assets, grass
from eden_pipe.models.mesh import Mesh

DEFAULT_MIX = [
    "kentucky_bluegrass",
    "perennial_ryegrass",
    "fine_fescue",
    "white_clover",
    "dandelion",
    "broadleaf_plantain",
    "creeping_charlie",
]
DEFAULT_WEIGHTS = [0.45, 0.3, 0.15, 0.05, 0.02, 0.015, 0.015]


def terrain(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return 0.15 * np.sin(0.6 * x) * np.cos(0.4 * y) + 0.02 * x


def bench_lawn(species, weights, budget: int, seed: int = 0, garden: float = 10.0) -> tuple[float, Mesh]:
    params = grass.LawnParams(triangles_per_m2=budget)
    t0 = time.perf_counter()
    patches = [
        grass.build_lawn_patch(float(i), float(j), 1.0, species, weights, seed, params, terrain)
        for i in range(int(garden))
        for j in range(int(garden))
    ]
    mesh = Mesh.concatenate(patches)
    return time.perf_counter() - t0, mesh


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--budget", type=int, default=grass.LawnParams().triangles_per_m2)
    ap.add_argument("--seeds", type=int, default=5, help="instances per asset type")
    ap.add_argument("--species", default=",".join(DEFAULT_MIX))
    ap.add_argument("--weights", default=None, help="default: the built-in mix's weights, else equal")
    args = ap.parse_args()
    species = args.species.split(",")
    if args.weights:
        weights = [float(w) for w in args.weights.split(",")]
    else:
        weights = DEFAULT_WEIGHTS if species == DEFAULT_MIX else [1.0] * len(species)

    bench_lawn(species, weights, args.budget, garden=1.0)  # warm caches (presets, imports)
    dt, mesh = bench_lawn(species, weights, args.budget)
    nbytes = sum(a.nbytes for a in mesh.to_npz_dict().values())
    # build_lawn_patch (in bench_lawn above) refuses species and weights of different lengths.
    print(f"lawn 10x10 m, budget {args.budget}/m^2, mix {dict(zip(species, weights, strict=True))}")
    print(
        f"  {dt:.2f} s  {mesh.n_faces:,} triangles ({mesh.n_faces / 100:,.0f}/m^2)  "
        f"{mesh.n_vertices:,} vertices  {nbytes / 2**20:.0f} MiB"
    )

    print(f"\nassets ({args.seeds} instances each): mean ms/instance, mean triangles")
    for t in assets.list_asset_types():
        t0 = time.perf_counter()
        faces = [assets.build_asset(t, s).n_faces for s in range(args.seeds)]
        ms = (time.perf_counter() - t0) / args.seeds * 1e3
        print(f"  {t:22s} {ms:7.2f} ms  {np.mean(faces):8.0f} tris")
    print("\nfences, 10 m run:")
    for style in assets.list_fence_styles():
        t0 = time.perf_counter()
        m = assets.build_fence(style, 10.0, 0)
        print(f"  {style:22s} {(time.perf_counter() - t0) * 1e3:7.2f} ms  {m.n_faces:8d} tris")


if __name__ == "__main__":
    main()
