"""Publishing the metadata that makes a dataset self-describing (docs/design.md, Dataset layout).

After a job's images are published, :func:`publish_metadata` writes, beside them, the
garden's instance table and scene mesh, the lighting actually sampled, the rig and every camera's
poses (JSON and TUM text) and the job's resolved config; :func:`describe_dataset`
keeps ``dataset.json`` at the root (generator, labels, column formats, splits, every
job's config) under the manifest lock. Files are only rewritten when their content
changes, so an identical rerun writes nothing. The file layout is :mod:`eden_pipe.metadata`'s.
"""

from __future__ import annotations

import json
from importlib import metadata as importlib_metadata
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from eden_pipe import labels, metadata, modalities
from eden_pipe.camera.effects import effects_on, without_effects_off
from eden_pipe.camera.rig import Intrinsics, Rig
from eden_pipe.camera.sensor import Sensor
from eden_pipe.config import EdenConfig, to_plain
from eden_pipe.io.atomic import link_or_copy, write_if_changed
from eden_pipe.lighting import without_still_wind
from eden_pipe.scene.description import read_scene
from eden_pipe.stages.cache import Artifact, file_lock
from eden_pipe.stages.trajectory import load_poses

MANIFEST_LOCK = ".manifest.lock"


# Run-environment keys: where files go and what to recompute change no byte of a dataset, so the
# published configs leave them out (two runs of one config into two folders publish the same files).
RUN_ONLY_KEYS = ("paths", "force", "progress")


def published_config(cfg: EdenConfig) -> dict:
    """The job's config without the run-environment keys (and without the wind's keys in still air and the
    camera effects' keys with every effect off: the config.yaml of a dataset made before they existed)."""
    plain = {k: v for k, v in to_plain(cfg).items() if k not in RUN_ONLY_KEYS}
    return {**plain, "camera": without_effects_off(plain["camera"]), "lighting": without_still_wind(plain["lighting"])}


def _json_bytes(obj) -> bytes:
    return (json.dumps(obj, indent=1, sort_keys=False) + "\n").encode()


def is_job_metadata(path: Path, job_dir: Path) -> bool:
    """Whether a file under a job folder is metadata (kept when stale images are pruned)."""
    rel = path.relative_to(job_dir)
    return rel.name in metadata.JOB_METADATA or (len(rel.parts) == 2 and rel.parts[0] == metadata.POSES_DIR)


def publish_metadata(
    cfg: EdenConfig, scene_art: Artifact, traj_art: Artifact, render_art: Artifact, root: str | Path
) -> int:
    """Write the job's metadata under the dataset root; returns the number of files written."""
    root = Path(root)
    scene = read_scene(scene_art)
    garden, lighting = scene.garden_id, str(cfg.lighting.name)
    job_dir = root / garden / lighting
    marker = render_art.marker()
    poses = load_poses(traj_art)
    timestamps = np.arange(len(poses)) / float(cfg.camera.trajectory.fps)
    intr = Intrinsics.from_config(cfg.camera)
    rig = Rig.from_config(cfg.camera)
    files = {
        root / garden / metadata.SCENE_FILE: _json_bytes(metadata.scene_metadata(scene.to_dict())),
        job_dir / metadata.LIGHTING_FILE: _json_bytes(
            metadata.lighting_metadata(marker["lighting"], marker["exposure"], marker.get("sun"), marker.get("wind"))
        ),
        job_dir / metadata.RIG_FILE: _json_bytes(
            {
                **metadata.rig_metadata(
                    intr.K, intr.width, intr.height, rig.baseline, rig.poses(np.zeros(3), 0.0), poses, timestamps
                ),
                # One random walk per lighting (EDEN), or one walk shared by every lighting of the garden.
                "trajectory_shared_across_lightings": bool(cfg.camera.trajectory.share_across_lightings),
            }
        ),
        job_dir / metadata.CONFIG_FILE: OmegaConf.to_yaml(OmegaConf.create(published_config(cfg))).encode(),
    }
    effects = camera_effects_metadata(cfg)
    if effects is not None:  # without any effect no file: the metadata stay as they were
        files[job_dir / metadata.CAMERA_FILE] = _json_bytes(effects)
    else:  # an earlier run's with effects would tell the validator and users of effects these PNGs lack
        (job_dir / metadata.CAMERA_FILE).unlink(missing_ok=True)
    for k in range(poses.shape[1]):
        for side in (0, 1):
            cam = metadata.camera_index(k, side)
            files[job_dir / metadata.POSES_DIR / f"cam{cam:02d}.txt"] = metadata.tum_lines(
                timestamps, poses[:, k, side]
            ).encode()
    written = sum(write_if_changed(path, data) for path, data in files.items())
    # The scene mesh is the scene stage's file itself (a hard link, as the images): one per garden.
    written += link_or_copy(scene_art.path / metadata.GEOMETRY_FILE, root / garden / metadata.GEOMETRY_FILE)
    return written + describe_dataset(root, cfg, garden, lighting)


