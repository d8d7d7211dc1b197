"""The metadata published beside the images, so a dataset explains itself without the stage cache.

Layout under the dataset root (docs/design.md, Dataset layout):

    dataset.json                          generator, label table, column formats, every job's config
    <garden>/scene.json                   every instance (id, class, pool, species, seed, transform, bounds)
    <garden>/geometry.ply                 the scene mesh every image was rendered from: binary PLY, per face its
                                          instance id, class id, material kind and values (eden_pipe.io.mesh_ply)
    <garden>/<lighting>/lighting.json     the lighting actually sampled (sun, sky, clouds, exposure)
    <garden>/<lighting>/rig.json          K, baseline, the ten camera offsets, per-frame poses of all ten cameras
    <garden>/<lighting>/camera.json       only with a camera effect on: the sensor model's parameters, the
                                          rolling shutter's readout and the exposure (docs/design.md, Camera effects)
    <garden>/<lighting>/poses/camNN.txt   the same poses as TUM trajectories (timestamp tx ty tz qx qy qz qw)
    <garden>/<lighting>/config.yaml       the job's resolved config

Cameras are numbered as in 3DRMS: camera 2k is the left and 2k+1 the right camera of
pair k (manifest column ``camera`` is the pair k). Everything is plain JSON, CSV-like
text or YAML that the standard library (or any YAML reader) reads.
"""

from __future__ import annotations

import math
import subprocess
from pathlib import Path

import numpy as np

from eden_pipe import labels
from eden_pipe.geometry import spherical_direction

SCENE_FILE = "scene.json"
GEOMETRY_FILE = "geometry.ply"
LIGHTING_FILE = "lighting.json"
RIG_FILE = "rig.json"
CAMERA_FILE = "camera.json"
CONFIG_FILE = "config.yaml"
POSES_DIR = "poses"
DATASET_FILE = "dataset.json"
# Files a job folder holds besides the images: publishing must never prune them.
JOB_METADATA = (LIGHTING_FILE, RIG_FILE, CONFIG_FILE, CAMERA_FILE)


# Decimals of the poses rig.json publishes; the camera effects interpolate these same rounded poses,
# so a user reproduces the renderer's per-row poses exactly from rig.json (docs/design.md, Camera effects).
POSE_DECIMALS = 9


def published_poses(poses: np.ndarray) -> np.ndarray:
    """Camera-to-world poses as ``rig.json`` publishes them (rounded to POSE_DECIMALS)."""
    return np.round(poses, POSE_DECIMALS)


def camera_index(pair: int, side: int) -> int:
    """3DRMS camera number: 2k for the left (side 0), 2k+1 for the right camera of pair k."""
    return 2 * pair + side


def scene_metadata(scene: dict) -> dict:
    """The published instance table: what each id in an instance PNG is."""
    instances = [
        {
            "id": int(i["id"]),
            "class": i["class"],
            "class_id": int(i["semantic"]),
            "pool": i["pool"],
            "species": i["type"],
            "model_seed": int(i["model_seed"]),
            "transform": i["transform"],
            "bbox_min": i["bbox_min"],
            "bbox_max": i["bbox_max"],
            "faces": int(i["faces"]),
        }
        for i in scene["instances"]
    ]
    lawn = scene.get("lawn") or {}
    # The fence's style is the type of its runs (a garden has one fence or none).
    fence_style = next((i["type"] for i in scene["instances"] if i["pool"] == "fence"), None)
    return {
        "garden": scene["garden_id"],
        "seed": int(scene["seed"]),
        "size_m": scene["size_m"],
        "instance_id_note": "0 = no instance (terrain, lawn, background); ids match the instance PNGs",
        "instances": instances,
        "requested": scene.get("requested", {}),
        "placed": scene.get("placed", {}),
        "unplaced": scene.get("unplaced", []),
        "terrain_types": scene.get("terrain_types", []),
        "lawn_species": sorted(set(_lawn_species(lawn))),
        "lawn": lawn,
        "fence_style": fence_style,
        "faces": scene.get("faces"),
        # The scene mesh published beside this file (GEOMETRY_FILE; the "geometry" entry is what readers
        # such as tools.scene_geometry follow).
        "geometry": GEOMETRY_FILE,
    }


