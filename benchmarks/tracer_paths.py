"""The two ray-tracing paths (render.tracer: embreex vs native) on a cached garden, same process.

Loads the scene and trajectory a stage cache holds (run benchmarks/render_throughput.py first),
builds one tracer of each path and, for camera views of the trajectory, times each kind of query
the renderer makes through both, interleaved (A, B, A, B, ...; the minimum of each), and checks
the hits are the same bit for bit:

- primary: the pixel-centre rays of a view (native: image packets);
- shadow: sun shadow rays from the hit pixels (native: masked packets in tile order), and the
  same rays as a plain batch (native: one at a time);
- flow: the forward flow's occlusion rays (``view.flow_to``; native: masked packets), alone and with
  the rest of ``flow_to``;
- bounce: cosine-distributed rays from the hits (incoherent; one at a time on both paths).

It also counts the hits whose per-face normal (``embree_kernels.face_normals``) differs from the
normal Embree returned, and the normal-PNG pixels that differ.

    python benchmarks/tracer_paths.py --root /work/cache/bench [--views 2] [--repeats 3]
    python benchmarks/tracer_paths.py --root /work/cache/bench --build native   # BVH time, peak RSS
"""

from __future__ import annotations

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.camera.rig import Intrinsics  # noqa: E402
from eden_pipe.config import make_cfg  # noqa: E402
from eden_pipe.render import vec  # noqa: E402
from eden_pipe.render.embree import RayTracer, unit_normals  # noqa: E402
from eden_pipe.render.offsets import leave  # noqa: E402
from eden_pipe.render.view import flow_to, primary_rays  # noqa: E402
from eden_pipe.scene.arrays import SceneArrays  # noqa: E402


def newest(folder: Path, name: str) -> Path:
    found = sorted(folder.glob(f"*/{name}"), key=lambda p: p.stat().st_mtime)
    if not found:
        raise SystemExit(f"no {name} under {folder}: build the stage cache first")
    return found[-1]


def load(root: Path) -> tuple[SceneArrays, np.ndarray]:
    from eden_pipe.models.mesh import Mesh

    with np.load(newest(root / "stages" / "scene", "geometry.npz")) as data:
        mesh = Mesh.from_npz_dict(data)
        arrays = SceneArrays(mesh, data["instance"].astype(np.uint16))
    return arrays, np.load(newest(root / "stages" / "trajectory", "poses.npy"))


def rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def timed(fn, repeats: int, *variants):
    """Each variant's minimum time over ``repeats`` interleaved runs, and its last result."""
    best = [np.inf] * len(variants)
    results = [None] * len(variants)
    for _ in range(repeats):
        for i, variant in enumerate(variants):
            start = time.perf_counter()
            results[i] = fn(variant)
            best[i] = min(best[i], time.perf_counter() - start)
    return best, results


def report(name: str, best, same: str) -> None:
    print(
        f"{name:<26} embreex {best[0] * 1e3:8.1f} ms  native {best[1] * 1e3:8.1f} ms  x{best[0] / best[1]:5.2f}  {same}"
    )


def same_hits(a, b) -> str:
    ok = np.array_equal(a.prim, b.prim) and np.array_equal(a.t, b.t) and np.array_equal(a.normal, b.normal)
    return "identical" if ok else f"DIFFER ({int(np.sum(a.prim != b.prim))} prims)"


def png16(normal: np.ndarray) -> np.ndarray:
    """The normal PNG's encoding (io.formats.write_normal)."""
    valid = np.any(normal != 0, axis=-1, keepdims=True)
    return (np.round((np.clip(normal, -1, 1) + np.float32(1.0)) * np.float32(0.5 * 65535.0)) * valid).astype(np.uint16)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"))
    parser.add_argument("--views", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=0, help="tracer threads (0 = one per core)")
    parser.add_argument("--build", choices=("native", "embreex"), help="only build this path's BVH: time and RSS")
    args = parser.parse_args()
    arrays, poses = load(Path(args.root))
    mesh = arrays.mesh
    if args.build:
        before = rss_mib()
        start = time.perf_counter()
        tracer = RayTracer(mesh, tracer=args.build)
        print(
            f"{args.build}: {mesh.n_faces:,} faces, setup {time.perf_counter() - start:.2f} s, "
            f"peak RSS {rss_mib():.0f} MiB ({rss_mib() - before:+.0f} MiB over the loaded scene)"
        )
        tracer.close()
        return
    intr = Intrinsics.from_config(make_cfg(Path(args.root), ["progress=false"]).camera)
    old, new = RayTracer(mesh, args.threads, tracer="embreex"), RayTracer(mesh, args.threads, tracer="native")
    table = face_table(mesh)
    rng = np.random.default_rng(0)
    sun = vec.normalize(np.array([[0.35, -0.45, 0.82]], np.float32))
    for view in range(args.views):
        bench_view(view, poses, intr, old, new, table, sun, rng, args.repeats)
    old.close()
    new.close()


