"""Render stage: every modality file for every frame and camera, resumable per frame.

Files go to ``stages/render/<key>/cam<k>/<column>/<frame>.<ext>`` where
``column`` is the manifest column (DESIGN sections 4 and 5). A frame is
finished when ``frames/<frame>.json`` exists (written after all its files),
so an interrupted render resumes at the first unfinished frame.
"""

from __future__ import annotations

import json
import os
import time
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from eden_pipe import labels
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.config import to_plain
from eden_pipe.io import formats
from eden_pipe.render.raytrace import RayTracer
from eden_pipe.render.shading import EnvironmentMap, ShadingSettings, srgb_to_uint8
from eden_pipe.render.sky import CloudShadowMap
from eden_pipe.render.view import render_view
from eden_pipe.rng import rng_for
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash
from eden_pipe.stages.scene import load_scene
from eden_pipe.stages.trajectory import load_poses

# Linear float layers (DESIGN section 4). glossy, background (B) and rgb_linear (the pixel-centre
# composite I, before exposure) are optional: with them I = albedo*shading + glossy + translucency + background.
INTRINSIC_LAYERS = ("albedo", "shading", "translucency", "glossy", "background", "rgb_linear")


def make_sky(lighting_cfg, seed: int):
    """The garden's sky under one lighting: parameters drawn from the scenario's ranges."""
    from eden_pipe.render.sky import Sky, sample_lighting

    lighting = to_plain(lighting_cfg)
    params = sample_lighting(lighting, rng_for(seed, "lighting", lighting["name"]))
    return Sky(params, seed), params


def render_key(cfg, scene_art: Artifact, traj_art: Artifact) -> str:
    render = to_plain(cfg.render)
    render.pop("threads")  # changes speed, not pixels
    render.pop("workers")
    intr = Intrinsics.from_config(cfg.camera).__dict__
    return config_hash(scene_art.key, traj_art.key, render, to_plain(cfg.lighting), intr,
                       code_fingerprint(__name__))


# Manifest columns each modality writes, with their file extension ("depth" = the configured one).
MODALITY_COLUMNS = {
    "rgb": (("rgb_left", "png"), ("rgb_right", "png")),
    "semantic": (("semantic", "png"),),
    "instance": (("instance", "png"),),
    "depth": (("depth", "depth"), ("depth_right", "depth")),
    "normal": (("normal", "png"),),
    **{layer: ((layer, "npy"),) for layer in INTRINSIC_LAYERS},
}


def frame_files(k: int, frame: int, modalities: set[str], depth_ext: str, has_next: bool, has_prev: bool) -> dict[str, str]:
    """Manifest column -> relative file path for one camera pair of one frame."""
    columns = [c for m in MODALITY_COLUMNS if m in modalities for c in MODALITY_COLUMNS[m]]
    if "flow" in modalities:
        # Flow is undefined past the ends of the trajectory.
        columns += [("flow_fwd", "flo"), ("occ_fwd", "png")] if has_next else []
        columns += [("flow_bwd", "flo"), ("occ_bwd", "png")] if has_prev else []
    return {column: f"cam{k}/{column}/{frame:05d}.{depth_ext if ext == 'depth' else ext}" for column, ext in columns}


def write_pass(path: Path, column: str, data: np.ndarray, cfg_render) -> None:
    c = int(cfg_render.png_compression)
    if column in ("rgb_left", "rgb_right"):
        formats.write_rgb(path, data, c)
    elif column == "semantic":
        formats.write_semantic(path, data, c)
    elif column == "instance":
        formats.write_instance(path, data, c)
    elif column in ("depth", "depth_right"):
        formats.write_depth(path, data, cfg_render.depth_format, c)
    elif column == "normal":
        formats.write_normal(path, data, c)
    elif column in ("flow_fwd", "flow_bwd"):
        formats.write_flo(path, data)
    elif column in ("occ_fwd", "occ_bwd"):
        formats.write_mask(path, data, c)
    else:
        formats.write_float(path, data)


def run_render_stage(cfg, scene_art: Artifact, traj_art: Artifact, cache: StageCache, *, progress: bool = True) -> Artifact:
    key = render_key(cfg, scene_art, traj_art)

    def builder(folder: Path) -> dict:
        return render_frames(folder, cfg, scene_art, traj_art, progress)

    return cache.build("render", key, builder, resumable=True)


