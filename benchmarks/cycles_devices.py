"""Blender Cycles on each device: seconds a view on the CPU and on the GPU Blender finds, and whether
their images agree (``render.cycles.device``; docs/realism.md, Cycles).

Two steps, so that the timing can run where bpy and a GPU are, without the rest of the pipeline:

- ``record FILE [overrides ...]`` builds the garden through its trajectory (the stages, as the CLI
  composes them) and writes what the ``render=cycles`` worker is sent for frame 0: the mesh with its
  per-face albedo, translucency and specular colour, the sky's two maps and sun, the intrinsics and
  the five left cameras' poses (one ``.npz``).
- ``run FILE [--devices cpu,auto] [--samples N] [--views K] [--python PY]`` starts the worker
  (``cycles.CyclesProcess``: the backend's own process and messages), sends the scene and the world
  once, then renders the views on each device in turn, the first view of a device apart (it holds
  the BVH build and, on a GPU, the kernels' compilation). It needs numpy, OpenEXR and this package's
  ``render.backends.cycles`` module here, and ``bpy==5.0.*`` in ``--python``.

The first render on a GPU compiles Cycles' kernels where bpy has none built for that GPU (bpy 5.0.1
ships CUDA binaries up to sm_89 and sm_120, and PTX: on an H200, sm_90, the first process compiled
for more than six minutes); the driver caches them, and later processes start in seconds. Measured
numbers: docs/realism.md, Cycles.

Agreement: each device's linear RGB (the image-formation sum) against the CPU's with the same seed,
per view: the relative mean absolute error and the bias of the mean, beside the CPU's own
seed-to-seed error (a second CPU render of the first view with seed + 1): a device agrees when its
error is within that noise and its bias within a few tenths of a percent.

The last line: ``cycles DEVICE (BACKEND) vs cpu: X x (A s vs B s a view, W x H, N samples)``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

MESH_KEYS = ("vertices", "faces", "albedo", "translucency", "specular")
INTRINSICS = ("width", "height", "fx", "fy", "cx", "cy")


def record(out: Path, overrides: list[str], root: Path) -> None:
    from benchmarks.realism import Unclouded
    from eden_pipe.camera.rig import Intrinsics
    from eden_pipe.config import make_cfg, to_config
    from eden_pipe.pipeline import run_stages
    from eden_pipe.render.backends.cycles import world_maps
    from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings
    from eden_pipe.scene.description import read_scene
    from eden_pipe.stages.cache import StageCache
    from eden_pipe.stages.render import make_sky
    from eden_pipe.stages.scene import load_scene
    from eden_pipe.stages.trajectory import load_poses

    cfg = to_config(make_cfg(root, ["progress=false", *overrides]))
    arts = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="trajectory")
    _, arrays = load_scene(arts["scene"])
    mesh = arrays.mesh
    seed = read_scene(arts["scene"]).seed
    sky, _ = make_sky(cfg.lighting, seed)
    # Cycles' sun lamp casts no cloud shadows: the frame's settings without them (as benchmarks/realism.py)
    settings = replace(frame_settings(cfg.render, sky, 0.0, cloud_map_regions(mesh), None), clouds=Unclouded())
    world = world_maps(sky, settings, 0.0, int(cfg.render.cycles.map_width))
    intr = Intrinsics.from_config(cfg.camera)
    poses = load_poses(arts["trajectory"])[0, :, 0]  # frame 0, every camera, the left one
    meta = {
        "garden": str(cfg.garden.name),
        "seed": int(seed),
        "lighting": str(cfg.lighting.name),
        "faces": len(mesh.faces),
    }
    write_job(out, {k: getattr(mesh, k) for k in MESH_KEYS}, world, intr, poses, meta)
    print(f"recorded {meta} with {len(poses)} views to {out} ({out.stat().st_size / 2**20:.1f} MiB)")


def write_job(out: Path, mesh: dict, world: dict, intr, poses: np.ndarray, meta: dict) -> None:
    """The worker's messages for some views (``mesh``: ``MESH_KEYS``; ``world``: ``cycles.world_maps``'s
    message; ``poses``: (V, 4, 4) camera-to-world) as one ``.npz``, read back by ``run``."""
    out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        out,
        **{f"mesh_{k}": np.asarray(mesh[k]) for k in MESH_KEYS},
        **{f"world_{k}": np.asarray(v) for k, v in world.items()},
        intrinsics=np.array([float(getattr(intr, k)) for k in INTRINSICS]),
        poses=np.asarray(poses, np.float64),
        meta=np.array(json.dumps(meta)),
    )


def relative_mae(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).mean() / max(np.abs(b).mean(), 1e-12))


def bias(a: np.ndarray, b: np.ndarray) -> float:
    return float(a.mean() / max(b.mean(), 1e-12) - 1.0)


def run(args) -> None:
    from eden_pipe.camera.rig import Intrinsics
    from eden_pipe.config.schema import CyclesConfig
    from eden_pipe.render.backends.cycles import CyclesProcess, layers_from_passes, worker_settings

    with np.load(args.file) as f:
        data = {k: f[k] for k in f.files}
    meta = json.loads(str(data["meta"]))
    width, height, fx, fy, cx, cy = (float(v) for v in data["intrinsics"])
    intr = Intrinsics(int(width), int(height), fx, fy, cx, cy)
    poses = data["poses"][: args.views]
    devices = [d for d in args.devices.split(",") if d]
    print(
        f"{meta['garden']} garden (seed {meta['seed']}, {meta['faces']:,} faces), {meta['lighting']}; "
        f"{len(poses)} views of {intr.width} x {intr.height}, {args.samples} samples, two renders a view",
        flush=True,
    )
    t0 = time.perf_counter()
    proc = CyclesProcess(args.python)
    print(f"worker up in {time.perf_counter() - t0:.1f} s: Blender {proc.facts['blender']}", flush=True)
    try:
        t0 = time.perf_counter()
        proc.call("scene", {k: data[f"mesh_{k}"] for k in MESH_KEYS})
        proc.call("world", {k[6:]: data[k] for k in data if k.startswith("world_")})
        print(f"scene and world sent in {time.perf_counter() - t0:.1f} s", flush=True)
        images: dict[str, list[np.ndarray]] = {}
        steady: dict[str, float] = {}
        backends: dict[str, str] = {}
        for device in devices:
            chosen = proc.call(
                "settings",
                worker_settings(
                    replace(CyclesConfig(), samples=args.samples, seed=args.seed, device=device), args.threads
                ),
            )
            backends[device] = chosen["device"] + "".join(f": {name}" for name in chosen["names"][:1])
            seconds = []
            images[device] = []
            for pose in poses:
                t0 = time.perf_counter()
                passes, facts = proc.render(intr, pose)
                seconds.append(time.perf_counter() - t0)
                images[device].append(layers_from_passes(passes)["linear"])
            rest = seconds[1:] or seconds
            steady[device] = float(np.mean(rest))
            print(
                f"{device} ({backends[device]}): first view {seconds[0]:.2f} s (BVH, kernels), then "
                f"{steady[device]:.2f} s a view (worker's renders {sum(facts['seconds']):.2f} s of the last)",
                flush=True,
            )
        if "cpu" in images:
            proc.call(
                "settings",
                worker_settings(
                    replace(CyclesConfig(), samples=args.samples, seed=args.seed + 1, device="cpu"), args.threads
                ),
            )
            passes, _ = proc.render(intr, poses[0])
            floor = relative_mae(layers_from_passes(passes)["linear"], images["cpu"][0])
            print(f"cpu seed {args.seed} vs seed {args.seed + 1}, view 0: relative error {floor:.2e} (the noise)")
            for device in devices:
                if device == "cpu":
                    continue
                errs = [relative_mae(a, b) for a, b in zip(images[device], images["cpu"], strict=True)]
                biases = [bias(a, b) for a, b in zip(images[device], images["cpu"], strict=True)]
                print(
                    f"{device} vs cpu, same seed: relative error {np.mean(errs):.2e} "
                    f"(views {min(errs):.2e}-{max(errs):.2e}), bias {np.mean(biases):+.2e} "
                    f"(views {min(biases):+.2e}..{max(biases):+.2e})"
                )
    finally:
        proc.close()
    if "cpu" in steady:
        for device in devices:
            if device != "cpu":
                print(
                    f"cycles {device} ({backends[device]}) vs cpu: {steady['cpu'] / steady[device]:.1f} x "
                    f"({steady[device]:.2f} s vs {steady['cpu']:.2f} s a view, {intr.width} x {intr.height}, "
                    f"{args.samples} samples)"
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="step", required=True)
    rec = sub.add_parser("record", help="build the garden and write the worker's messages for frame 0")
    rec.add_argument("file", type=Path)
    rec.add_argument("--root", type=Path, default=REPO / "outputs" / "bench_cycles", help="outputs of the stages")
    rec.add_argument("overrides", nargs="*", help="config overrides, as the CLI takes them")
    go = sub.add_parser("run", help="time the recorded views on each device")
    go.add_argument("file", type=Path)
    go.add_argument("--devices", default="cpu,auto", help="render.cycles.device values, in turn")
    go.add_argument("--samples", type=int, default=64, help="paths per pixel in each of a view's two renders")
    go.add_argument("--seed", type=int, default=0)
    go.add_argument("--views", type=int, default=5, help="the first K of the recorded left cameras")
    go.add_argument("--threads", type=int, default=0, help="Cycles' CPU threads (0: every core)")
    go.add_argument("--python", default="", help="an interpreter with bpy==5.0.* (render.cycles.python)")
    args = parser.parse_args()
    if args.step == "record":
        record(args.file, args.overrides, args.root)
    else:
        run(args)


if __name__ == "__main__":
    main()
