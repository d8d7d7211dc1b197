"""Find and sample a garden's scene mesh.

A dataset publishes it as ``<root>/<garden>/geometry.ply`` (:mod:`eden_pipe.io.mesh_ply`; named by the
``"geometry"`` entry of ``<garden>/scene.json``); the stage cache holds it too (``<stages>/scene/<key>/``:
``scene.json`` with ``garden_id``, ``geometry.npz`` and ``geometry.ply``). :func:`locate_geometry` tries,
in order: an explicit path; the dataset's metadata (``<root>/<garden>/scene.json`` or
``<root>/<garden>/metadata.json`` with a ``"geometry"`` entry, relative to that file, or a
``geometry.npz`` beside it); then a scan of ``<stages>/scene/*`` for a finished artifact whose
``scene.json`` has that ``garden_id`` (datasets published before the mesh was). :func:`load_geometry`
reads either file.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from eden_pipe import labels
from eden_pipe.io.mesh_ply import read_mesh_ply


def _from_metadata(dataset_root: Path, garden: str) -> Path | None:
    folder = dataset_root / garden
    for name in ("metadata.json", "scene.json"):
        meta = folder / name
        if meta.is_file():
            try:
                ref = json.loads(meta.read_text()).get("geometry")
            except (ValueError, AttributeError):
                ref = None
            if isinstance(ref, str) and (folder / ref).is_file():
                return folder / ref
    direct = folder / "geometry.npz"
    return direct if direct.is_file() else None


def _from_stages(stages: Path, garden: str) -> Path | None:
    hits = []
    for scene_json in sorted((stages / "scene").glob("*/scene.json")):
        folder = scene_json.parent
        if not (folder / "geometry.npz").is_file() or not (folder / "DONE.json").is_file():
            continue
        try:
            garden_id = json.loads(scene_json.read_text()).get("garden_id")
        except ValueError:
            continue
        if garden_id == garden:
            hits.append(folder / "geometry.npz")
    # Several finished artifacts for one garden (code changed between runs): take the newest.
    return max(hits, key=lambda p: p.stat().st_mtime) if hits else None


def locate_geometry(
    garden: str,
    *,
    dataset_root: str | os.PathLike | None = None,
    stages: str | os.PathLike | None = None,
    explicit: str | os.PathLike | None = None,
) -> Path | None:
    """Path of ``garden``'s geometry.npz, or None when none of the sources has it."""
    if explicit is not None:
        return Path(explicit) if Path(explicit).is_file() else None
    if dataset_root is not None:
        hit = _from_metadata(Path(dataset_root), garden)
        if hit is not None:
            return hit
    if stages is not None:
        return _from_stages(Path(stages), garden)
    return None


def load_geometry(path: str | os.PathLike) -> dict[str, np.ndarray | None]:
    """``vertices`` (V, 3) float64, ``faces`` (F, 3) int64, ``semantic`` (F,) uint8 and ``instance`` (F,)
    int64 (None when the file has none) from a published ``geometry.ply`` or a stage's ``geometry.npz``."""
    if Path(path).suffix.lower() == ".ply":
        mesh = read_mesh_ply(path)
        return {
            "vertices": np.asarray(mesh["vertices"], np.float64),
            "faces": np.asarray(mesh["faces"], np.int64),
            "semantic": np.asarray(mesh["class"], np.uint8),
            "instance": np.asarray(mesh["instance"], np.int64),
        }
    with np.load(path) as data:
        return {
            "vertices": np.asarray(data["vertices"], np.float64),
            "faces": np.asarray(data["faces"], np.int64),
            "semantic": np.asarray(data["semantic"], np.uint8),
            "instance": np.asarray(data["instance"], np.int64) if "instance" in data else None,
        }


def face_areas(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def sample_points(geometry: dict, n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """``n`` points uniform over the mesh surface (faces drawn by area, uniform barycentrics).

    Returns ``points`` (n, 3) float32, ``label`` (n,) uint8 (the face's semantic id),
    ``instance`` (n,) uint16 (0 when the geometry has no per-face instance) and ``face`` (n,) int64.
    """
    v, f = geometry["vertices"], geometry["faces"]
    areas = face_areas(v, f)
    total = areas.sum()
    if len(f) == 0 or total <= 0:
        raise ValueError("the scene mesh has no area to sample")
    rng = np.random.default_rng(seed)
    face = rng.choice(len(f), size=int(n), p=areas / total)
    r1, r2 = rng.random(int(n)), rng.random(int(n))
    s = np.sqrt(r1)
    w0, w1, w2 = 1 - s, s * (1 - r2), s * r2
    tri = v[f[face]]
    pts = w0[:, None] * tri[:, 0] + w1[:, None] * tri[:, 1] + w2[:, None] * tri[:, 2]
    inst = geometry.get("instance")
    return {
        "points": pts.astype(np.float32),
        "label": geometry["semantic"][face].astype(np.uint8),
        "instance": (inst[face] if inst is not None else np.zeros(len(face))).astype(np.uint16),
        "face": face,
    }


def write_ply(
    path: str | os.PathLike, points: np.ndarray, label: np.ndarray, instance: np.ndarray | None = None
) -> None:
    """Binary little-endian PLY: x y z float32, red green blue uchar (3DRMS colours), label uchar, instance ushort."""
    n = len(points)
    dtype = np.dtype(
        [
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
            ("label", "u1"),
            ("instance", "<u2"),
        ]
    )
    rec = np.empty(n, dtype)
    rec["x"], rec["y"], rec["z"] = (points[:, i] for i in range(3))
    colours = labels.palette_rgb()[np.asarray(label, np.uint8)]
    rec["red"], rec["green"], rec["blue"] = colours[:, 0], colours[:, 1], colours[:, 2]
    rec["label"] = label
    rec["instance"] = 0 if instance is None else instance
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        "comment eden-pipe semantic point cloud: label = 3DRMS class id (eden_pipe.labels), world frame, metres\n"
        f"element vertex {n}\nproperty float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "property uchar label\nproperty ushort instance\nend_header\n"
    )
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(rec.tobytes())
