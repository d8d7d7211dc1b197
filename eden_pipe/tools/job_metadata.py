"""A published job's metadata as the validator reads it: the garden's instance table
(``<garden>/scene.json``) and the job's render settings recorded in ``dataset.json`` (its RGB
samples per pixel, its backend and that backend's depth error)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from eden_pipe import labels, metadata

# Where the per-garden instance table is published (eden_pipe.metadata), relative to the dataset root.
METADATA_CANDIDATES = ("{garden}/" + metadata.SCENE_FILE,)


def metadata_path(root, garden: str, lighting: str) -> Path | None:
    """The first existing metadata file of (garden, lighting), or None."""
    for pattern in METADATA_CANDIDATES:
        path = Path(root) / pattern.format(garden=garden, lighting=lighting)
        if path.is_file():
            return path
    return None


def _class_id(entry: dict) -> int:
    for key in ("class_id", "semantic"):
        if key in entry:
            return int(entry[key])
    cls = entry.get("class")
    if isinstance(cls, (int, np.integer)):
        return int(cls)
    if isinstance(cls, str) and cls in labels.BY_NAME:
        return labels.BY_NAME[cls]
    raise ValueError(f"instance {entry.get('id')!r} has no class_id")


def load_instance_classes(root, garden: str, lighting: str) -> dict[int, int] | None:
    """{instance id: class id} from the garden's metadata, or None when there is no metadata file.

    Format: ``{"instances": [{"id": int, "class_id": int, ...}, ...]}`` (``semantic`` or a
    class name in ``class`` are accepted in place of ``class_id``). Raises ValueError on a
    malformed file.
    """
    path = metadata_path(root, garden, lighting)
    if path is None:
        return None
    try:
        meta = json.loads(path.read_text())
        return {int(e["id"]): _class_id(e) for e in meta["instances"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: cannot read the instance table ({exc})") from exc


def load_render_setting(root, garden: str, lighting: str, key: str):
    """A ``render`` key of the job's config recorded in dataset.json (None if absent)."""
    path = Path(root) / metadata.DATASET_FILE
    try:
        return json.loads(path.read_text())["jobs"][f"{garden}/{lighting}"]["render"][key]
    except (OSError, ValueError, KeyError, TypeError):
        return None


def load_rgb_spp(root, garden: str, lighting: str) -> int | None:
    """Samples per pixel of the RGB PNGs, from the job's config recorded in dataset.json (None if absent)."""
    spp = load_render_setting(root, garden, lighting, "rgb_spp")
    return None if spp is None else int(spp)


def backend_depth_error(root, garden: str, lighting: str):
    """The job's rendering backend's own z-depth error (``Backend.depth_error``; a ray tracer's when
    the backend is not recorded or not known here)."""
    from eden_pipe.render import backends

    name = load_render_setting(root, garden, lighting, "backend")
    return backends.get(name if name in backends.names() else "raytrace").depth_error
