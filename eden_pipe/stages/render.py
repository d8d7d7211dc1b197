"""Render stage: every modality file for every frame and camera, resumable per frame.

This module schedules the work: the stage and its cache key, frames across
threads (``worker_layout``), and one frame's views through the configured
backend (:mod:`eden_pipe.render.backends`). What files a frame has and how they
are written is :mod:`eden_pipe.io.layout` (from the modality table,
:mod:`eden_pipe.modalities`).
"""

from __future__ import annotations

import os
import time
from concurrent.futures import Executor, ThreadPoolExecutor
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from eden_pipe.camera.effects import EFFECT_KEYS, effects_on, exposure_effects_on
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.camera.sensor import Sensor
from eden_pipe.camera.shutter import exposure_poses, sample_offsets
from eden_pipe.config import to_plain
from eden_pipe.io import layout
from eden_pipe.io.quantise import srgb8_codes
from eden_pipe.lighting import lighting_files, without_still_wind
from eden_pipe.metadata import published_poses
from eden_pipe.modalities import COLUMNS, WriteOptions, add_derived, camera_passes, derived_inputs, producible
from eden_pipe.render import backends
from eden_pipe.render.wind import WindField, draw_wind
from eden_pipe.rng import rng_for
from eden_pipe.scene.description import read_scene
from eden_pipe.stages.cache import Artifact, StageCache, code_fingerprint, config_hash
from eden_pipe.stages.scene import load_scene
from eden_pipe.stages.sky_visibility import load_sky_visibility
from eden_pipe.stages.trajectory import load_poses


def make_sky(lighting_cfg, seed: int):
    """The garden's sky under one lighting: parameters drawn from the scenario's ranges (or an HDR map)."""
    from eden_pipe.render.sky import build_sky, sample_lighting

    params = sample_lighting(lighting_cfg, rng_for(seed, "lighting", lighting_cfg.name))
    return build_sky(params, seed), params


def render_key(cfg, scene_art: Artifact, traj_art: Artifact, sky_visibility: Artifact | None = None) -> str:
    render = to_plain(cfg.render)
    lighting = without_still_wind(to_plain(cfg.lighting))  # still air: as keyed before the wind existed
    render.pop("threads")  # changes speed, not pixels
    render.pop("workers")
    render.pop("tracer")  # which Embree path traces: the same hits either way
    if cfg.render.backend != "cycles":
        render.pop("cycles")  # Cycles' settings change only its own renders: keys without it stay as they were
    intr = Intrinsics.from_config(cfg.camera).__dict__
    parts = [] if sky_visibility is None else [sky_visibility.key]  # keys without a bake stay as they were
    # The lighting's image files by content (lighting_files: {} without any): a changed map renders again.
    return config_hash(
        scene_art.key,
        traj_art.key,
        render,
        lighting,
        lighting_files(cfg.lighting),
        intr,
        code_fingerprint(__name__),
        code_fingerprint(backends.module_of(cfg.render.backend)),
        *parts,
        *camera_effects_key(cfg.camera),
    )


def camera_effects_key(camera_cfg) -> list:
    """The camera effects' keys where any is on (docs/design.md, Camera effects); [] with every
    effect off, so keys without them stay as they were."""
    cam = to_plain(camera_cfg)
    if not effects_on(cam):
        return []
    return [{k: cam[k] for k in EFFECT_KEYS}]


def run_render_stage(
    cfg,
    scene_art: Artifact,
    traj_art: Artifact,
    cache: StageCache,
    *,
    progress: bool = True,
    sky_visibility: Artifact | None = None,
) -> Artifact:
    """``sky_visibility``: the garden's bake (stage ``sky_visibility``) when the light model uses it."""
    key = render_key(cfg, scene_art, traj_art, sky_visibility)

    def builder(folder: Path) -> dict:
        return render_frames(folder, cfg, scene_art, traj_art, progress, sky_visibility)

    return cache.build("render", key, builder, resumable=True)


