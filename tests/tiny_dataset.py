"""One TINY dataset (96x72, 4 frames, small garden, every modality) per test session, shared by the
loader, export, validate and stats tests (its files are hard links into the stage cache: copy before corrupting)."""

from __future__ import annotations

from pathlib import Path

from tests.conftest import TINY, make_cfg

ALL_MODALITIES = (
    "render.modalities=[rgb,semantic,instance,depth,normal,flow,albedo,shading,translucency,glossy,"
    "background,rgb_linear]"
)
_BUILT: dict[str, Path] = {}


def tiny_root(tmp_path_factory) -> Path:
    """Root folder holding ``stages/`` and ``dataset/`` (built on first use, about 15 s)."""
    if "root" not in _BUILT:
        from eden_pipe.pipeline import run_job

        root = tmp_path_factory.mktemp("tiny_consumers")
        run_job(make_cfg(root, TINY + [ALL_MODALITIES]), echo=lambda *_: None)
        _BUILT["root"] = root
    return _BUILT["root"]
