"""Pre-flight: everything that can stop a job is checked before its first stage (docs/reliability.md).

:func:`check_job` is what ``run_job`` and the Hydra callback call: the config converted once
(``config.to_config``: unknown keys rejected with a did-you-mean), every value checked against
its key's domain (``config.validate``: the destination folders, ``paths.stages`` and
``paths.dataset``, are a domain too: a temporary file is created and removed in the folder, or
in its nearest existing parent when the folder does not exist yet, so a failing check never
creates the dataset folder), then what lies outside the config:

- the species and asset presets the garden will use (``conf/species/<kind>/<name>.yaml``,
  a user's own included) load through their family's loader: unknown keys, values of the
  wrong form (``models.presets.check_values``) or a loader's own complaint become one line
  naming the file, the key, the value and what is allowed;
- the free disk space covers what the job still has to write (:func:`space_needed`):
  bytes per manifest row from the modality table (each format's ``pixel_bytes`` times the
  resolution, in the configured storage mode; 1.25x the measured size of compact rows at
  640x480), times camera pairs and frames, plus the garden's meshes, minus the
  frames the stage cache already holds (found by running the stage functions on a
  lookup-only cache: their own keys, no second definition). ``paths.check_free_space=false``
  skips it.

Every failure is a ``ConfigError`` (:class:`PreflightError` past the config): one line, exit 2, nothing written.
"""

from __future__ import annotations

import contextlib
import math
import os
import shutil
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from eden_pipe.config import EdenConfig, to_config, validate
from eden_pipe.config.domains import nearest_existing
from eden_pipe.errors import ConfigError

#: Model and scene artifacts hold meshes: 53 bytes per face measured (npz of vertices, faces and
#: per-face labels), written twice (each model, then the garden's merged scene); a small garden
#: measured 122k lawn faces and 80k faces per instance (847k faces, 45 MB of scene, 77 MB in all).
#: The scene also writes the published mesh, geometry.ply: 54.5-54.7 bytes per face measured (37 per
#: face, 12 per vertex at ~1.5 vertices per face; small garden 55.7 MB, default garden 336 MB).
BYTES_PER_FACE = 2 * 55 + 55
FACES_PER_INSTANCE = 100_000


class PreflightError(ConfigError):
    """A job cannot start: one line saying what, where and what would do."""


def check_job(cfg) -> EdenConfig:
    """The typed config of a job that can start; raises :class:`ConfigError` (one line) otherwise."""
    cfg = to_config(cfg)
    validate(cfg)
    check_backend(cfg)
    check_presets(cfg)
    if cfg.paths.check_free_space:
        check_free_space(cfg)
    return cfg


def check_backend(cfg: EdenConfig) -> None:
    """The backend's own libraries (``Backend.unavailable``: bpy for Cycles), before any work."""
    from eden_pipe.camera.effects import exposure_effects_on
    from eden_pipe.lighting import wind_blows
    from eden_pipe.render import backends

    backend = backends.get(cfg.render.backend)
    why = backend.unavailable(cfg.render)
    if why is not None:
        raise PreflightError(why)
    if wind_blows(cfg.lighting) and not backend.moves_geometry:
        moving = ", ".join(n for n in backends.names() if backends.get(n).moves_geometry)
        raise PreflightError(
            f"invalid config: lighting.wind_mps={cfg.lighting.wind_mps!r} with render.backend={cfg.render.backend}; "
            f"allowed: wind_mps 0 with this backend, or a backend that moves the mesh ({moving})"
        )
    if exposure_effects_on(cfg.camera) and not backend.exposure_effects:
        raise PreflightError(
            f"camera.readout_s and camera.exposure_s need a backend that renders them "
            f"(raytrace); render.backend={cfg.render.backend} does not"
        )


# ---------------------------------------------------------------------- presets
def presets_in_use(cfg: EdenConfig) -> list[tuple[str, str, Callable[[str], object]]]:
    """(kind, name, reader) of every preset the garden can draw (pools with a non-zero count, the
    lawn); ``reader(name)`` is the loader its builder uses (the family's ``read_preset``): it checks
    keys and builds the typed parameters, the strongest check short of building."""
    from eden_pipe.models.grass import grass_preset
    from eden_pipe.models.registry import FAMILIES

    garden = cfg.garden
    used = [preset for fam in FAMILIES for preset in fam.presets_in_use(garden)]
    if garden.lawn.enabled and "grass" in garden.terrain.patch_types:
        used += [("grass", str(name), grass_preset) for name in garden.lawn.species_pool()]
    return list(dict.fromkeys(used))


def check_presets(cfg: EdenConfig) -> None:
    from eden_pipe.models.presets import preset_source

    for kind, name, read in presets_in_use(cfg):
        try:
            read(name)
        except ConfigError:
            raise
        except Exception as err:  # a loader's own complaint (a wrong type deep in a preset): name the file
            detail = " ".join(str(err).split())
            raise PreflightError(
                f"{preset_source(kind, name)}: invalid preset: {type(err).__name__}: {detail}"
            ) from err


# ---------------------------------------------------------------------- free space
@dataclass
class SpaceNeed:
    path: Path  # where the bytes go (the nearest existing folder)
    need: int  # bytes still to write there
    free: int  # bytes free there
    detail: str  # how ``need`` was counted


