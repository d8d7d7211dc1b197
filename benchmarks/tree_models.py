"""Benchmark: build every Weber-Penn tree species once and print a table.

    python benchmarks/tree_models.py [--budget 150000] [--seed 0] [--repeat 1] [--species a,b]

Columns: seconds (best of ``--repeat``), triangles (stems + leaves), leaves
placed, stems per level, height in metres. Target: every species <= 3 s at
the default budget.
"""

from __future__ import annotations

import argparse
import time

from eden_pipe.models.mesh import MATERIALS
from eden_pipe.models.tree import build_tree, grow_skeleton, list_tree_species


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--budget", type=int, default=150_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--species", default="", help="comma-separated subset (default: all)")
    args = ap.parse_args()
    names = [s for s in args.species.split(",") if s] or list_tree_species()

    print(f"{'species':20s} {'seconds':>8s} {'triangles':>10s} {'leaf tris':>10s} {'height':>7s}  stems per level")
    total = 0.0
    for name in names:
        best, mesh = float("inf"), None
        for _ in range(max(1, args.repeat)):
            t0 = time.perf_counter()
            mesh = build_tree(name, args.seed, triangle_budget=args.budget)
            best = min(best, time.perf_counter() - t0)
        total += best
        stems = [lvl.n for lvl in grow_skeleton(name, args.seed).levels]
        leaf = int((mesh.material == MATERIALS["leaf"]).sum())
        print(f"{name:20s} {best:8.3f} {mesh.n_faces:10d} {leaf:10d} {float(mesh.bounds()[1, 2]):7.2f}  {stems}")
    print(f"{'total':20s} {total:8.3f}")


if __name__ == "__main__":
    main()