def _lawn_species(lawn: dict) -> list[str]:
    species = lawn.get("species") or []
    return [s if isinstance(s, str) else s.get("name", str(s)) for s in species]


def lighting_metadata(params: dict, exposure: float, sun: dict | None = None, wind: dict | None = None) -> dict:
    """The lighting actually sampled for a (garden, lighting) job, in degrees and plain units.

    ``params`` are the sampled LightingParams (radians); ``sun`` adds what the sky derived
    from them (``Sky.facts``: the direct light's irradiance, colour and size, the environment
    map with its hash and extracted sun, the scenery) when the renderer reports it. At night
    the direct light is the moon: the ``sun_*`` values describe it (``direct_light``). ``wind``:
    the wind drawn (``render.wind.WindParams.facts``), only when it blows."""
    degrees = lambda key: None if params.get(key) is None else math.degrees(params[key])  # noqa: E731
    out = {
        "scenario": params["scenario"],
        "sun_elevation_deg": math.degrees(params["sun_elevation"]),
        "sun_azimuth_deg": math.degrees(params["sun_azimuth"]),
        "sun_azimuth_convention": "degrees from world +x toward +y (world Z up)",
        "sun_direction": spherical_direction(params["sun_elevation"], params["sun_azimuth"]).tolist(),
        "turbidity": params["turbidity"],
        "sun_intensity": params.get("sun_intensity"),
        "sun_drawn_angular_diameter_deg": degrees("sun_angular_diameter"),
        "sun_temperature_k": params.get("sun_temperature"),
        "moon_phase": params.get("moon_phase"),
        "sky_intensity": params.get("sky_intensity"),
        "cloud_cover": params.get("cloud_cover"),
        "cloud_speed_mps": params.get("cloud_speed"),
        "environment_rotation_deg": degrees("environment_rotation"),
        "exposure": float(exposure),
        "exposure_note": "rgb PNG = sRGB(exposure * rgb_linear)",
    }
    for key, value in (sun or {}).items():
        out[key] = value
    found = (out.get("environment") or {}).get("sun_found")
    if found:  # the sun is the map's (environment_sun=auto), not the drawn one
        x, y, z = found["direction"]
        out.update(
            sun_direction=list(found["direction"]),
            sun_elevation_deg=math.degrees(math.asin(max(-1.0, min(1.0, z)))),
            sun_azimuth_deg=math.degrees(math.atan2(y, x)),
        )
    if wind is not None:
        out["wind"] = {**wind, "direction_convention": "degrees from world +x toward +y: where the wind blows to"}
    return out


def rig_metadata(
    K: np.ndarray,
    width: int,
    height: int,
    baseline: float,
    rig_offsets: np.ndarray,
    poses: np.ndarray,
    timestamps: np.ndarray,
) -> dict:
    """K, the ten camera offsets in the rig frame and every camera's camera-to-world pose per frame.

    ``rig_offsets``: (pairs, 2, 4, 4) camera-to-rig transforms (rig frame: centre, heading 0);
    ``poses``: (frames, pairs, 2, 4, 4) camera-to-world."""
    pairs = poses.shape[1]
    cameras = []
    for k in range(pairs):
        for side in (0, 1):
            cameras.append(
                {
                    "camera": camera_index(k, side),
                    "pair": k,
                    "side": "left" if side == 0 else "right",
                    "rig_offset": np.round(rig_offsets[k, side], 9).tolist(),
                    "poses": published_poses(poses[:, k, side]).tolist(),
                }
            )
    return {
        "width": int(width),
        "height": int(height),
        "K": np.asarray(K, float).tolist(),
        "baseline_m": float(baseline),
        "conventions": "OpenCV camera axes (x right, y down, z forward); poses are camera-to-world 4x4; "
        "world right-handed, Z up, metres; camera 2k = left, 2k+1 = right camera of pair k",
        "timestamps": np.round(timestamps, 6).tolist(),
        "cameras": cameras,
    }


