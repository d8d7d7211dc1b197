"""Wind-blown foliage: what it costs, and what its ground truth is worth (docs/design.md, "Wind").

Renders the same garden, trajectory and lighting in still air and with wind, in one command (each
side a fresh process, the render stage forced; ``--repeats`` alternates them and keeps each side's
best), and prints:

- throughput: pairs/s of each side, the setup (scene load, BVH builds, the wind's weights) and peak
  RSS, and ``wind / still`` as a ratio of the same run;
- the validator's wind figures on the windy dataset: rigid pixels' flow against the depth
  reprojection, moving pixels' flow against the reprojection of the moved point, and how far the
  moving pixels' flow lies from the static reprojection (median and 95th percentile);
- the photometric check: frame t+1's RGB warped back to frame t by the ground-truth flow and by the
  rigid flow (the depth reprojection a static-scene dataset would give), mean absolute error in 8-bit
  levels on moving plant pixels that stay visible (occ_fwd = 0); a correct non-rigid flow must warp
  better.

Nothing here is tuned: the wind's responses are fixed constants (render/wind.py). The last line is

    wind throughput: X of still air (A pairs/s vs B pairs/s)

    python benchmarks/wind.py [--frames 4] [--wind 5] [--repeats 1] [overrides ...]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from render_throughput import REPO, measure, pairs_per_second, report

from eden_pipe import labels
from eden_pipe.data.manifest_reader import load_manifest, row_pose
from eden_pipe.modalities import read_modality
from eden_pipe.tools.consistency import reprojection_flow
from eden_pipe.tools.validate import check_dataset

PLANTS = (labels.TREE, labels.HEDGE, labels.TOPIARY, labels.FLOWER, labels.GRASS)


def warp_errors(root: Path) -> dict[str, np.ndarray]:
    """Per moving, visible plant pixel: |I_t - I_t+1(x + flow)| for the ground-truth and the rigid flow."""
    import cv2

    rows = load_manifest(root)
    index = {(r.garden, r.lighting, r.camera, r.frame): i for i, r in enumerate(rows.itertuples())}
    out: dict[str, list] = {"ground truth": [], "rigid": []}
    for _, row in rows.iterrows():
        key = (row["garden"], row["lighting"], row["camera"], row["frame"] + 1)
        if not row["flow_fwd"] or key not in index:
            continue
        other = rows.iloc[index[key]]
        read = lambda r, c: read_modality(root / r[c], c)  # noqa: E731
        rgb0, rgb1 = read(row, "rgb_left").astype(np.float32), read(other, "rgb_left").astype(np.float32)
        flow, occ, depth = read(row, "flow_fwd"), read(row, "occ_fwd"), read(row, "depth")
        semantic, dynamic = read(row, "semantic"), read(row, "dynamic")
        K = np.array([[row["fx"], 0, row["cx"]], [0, row["fy"], row["cy"]], [0, 0, 1.0]])
        rigid = reprojection_flow(depth, K, row_pose(row), row_pose(other)).astype(np.float32)
        keep = (occ == 0) & (dynamic == 1) & np.isin(semantic, PLANTS) & np.isfinite(flow).all(-1)
        keep &= np.isfinite(rigid).all(-1)
        h, w = depth.shape
        v, u = np.mgrid[0:h, 0:w].astype(np.float32)
        for name, f in (("ground truth", flow), ("rigid", rigid)):
            f = np.nan_to_num(f)
            warped = cv2.remap(rgb1, u + f[..., 0], v + f[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
            out[name].append(np.abs(warped - rgb0).mean(-1)[keep])
    return {k: np.concatenate(v) if v else np.zeros(0) for k, v in out.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=4, help="frames to render (each = 5 camera pairs)")
    parser.add_argument("--wind", type=float, default=5.0, help="lighting.wind_mps of the windy side")
    parser.add_argument("--repeats", type=int, default=1, help="alternate the two sides this many times")
    parser.add_argument("--root", default=str(REPO / "outputs" / "bench"), help="cache and dataset folder")
    parser.add_argument("--quiet", action="store_true", help="no stage timings")
    parser.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. garden=small")
    args = parser.parse_args()
    if args.frames < 2 or args.repeats < 1 or args.wind <= 0:
        parser.error("--frames >= 2, --repeats >= 1 and --wind > 0 are needed")
    root = Path(args.root)
    steps = args.frames + 1
    base = ["progress=false", f"camera.trajectory.frames=[{steps},{steps}]", f"render.max_frames={steps}"]
    base += args.overrides
    sides = {
        "still": [*base, f"paths.dataset={root}/dataset_still"],
        "wind": [*base, f"lighting.wind_mps={args.wind}", f"paths.dataset={root}/dataset_wind"],
    }
    best: dict[str, dict] = {}
    for _ in range(args.repeats):
        for side, overrides in sides.items():
            result = measure(REPO, root, overrides, verbose=not args.quiet)
            if side not in best or result["seconds_per_frame"] < best[side]["seconds_per_frame"]:
                best[side] = result
    print(f"scene faces: {best['still']['faces']:,}; {steps} frames a side")
    for side in sides:
        report(side, best[side])

    validation = check_dataset(root / "dataset_wind", progress=False)
    print(validation.motion_line())
    verdict = "OK" if validation.ok else "FAILED"
    print(f"validator on the windy dataset: {verdict} ({len(validation.failures)} failures)")
    errors = warp_errors(root / "dataset_wind")
    gt, rigid = errors["ground truth"], errors["rigid"]
    print(
        f"warp t+1 -> t on moving, visible plant pixels ({len(gt)} px): mean |error| ground-truth flow "
        f"{gt.mean():.2f} levels (median {np.median(gt):.2f}), rigid flow {rigid.mean():.2f} (median "
        f"{np.median(rigid):.2f}); ground truth better on {np.mean(gt < rigid):.1%} of them, worse on "
        f"{np.mean(gt > rigid):.1%}"
    )
    a, b = pairs_per_second(best["wind"]), pairs_per_second(best["still"])
    print(f"wind throughput: {a / b:.2f} of still air ({a:.3f} pairs/s vs {b:.3f} pairs/s)")


if __name__ == "__main__":
    main()
