"""Could flow occlusion come from the neighbouring frame's depth instead of occlusion rays?

The renderer marks a pixel of frame t occluded in frame t+1 when a segment
from its surface point to frame t+1's camera centre is blocked (an occlusion
ray per pixel: about 440 K rays a camera pair, ``render.view.flow_to``). A
cheaper method would read frame t+1's own primary hits, which that frame
traces anyway: project the point into frame t+1 and compare it with the hits
at the four pixel centres around its projection. This script measures how
often that test agrees with the rays, for two rules:

- sure visible: all four pixel centres hit the point's own face, at a depth
  within ``tol`` (relative) of the point's depth in frame t+1;
- sure occluded: all four hit other faces, nearer by more than ``tol`` and 1 cm.

Pixels the rules leave undecided would still need their ray. Cameras are split
into tuning cameras (to choose ``tol``) and held-out cameras (the figures to
report); every frame pair of the trajectory is used. The geometry stages come
from the root's stage cache (built on first use).

    python benchmarks/flow_occlusion_depth.py --root /work/cache/bench [--frames 11] [--tune-cameras 2]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from eden_pipe.camera.rig import Intrinsics  # noqa: E402
from eden_pipe.config import make_cfg  # noqa: E402
from eden_pipe.models.mesh import Mesh  # noqa: E402
from eden_pipe.pipeline import run_job  # noqa: E402
from eden_pipe.render import vec  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.view import flow_to, primary_rays  # noqa: E402

TOLERANCES = (0.002, 0.005, 0.01)


def neighbour_test(intr: Intrinsics, points, hits, flow, hits_next, pose_next, tol: float):
    """(checked, sure visible, sure occluded) masks of one view for one tolerance."""
    h, w = intr.height, intr.width
    rot, centre = pose_next[:3, :3], pose_next[:3, 3]
    z = ((points - centre) @ rot)[:, 2]  # the point's depth in the next camera
    u = np.tile(np.arange(w), h) + flow[:, 0]
    v = np.repeat(np.arange(h), w) + flow[:, 1]
    checked = hits.hit & (z > 0) & (u >= 0) & (u <= w - 1) & (v >= 0) & (v <= h - 1)
    u0 = np.clip(np.floor(u).astype(np.int64), 0, w - 2)
    v0 = np.clip(np.floor(v).astype(np.int64), 0, h - 2)
    corners = [(v0 + dv) * w + (u0 + du) for dv in (0, 1) for du in (0, 1)]
    prim = np.stack([hits_next.prim[c] for c in corners])
    t = np.stack([hits_next.t[c] for c in corners])
    own = prim == hits.prim[None]
    visible = checked & np.all(own, axis=0) & np.all(np.abs(t - z) <= tol * z, axis=0)
    occluded = checked & np.all(~own, axis=0) & np.all(t < z * (1 - tol) - 0.01, axis=0)
    return checked, visible, occluded


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="stage cache root")
    parser.add_argument("--frames", type=int, default=11, help="trajectory frames (frames - 1 frame pairs)")
    parser.add_argument("--tune-cameras", type=int, default=2, help="cameras 0..N-1 tune; the rest are held out")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    threadpool_limits(1)
    overrides = ["progress=false", f"camera.trajectory.frames=[{args.frames},{args.frames}]", "render.max_frames=1"]
    cfg = make_cfg(Path(args.root), [*overrides, *args.overrides])
    result = run_job(cfg, echo=lambda *_: None)
    poses = np.load(result.artifacts["trajectory"].path / "poses.npy")
    with np.load(result.artifacts["scene"].path / "geometry.npz") as data:
        mesh = Mesh.from_npz_dict(data)
    intr = Intrinsics.from_config(cfg.camera)
    counts: dict[tuple[str, float], np.ndarray] = {}
    with RayTracer(mesh) as tracer:
        for cam in range(poses.shape[1]):
            group = "tuning" if cam < args.tune_cameras else "held-out"
            hits_next = None
            for frame in range(poses.shape[0] - 1):
                o, d = primary_rays(intr, poses[frame, cam, 0])
                hits = hits_next or tracer.intersect(o, d, image=(intr.height, intr.width))
                o1, d1 = primary_rays(intr, poses[frame + 1, cam, 0])
                hits_next = tracer.intersect(o1, d1, image=(intr.height, intr.width))
                points = o + d * np.where(hits.hit, hits.t, 0.0)[:, None]
                flow, occ = flow_to(intr, tracer, points, vec.normalize(d), hits.hit, poses[frame + 1, cam, 0])
                occ = occ.astype(bool)
                for tol in TOLERANCES:
                    checked, visible, occluded = neighbour_test(
                        intr, points, hits, flow, hits_next, poses[frame + 1, cam, 0], tol
                    )
                    row = counts.setdefault((group, tol), np.zeros(6, np.int64))
                    row += [
                        checked.sum(),
                        (checked & occ).sum(),
                        visible.sum(),
                        (visible & occ).sum(),
                        occluded.sum(),
                        (occluded & ~occ).sum(),
                    ]
    print(f"{mesh.n_faces:,} faces, {poses.shape[0] - 1} frame pairs x {poses.shape[1]} cameras")
    print("| cameras | tol | checked pixels | occluded (rays) | sure visible | of them wrong | sure occluded | wrong |")
    print("|---|---|---|---|---|---|---|---|")
    for (group, tol), (n, occ, vis, vis_bad, hid, hid_bad) in sorted(counts.items()):
        print(
            f"| {group} | {tol:g} | {n:,} | {occ / n:.1%} | {vis / n:.1%} | {vis_bad / max(vis, 1):.2e} "
            f"| {hid / n:.1%} | {hid_bad / max(hid, 1):.1%} |"
        )


if __name__ == "__main__":
    main()