def camera_metadata(sensor: dict | None, readout_s: float, exposure_s: float, blur_samples: int, fps: float) -> dict:
    """The camera effects a job's PNGs went through (``camera.json``; docs/design.md, Camera effects).

    ``sensor``: ``camera.sensor.Sensor.facts()``, or None when the sensor model is off."""
    return {
        "sensor": sensor,
        "sensor_model": (
            "x = vignetting * CA(exposure * I); e = Poisson(x * full_well_e / gain) + Normal(0, read_noise_e); "
            "DN = clip(round(e * gain * (white_dn - black_dn) / full_well_e + black_dn), 0, white_dn); "
            "png = round(255 * tone(clip((DN - black_dn) / (white_dn - black_dn), 0, 1)))"
        ),
        "readout_s": float(readout_s),
        "exposure_s": float(exposure_s),
        "blur_samples": int(blur_samples) if exposure_s > 0 else 1,
        "fps": float(fps),
        "timing": (
            "row r of a view (height H) at sub-frame sample j of S is seen at frame time + (r / (H - 1) - 0.5) "
            "* readout_s + ((j + 0.5) / S - 0.5) * exposure_s; its pose interpolates rig.json's poses of that "
            "camera (rotation slerp, translation lerp; past the trajectory's ends, extrapolated from the last "
            "two frames): eden_pipe.camera.shutter.exposure_poses(rig.json's poses of the camera, fps, frame, height, "
            "readout_s, exposure_s, blur_samples) gives exactly the poses the renderer used"
        ),
        "ground_truth": (
            "only the rgb PNG holds these effects; labels, depth, normals, flow and every linear layer "
            "(rgb_linear included) are the sharp, global-shutter render at the frame time"
        ),
    }


def tum_lines(timestamps: np.ndarray, poses: np.ndarray) -> str:
    """A TUM trajectory: one line `timestamp tx ty tz qx qy qz qw` per frame (camera-to-world)."""
    from eden_pipe.camera.rig import rotation_to_quaternion

    lines = ["# timestamp tx ty tz qx qy qz qw  (camera-to-world, OpenCV camera axes, world Z up)"]
    for t, pose in zip(timestamps, poses, strict=True):
        qw, qx, qy, qz = rotation_to_quaternion(pose[:3, :3])
        tx, ty, tz = pose[:3, 3]
        lines.append(" ".join(f"{v:.9g}" for v in (t, tx, ty, tz, qx, qy, qz, qw)))
    return "\n".join(lines) + "\n"


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(timestamps (N,), camera-to-world poses (N, 4, 4)) from a TUM trajectory file."""
    from eden_pipe.camera.rig import quaternion_to_rotation

    data = np.loadtxt(path, comments="#", ndmin=2)
    poses = np.tile(np.eye(4), (len(data), 1, 1))
    for i, (_, tx, ty, tz, qx, qy, qz, qw) in enumerate(data):
        poses[i, :3, :3] = quaternion_to_rotation([qw, qx, qy, qz])
        poses[i, :3, 3] = (tx, ty, tz)
    return data[:, 0], poses


def label_table() -> list[dict]:
    return [{"id": i, "name": n, "rgb": labels.COLORS[i].tolist()} for i, n in enumerate(labels.NAMES)]


def git_commit(repo: Path | None = None) -> str | None:
    """The generator's git commit, or None when it does not run from a checkout."""
    repo = repo or Path(__file__).resolve().parents[1]
    try:
        out = subprocess.run(["git", "-C", str(repo), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=10)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if out.returncode != 0:
        return None
    dirty = subprocess.run(
        ["git", "-C", str(repo), "status", "--porcelain", "--untracked-files=no"],
        capture_output=True,
        text=True,
        timeout=10,
    ).stdout.strip()
    return out.stdout.strip() + ("-dirty" if dirty else "")
