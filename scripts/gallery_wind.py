"""Regenerate docs/gallery/wind.png: one view in still air and in wind (docs/design.md, "Wind").

Row 1, still air: RGB, forward flow, occlusion. Row 2, the same garden, trajectory and frame with
``lighting.wind_mps``: RGB, forward flow (same colour scale), the dynamic mask, the magnitude of each
pixel's own motion to the next frame (``motion_fwd``), and the flow's departure from the still-air
reprojection. Everything goes through the pipeline (``run_job``) exactly as the CLI does, into a cache
under ``outputs/gallery/wind/`` (git-ignored); the two jobs share geometry, bake and trajectory.

    python scripts/gallery_wind.py [--seed 10] [--wind 8] [--frame 1] [--pair 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from eden_pipe.config import make_cfg  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.io.formats import read_modality  # noqa: E402
from eden_pipe.pipeline import run_job  # noqa: E402
from eden_pipe.render import gallery  # noqa: E402
from eden_pipe.tools.stats import colour_flow  # noqa: E402


def label(img: np.ndarray, text: str) -> np.ndarray:
    return gallery.label(img, text, (10, 30), 0.7, 2)


def heat(x: np.ndarray, top: float) -> np.ndarray:
    """A scalar map as an inferno colour image, 0..top."""
    scaled = (np.clip(np.nan_to_num(x) / max(top, 1e-9), 0, 1) * 255).astype(np.uint8)
    return cv2.cvtColor(cv2.applyColorMap(scaled, cv2.COLORMAP_INFERNO), cv2.COLOR_BGR2RGB)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=10, help="default garden seed")
    ap.add_argument("--wind", type=float, default=8.0, help="lighting.wind_mps of the windy row")
    ap.add_argument("--frame", type=int, default=1, help="frame shown (its forward flow)")
    ap.add_argument("--pair", type=int, default=0, help="camera pair shown")
    ap.add_argument("--root", default=str(ROOT / "outputs" / "gallery" / "wind"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "wind.png"))
    ap.add_argument("overrides", nargs="*", help="extra Hydra overrides")
    args = ap.parse_args()
    root = Path(args.root)
    steps = args.frame + 2
    base = [
        f"garden.seed={args.seed}",
        "progress=false",
        f"camera.trajectory.frames=[{steps},{steps}]",
        *args.overrides,
    ]
    folders = {}
    for name, extra in (("still", []), ("wind", [f"lighting.wind_mps={args.wind}"])):
        result = run_job(make_cfg(root, [*base, *extra, f"paths.dataset={root}/{name}"]), echo=lambda *_: None)
        folders[name] = result.artifacts["render"].path / f"cam{args.pair}"

    def read(name: str, column: str) -> np.ndarray:
        ext = {"dynamic": "png", "motion_fwd": "exr", "rgb_left": "png", "flow_fwd": "png", "occ_fwd": "png"}[column]
        return read_modality(folders[name] / column / f"{args.frame:05d}.{ext}", column)

    still_flow, wind_flow = read("still", "flow_fwd"), read("wind", "flow_fwd")
    scale = max(float(np.nanpercentile(np.hypot(*np.moveaxis(still_flow, -1, 0)), 99)), 1e-6)
    dynamic = read("wind", "dynamic")
    motion = np.linalg.norm(read("wind", "motion_fwd"), axis=-1) * 1000.0  # mm
    apart = np.hypot(*np.moveaxis(wind_flow - still_flow, -1, 0))
    apart = np.where(dynamic == 1, apart, 0.0)
    top_mm = max(float(np.percentile(motion[dynamic == 1], 99)), 1e-3) if dynamic.any() else 1.0
    top_px = max(float(np.percentile(apart[dynamic == 1], 99)), 1e-3) if dynamic.any() else 1.0
    row1 = [
        label(read("still", "rgb_left"), "still air: RGB"),
        label(colour_flow(np.nan_to_num(still_flow), scale), "still: flow t->t+1"),
        label(np.repeat(read("still", "occ_fwd")[..., None] * 255, 3, -1).astype(np.uint8), "still: occlusion"),
    ]
    row2 = [
        label(read("wind", "rgb_left"), f"wind {args.wind:g} m/s: RGB"),
        label(colour_flow(np.nan_to_num(wind_flow), scale), "wind: flow t->t+1"),
        label(np.repeat(dynamic[..., None] * 255, 3, -1).astype(np.uint8), "wind: dynamic mask"),
        label(heat(motion, top_mm), f"|motion_fwd| 0..{top_mm:.0f} mm"),
        label(heat(apart, top_px), f"|flow - still flow| 0..{top_px:.1f} px"),
    ]
    blank = np.zeros_like(row2[0])
    sheet = np.vstack([np.hstack(row1 + [blank, blank]), np.hstack(row2)])
    sheet = cv2.resize(sheet, (sheet.shape[1] // 2, sheet.shape[0] // 2), interpolation=cv2.INTER_AREA)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(f"wrote {args.out}: {int(dynamic.sum())} dynamic px of {dynamic.size}")


if __name__ == "__main__":
    main()
