"""Regenerate docs/gallery/bushes.png and docs/gallery/flowers.png.

    python scripts/gallery_bushes.py [--seed 0] [--out docs/gallery]

bushes.png: every hedge/topiary preset for two seeds, titled with the leaf type
each variant drew (top), then one specimen of every leaf type (bottom).
flowers.png: every flowering-plant preset for two seeds (colour variation between seeds).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import cv2
import numpy as np

from eden_pipe.colour import jitter_colors
from eden_pipe.models.bush import build_bush_model, bush_types
from eden_pipe.models.flower import build_flower, flower_types
from eden_pipe.models.leaves import leaf_types, place_leaves
from eden_pipe.models.mesh import Mesh
from eden_pipe.render.gallery import render_mesh_grid

ROOT = Path(__file__).resolve().parents[1]


def leaf_specimen(name: str) -> Mesh:
    """One 10 cm leaf standing upright, facing the gallery camera (yaw -60, pitch -15 deg)."""
    yaw, pitch = np.deg2rad(-60.0), np.deg2rad(-15.0)
    forward = np.array([np.cos(yaw) * np.cos(pitch), np.sin(yaw) * np.cos(pitch), np.sin(pitch)])
    rng = np.random.default_rng(0)
    v, f = place_leaves(
        name, [[0.0, 0.0, 0.02]], [-forward], [[0.0, 0.0, 1.0]], [0.1], rng, fold=0.12, curl=0.05, width_jitter=0.0
    )
    col = jitter_colors([0.25, 0.45, 0.15], 1, rng)
    return Mesh.from_arrays(v, f, semantic=0, material="leaf", albedo=col[0], translucency=0.25, specular=0.04)


def _sheet(meshes, titles, tile, cols, **opts) -> np.ndarray:
    with tempfile.TemporaryDirectory() as tmp:
        return render_mesh_grid(meshes, titles, Path(tmp) / "sheet.png", tile=tile, cols=cols, **opts)


def _write(path: Path, rgb: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 6])
    print(f"wrote {path} ({rgb.shape[1]}x{rgb.shape[0]})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery"))
    args = ap.parse_args()
    out = Path(args.out)

    meshes, titles = [], []
    for n in bush_types():
        for seed in (args.seed, args.seed + 1):
            bush = build_bush_model(n, seed)
            meshes.append(bush.mesh)
            titles.append(f"{n} s{seed}: {bush.params['leaf_type']}")
    top = _sheet(meshes, titles, (400, 400), 4)
    names = leaf_types()
    bottom = _sheet([leaf_specimen(n) for n in names], names, (200, 200), 8, spp=2)
    width = max(top.shape[1], bottom.shape[1])
    pad = lambda im: np.pad(im, ((0, 0), (0, width - im.shape[1]), (0, 0)), constant_values=255)  # noqa: E731
    _write(out / "bushes.png", np.concatenate([pad(top), pad(bottom)], 0))

    flowers = flower_types()
    meshes, titles = [], []
    for seed in (args.seed, args.seed + 1):
        for n in flowers:
            meshes.append(build_flower(n, seed))
            titles.append(f"{n} s{seed}")
    _write(out / "flowers.png", _sheet(meshes, titles, (400, 400), 4))


if __name__ == "__main__":
    main()