def sequence_length(n_total: int, render_cfg) -> int:
    """The frames a job renders: the trajectory's first ``render.max_frames`` (all of them when null).
    The sequence ends at its last one, as the trajectory does at its own last frame: that frame has no
    forward flow, so every flow file's partner image is in the dataset."""
    return n_total if render_cfg.max_frames is None else min(n_total, int(render_cfg.max_frames))


class FrameRenderer:
    """Everything needed to render and write whole frames; ``render(f)`` is thread-safe when the
    backend allows several frame threads (each frame has its own generator, state and files).

    ``writers``: where a camera pair's files are encoded and written while the frame renders its
    next pair (encoders release the GIL); the frame's marker waits for all of them. None: in turn."""

    def __init__(
        self,
        folder: Path,
        cfg,
        backend: backends.Backend,
        sky,
        poses: np.ndarray,
        modalities: set[str],
        seed: int,
        writers: Executor | None = None,
        moving: bool = False,
    ):
        self.folder, self.cfg, self.backend, self.sky, self.poses = folder, cfg, backend, sky, poses
        # The sequence the job renders ends at its last rendered frame: no forward flow past it.
        self.frames = sequence_length(len(poses), cfg.render)
        self.modalities, self.seed, self.writers = modalities, seed, writers
        self.moving = moving  # the mesh moves (wind): each frame asks the backend for its neighbours' times too
        self.intr = Intrinsics.from_config(cfg.camera)
        self.sensor = Sensor.from_config(cfg.camera.sensor)  # None: the PNG is sRGB(exposure * I)
        self.fps = float(cfg.camera.trajectory.fps)
        self.options = WriteOptions.from_config(cfg.render)
        # Derived modalities are computed after the backend's view, from the passes they need.
        self.left_want = set(modalities) | {"depth"} | derived_inputs(modalities)
        right = camera_passes(modalities, "right")  # empty: no right view
        self.right_want = right | derived_inputs(right) if right else right

    def render(self, f: int) -> int:
        cfg, poses, modalities = self.cfg, self.poses, self.modalities
        written = {}
        pending = []  # the pairs' writes under way
        has_next, has_prev = f + 1 < self.frames, f > 0
        if self.moving:
            state = self.backend.frame(
                f / self.fps, (f - 1) / self.fps if has_prev else None, (f + 1) / self.fps if has_next else None
            )
        else:
            state = self.backend.frame(f / self.fps)
        whole_frame = self.moving and bool(cfg.camera.exposure_s) and "rgb" in modalities
        held = []  # with whole_frame: each pair's sharp views until the frame's exposure is rendered
        for k in range(poses.shape[1]):
            files = layout.frame_files(k, f, modalities, self.options, has_next, has_prev)
            views = {
                "left": self.backend.render_view(
                    state,
                    self.intr,
                    poses[f, k, 0],
                    want=self.left_want,
                    pose_next=poses[f + 1, k, 0] if has_next else None,
                    pose_prev=poses[f - 1, k, 0] if has_prev else None,
                    rng=rng_for(self.seed, "render", cfg.lighting.name, f, k, "left"),
                    rgb_spp=int(cfg.render.rgb_spp),
                )
            }
            if self.right_want:
                views["right"] = self.backend.render_view(
                    state,
                    self.intr,
                    poses[f, k, 1],
                    want=self.right_want,
                    rng=rng_for(self.seed, "render", cfg.lighting.name, f, k, "right"),
                    rgb_spp=int(cfg.render.rgb_spp),
                    partner=views["left"],
                )
            written[str(k)] = files
            if whole_frame:
                held.append((views, files, k))
                continue
            self.expose(state, views, f, k)
            pending.append(self.write(views, files, f, k))
        if whole_frame:
            # Motion blur of a moving mesh: every view of the frame sample by sample, the mesh moved
            # once per sub-frame time (render.backends.raytrace.MovingScenes.exposure_at).
            self.expose_pairs(state, [(views, k) for views, _, k in held], f)
            pending += [self.write(views, files, f, k) for views, files, k in held]
        for write in pending:
            if write is not None:
                write.result()  # every file is on disk (a failed write raises here) before the frame's marker
        layout.write_marker(self.folder, f, f / self.fps, written)
        return f

    def write_pair(
        self, views: dict[str, dict[str, np.ndarray]], files: dict[str, str], frame: int = 0, pair: int = 0
    ) -> None:
        """A camera pair's display RGB and derived passes, and its files (``files``: column -> path)."""
        if "rgb" in self.modalities:
            for camera, view in views.items():
                view["rgb"] = self.display_rgb(view, frame, pair, camera)
        for camera, view in views.items():
            add_derived(view, self.modalities, camera)
        data = {column: views[COLUMNS[column].camera][COLUMNS[column].source] for column in files}
        layout.write_files(self.folder, files, data, self.options)

    def write(self, views: dict[str, dict[str, np.ndarray]], files: dict[str, str], frame: int, pair: int):
        """Write a pair's files, on a writer thread when there are any (its future), else now (None)."""
        if self.writers is None:
            self.write_pair(views, files, frame, pair)
            return None
        return self.writers.submit(self.write_pair, views, files, frame, pair)

    def expose(self, state, views: dict[str, dict[str, np.ndarray]], frame: int, pair: int) -> None:
        """With a rolling shutter or motion blur, each view's display RGB over its exposure
        (``rgb_exposed``; docs/design.md, Camera effects): rows from the poses of
        ``camera.shutter.exposure_poses``, its own generator, so the sharp passes stay as they were."""
        self.expose_pairs(state, [(views, pair)], frame)

    def expose_pairs(self, state, pairs: list[tuple[dict[str, dict[str, np.ndarray]], int]], frame: int) -> None:
        """``expose`` for several pairs of one frame at once: the backend renders their views over the
        same sub-frame times together (``Backend.render_exposed_views``)."""
        cam = self.cfg.camera
        if "rgb" not in self.modalities or not exposure_effects_on(cam):
            return
        samples = int(cam.blur_samples)
        todo = []  # (view, (its pose samples, its generator))
        for views, pair in pairs:
            # The poses as rig.json publishes them: a user's exposure_poses of those is exactly what is traced.
            published = published_poses(self.poses[:, pair])
            for camera, view in views.items():
                if "rgb_linear" not in view:
                    continue  # a view for other passes (depth_right) only
                side = 0 if camera == "left" else 1
                poses = exposure_poses(
                    published[:, side], self.fps, frame, self.intr.height, cam.readout_s, cam.exposure_s, samples
                )
                todo.append(
                    (view, (poses, rng_for(self.seed, "exposure", self.cfg.lighting.name, frame, pair, camera)))
                )
        exposed = self.backend.render_exposed_views(
            state,
            self.intr,
            [job for _, job in todo],
            sample_offsets(cam.exposure_s, samples),
            rgb_spp=int(self.cfg.render.rgb_spp),
        )
        for (view, _), rgb in zip(todo, exposed, strict=True):
            view["rgb_exposed"] = rgb

    def display_rgb(self, view: dict[str, np.ndarray], frame: int, pair: int, camera: str) -> np.ndarray:
        """The PNG of one view: sRGB(exposure * I), or through the sensor model when it is on (its
        noise seeded per lighting, frame, pair and camera, so a frame rendered again is the same)."""
        exposed = view.get("rgb_exposed", view["rgb_linear"]) * self.sky.exposure
        if self.sensor is None:
            return srgb8_codes(exposed)
        rng = rng_for(self.seed, "sensor", self.cfg.lighting.name, frame, pair, camera)
        return self.sensor.apply(exposed, self.intr, rng)


