"""Regenerate docs/gallery/camera_effects.png: one view, clean | sensor noise | rolling shutter | motion blur.

Each image is the pipeline's own PNG (``run_job``, as the CLI makes it) of frame 1, camera pair 0
of garden=small, under the camera effects' keys (docs/design.md, Camera effects); the four jobs
share the garden, the trajectory and the bake through the cache under
``outputs/gallery/camera_effects/`` (git-ignored). The bottom row enlarges one crop of each (near
the top of the image, where the rolling shutter's rows are furthest from the frame time), so the
noise, the shift of a rolling shutter's rows and the smear of motion blur can be seen. The readout
and exposure are exaggerated (a whole frame interval) so the effects show at a glance.

With ``--time N`` it also times one view of each effect against the clean view (N interleaved
rounds, the median of each), in the same process: the clean view is the render stage's left view
(every default pass), the sensor its ``Sensor.apply``, the rolling shutter and the blur the extra
RGB render over the exposure (``RaytraceBackend.render_exposed``).

    python scripts/gallery_camera_effects.py [--readout 0.1] [--exposure 0.1] [--time 3]
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
from eden_pipe.pipeline import run_job  # noqa: E402
from eden_pipe.render import gallery  # noqa: E402

FRAME = 1
SENSOR = [
    "camera.sensor.enabled=true",
    "camera.sensor.gain=16",  # ISO 1600-like: 625 electrons at the white point
    "camera.sensor.vignetting=cos4",
    "camera.sensor.ca_red=0.004",
    "camera.sensor.ca_blue=-0.004",
]


def label(img: np.ndarray, text: str) -> np.ndarray:
    return gallery.label(img, text, (10, 30), 0.7, 2)


def crop_zoom(img: np.ndarray, box: tuple[int, int, int, int], zoom: int) -> np.ndarray:
    x, y, w, h = box
    return cv2.resize(img[y : y + h, x : x + w], (w * zoom, h * zoom), interpolation=cv2.INTER_NEAREST)


def time_effects(result, cfg, rounds: int, readout: float, exposure: float, samples: int) -> dict[str, float]:
    """Median seconds of one view per effect (interleaved rounds), and the clean view's."""
    from eden_pipe.camera.rig import Intrinsics
    from eden_pipe.camera.sensor import Sensor
    from eden_pipe.camera.shutter import exposure_poses, sample_offsets
    from eden_pipe.modalities import derived_inputs
    from eden_pipe.render.backends.raytrace import RaytraceBackend
    from eden_pipe.stages.render import make_sky
    from eden_pipe.stages.scene import load_scene
    from eden_pipe.stages.sky_visibility import load_sky_visibility
    from eden_pipe.stages.trajectory import load_poses

    scene, arrays = load_scene(result.artifacts["scene"])
    if "sky_visibility" in result.artifacts:
        arrays.sky_visibility = load_sky_visibility(result.artifacts["sky_visibility"])
    sky, _ = make_sky(cfg.lighting, scene.seed)
    modalities = set(cfg.render.modalities)
    want = modalities | {"depth"} | derived_inputs(modalities)
    poses = load_poses(result.artifacts["trajectory"])[:, 0, 0]
    fps = float(cfg.camera.trajectory.fps)
    intr = Intrinsics.from_config(cfg.camera)
    sensor = Sensor()
    times: dict[str, list[float]] = {"clean view": [], "sensor": [], "rolling shutter": [], "motion blur": []}
    with RaytraceBackend(arrays, sky, cfg.render, modalities=modalities) as backend:
        state = backend.frame(FRAME / fps)
        shutter = exposure_poses(poses, fps, FRAME, intr.height, readout)
        blur = exposure_poses(poses, fps, FRAME, intr.height, 0.0, exposure, samples)
        for _ in range(rounds):
            rng = np.random.default_rng(0)
            t = time.perf_counter()
            view = backend.render_view(state, intr, poses[FRAME], want=want, rng=rng)
            times["clean view"].append(time.perf_counter() - t)
            t = time.perf_counter()
            sensor.apply(view["rgb_linear"] * sky.exposure, intr, rng)
            times["sensor"].append(time.perf_counter() - t)
            t = time.perf_counter()
            backend.render_exposed(state, intr, shutter, sample_offsets(0.0, 1), rng=rng)
            times["rolling shutter"].append(time.perf_counter() - t)
            t = time.perf_counter()
            backend.render_exposed(state, intr, blur, sample_offsets(exposure, samples), rng=rng)
            times["motion blur"].append(time.perf_counter() - t)
    return {k: float(np.median(v)) for k, v in times.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--readout", type=float, default=0.1, help="camera.readout_s of the rolling-shutter image")
    ap.add_argument("--exposure", type=float, default=0.1, help="camera.exposure_s of the motion-blur image")
    ap.add_argument("--samples", type=int, default=16, help="camera.blur_samples")
    ap.add_argument("--time", type=int, default=0, help="rounds of per-view timing (0: none)")
    ap.add_argument("--root", default=str(ROOT / "outputs" / "gallery" / "camera_effects"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "gallery" / "camera_effects.png"))
    ap.add_argument("overrides", nargs="*", help="extra Hydra overrides")
    args = ap.parse_args()

    base = [
        "garden=small",
        "progress=false",
        "camera.pairs=1",
        "camera.trajectory.frames=[3,3]",
        "render.max_frames=2",
        *args.overrides,
    ]
    variants = {
        "clean": [],
        "sensor: gain 16, cos4 vignetting, CA": SENSOR,
        f"rolling shutter: readout {args.readout * 1e3:.0f} ms": [f"camera.readout_s={args.readout}"],
        f"motion blur: exposure {args.exposure * 1e3:.0f} ms, {args.samples} samples": [
            f"camera.exposure_s={args.exposure}",
            f"camera.blur_samples={args.samples}",
        ],
    }
    images, results = {}, {}
    for name, overrides in variants.items():
        cfg = make_cfg(Path(args.root), base + overrides)
        result = run_job(cfg, echo=lambda *_: None)
        art = result.artifacts["render"]
        images[name] = read_modality(art.path / "cam0" / "rgb_left" / f"{FRAME:05d}.png", "rgb_left")
        results[name] = (result, cfg)
        print(f"{name:<50} {'cached' if art.cached else f'{art.seconds:.1f} s'}")

    h, w = next(iter(images.values())).shape[:2]
    # Near the top, where a rolling shutter's rows are furthest from the frame time (the middle row's is 0).
    box = (w // 2 - w // 8, h // 24, w // 4, h // 4)
    top = [label(img.copy(), name) for name, img in images.items()]
    bottom = [crop_zoom(img, box, 4 if w <= 640 else 2) for img in images.values()]
    bottom = [
        cv2.resize(b, (w, int(round(b.shape[0] * w / b.shape[1]))), interpolation=cv2.INTER_NEAREST) for b in bottom
    ]
    for img in top:
        cv2.rectangle(img, (box[0], box[1]), (box[0] + box[2], box[1] + box[3]), (255, 255, 255), 1)
    sheet = np.vstack([np.hstack(top), np.hstack(bottom)])
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(args.out, cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]})")

    if args.time:
        result, cfg = results["clean"]
        seconds = time_effects(result, cfg, args.time, args.readout, args.exposure, args.samples)
        clean = seconds["clean view"]
        for name, s in seconds.items():
            print(f"{name:<16} {s * 1e3:8.1f} ms/view  {s / clean:6.2f}x the clean view")


if __name__ == "__main__":
    main()