def row_bytes(cfg: EdenConfig, has_next: bool = True, has_prev: bool = True) -> int:
    """Upper bound on the bytes of one manifest row's files (one frame, one camera pair)."""
    from eden_pipe.lighting import wind_blows
    from eden_pipe.modalities import WriteOptions, columns_for
    from eden_pipe.render import backends

    modalities = set(cfg.render.modalities) | ({"dynamic"} if wind_blows(cfg.lighting) else set())
    modalities &= backends.get(cfg.render.backend).capabilities
    options = WriteOptions.from_config(cfg.render)
    pixels = int(cfg.camera.width) * int(cfg.camera.height)
    return int(sum(c.file_format(options).pixel_bytes for c in columns_for(modalities, has_next, has_prev)) * pixels)


def mesh_bytes(cfg: EdenConfig) -> int:
    """Rough bytes of a garden's model and scene artifacts (see BYTES_PER_FACE)."""
    from eden_pipe.models.registry import FAMILIES

    garden = cfg.garden
    lawn = garden.lawn.triangles_per_m2 * garden.size_m**2 if garden.lawn.enabled else 0
    instances = sum(fam.max_instances(garden) for fam in FAMILIES)
    return int(BYTES_PER_FACE * (lawn + FACES_PER_INSTANCE * instances))


def job_progress(cfg: EdenConfig) -> tuple[int, list[int], bool]:
    """(frames the job renders, those not rendered yet, whether the scene is cached): exact when the
    trajectory is cached, else the length its stage will draw (``trajectory.frame_count``), none done. Reads the cache,
    writes nothing."""
    from eden_pipe.stages.cache import NotBuilt, StageCache

    with quiet_native_stderr():  # pybullet's import prints a build banner: a failed check stays one line
        from eden_pipe.pipeline import run_stages
        from eden_pipe.stages.render import sequence_length
        from eden_pipe.stages.trajectory import frame_count, load_poses

    n_total = frame_count(cfg.camera, cfg.garden.seed, cfg.lighting.name)
    done: set[int] = set()
    found: dict = {}

    def step(name, fn, *args, **kwargs):
        found[name] = fn(*args, **kwargs)
        return found[name]

    cache = StageCache(cfg.paths.stages, lookup_only=True)
    try:
        run_stages(cfg, cache, step)  # the job's own chain, on a cache that builds nothing
        done = set(range(len(load_poses(found["trajectory"]))))
    except NotBuilt as missing:
        if missing.stage == "render":
            from eden_pipe.io.layout import MARKERS

            done = {int(p.stem) for p in (missing.path / MARKERS).glob("*.json") if p.stem.isdigit()}
    except (OSError, ValueError, KeyError):  # an unreadable cache: the job will rebuild it, count it all
        done = set()
    if "trajectory" in found:
        n_total = len(load_poses(found["trajectory"]))
    scene_cached = "scene" in found
    if {"render", "all"} & set(cfg.force):
        done = set()
    n_frames = sequence_length(n_total, cfg.render)
    return n_frames, [f for f in range(n_frames) if f not in done], scene_cached


def space_needed(cfg: EdenConfig) -> list[SpaceNeed]:
    """Bytes the job still writes, per destination filesystem (stages; the dataset when it is on
    another filesystem, where publishing copies instead of hard-linking)."""
    n_frames, todo, scene_cached = job_progress(cfg)
    pairs = int(cfg.camera.pairs)
    frame_bytes = [row_bytes(cfg, f + 1 < n_frames, f > 0) * pairs for f in todo]
    render = sum(frame_bytes)
    per_row = max(frame_bytes) / pairs if frame_bytes else 0
    detail = (
        f"{len(todo)} frames x {pairs} camera pairs x {_size(per_row)} per row, "
        f"{cfg.camera.width}x{cfg.camera.height}, storage={cfg.render.storage}"
    )
    stages = nearest_existing(Path(cfg.paths.stages))
    dataset = nearest_existing(Path(cfg.paths.dataset))
    meshes = 0 if scene_cached else mesh_bytes(cfg)
    if meshes:
        detail += f", plus ~{_size(meshes)} of models and scene"
    needs = [SpaceNeed(stages, render + meshes, shutil.disk_usage(stages).free, detail)]
    if os.stat(dataset).st_dev != os.stat(stages).st_dev:
        copies = sum(row_bytes(cfg, f + 1 < n_frames, f > 0) * pairs for f in range(n_frames))
        needs.append(
            SpaceNeed(
                dataset,
                copies,
                shutil.disk_usage(dataset).free,
                f"a copy of all {n_frames} frames: {cfg.paths.dataset} is on another filesystem",
            )
        )
    return needs


def check_free_space(cfg: EdenConfig) -> None:
    for need in space_needed(cfg):
        if need.need > need.free:
            raise PreflightError(
                f"not enough free space: the job needs ~{_size(need.need)}, {_size(need.free)} free at {need.path} "
                f"({need.detail}); free some space or set paths.check_free_space=false"
            )


@contextlib.contextmanager
def quiet_native_stderr():
    """File descriptor 2 to /dev/null for the block (what C libraries print at import)."""
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _size(n: float) -> str:
    units = ["B", "KB", "MB", "GB", "TB", "PB", "EB"]
    i = min(len(units) - 1, int(math.log(max(n, 1), 1024)))
    return f"{n / 1024**i:.1f} {units[i]}"