# With wind, each frame thread holds three scenes of its own (docs/design.md, "Wind"): ``render.workers``
# 0 (one per core) then means at most this many frame threads, the rest of the cores going to Embree.
MOVING_FRAME_THREADS = 2


def worker_layout(render_cfg, n_frames: int, moving: bool = False) -> tuple[int, int]:
    """(frame threads, backend threads per frame thread), within the backend's ``max_frame_threads``.

    Frames render in threads that share one Embree scene: Embree and numpy's large-array
    kernels release the GIL, so two frame threads ran 1.43x faster than one on 2 cores,
    where two processes (one BVH each, competing for cache and memory) gained only 1.15x.
    ``moving``: the mesh moves (wind), and an automatic count stops at ``MOVING_FRAME_THREADS``.
    """
    cores = os.cpu_count() or 1
    limit = backends.get(render_cfg.backend).max_frame_threads
    if limit == 1:
        return 1, 1  # e.g. one pybullet client: not safe to share between threads
    threads = int(render_cfg.threads) or cores
    workers = int(render_cfg.workers) or (min(cores, MOVING_FRAME_THREADS) if moving else cores)
    workers = max(1, min(workers, n_frames, threads, limit or n_frames))
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


def render_frames(
    folder: Path, cfg, scene_art: Artifact, traj_art: Artifact, progress: bool, sky_visibility: Artifact | None = None
) -> dict:
    poses = load_poses(traj_art)
    n_frames = sequence_length(len(poses), cfg.render)
    backend_cls = backends.get(cfg.render.backend)
    # Passes the backend cannot make are omitted (empty manifest paths).
    modalities = set(cfg.render.modalities) & producible(backend_cls.capabilities)
    todo = layout.unfinished(folder, n_frames)
    seed = read_scene(scene_art).seed
    sky, params = make_sky(cfg.lighting, seed)
    wind = draw_wind(cfg.lighting, seed)
    if wind is not None:
        modalities |= {"dynamic"} & producible(backend_cls.capabilities)  # which pixels move, and by how much
    # What the sky derived (direct light, environment map, scenery; published in lighting.json).
    sun = sky.facts()
    facts = {
        "frames": n_frames,
        "rendered": len(todo),
        "exposure": float(sky.exposure),
        "sun": sun,
        "lighting": {
            k: (float(v) if isinstance(v, (int, float, np.floating)) else v) for k, v in params.__dict__.items()
        },
        **({} if wind is None else {"wind": wind.facts()}),
    }
    if not todo:
        return facts
    start = time.perf_counter()
    _, arrays = load_scene(scene_art)
    if sky_visibility is not None:
        arrays.sky_visibility = load_sky_visibility(sky_visibility)
    workers, threads = worker_layout(cfg.render, len(todo), moving=wind is not None)
    moving = {}
    if wind is not None:
        moving = {
            "wind": WindField.build(arrays.mesh, arrays.instance, wind, seed),
            "frame_threads": workers,
            "blur": bool(cfg.camera.exposure_s) and "rgb" in modalities,  # foliage blurs too
        }
    backend = backend_cls(arrays, sky, cfg.render, modalities=modalities, threads=threads, **moving)  # the BVH
    # One writer per frame thread: a frame's encoders run beside its next pair's rays and shading.
    writers = ThreadPoolExecutor(workers, thread_name_prefix="render-writer")
    renderer = FrameRenderer(folder, cfg, backend, sky, poses, modalities, seed, writers, moving=bool(moving))
    # A moving mesh: each frame thread takes a run of consecutive frames, so its ring of scenes moves
    # one scene a frame (render.backends.raytrace.MovingScenes); otherwise frames go to whichever
    # thread is free.
    if moving:
        batches = [[int(f) for f in b] for b in np.array_split(np.asarray(todo), workers) if len(b)]
    else:
        batches = [[f] for f in todo]
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

                def run_batch(batch: list[int]) -> None:
                    for f in batch:
                        renderer.render(f)
                        bar.update()

                with ThreadPoolExecutor(workers) as pool:
                    try:
                        for _ in pool.map(run_batch, batches):
                            pass
                    except BaseException:  # Ctrl-C, SIGTERM or a failed frame: drop the queued frames
                        pool.shutdown(wait=True, cancel_futures=True)  # (running ones finish and are kept)
                        raise
    finally:
        writers.shutdown(wait=True)
        backend.close()
    bar.close()
    seconds = time.perf_counter() - start
    # setup_seconds: scene load and BVH build, once per job; seconds_per_frame: the frames alone.
    return {
        **facts,
        "setup_seconds": round(setup, 3),
        "seconds_per_frame": round(seconds / len(todo), 4),
        "workers": workers,
    }
