"""Regenerate docs/gallery/environment.png: one garden view lit by an HDR map, and at night.

Nothing is downloaded: the HDR map is generated from the pipeline's own cloudy sky
(``render.sky.bake_panorama``: Preetham sky with fBm clouds, the sun disc and the
procedural scenery below the horizon), written as a Radiance ``.hdr`` and handed to
the pipeline as ``lighting.environment=PATH`` exactly as a user's map would be.

Top row: the map (tone-mapped, with the extracted sun marked); the view lit by it with
the sun extracted (``environment_sun=auto``), and without a direct sun
(``environment_sun=none``: the map's ambient light alone). Bottom row: the same view at
night (``lighting=night``) at a full and a crescent moon, and under the clear model sky
for comparison.

Every render goes through ``run_job`` into ``outputs/gallery/environment/`` (git-ignored),
at a reduced size so the sheet renders in a couple of minutes on two cores.

    python scripts/gallery_environment.py [--seed 10] [--spp 2] [--width 320]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from eden_pipe.config import make_cfg  # noqa: E402  (composes conf/ exactly as the CLI does)
from eden_pipe.io.formats import read_modality  # noqa: E402
from eden_pipe.io.hdr import write_hdr  # noqa: E402
from eden_pipe.pipeline import run_job  # noqa: E402
from eden_pipe.render import gallery  # noqa: E402
from eden_pipe.render.shading import srgb_to_uint8  # noqa: E402
from eden_pipe.render.sky import LUMA, Sky, bake_panorama, extract_sun, sample_lighting  # noqa: E402
from eden_pipe.render.sky.equirect import texel_coordinates  # noqa: E402


def label(img: np.ndarray, text: str) -> np.ndarray:
    return gallery.label(img, text, (6, 18), 0.45, 1)


def fit(img: np.ndarray, width: int, height: int) -> np.ndarray:
    return cv2.resize(img, (width, height), interpolation=cv2.INTER_AREA)


def make_map(path: Path, width: int, seed: int) -> np.ndarray:
    """A cloudy afternoon sky with its sun and the procedural scenery, as an HDR file."""
    sky = Sky(
        sample_lighting(
            {
                "name": "cloudy",
                "sun_elevation_deg": 32.0,
                "sun_azimuth_deg": 40.0,
                "cloud_cover": 0.4,
                "sun_angular_diameter_deg": 0.8,
            },
            np.random.default_rng(seed),
        ),
        seed=seed + 1000,
    )
    image = bake_panorama(sky, width)
    write_hdr(path, image)
    return image


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seed", type=int, default=10, help="default garden seed")
    ap.add_argument("--spp", type=int, default=2, help="render.rgb_spp")
    ap.add_argument("--width", type=int, default=320, help="render width (height 3/4 of it)")
    ap.add_argument("--map-width", type=int, default=1024, help="width of the generated HDR map")
    ap.add_argument("--rotation", type=float, default=150.0, help="lighting.environment_rotation_deg")
    ap.add_argument("--root", default=str(ROOT / "outputs" / "gallery" / "environment"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "environment.png"))
    args = ap.parse_args()

    root = Path(args.root)
    root.mkdir(parents=True, exist_ok=True)
    hdr = root / "generated_sky.hdr"
    image = make_map(hdr, args.map_width, args.seed)
    w, h = args.width, args.width * 3 // 4
    camera = [
        f"camera.width={w}",
        f"camera.height={h}",
        f"camera.fx={w}",
        f"camera.fy={w}",
        f"camera.cx={w / 2}",
        f"camera.cy={h / 2}",
    ]
    base = [
        f"garden.seed={args.seed}",
        "progress=false",
        "camera.pairs=1",
        "camera.trajectory.frames=[2,2]",
        "render.max_frames=1",
        f"render.rgb_spp={args.spp}",
        "render.modalities=[rgb]",
        *camera,
    ]
    env = [
        f"lighting.environment={hdr}",
        f"lighting.environment_rotation_deg={args.rotation}",
        "lighting.sun_intensity=1",
    ]
    jobs = [
        ("HDR map, sun extracted", ["lighting=clear", *env]),
        ("HDR map, ambient only", ["lighting=clear", *env, "lighting.environment_sun=none"]),
        ("night, full moon", ["lighting=night", "lighting.moon_phase=1.0", "lighting.sun_elevation_deg=45"]),
        ("night, crescent moon", ["lighting=night", "lighting.moon_phase=0.3", "lighting.sun_elevation_deg=45"]),
        ("clear model sky", ["lighting=clear"]),
    ]
    t0 = time.perf_counter()
    tiles = {}
    for title, overrides in jobs:
        result = run_job(make_cfg(root, base + overrides), echo=lambda *_: None)
        art = result.artifacts["render"]
        facts = art.marker()
        tiles[title] = read_modality(art.path / "cam0" / "rgb_left" / "00000.png", "rgb_left")
        print(
            f"{title:<24} exposure {facts['exposure']:.2f}  direct light {facts['sun'].get('direct_light')}  "
            f"({'cached' if art.cached else f'{art.seconds:.1f} s'})"
        )
    t1 = time.perf_counter()

    # The map: Reinhard-tone-mapped, the extracted sun circled (at the map's own orientation).
    found, _ = extract_sun(image)
    lum = image @ LUMA
    key = float(np.exp(np.mean(np.log(lum + 1e-6))))
    shown = image * (0.25 / key)
    shown = srgb_to_uint8(shown / (1.0 + shown @ LUMA)[..., None])
    shown = fit(shown, 2 * h, h)
    if found is not None:
        col, row = texel_coordinates(found.direction[None], h, 2 * h)
        cv2.circle(shown, (int(col[0]), int(row[0])), 9, (255, 40, 40), 2, cv2.LINE_AA)
    tile_map = label(shown, f"generated HDR map ({image.shape[1]}x{image.shape[0]})")

    titled = [label(fit(img, w, h), t) for t, img in tiles.items()]
    gap = np.full((h, 6, 3), 255, np.uint8)
    row1 = np.hstack([tile_map, gap, titled[0], gap, titled[1]])
    row2 = np.hstack([titled[2], gap, titled[3], gap, titled[4]])
    width = max(row1.shape[1], row2.shape[1])
    rows = [np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in (row1, row2)]
    sheet = np.vstack([rows[0], np.full((6, width, 3), 255, np.uint8), rows[1]])
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(out), cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_PNG_COMPRESSION, 9])
    sun = "none" if found is None else f"{math.degrees(2 * found.angular_radius):.2f} deg"
    print(
        f"{len(jobs)} renders in {t1 - t0:.1f} s (garden seed {args.seed}, {w}x{h}, rgb_spp {args.spp}; "
        f"extracted sun {sun}); sheet {sheet.shape[1]}x{sheet.shape[0]} -> {out}"
    )


if __name__ == "__main__":
    main()
