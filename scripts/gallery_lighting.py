"""Regenerate docs/gallery/lighting.png: one garden view under the five lighting scenarios.

Top row: the same view (garden, frame 0, camera pair 0) rendered by the
pipeline under clear, cloudy, overcast, sunset and twilight light, as the
EDEN paper's lighting figure. Bottom row: the intrinsic layers of one of those
renders (albedo, shading, translucency) next to its RGB image.

Everything goes through the pipeline (``run_job``) exactly as the CLI does,
into a cache under ``outputs/gallery/lighting/`` (git-ignored); the five
lightings share the garden's geometry and (``share_across_lightings``) trajectory through the cache.
``camera.pairs=1`` renders only pair 0 of the rig: its pose is the same as
pair 0 of the five-pair ring (the trajectory's draws do not depend on the
number of pairs), so the other four pairs are not rendered for nothing.

    python scripts/gallery_lighting.py [--seed 10] [--spp 4] [--indirect 0] [--layers-of clear]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from eden_pipe.config import make_cfg  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.io.formats import read_modality  # noqa: E402
from eden_pipe.lighting import DEFAULT_SWEEP as SCENARIOS  # noqa: E402  (the paper's five; night: gallery_environment.py)
from eden_pipe.pipeline import run_job  # noqa: E402
from eden_pipe.render import gallery  # noqa: E402
from eden_pipe.render.shading import srgb_to_uint8  # noqa: E402

MODALITIES = "render.modalities=[rgb,albedo,shading,translucency,rgb_linear]"


def label(img: np.ndarray, text: str) -> np.ndarray:
    return gallery.label(img, text, (10, 34), 0.8, 2)


def fit(img: np.ndarray, width: int) -> np.ndarray:
    h, w = img.shape[:2]
    return cv2.resize(img, (width, int(round(h * width / w))), interpolation=cv2.INTER_AREA)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=10, help="default garden seed (10: tree, flowers, topiary, lawn, sky)")
    ap.add_argument("--spp", type=int, default=4, help="render.rgb_spp")
    ap.add_argument(
        "--indirect",
        type=int,
        default=0,
        help=(
            "render.indirect_samples (0 = sky ambient, the pipeline default; "
            "1-2 leave white surfaces in shade speckled)"
        ),
    )
    ap.add_argument(
        "--layers-of", default="clear", choices=SCENARIOS, help="scenario whose intrinsic layers fill row 2"
    )
    ap.add_argument(
        "--shading-gain",
        type=float,
        default=0.5,
        help="display gain of the shading layer on top of the exposure (sunlit shading is ~1-1.5)",
    )
    ap.add_argument("--translucency-gain", type=float, default=4.0, help="display gain of the translucency layer")
    ap.add_argument("--width", type=int, default=2400, help="sheet width in pixels")
    ap.add_argument("--root", default=str(ROOT / "outputs" / "gallery" / "lighting"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "lighting.png"))
    ap.add_argument("overrides", nargs="*", help="extra Hydra overrides")
    args = ap.parse_args()

    base = [
        f"garden.seed={args.seed}",
        "progress=false",
        "camera.pairs=1",
        "camera.trajectory.frames=[2,2]",
        "camera.trajectory.share_across_lightings=true",
        "render.max_frames=1",
        f"render.rgb_spp={args.spp}",
        f"render.indirect_samples={args.indirect}",
        MODALITIES,
        *args.overrides,
    ]
    t0 = time.perf_counter()
    renders = {}
    for scenario in SCENARIOS:
        result = run_job(make_cfg(Path(args.root), base + [f"lighting={scenario}"]), echo=lambda *_: None)
        art = result.artifacts["render"]
        facts = art.marker()
        renders[scenario] = (art.path / "cam0", facts)
        light = facts["lighting"]
        print(
            f"{scenario:<9} elevation {np.degrees(light['sun_elevation']):6.1f} deg  azimuth "
            f"{np.degrees(light['sun_azimuth']) % 360:6.1f} deg  exposure {facts['exposure']:.2f}  "
            f"({'cached' if art.cached else f'{art.seconds:.1f} s'})"
        )
    t1 = time.perf_counter()

    # Row 1: the pipeline's own sRGB images (supersampled, exposed).
    tile_w = args.width // len(SCENARIOS)
    row1 = []
    for scenario, (cam, facts) in renders.items():
        rgb = read_modality(cam / "rgb_left" / "00000.png", "rgb_left")
        elev = np.degrees(facts["lighting"]["sun_elevation"])
        row1.append(label(fit(rgb, tile_w), f"{scenario}  (sun {elev:+.0f} deg)"))

    # Row 2: linear layers of one render, tone-mapped for display with that render's exposure.
    cam, facts = renders[args.layers_of]
    exposure = float(facts["exposure"])
    albedo = read_modality(cam / "albedo" / "00000.npy", "albedo")
    shading = read_modality(cam / "shading" / "00000.npy", "shading")
    trans = read_modality(cam / "translucency" / "00000.npy", "translucency")
    rgb = read_modality(cam / "rgb_left" / "00000.png", "rgb_left")
    tiles = [
        (srgb_to_uint8(albedo), "albedo"),
        (srgb_to_uint8(shading * exposure * args.shading_gain), f"shading x {exposure * args.shading_gain:.2f}"),
        (
            srgb_to_uint8(trans * exposure * args.translucency_gain),
            f"translucency x {exposure * args.translucency_gain:.2f}",
        ),
        (rgb, f"RGB ({args.layers_of})"),
    ]
    tile2_w = args.width // len(tiles)
    row2 = [label(fit(img, tile2_w), text) for img, text in tiles]

    rows = [np.hstack(row1), np.hstack(row2)]
    width = max(r.shape[1] for r in rows)
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows]
    sheet = np.vstack([rows[0], np.full((8, width, 3), 255, np.uint8), rows[1]])
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 6])
    print(
        f"5 lightings rendered in {t1 - t0:.1f} s "
        f"(garden seed {args.seed}, rgb_spp {args.spp}, indirect {args.indirect}); "
        f"sheet {sheet.shape[1]}x{sheet.shape[0]} -> {out}"
    )


if __name__ == "__main__":
    main()
