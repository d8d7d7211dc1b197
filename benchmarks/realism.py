"""Lighting realism, measured on views never used for tuning (docs/realism.md, The protocol).

Two sets of views, defined once in ``PROTOCOLS``:

- ``tuning``: the default garden of seed 0, frame 0, the five left cameras, 1500 random non-sky
  pixels a view. Settings of the light model are chosen here and nowhere else.
- ``held-out``: default gardens of seeds 101, 102 and 103 (disjoint from the tuning garden's), three
  frames spread over each trajectory (its first, middle and last but one), the five left cameras,
  200 random non-sky pixels a view. Nothing is ever chosen on it: it reports.

Both at the camera's full 640 x 480 and under every lighting: the paper's five and ``hdr``, an HDR
environment map baked from the project's own cloudy sky with a seed of the set's own
(``scripts/gallery_environment.make_map``), as a user's map would be given.

Each variant (``--variant NAME=OVERRIDES``; ``current``: the config as given, always there) renders
the views' full left-camera stack, with a bake of its own where its overrides change the bake's
settings (``render.sky_visibility.*``); its linear RGB and shading layer at the sampled pixels are
compared with the reference there:

- ``--reference path`` (default): ``render.mode=reference`` path tracing (``--samples`` paths per
  pixel and side, in two halves of different seeds, ``--bounces``);
- ``--reference cycles``: Blender Cycles (``render.backend=cycles``'s worker, ``--cycles-samples``
  per render, two seeds); the variants and Cycles both without cloud shadows (Cycles' sun lamp has
  none). ``--reference both`` also scores the path tracer against Cycles, per class: its mean bias
  and its per-pixel error against Cycles' own seed-to-seed difference.

Errors, per lighting and per semantic class (pixels pooled over the set's gardens and views):
the mean absolute error relative to the reference's mean there, and the signed bias (mean / reference
mean - 1), for linear RGB (``I`` without exposure) and shading; the reference's halves' difference
(about twice its own error) beside them. A uniform pixel sample estimates a per-pixel mean without
bias at a fraction of the cost of whole reference images.

``--lawn-views K``: K views of each garden's lawn (looking down at it, most of each view grass) in place
of the trajectory's, for the class the trajectory's views see only at their feet.

Throughput: each variant's views are timed (the fastest of ``--repeats``); and the render stage's
own rate (``render_frames``: frame threads, left and right views, every file written) for each
variant on ``--job-frames`` frames of the first garden, in turns, as a ratio against the first
variant, in the same run.

    python benchmarks/realism.py [--set held-out|tuning] [--lightings clear,...,hdr]
        [--reference path|cycles|both] [--variant previous=render.mirror_rays=0.6 ...] [overrides ...]

The last line, for the held-out set:
``held-out per-pixel error vs reference: overall X, worst class Y (NAME)``: X the worst lighting's
error (over linear RGB and shading), Y the worst (lighting, class, layer) over classes with at least
1 % of the lighting's pixels, for the ``current`` variant.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import inspect
import json
import sys
import time
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.realism_report import Pool, job_throughput, report, score  # noqa: E402
from eden_pipe import labels  # noqa: E402
from eden_pipe.camera.rig import Intrinsics, look_rotation  # noqa: E402
from eden_pipe.config import make_cfg, to_config, to_plain  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.render.backends.cycles import FOOTPRINT_REACH_PX  # noqa: E402
from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.pathtrace import reference_shade  # noqa: E402
from eden_pipe.render.view import primary_rays, render_view  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402
from eden_pipe.stages.scene import load_scene  # noqa: E402
from eden_pipe.stages.sky_visibility import load_sky_visibility  # noqa: E402
from eden_pipe.stages.trajectory import load_poses  # noqa: E402

LIGHTINGS = ("clear", "cloudy", "overcast", "sunset", "twilight", "hdr")
LEFT = {"rgb", "semantic", "instance", "depth", "normal", "flow", "albedo", "shading", "translucency"}
LAYERS = ("linear", "shading")


@dataclass(frozen=True)
class Protocol:
    """A set of views: gardens, frames per trajectory, pixels per view, the HDR map's seed."""

    seeds: tuple[int, ...]
    frames: int  # spread over the trajectory: first, ..., last but one (its forward flow needs the next)
    pixels: int
    map_seed: int

    def frame_indices(self, n_frames: int) -> list[int]:
        if self.frames == 1:
            return [0]
        return sorted({int(round(f)) for f in np.linspace(0, n_frames - 2, self.frames)})