def cloud_map_regions(mesh) -> list:
    """Cloud-shadow tables for a scene: 0.2 m over the garden itself, 0.5 m over everything
    (the background skirt reaches 60 m out, seen at grazing angles). Worst-case error against
    the exact sum, where a shadow edge crosses a cell: 0.003 and 0.02 in transmittance."""
    if mesh.n_faces == 0:
        return []
    v = mesh.vertices
    garden_faces = mesh.semantic != labels.BACKGROUND
    used = np.zeros(len(v), bool)
    used[mesh.faces[garden_faces].ravel()] = True
    garden = v[used] if np.any(used) else v
    return [(garden.min(axis=0), garden.max(axis=0), 0.2), (v.min(axis=0), v.max(axis=0), 0.5)]


class FrameRenderer:
    """Everything needed to render and write whole frames; ``render(f)`` is thread-safe
    (each frame has its own generator and files; Embree queries on a committed scene are)."""

    def __init__(self, folder: Path, cfg, arrays, sky, poses: np.ndarray, modalities: set[str], seed: int, threads: int):
        self.folder, self.cfg, self.arrays, self.sky, self.poses = folder, cfg, arrays, sky, poses
        self.modalities, self.seed = modalities, seed
        self.intr = Intrinsics.from_config(cfg.camera)
        self.fps = float(cfg.camera.trajectory.fps)
        self.depth_ext = "png" if cfg.render.depth_format == "png16" else "npy"
        self.left_want = set(modalities) | {"depth"}
        if cfg.render.backend == "tinyrenderer":
            from eden_pipe.render.tinyrenderer import TinyRenderer, light_direction_for, render_view_tinyrenderer

            self.backend = TinyRenderer(arrays, light_direction=light_direction_for(sky), shade="rgb" in modalities)
            self.view_fn = render_view_tinyrenderer
        else:
            self.backend, self.view_fn = RayTracer(arrays.mesh, threads), render_view
        self.cloud_regions = cloud_map_regions(arrays.mesh)

    def close(self) -> None:
        close = getattr(self.backend, "close", None)
        close() if close else self.backend.__exit__(None, None, None)

    def render(self, f: int) -> int:
        cfg, poses, modalities, sky = self.cfg, self.poses, self.modalities, self.sky
        n_total = len(poses)
        written = {}
        raytrace = cfg.render.backend == "raytrace"
        environment = EnvironmentMap(sky, f / self.fps) if raytrace else None
        clouds = CloudShadowMap(sky, f / self.fps, self.cloud_regions) if raytrace else None
        settings = ShadingSettings(indirect_samples=int(cfg.render.indirect_samples),
                                   soft_shadow_samples=int(cfg.render.soft_shadow_samples), time=f / self.fps,
                                   environment=environment, clouds=clouds)
        for k in range(poses.shape[1]):
            has_next, has_prev = f + 1 < n_total, f > 0
            files = frame_files(k, f, modalities, self.depth_ext, has_next, has_prev)
            left = self.view_fn(self.backend, self.arrays, self.intr, poses[f, k, 0], sky, want=self.left_want,
                                pose_next=poses[f + 1, k, 0] if has_next else None,
                                pose_prev=poses[f - 1, k, 0] if has_prev else None, settings=settings,
                                rng=rng_for(self.seed, "render", cfg.lighting.name, f, k, "left"),
                                rgb_spp=int(cfg.render.rgb_spp))
            data = {"semantic": left.get("semantic"), "instance": left.get("instance"), "depth": left["depth"],
                    "normal": left.get("normal"), "flow_fwd": left.get("flow_fwd"), "flow_bwd": left.get("flow_bwd"),
                    "occ_fwd": left.get("occ_fwd"), "occ_bwd": left.get("occ_bwd")}
            for layer in INTRINSIC_LAYERS:
                data[layer] = left.get("linear" if layer == "rgb_linear" else layer)
            if "rgb" in modalities or "depth" in modalities:
                right = self.view_fn(self.backend, self.arrays, self.intr, poses[f, k, 1], sky,
                                     want={"rgb"} if "rgb" in modalities else {"depth"}, settings=settings,
                                     rng=rng_for(self.seed, "render", cfg.lighting.name, f, k, "right"),
                                     rgb_spp=int(cfg.render.rgb_spp))
                data["depth_right"] = right["depth"]
                if "rgb" in modalities:
                    data["rgb_left"] = srgb_to_uint8(left["rgb_linear"] * sky.exposure)
                    data["rgb_right"] = srgb_to_uint8(right["rgb_linear"] * sky.exposure)
            for column, rel in files.items():
                write_pass(self.folder / rel, column, data[column], cfg.render)
            written[str(k)] = files
        marker = {"frame": f, "time": f / self.fps, "files": written}
        marker_dir = self.folder / "frames"
        tmp = marker_dir / f".{f:05d}.json.tmp"
        tmp.write_text(json.dumps(marker))
        tmp.replace(marker_dir / f"{f:05d}.json")
        return f


