"""Build time and size of every hedge/topiary and flower preset.

    python benchmarks/bush_models.py [--seeds 3]

Prints one row per preset: median build time over the seeds, triangles
(min-max over the seeds) and, for bushes, leaves, ivy roots and nodes.
Target: <= 5 s per bush on the project machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from eden_pipe.models.bush import build_bush_model, bush_types
from eden_pipe.models.flower import build_flower, flower_types


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    args = ap.parse_args()
    seeds = range(args.seeds)

    print(
        f"{'model':28s} {'kind':8s} {'time s (med)':>12s} {'max s':>6s} "
        f"{'triangles':>17s} {'leaves':>7s} {'roots':>6s} {'nodes':>7s}"
    )
    for name in bush_types():
        times, tris, leaves, roots, nodes = [], [], [], [], []
        for s in seeds:
            t0 = time.perf_counter()
            bm = build_bush_model(name, s)
            times.append(time.perf_counter() - t0)
            tris.append(bm.mesh.n_faces)
            leaves.append(bm.params["leaves"])
            roots.append(bm.params["roots"])
            nodes.append(bm.params["nodes"])
        print(
            f"{name:28s} {'bush':8s} {np.median(times):12.3f} {max(times):6.2f} {min(tris):8d}-{max(tris):8d} "
            f"{int(np.median(leaves)):7d} {int(np.median(roots)):6d} {int(np.median(nodes)):7d}"
        )
    for name in flower_types():
        times, tris = [], []
        for s in seeds:
            t0 = time.perf_counter()
            m = build_flower(name, s)
            times.append(time.perf_counter() - t0)
            tris.append(m.n_faces)
        print(f"{name:28s} {'flower':8s} {np.median(times):12.3f} {max(times):6.2f} {min(tris):8d}-{max(tris):8d}")


if __name__ == "__main__":
    main()