PROTOCOLS = {
    "tuning": Protocol(seeds=(0,), frames=1, pixels=1500, map_seed=10),
    "held-out": Protocol(seeds=(101, 102, 103), frames=3, pixels=200, map_seed=20),
}


def pixel_sample(seed: int, frame: int, camera: int, hit: np.ndarray, pixels: int) -> np.ndarray:
    """The protocol's pixels of a view: a seeded uniform sample (sorted) of its hit pixels ``hit`` (bool)."""
    rng = rng_for(seed, "realism", "pixels", frame, camera)
    hits = np.nonzero(hit)[0]
    return np.sort(rng.choice(hits, min(pixels, len(hits)), replace=False))


def one_face_pixels(tracer, intr, pose, pick: np.ndarray, prim: np.ndarray, reach: float) -> np.ndarray:
    """Whether each pixel of ``pick`` sees its centre ray's face ``prim`` (-1: the sky) at eight points
    ``reach`` pixels from its centre, the edge of a Cycles pixel's footprint: where it does not, Cycles'
    pixel blends two faces while the path tracer takes the centre ray, and the two are not compared
    (docs/realism.md, The path tracer against Cycles)."""
    v, u = np.divmod(pick, intr.width)
    same = np.ones(len(pick), bool)
    for du, dv in ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)):
        dirs = intr.camera_rays(u + du * reach, v + dv * reach).reshape(-1, 3) @ pose[:3, :3].T
        hits = tracer.intersect(np.ascontiguousarray(np.broadcast_to(pose[:3, 3], dirs.shape)), dirs)
        same &= np.where(hits.hit, hits.prim, -1) == prim
    return same


def lawn_views(mesh, tracer, intr, seed: int, count: int, tries: int = 400) -> np.ndarray:
    """(2, count, 2, 4, 4) poses shaped as a trajectory's (two still frames, left = right): cameras 0.9 m
    above random points of the garden's lawn, 0.9 m back at a random heading, looking down at them at
    45 degrees, kept where at least 60 % of the view is grass (``--lawn-views``: a class that the
    trajectory's views see at their feet only)."""
    rng = rng_for(seed, "realism", "lawn")
    grass = np.nonzero(mesh.semantic == labels.GRASS)[0]
    centres = mesh.vertices[mesh.faces[grass]].mean(axis=1)
    kept: list[np.ndarray] = []
    for _ in range(tries if len(grass) else 0):
        target = centres[rng.integers(len(centres))]
        heading = rng.uniform(0.0, 2.0 * np.pi)
        pose = np.eye(4)
        pose[:3, :3] = look_rotation(heading, -np.pi / 4)
        pose[:3, 3] = target + np.array([-0.9 * np.cos(heading), -0.9 * np.sin(heading), 0.9])
        hits = tracer.intersect(*primary_rays(intr, pose))
        if np.sum(mesh.semantic[hits.prim[hits.hit]] == labels.GRASS) >= 0.6 * len(hits.hit):
            kept.append(pose)
        if len(kept) == count:
            break
    if len(kept) < count:
        raise SystemExit(f"--lawn-views {count}: garden {seed} gave {len(kept)} views of its lawn")
    return np.broadcast_to(np.stack(kept)[None, :, None], (2, count, 2, 4, 4)).copy()


