"""Whether a camera config turns any camera effect on (docs/design.md, Camera effects): the one predicate
the render key and the published config.yaml read, so a job with every effect off keys and publishes as
one made before the effects existed."""

from __future__ import annotations

from collections.abc import Mapping

EFFECT_KEYS = ("readout_s", "exposure_s", "blur_samples", "sensor")


def effects_on(camera: Mapping) -> bool:
    """A plain camera config (a dict): the sensor model, a rolling shutter or motion blur is on."""
    return bool(camera["sensor"]["enabled"] or camera["readout_s"] or camera["exposure_s"])


def without_effects_off(camera: dict) -> dict:
    """A plain camera config without the effects' keys when every effect is off."""
    return camera if effects_on(camera) else {k: v for k, v in camera.items() if k not in EFFECT_KEYS}
