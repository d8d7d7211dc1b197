"""Regenerate docs/gallery/terrain.png: close-ups of every terrain type, as the EDEN paper's terrain figure.

Each tile is a small one-type garden (``build_terrain`` with a single patch
type) seen by a camera 0.8 m above the ground looking down 35 deg, rendered by
our ray tracer under a fixed clear sky. The grass tiles add a lawn
(``build_lawn_patch``) on the patches in view: a bluegrass lawn with white
clover and dandelion, and the same mix dry, browned, short and striped.

    python scripts/gallery_terrain.py [--seed 0] [--spp 4] [--out docs/gallery/terrain.png]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

from eden_pipe.camera.rig import Intrinsics, look_rotation
from eden_pipe.models.grass import LawnParams, build_lawn_patch
from eden_pipe.models.mesh import Mesh
from eden_pipe.models.terrain import build_terrain
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.shading import ShadingSettings, srgb_to_uint8
from eden_pipe.render.sky import Sky, sample_lighting
from eden_pipe.render.view import SceneArrays, render_view

ROOT = Path(__file__).resolve().parents[1]
SIZE_M = 6.0  # each tile's garden: 6 x 6 m, camera near one edge looking across it
CAMERA_XY = (3.0, 1.0)
CAMERA_HEIGHT_M = 0.8
PITCH_DEG = -35.0
WEEDY_LAWN = (["kentucky_bluegrass", "white_clover", "dandelion"], [0.6, 0.25, 0.15])
# Above the garden default (20000): build_lawn_patch thins every species by one factor and floors the
# per-patch counts, so at 20000/m^2 sparse weeds (clover 25, dandelion 12 plants/m^2 at full weight) round
# down to none in every patch. 60000/m^2 keeps ~6 clover and ~1 dandelion per m^2 visible.
LAWN_TRIANGLES_PER_M2 = 60000
# (title, terrain type, lawn parameters or None)
TILES = [
    ("grass with clover and dandelion", "grass", LawnParams(freshness=1.0, brownness=0.05, wetness=0.0, trim=0.5)),
    (
        "grass, dry and trimmed, mowing stripes",
        "grass",
        LawnParams(freshness=0.35, brownness=0.35, trim=0.4, stripes=True),
    ),
    ("gravel", "gravel", None),
    ("pavement", "pavement", None),
    ("pebbles", "pebbles", None),
    ("dirt", "dirt", None),
]


def terrain_scene(
    type_name: str, seed: int, lawn: LawnParams | None = None, lawn_triangles_per_m2: int = LAWN_TRIANGLES_PER_M2
):
    """(Terrain, world Mesh): a one-type garden, with a lawn on the patches in view when ``lawn`` is given."""
    terrain = build_terrain(seed, SIZE_M, 8, 0.08, 3.0, [type_name], [1.0], (1, 1))
    parts = [terrain.mesh()]
    if lawn is not None:
        lawn.triangles_per_m2 = lawn_triangles_per_m2
        species, weights = WEEDY_LAWN
        for px, py in terrain.patches_of("grass"):
            if 0 <= py <= 4 and 1 <= px <= 4:  # the camera sees y in [1.5, 4.3], |x - 3| < 1.6
                parts.append(
                    build_lawn_patch(float(px), float(py), 1.0, species, weights, seed, lawn, terrain.height_at)
                )
    return terrain, Mesh.concatenate(parts)


def camera_pose(terrain) -> np.ndarray:
    x, y = CAMERA_XY
    pose = np.eye(4)
    pose[:3, :3] = look_rotation(np.pi / 2, np.deg2rad(PITCH_DEG))  # looking along +y, down 35 deg
    pose[:3, 3] = (x, y, float(terrain.height_at(x, y)) + CAMERA_HEIGHT_M)
    return pose


def gallery_sky(seed: int = 0) -> Sky:
    """A clear sky with the sun 40 deg high, to the left of and behind the camera: grazing enough to show relief."""
    params = sample_lighting(
        {"name": "clear", "sun_elevation_deg": 40.0, "sun_azimuth_deg": 200.0, "turbidity": 2.5},
        np.random.default_rng(seed),
    )
    return Sky(params, seed)


def render_tile(mesh: Mesh, pose: np.ndarray, sky: Sky, size=(640, 480), spp: int = 4, seed: int = 0) -> np.ndarray:
    w, h = size
    intr = Intrinsics(w, h, float(w), float(w), w / 2.0, h / 2.0)  # the EDEN lens: 32 mm on a 32 mm sensor
    with RayTracer(mesh) as tracer:
        out = render_view(
            tracer,
            SceneArrays(mesh, np.zeros(mesh.n_faces, np.uint16)),
            intr,
            pose,
            sky,
            want={"rgb"},
            settings=ShadingSettings(),
            rng=np.random.default_rng(seed),
            rgb_spp=spp,
        )
    return srgb_to_uint8(out["rgb_linear"] * sky.exposure)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spp", type=int, default=4)
    ap.add_argument("--cols", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "terrain.png"))
    args = ap.parse_args()
    sky = gallery_sky(args.seed)
    w, h = 640, 480
    rows = int(np.ceil(len(TILES) / args.cols))
    sheet = np.full((rows * h, args.cols * w, 3), 255, np.uint8)
    t0 = time.perf_counter()
    for i, (title, type_name, lawn) in enumerate(TILES):
        start = time.perf_counter()
        terrain, mesh = terrain_scene(type_name, args.seed + i, lawn)  # its own seed: the two lawns differ
        img = np.ascontiguousarray(render_tile(mesh, camera_pose(terrain), sky, (w, h), args.spp, args.seed))
        cv2.putText(img, title, (10, h - 14), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 0), 4, cv2.LINE_AA)
        cv2.putText(img, title, (10, h - 14), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2, cv2.LINE_AA)
        r, c = divmod(i, args.cols)
        sheet[r * h : (r + 1) * h, c * w : (c + 1) * w] = img
        print(f"{title:<40} {mesh.n_faces:>9,} triangles  {time.perf_counter() - start:5.1f} s")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 6])
    print(f"{len(TILES)} tiles in {time.perf_counter() - t0:.1f} s -> {out}")


if __name__ == "__main__":
    main()
