"""The validator's check of PNGs made with camera effects (docs/design.md, Camera effects): the job's
``camera.json`` and the PNG against the sensor model's noise-free response and its noise."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from eden_pipe import metadata
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.camera.sensor import Sensor
from eden_pipe.tools.consistency import Layer


def load_camera_effects(root, garden: str, lighting: str) -> dict | None:
    """The job's ``camera.json`` (the camera effects its PNGs went through), or None without one."""
    path = Path(root) / garden / lighting / metadata.CAMERA_FILE
    try:
        return json.loads(path.read_text()) if path.is_file() else None
    except (OSError, ValueError) as exc:
        raise ValueError(f"{path}: cannot read the camera effects ({exc})") from exc


SENSOR_SIGMAS = 6.0  # noise bound of the sensor check, in the model's standard deviations ...
SENSOR_OUTSIDE = 1e-4  # ... and the fraction of values allowed past it (Poisson tails at few electrons)


def check_rgb_sensor(report, rel, row, rgb, linear: Layer, exposure: float, sensor_facts: dict) -> None:
    """The PNG against the sensor model of camera.json (docs/design.md, Camera effects): its noise-free
    response to the composite's bounds, widened by SENSOR_SIGMAS of the model's shot and read noise and
    one ADC step; the optics (vignetting, chromatic aberration) are applied as the render did."""
    sensor = Sensor(**{k: sensor_facts[k] for k in Sensor.__dataclass_fields__})
    intr = Intrinsics(int(row["width"]), int(row["height"]), row["fx"], row["fy"], row["cx"], row["cy"])
    e = np.float32(exposure)
    x_lo = sensor.optics(np.maximum(linear.values - linear.error, 0) * e, intr)
    x_hi = sensor.optics((linear.values + linear.error) * e, intr)
    step = 1.0 / (sensor.white_dn - sensor.black_dn)
    lo = sensor.tone(x_lo - SENSOR_SIGMAS * sensor.noise_sigma(x_lo) - step).astype(np.int16)
    hi = sensor.tone(x_hi + SENSOR_SIGMAS * sensor.noise_sigma(x_hi) + step).astype(np.int16)
    if linear.open_above is not None:
        hi[linear.open_above] = 255
    png = rgb.astype(np.int16)
    outside = (png < lo) | (png > hi)
    if outside.mean() > SENSOR_OUTSIDE:
        report.fail(
            rel,
            "rgb-sensor",
            f"the sensor model's response to the composite (camera.json) outside {SENSOR_SIGMAS:g} sigma of its "
            f"noise on {float(outside.mean()):.3%} of values",
        )
    report.ran("rgb")
