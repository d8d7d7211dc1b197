"""Whether a camera config turns any camera effect on (docs/design.md, Camera effects): the one predicate
the render key and the published config.yaml read, so a job with every effect off keys and publishes as
one made before the effects existed."""

from __future__ import annotations

from collections.abc import Mapping

EFFECT_KEYS = ("readout_s", "exposure_s", "blur_samples", "sensor")


def _value(section, key: str):
    return section[key] if isinstance(section, Mapping) else getattr(section, key)


def exposure_effects_on(camera) -> bool:
    """A camera config (a dict or a config object): a rolling shutter or motion blur is on (the RGB is
    rendered over the exposure, by a backend with ``exposure_effects``)."""
    return bool(_value(camera, "readout_s") or _value(camera, "exposure_s"))


def effects_on(camera) -> bool:
    """A camera config (a dict or a config object): the sensor model, a rolling shutter or motion blur is on."""
    return bool(_value(_value(camera, "sensor"), "enabled")) or exposure_effects_on(camera)


def without_effects_off(camera: dict) -> dict:
    """A plain camera config without the effects' keys when every effect is off."""
    return camera if effects_on(camera) else {k: v for k, v in camera.items() if k not in EFFECT_KEYS}
