"""Regenerate docs/gallery/trees.png: all 19 Weber-Penn tree species (seed 0).

python scripts/gallery_trees.py [--seed 0] [--budget 150000] [--out docs/gallery/trees.png]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from eden_pipe.models.tree import build_tree, list_tree_species
from eden_pipe.render.gallery import render_mesh_grid

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--budget", type=int, default=150_000)
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "trees.png"))
    args = ap.parse_args()
    t0 = time.perf_counter()
    names = list_tree_species()
    meshes = [build_tree(name, args.seed, triangle_budget=args.budget) for name in names]
    t1 = time.perf_counter()
    render_mesh_grid(meshes, [n.replace("_", " ") for n in names], args.out, tile=(320, 320), cols=5)
    print(f"{len(names)} trees built in {t1 - t0:.1f} s, rendered in {time.perf_counter() - t1:.1f} s -> {args.out}")


if __name__ == "__main__":
    main()