def worker_layout(render_cfg, n_frames: int) -> tuple[int, int]:
    """(frame threads, Embree threads per frame thread).

    Frames render in threads that share one Embree scene: Embree and numpy's large-array
    kernels release the GIL, so two frame threads ran 1.43x faster than one on 2 cores,
    where two processes (one BVH each, competing for cache and memory) gained only 1.15x.
    """
    cores = os.cpu_count() or 1
    if render_cfg.backend == "tinyrenderer":
        return 1, 1  # one pybullet client: not safe to share between threads
    threads = int(render_cfg.threads) or cores
    workers = int(render_cfg.workers) or cores
    workers = max(1, min(workers, n_frames, threads))
    return workers, max(1, threads // workers)


@contextmanager
def single_threaded_kernels():
    """Run BLAS and OpenCV on the calling thread only, for the duration of the block.

    Parallelism comes from frame threads. Multithreaded kernels underneath them only
    oversubscribe the cores: OpenBLAS workers spin after every small (N, 3) @ (3, 3)
    product and starved the other frame thread, which cut two-thread scaling from
    1.9x to 1.4x.
    """
    previous = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        cv2.setNumThreads(previous)


def render_frames(folder: Path, cfg, scene_art: Artifact, traj_art: Artifact, progress: bool) -> dict:
    poses = load_poses(traj_art)
    n_total = len(poses)
    n_frames = n_total if cfg.render.max_frames is None else min(n_total, int(cfg.render.max_frames))
    modalities = set(cfg.render.modalities)
    if cfg.render.backend == "tinyrenderer":
        from eden_pipe.render.tinyrenderer import SUPPORTED

        modalities &= SUPPORTED  # passes the backend cannot make are omitted (empty manifest paths)
    marker_dir = folder / "frames"
    marker_dir.mkdir(exist_ok=True)
    todo = [f for f in range(n_frames) if not (marker_dir / f"{f:05d}.json").is_file()]
    seed = json.loads((scene_art.path / "scene.json").read_text())["seed"]
    sky, params = make_sky(cfg.lighting, seed)
    facts = {"frames": n_frames, "rendered": len(todo), "exposure": float(sky.exposure),
             "lighting": {k: (float(v) if isinstance(v, (int, float, np.floating)) else v) for k, v in params.__dict__.items()}}
    if not todo:
        return facts
    start = time.perf_counter()
    _, arrays = load_scene(scene_art)
    workers, threads = worker_layout(cfg.render, len(todo))
    renderer = FrameRenderer(folder, cfg, arrays, sky, poses, modalities, seed, threads)  # builds the BVH
    setup = time.perf_counter() - start
    bar = tqdm(total=len(todo), desc="render", unit="frame", disable=not progress, leave=False)
    start = time.perf_counter()
    try:
        with single_threaded_kernels():
            if workers == 1:
                for f in todo:
                    renderer.render(f)
                    bar.update()
            else:
                with ThreadPoolExecutor(workers) as pool:
                    for _ in pool.map(renderer.render, todo):
                        bar.update()
    finally:
        renderer.close()
    bar.close()
    seconds = time.perf_counter() - start
    # setup_seconds: scene load and BVH build, once per job; seconds_per_frame: the frames alone.
    return {**facts, "setup_seconds": round(setup, 3), "seconds_per_frame": round(seconds / len(todo), 4),
            "workers": workers}