def bench_view(view, poses, intr, old, new, table, sun, rng, repeats: int) -> None:
    h, w = intr.height, intr.width
    frame, cam = divmod(view, poses.shape[1])
    pose, pose_next = poses[frame, cam, 0], poses[frame + 1, cam, 0]
    print(f"view {view} (frame {frame}, camera {cam}), {w} x {h}")
    o, d = primary_rays(intr, pose)
    o, d = o.astype(np.float32), d.astype(np.float32)
    best, (a, b) = timed(lambda t: t.intersect(o, d, image=(h, w)), repeats, old, new)
    report("primary (image packets)", best, same_hits(a, b))
    normals_against_table(a, table, d, pose)
    idx = np.nonzero(a.hit)[0]
    points = vec.gather(o, idx) + vec.gather(d, idx) * a.t[idx][:, None]
    side = vec.facing(vec.gather(a.normal, idx), vec.gather(d, idx))
    starts = leave(points, side, a.t[idx]).astype(np.float32)
    best, res = timed(lambda t: t.occluded(starts, sun, image=(h, w), pixels=idx), repeats, old, new)
    report("shadow (tile order)", best, "identical" if np.array_equal(*res) else "DIFFER")
    best, res = timed(lambda t: t.occluded(starts, sun), repeats, old, new)
    report("shadow (one at a time)", best, "identical" if np.array_equal(*res) else "DIFFER")
    unit = vec.normalize(d)
    pts = o + d * np.where(a.hit, a.t, 0.0)[:, None]
    rays = {id(old): [], id(new): []}  # the occlusion rays' own time in each flow_to call

    def flow(tracer):
        timer = OcclusionTimer(tracer)
        out = flow_to(intr, timer, pts, unit, a.hit, pose_next)
        rays[id(tracer)].append(timer.seconds)
        return out

    best, res = timed(flow, repeats, old, new)
    same = "identical" if np.array_equal(res[0][1], res[1][1]) else "DIFFER"
    report("flow_to (whole)", best, same)
    report("flow occlusion rays", [min(rays[id(old)]), min(rays[id(new)])], same)
    bounce = cosine_around(side, rng).astype(np.float32)
    best, (ba, bb) = timed(lambda t: t.intersect(starts, bounce), repeats, old, new)
    report("bounce (incoherent)", best, same_hits(ba, bb))


class OcclusionTimer:
    """A tracer that adds up the time its ``occluded`` calls take."""

    def __init__(self, tracer):
        self.tracer, self.seconds = tracer, 0.0

    def occluded(self, *args, **kwargs):
        start = time.perf_counter()
        out = self.tracer.occluded(*args, **kwargs)
        self.seconds += time.perf_counter() - start
        return out


def face_table(mesh) -> np.ndarray:
    from eden_pipe.render.embree_kernels import face_normals

    start = time.perf_counter()
    raw = face_normals(np.ascontiguousarray(mesh.vertices, np.float32), np.ascontiguousarray(mesh.faces, np.int32))
    unit = unit_normals(raw)
    print(f"face normal table: {time.perf_counter() - start:.2f} s for {len(unit):,} faces")
    return unit


def normals_against_table(hits, table: np.ndarray, d: np.ndarray, pose: np.ndarray) -> None:
    hit = hits.hit
    from_table = np.where(hit[:, None], np.take(table, np.where(hit, hits.prim, 0), axis=0), np.float32(0))
    differ = np.any(from_table != hits.normal, axis=1)
    unit = vec.normalize(d).astype(np.float32)
    rot = pose[:3, :3].astype(np.float32)
    png_a = png16(vec.facing(hits.normal, unit) @ rot)
    png_b = png16(vec.facing(from_table, unit) @ rot)
    print(
        f"{'':<26} face-table normals differ from Embree's on {int(differ.sum())} of {int(hit.sum())} hits; "
        f"normal PNG pixels that differ: {int(np.any(png_a != png_b, axis=1).sum())}"
    )


def cosine_around(normals: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    t, b = vec.orthonormal_basis(normals.astype(np.float64))
    u1, u2 = rng.random(len(normals)), rng.random(len(normals))
    r, phi = np.sqrt(u1), 2 * np.pi * u2
    return t * (r * np.cos(phi))[:, None] + b * (r * np.sin(phi))[:, None] + normals * np.sqrt(1 - u1)[:, None]


if __name__ == "__main__":
    main()