def render_left(tracer, arrays, intr, poses, frame: int, camera: int, sky, settings, seed: int, lighting: str):
    """A view's full left-camera stack, as the render stage draws it (its own generator)."""
    return render_view(
        tracer,
        arrays,
        intr,
        poses[frame, camera, 0],
        sky,
        want=LEFT,
        pose_next=poses[frame + 1, camera, 0],
        settings=settings,
        rng=rng_for(seed, "render", lighting, frame, camera, "left"),
    )


def reference_key(seed: int, lighting: str, frame: int, camera: int, pixels: int, intr) -> str:
    """A view's name in ``reference_cache/`` (the renderer's settings follow it)."""
    return f"{seed}_{lighting}_{frame}_{camera}_{pixels}_{intr.width}x{intr.height}"


class Unclouded:
    """Cloud shadows off (the Cycles comparison: its sun lamp has none)."""

    def transmittance(self, points: np.ndarray) -> np.ndarray:
        return np.ones(len(np.asarray(points).reshape(-1, 3)), np.float32)


def lighting_overrides(lighting: str, root: Path, protocol: Protocol) -> list[str]:
    if lighting != "hdr":
        return [f"lighting={lighting}"]
    from scripts.gallery_environment import make_map

    path = root / f"hdr_sky_{protocol.map_seed}.hdr"
    if not path.exists():
        root.mkdir(parents=True, exist_ok=True)
        make_map(path, 1024, protocol.map_seed)
    return ["lighting=cloudy", f"lighting.environment={path}"]


class CyclesReference:
    """Cycles renders of whole views (the ``render=cycles`` worker), read at the sampled pixels."""

    def __init__(self, mesh, samples: int, bounces: int, python: str):
        from eden_pipe.render.backends.cycles import CyclesProcess

        self.process = CyclesProcess(python)
        self.process.call(
            "scene",
            {k: getattr(mesh, k) for k in ("vertices", "faces", "albedo", "translucency", "specular")},
        )
        self.samples, self.bounces = samples, bounces
        self.seconds, self.renders = 0.0, 0  # renders: one a seed and view (two Blender renders each)

    def world(self, sky, settings) -> None:
        from eden_pipe.render.backends.cycles import world_maps

        self.process.call("world", world_maps(sky, settings, settings.time, 1024))

    def halves(self, intr, pose, pick: np.ndarray, seeds: tuple[int, int]) -> dict[str, list[np.ndarray]]:
        from eden_pipe.render.backends.cycles import layers_from_passes

        out: dict[str, list[np.ndarray]] = {layer: [] for layer in LAYERS}
        for seed in seeds:
            self.process.call("settings", cycles_settings(self.samples, seed, self.bounces))
            t0 = time.perf_counter()
            passes, _ = self.process.render(intr, pose)
            self.seconds += time.perf_counter() - t0
            self.renders += 1
            layers = layers_from_passes(passes)
            for layer in LAYERS:
                out[layer].append(layers[layer].reshape(-1, 3)[pick])
        return out

    def close(self) -> None:
        self.process.close()


def flat_terrain() -> None:
    """Terrain as Cycles renders it: each face its own albedo and normal (the renderers' texture lookup is
    replaced for this process only)."""
    from eden_pipe.render import pathtrace, shading

    def untextured(material, points, albedo, normal):
        return albedo, normal

    shading.apply_terrain_textures = untextured
    pathtrace.apply_terrain_textures = untextured


# The modules whose source decides a reference's values (not their imports: a change anywhere in the
# package would otherwise re-render hours of references that cannot have changed); "render.sky" stands for
# every module of that folder.
REFERENCE_CODE = {
    "path": (
        "eden_pipe.render.pathtrace",
        "eden_pipe.render.shading",
        "eden_pipe.render.kernels",
        "eden_pipe.render.offsets",
        "eden_pipe.render.textures",
        "eden_pipe.render.vec",
        "eden_pipe.render.embree",
        "eden_pipe.render.backends.raytrace",
        "eden_pipe.camera.rig",
        "eden_pipe.render.sky",
    ),
    "cycles": (
        "eden_pipe.render.backends.cycles",
        "eden_pipe.render.backends.cycles_worker",
        "eden_pipe.render.backends.raytrace",
        "eden_pipe.camera.rig",
        "eden_pipe.render.sky",
    ),
}