def camera_effects_metadata(cfg: EdenConfig) -> dict | None:
    """``camera.json``'s contents, or None with every camera effect off."""
    cam = cfg.camera
    if not effects_on(cam):
        return None
    sensor = Sensor.from_config(cam.sensor)
    facts = None if sensor is None else sensor.facts()
    return metadata.camera_metadata(
        facts, float(cam.readout_s), float(cam.exposure_s), int(cam.blur_samples), float(cam.trajectory.fps)
    )


def _generator() -> dict:
    try:
        version = importlib_metadata.version("eden-pipe")
    except importlib_metadata.PackageNotFoundError:
        version = None
    return {"name": "eden-pipe", "version": version, "git_commit": metadata.git_commit()}


def column_table(options: modalities.WriteOptions) -> dict:
    """Each manifest path column: its modality, file extension, encoding and units (from the modality table)."""
    table = {}
    for modality in modalities.TABLE:
        for column in modality.columns:
            fmt = column.file_format(options)
            table[column.name] = {
                "modality": modality.name,
                "camera": column.camera,
                "extension": fmt.ext,
                "encoding": fmt.encoding,
                "only_with": column.needs,
                "channels": column.channels,
                "dtype": column.dtype,
                "units": column.units,
                "values": modalities.VALUE_DOMAINS[column.values].description,
                "precision": {"step": fmt.step, "relative": fmt.relative},
                "image_formation": column.role,
            }
    return table


CONVENTIONS = {
    "units": "metres, seconds; angles in degrees in metadata",
    "world": "right-handed, Z up; the garden ground spans x, y in [0, size_m]",
    "camera": "OpenCV axes (x right, y down, z forward); pixel centres at integer coordinates",
    "poses": "camera-to-world 4x4; manifest qw..tz are the left camera of pair `camera`; "
    "the right camera is the left one shifted +baseline along its own x axis",
    "cameras": "camera 2k / 2k+1 = left / right camera of pair k (rig.json, poses/camNN.txt)",
    "depth": "z along the optical axis (not ray length)",
    "flow": "(dx, dy) pixels from frame t to t+1 (flow_fwd) or t-1 (flow_bwd), same camera; occ_* = 1 where "
    "the point is hidden or leaves the image",
    "image_formation": modalities.formation_identity(),
    "instances": "instance PNG ids are listed in <garden>/scene.json; 0 = none",
}


def describe_dataset(root: Path, cfg: EdenConfig, garden: str, lighting: str) -> int:
    """Add this job to ``<root>/dataset.json`` (under the manifest lock); 1 if the file changed."""
    path = root / metadata.DATASET_FILE
    root.mkdir(parents=True, exist_ok=True)
    with file_lock(root / MANIFEST_LOCK):
        old = json.loads(path.read_text()) if path.is_file() else {}
        jobs = dict(old.get("jobs", {}))
        jobs[f"{garden}/{lighting}"] = published_config(cfg)
        split = to_plain(cfg.split)
        description = {
            "name": "eden-pipe synthetic garden dataset",
            "generator": _generator(),
            "manifest": (
                "manifest.csv: one row per (garden, lighting, frame, camera pair); paths relative to this folder"
            ),
            "conventions": CONVENTIONS,
            "labels": metadata.label_table(),
            "ignore_label": labels.VOID,
            "columns": column_table(modalities.WriteOptions.from_config(cfg.render)),
            "metadata_files": {
                "scene": f"<garden>/{metadata.SCENE_FILE}",
                "geometry": f"<garden>/{metadata.GEOMETRY_FILE}",
                "lighting": f"<garden>/<lighting>/{metadata.LIGHTING_FILE}",
                "rig": f"<garden>/<lighting>/{metadata.RIG_FILE}",
                "camera_effects": f"<garden>/<lighting>/{metadata.CAMERA_FILE} (only with a camera effect on)",
                "config": f"<garden>/<lighting>/{metadata.CONFIG_FILE}",
                "tum_poses": f"<garden>/<lighting>/{metadata.POSES_DIR}/camNN.txt",
                "test_subsample": TEST_SUBSAMPLE_FILE,
            },
            "split": {"preset": split["preset"], "test_subsample": split["test_subsample"]},
            "jobs": dict(sorted(jobs.items())),
        }
        return int(write_if_changed(path, _json_bytes(description)))


TEST_SUBSAMPLE_FILE = "test_subsample.txt"


def subsample_settings(root: Path) -> dict | None:
    """The test-subsample settings recorded in dataset.json (None when off or absent)."""
    path = Path(root) / metadata.DATASET_FILE
    if not path.is_file():
        return None
    settings = json.loads(path.read_text()).get("split", {}).get("test_subsample") or {}
    if settings.get("count") is None and settings.get("fraction") is None:
        return None
    return settings