def reference_tag(kind: str, mesh, poses: np.ndarray, intr, lighting, settings: dict | None = None) -> str:
    """A short hash of what a cached ``kind`` reference ("path" or "cycles") depends on beyond its name:
    the source of its renderer (``REFERENCE_CODE`` and this benchmark's function that calls it), the
    mesh's arrays, the views' poses, the intrinsics, the ``lighting`` config and its environment map's
    bytes, and the renderer's ``settings`` beyond those in the file's name. A change to any of them
    renders afresh instead of reading another code's or scene's values."""
    digest = hashlib.sha256()
    for name in REFERENCE_CODE[kind]:
        spec = importlib.util.find_spec(name)
        assert spec is not None and spec.origin, name
        origin = Path(spec.origin)
        files = sorted(origin.parent.glob("*.py")) if origin.name == "__init__.py" else [origin]
        for file in files:
            digest.update(file.name.encode() + b"\0" + file.read_bytes())
    digest.update(inspect.getsource(path_reference if kind == "path" else CyclesReference).encode())
    for key in ("vertices", "faces", "semantic", "material", "albedo", "translucency", "specular"):
        digest.update(np.ascontiguousarray(getattr(mesh, key)).tobytes())
    digest.update(np.ascontiguousarray(poses, np.float64).tobytes())
    intrinsics = (intr.width, intr.height, intr.fx, intr.fy, intr.cx, intr.cy)
    digest.update(json.dumps([intrinsics, to_plain(lighting), settings], sort_keys=True, default=str).encode())
    if lighting.environment:
        digest.update(Path(lighting.environment).read_bytes())
    return digest.hexdigest()[:12]


def reference_file(
    root: Path, kind: str, key: str, tag: str, samples: int, bounces: int = 0, flat: bool = False
) -> Path:
    """Where a view's cached ``kind`` reference lives: its ``reference_key``, its renderer's settings and
    its ``reference_tag``."""
    if kind == "cycles":
        return root / "reference_cache" / f"cycles_{key}_{samples}_{tag}.npz"
    return root / "reference_cache" / f"path_{key}_{samples}_{bounces}{'_flat' if flat else ''}_{tag}.npz"


def cached(path: Path, compute) -> dict[str, np.ndarray]:
    """A view's reference values, computed once per code, scene and settings (the reference is the slow
    part: later runs of the same set and settings re-render only the variants; ``path``'s name carries
    ``reference_tag``)."""
    if path.exists():
        with np.load(path) as f:
            return {k.replace("|", "/"): f[k] for k in f.files}
    values = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, **{k.replace("/", "|"): v for k, v in values.items()})
    return values


def path_reference(tracer, mesh, o, d, sky, settings, args, names) -> dict[str, np.ndarray]:
    """The path-traced reference at rays ``o``, ``d``: two halves of ``--samples`` with their own seeds."""
    hits = tracer.intersect(o, d)
    settings = replace(
        settings, mode="reference", reference_samples=max(1, args.samples // 2), reference_bounces=args.bounces
    )
    out = {}
    for half in ("half1", "half2"):
        rng = rng_for(names[0], "realism", "reference", *names[1:], half)
        ref = reference_shade(tracer, mesh, hits, o, d, sky, settings, rng, layers=("shading",))
        for layer in LAYERS:
            out[f"path_{half}/{layer}"] = ref[layer]
    return out


def cycles_reference(cyc, intr, pose, pick) -> dict[str, np.ndarray]:
    got = cyc.halves(intr, pose, pick, (1, 2))
    out = {}
    for layer in LAYERS:
        out[f"cycles_half1/{layer}"], out[f"cycles_half2/{layer}"] = got[layer]
    return out


def cycles_settings(samples: int, seed: int, bounces: int | None = None) -> dict:
    """The Cycles worker's settings for a reference render: ``render.cycles`` defaults, CPU, unclamped;
    with ``bounces``, the path tracer's limit as Cycles' total, diffuse and transmission limits. The path
    tracer ends a path only at its total, while Cycles also ends one at its diffuse or transmission limit
    (a translucent scattering counts as a transmission, not a diffuse bounce), so the two estimate the
    same light only with those limits at least the total (docs/realism.md, Cycles)."""
    from eden_pipe.config.schema import CyclesConfig
    from eden_pipe.render.backends.cycles import worker_settings

    limits = (
        {} if bounces is None else dict.fromkeys(("max_bounces", "diffuse_bounces", "transmission_bounces"), bounces)
    )
    return worker_settings(CyclesConfig(samples=samples, seed=seed, **limits))


def variant_bakes(root: Path, gbase: list[str], variants: dict, garden_bake, vis) -> dict:
    """{variant: its bake}: the garden's own (``vis``, the artifact ``garden_bake``) unless the
    variant's overrides change the bake's key, else its own, built or read from the stage cache."""
    bakes = {}
    for name, overrides in variants.items():
        vcfg = to_config(make_cfg(root, gbase + overrides))
        varts = run_stages(vcfg, StageCache(vcfg.paths.stages, set()), through="sky_visibility")
        same = varts["sky_visibility"].path == garden_bake.path
        bakes[name] = vis if same else load_sky_visibility(varts["sky_visibility"])
        if not same:
            print(f"  {name}: a bake of its own ({varts['sky_visibility'].marker()['bake_seconds']:.0f} s)")
    return bakes


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--set", default="held-out", choices=tuple(PROTOCOLS))
    ap.add_argument("--lightings", default=",".join(LIGHTINGS))
    ap.add_argument("--reference", default="path", choices=("path", "cycles", "both"))
    ap.add_argument("--samples", type=int, default=2048, help="reference paths per pixel and side")
    ap.add_argument("--bounces", type=int, default=6, help="reference bounces per path")
    ap.add_argument("--cycles-samples", type=int, default=512, help="Cycles paths per pixel and render")
    ap.add_argument("--cycles-python", default="", help="render.cycles.python for the Cycles reference")
    ap.add_argument(
        "--flat-terrain",
        action="store_true",
        help="terrain textures and bump off in every render compared (Cycles shades faces with their own albedo)",
    )
    ap.add_argument("--pixels", type=int, default=0, help="sampled pixels per view (0: the set's)")
    ap.add_argument("--gardens", default="", help="garden seeds (default: the set's)")
    ap.add_argument("--frames", type=int, default=0, help="frames a trajectory (0: the set's)")
    ap.add_argument("--cameras", default="", help="left cameras, e.g. 0,2,4 (default: all five)")
    ap.add_argument(
        "--lawn-views", type=int, default=0, help="this many views of each garden's lawn instead of its trajectory"
    )
    ap.add_argument("--variant", action="append", default=[], help="NAME=OVERRIDE[,OVERRIDE...] (repeatable)")
    ap.add_argument("--repeats", type=int, default=1, help="timed renders of each view and variant (fastest)")
    ap.add_argument("--job-frames", type=int, default=8, help="render-stage throughput frames (0: skip)")
    ap.add_argument("--root", default=str(REPO / "outputs" / "bench_realism"), help="stage cache")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides for every variant, e.g. render.mirror_rays=0.5")
    args = ap.parse_args()

    protocol = PROTOCOLS[args.set]
    if args.flat_terrain:
        flat_terrain()
    if args.pixels:
        protocol = replace(protocol, pixels=args.pixels)
    if args.frames:
        protocol = replace(protocol, frames=args.frames)
    if args.gardens:
        protocol = replace(protocol, seeds=tuple(int(s) for s in args.gardens.split(",")))
    root = Path(args.root)
    variants = {"current": []}
    for spec in args.variant:
        name, _, overrides = spec.partition("=")
        variants[name] = [o for o in overrides.split(",") if o]
    lightings = [x for x in args.lightings.split(",") if x]
    unknown = sorted(set(lightings) - set(LIGHTINGS))
    if unknown:
        raise SystemExit(f"--lightings: {', '.join(unknown)} not among {', '.join(LIGHTINGS)}")
    base = ["progress=false", "camera.trajectory.share_across_lightings=true", *args.overrides]
    with_cycles = args.reference in ("cycles", "both")
    with_path = args.reference in ("path", "both")
    print(
        f"set {args.set}: gardens {protocol.seeds}, {protocol.frames} frame(s) a trajectory, 5 left cameras, "
        f"{protocol.pixels} pixels a view; lightings {', '.join(lightings)}; reference {args.reference} "
        f"(path: {args.samples} samples in two halves, {args.bounces} bounces; cycles: {args.cycles_samples} "
        f"samples, two seeds); variants {variants}",
        flush=True,
    )

    pool = Pool()
    seconds = dict.fromkeys(variants, 0.0)
    views_timed = 0
    first_arts = None
    for seed in protocol.seeds:
        gbase = base + [f"garden.seed={seed}"]
        cfg = to_config(make_cfg(root, gbase))
        cache = StageCache(cfg.paths.stages, set())
        t0 = time.perf_counter()
        arts = run_stages(cfg, cache, through="sky_visibility")
        first_arts = first_arts or (gbase, arts)
        bake = arts["sky_visibility"].marker()
        print(
            f"garden {seed}: stages {time.perf_counter() - t0:.0f} s (bake {bake['bake_seconds']:.0f} s "
            f"+ BVH {bake['bvh_seconds']:.0f} s, {'cached' if arts['sky_visibility'].cached else 'built'})",
            flush=True,
        )
        _, arrays = load_scene(arts["scene"])
        vis = load_sky_visibility(arts["sky_visibility"])
        bakes = variant_bakes(root, gbase, variants, arts["sky_visibility"], vis)
        poses = load_poses(arts["trajectory"])
        intr = Intrinsics.from_config(cfg.camera)
        tracer = RayTracer(arrays.mesh)
        cameras = [int(c) for c in args.cameras.split(",")] if args.cameras else list(range(poses.shape[1]))
        views = [(f, k) for f in protocol.frame_indices(len(poses)) for k in cameras]
        if args.lawn_views:
            poses = lawn_views(arrays.mesh, tracer, intr, seed, args.lawn_views)
            views = [(0, k) for k in range(args.lawn_views)]
        picks = {}
        for f, k in views:
            o, d = primary_rays(intr, poses[f, k, 0])
            hits = tracer.intersect(o, d)
            pick = pixel_sample(seed, f, k, hits.hit, protocol.pixels)
            one_face = (
                one_face_pixels(tracer, intr, poses[f, k, 0], pick, hits.prim[pick], FOOTPRINT_REACH_PX)
                if with_cycles
                else np.ones(len(pick), bool)
            )
            picks[f, k] = (pick, arrays.mesh.semantic[hits.prim[pick]], one_face)
        cyc = (
            CyclesReference(arrays.mesh, args.cycles_samples, args.bounces, args.cycles_python) if with_cycles else None
        )
        try:
            for lighting in lightings:
                extra = lighting_overrides(lighting, root, protocol)
                lcfg = to_config(make_cfg(root, gbase + extra))
                sky, _ = make_sky(lcfg.lighting, seed)
                cycles_setup = cycles_settings(args.cycles_samples, 0, args.bounces)
                tags = {
                    "path": reference_tag("path", arrays.mesh, poses, intr, lcfg.lighting),
                    "cycles": reference_tag("cycles", arrays.mesh, poses, intr, lcfg.lighting, cycles_setup),
                }
                vcfgs = {name: to_config(make_cfg(root, gbase + extra + o)) for name, o in variants.items()}
                regions = cloud_map_regions(arrays.mesh)
                t_ref = 0.0
                for f in sorted({f for f, _ in views}):
                    t = f / float(cfg.camera.trajectory.fps)
                    frame = {}  # each variant's settings for the frame: its per-probe light shared by its views
                    for name, vcfg in vcfgs.items():
                        frame[name] = frame_settings(
                            vcfg.render, sky, t, regions, bakes[name] if vcfg.render.sky_visibility.enabled else None
                        )
                    ref_settings = frame_settings(lcfg.render, sky, t, regions, None)
                    if with_cycles:
                        frame = {name: replace(st, clouds=Unclouded()) for name, st in frame.items()}
                        ref_settings = replace(ref_settings, clouds=Unclouded())
                        cyc.world(sky, ref_settings)
                    for k in sorted(k for g, k in views if g == f):
                        pose = poses[f, k, 0]
                        pick, classes, one_face = picks[f, k]
                        record = {"lighting": lighting, "garden": seed, "classes": classes, "one_face": one_face}
                        for name, settings in frame.items():
                            fastest = np.inf
                            for _ in range(max(1, args.repeats)):
                                t0 = time.perf_counter()
                                out = render_left(tracer, arrays, intr, poses, f, k, sky, settings, seed, lighting)
                                fastest = min(fastest, time.perf_counter() - t0)
                            seconds[name] += fastest
                            for layer in LAYERS:
                                record[f"{name}/{layer}"] = out[layer].reshape(-1, 3)[pick]
                        views_timed += 1
                        o, d = primary_rays(intr, pose)
                        o, d = o[pick], d[pick]
                        t0 = time.perf_counter()
                        key = reference_key(seed, lighting, f, k, protocol.pixels, intr) + (
                            "_lawn" * bool(args.lawn_views)
                        )
                        if with_path:
                            record |= cached(
                                reference_file(
                                    root, "path", key, tags["path"], args.samples, args.bounces, args.flat_terrain
                                ),
                                partial(
                                    path_reference,
                                    tracer,
                                    arrays.mesh,
                                    o,
                                    d,
                                    sky,
                                    ref_settings,
                                    args,
                                    (seed, lighting, f, k),
                                ),
                            )
                        if cyc is not None:
                            record |= cached(
                                reference_file(root, "cycles", key, tags["cycles"], args.cycles_samples),
                                partial(cycles_reference, cyc, intr, pose, pick),
                            )
                        t_ref += time.perf_counter() - t0
                        pool.add(record)
                print(f"  {lighting}: {len(views)} views, reference {t_ref:.0f} s", flush=True)
        finally:
            if cyc is not None:
                print(
                    f"  Cycles: {cyc.seconds:.0f} s for {cyc.renders} renders of a view, the others cached "
                    f"({cyc.seconds / max(1, cyc.renders):.1f} s a view and seed at {intr.width} x {intr.height}, "
                    f"{args.cycles_samples} samples, two Blender renders each)",
                    flush=True,
                )
                cyc.close()
        tracer.close()

    reference = "cycles" if args.reference == "cycles" else "path"
    results = score(pool, list(variants), reference, compare_cycles=args.reference == "both")
    rate = {name: views_timed / max(seconds[name], 1e-9) for name in variants}
    job = None
    if args.job_frames > 0 and first_arts is not None:
        gbase, _ = first_arts
        job = job_throughput(
            root, gbase, lightings[:1], args.job_frames, variants, [lighting_overrides(lightings[0], root, protocol)]
        )
    report(results, args.set, rate, job, views_timed)


if __name__ == "__main__":
    main()
