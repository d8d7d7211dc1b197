"""Write a Rerun recording of one garden under one lighting (docs/viewer.md).

    python -m eden_pipe.tools.view DATASET [--garden G] [--lighting L] --out garden.rrd [--spawn]
                                   [--frames N] [--depth-stride S] [--max-faces F]

What it logs (world frame: right-handed, Z up, metres; camera frames OpenCV, docs/design.md):

* ``/`` (static): the class table as an annotation context (ids, names and colours of ``eden_pipe.labels``),
  so every segmentation image and the mesh's class ids show their class name and colour;
* ``world/mesh`` (static): the published scene mesh (``<garden>/geometry.ply``) coloured by class, with
  each vertex's class id (a vertex takes the class of a face using it: vertices are shared across classes
  only on a handful of borders, 105 of 1.5 M in the small garden); every face by default (the default
  garden's 6.2 M faces: a 237 MB recording over 4 frames, 231 MB with 4 M faces, so subsampling saves
  little), or a seeded uniform subset of ``--max-faces`` faces (the log says so);
* ``world/camNN`` for each of the rig's cameras (3DRMS numbering: 2k left, 2k+1 right of pair k): its
  intrinsics (``Pinhole``, static) and, on the ``frame`` and ``time`` timelines, its camera-to-world pose;
* ``world/camNN/<column>`` per frame: every column of the modality table the dataset writes for that
  camera, by the column's kind (``Column.loader``): images as images, class and instance ids as
  segmentation images (instance images with the garden's instance table: "<id> <class> <species>"), depth
  as a depth image (metres; sky = 0), normals, flow (colour wheel), occlusion
  masks and linear layers (sRGB of exposure times the layer) as colour images;
* ``world/points/camNN`` per frame: the camera's depth as a point cloud in the world, coloured by its RGB
  image and labelled with its class ids where the camera has them (every ``--depth-stride``-th pixel).

Needs the ``viz`` extra (``pip install "eden-pipe[viz]"``: rerun-sdk). ``--spawn`` opens the written
recording in the Rerun viewer (``python -m rerun FILE``) where a display is available.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from eden_pipe import labels, metadata, modalities
from eden_pipe.data.manifest_reader import filter_manifest, load_manifest, row_pose
from eden_pipe.io.mesh_ply import read_mesh_ply
from eden_pipe.tools.scene_geometry import locate_geometry
from eden_pipe.tools.stats import colour_flow, colour_instance, colour_linear, colour_normal

FRAME_TIMELINE = "frame"
TIME_TIMELINE = "time"
IMAGE_PLANE_M = 0.4


def _log(msg: str) -> None:
    print(f"[eden-pipe view] {msg}", file=sys.stderr)


def _rerun() -> Any:
    try:
        import rerun
    except ImportError as exc:
        raise SystemExit(
            'eden_pipe.tools.view needs rerun-sdk: pip install "eden-pipe[viz]" (or pip install rerun-sdk)'
        ) from exc
    return rerun


def camera_entity(camera: int) -> str:
    return f"world/cam{camera:02d}"


def points_entity(camera: int) -> str:
    return f"world/points/cam{camera:02d}"


def select_job(root: Path, garden: str | None, lighting: str | None) -> pd.DataFrame:
    """The manifest rows of (garden, lighting): the first garden and lighting in the manifest when not given."""
    manifest = load_manifest(root)
    for key, value in (("garden", garden), ("lighting", lighting)):
        have = sorted(manifest[key].astype(str).unique())
        if value is not None and value not in have:
            raise SystemExit(f"--{key} {value!r} is not in {root}/manifest.csv; it holds: {', '.join(have)}")
    garden = garden or sorted(manifest["garden"].unique())[0]
    rows = filter_manifest(manifest, garden=garden)
    lighting = lighting or sorted(rows["lighting"].unique())[0]
    rows = filter_manifest(rows, lighting=lighting)
    if rows.empty:
        raise SystemExit(f"no manifest rows for garden {garden!r} under lighting {lighting!r} in {root}")
    return rows.sort_values(["frame", "camera"], kind="stable").reset_index(drop=True)


def instance_context(rr: Any, root: Path, garden: str) -> Any:
    """The garden's instance table (``scene.json``) as an annotation context: id -> "<id> <class> <species>",
    in the contact sheets' instance colours; logged on every instance image, where it overrides the class table."""
    try:
        instances = json.loads((root / garden / metadata.SCENE_FILE).read_text())["instances"]
    except (OSError, ValueError, KeyError) as exc:
        raise SystemExit(f"{root / garden / metadata.SCENE_FILE}: cannot read the instance table ({exc})") from exc
    ids = [0] + [int(i["id"]) for i in instances]
    names = ["none"] + [f"{i['id']} {i['class']} {i['species']}" for i in instances]
    colours = colour_instance(np.array(ids, np.int64))
    return rr.AnnotationContext(
        [rr.AnnotationInfo(id=i, label=name, color=c.tolist()) for i, name, c in zip(ids, names, colours, strict=True)]
    )


def annotation_context(rr: Any) -> Any:
    return rr.AnnotationContext(
        [
            rr.ClassDescription(info=rr.AnnotationInfo(id=i, label=name, color=labels.COLORS[i].tolist()))
            for i, name in enumerate(labels.NAMES)
        ]
    )


def mesh_archetype(rr: Any, path: Path, max_faces: int | None, seed: int = 0) -> tuple[Any, int, int]:
    """(Mesh3D of the published mesh coloured by class, faces in the file, faces logged)."""
    mesh = read_mesh_ply(path)
    faces, cls = mesh["faces"], mesh["class"]
    total = len(faces)
    if max_faces is not None and total > max_faces:
        keep = np.sort(np.random.default_rng(seed).choice(total, size=max_faces, replace=False))
        faces, cls = faces[keep], cls[keep]
    vertex_class = np.zeros(len(mesh["vertices"]), np.uint8)
    vertex_class[faces.ravel()] = np.repeat(cls, 3)
    archetype = rr.Mesh3D(
        vertex_positions=mesh["vertices"],
        triangle_indices=faces.astype(np.uint32),
        vertex_colors=labels.palette_rgb()[vertex_class],
        class_ids=vertex_class.astype(np.uint16),
    )
    return archetype, total, len(faces)


def _pixel_archetype(rr: Any, column: modalities.Column, array: np.ndarray, exposure: float) -> Any:
    """The archetype showing one decoded file, by its column's kind (modalities.Column.loader)."""
    kind = column.loader
    if kind == "image":
        return rr.Image(array)
    if kind in ("labels", "ids"):
        return rr.SegmentationImage(array)
    if kind == "depth":
        return rr.DepthImage(np.where(np.isfinite(array), array, 0).astype(np.float32), meter=1.0)
    if kind == "normal":
        return rr.Image(colour_normal(array))
    if kind == "flow":
        return rr.Image(colour_flow(np.nan_to_num(array)))
    if kind == "mask":
        return rr.Image((array > 0).astype(np.uint8) * 255)
    if kind == "layer":
        return rr.Image(colour_linear(array, exposure))  # linear radiance: sRGB of exposure times it, as the PNG
    raise ValueError(f"column {column.name}: no view for loader kind {kind!r} (modalities.LOADERS)")


def blueprint(rr: Any, size_m: float | None, columns: list[str], cameras: list[int]) -> Any:
    """The layout the recording opens with: the garden in 3-D (the mesh, the depth point clouds, each camera's
    frustum with its RGB image) beside every image of camera 0. The 3-D view leaves out the depth images'
    own point clouds (the viewer's, which misplaced the points of most cameras in rerun-sdk 0.41 on the
    software renderer): ``world/points`` holds the depth in 3-D, back-projected as the validator does."""
    import rerun.blueprint as rrb

    eye = None
    if size_m:
        centre = np.array([size_m / 2, size_m / 2, 0.0])
        eye = rrb.EyeControls3D(
            position=centre + np.array([-0.8, -1.05, 1.0]) * size_m, look_target=centre, eye_up=[0.0, 0.0, 1.0]
        )
    images = [rrb.Spatial2DView(origin=camera_entity(0), contents=[f"$origin/{c}"], name=f"cam00 {c}") for c in columns]
    rgb = [c.name for c in modalities.COLUMNS.values() if c.loader == "image"]
    contents = ["+ world/mesh", "+ world/points/**"]
    contents += [f"+ {camera_entity(k)}" for k in cameras] + [f"+ {camera_entity(k)}/{c}" for k in cameras for c in rgb]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                origin="world",
                contents=contents,
                name="garden (mesh by class, cameras, depth points)",
                eye_controls=eye,
            ),
            rrb.Grid(*images),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


def depth_points(depth: np.ndarray, K: np.ndarray, pose: np.ndarray, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """(world points (n, 3), (v, u) pixel index arrays) of every ``stride``-th pixel with a finite depth."""
    v, u = np.mgrid[0 : depth.shape[0] : stride, 0 : depth.shape[1] : stride]
    z = depth[v, u]
    ok = np.isfinite(z) & (z > 0)
    v, u, z = v[ok], u[ok], z[ok].astype(np.float64)
    cam = np.stack([(u - K[0, 2]) / K[0, 0] * z, (v - K[1, 2]) / K[1, 1] * z, z], axis=1)
    return (cam @ pose[:3, :3].T + pose[:3, 3]).astype(np.float32), np.stack([v, u])


def _garden_size(root: Path, garden: str) -> float | None:
    try:
        return float(json.loads((root / garden / metadata.SCENE_FILE).read_text())["size_m"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _columns_by_camera() -> dict[str, list[modalities.Column]]:
    out: dict[str, list[modalities.Column]] = {"left": [], "right": []}
    for column in modalities.COLUMNS.values():
        out[column.camera].append(column)
    return out


def write_recording(
    dataset,
    out,
    *,
    garden: str | None = None,
    lighting: str | None = None,
    frames: int | None = None,
    depth_stride: int = 4,
    max_faces: int | None = None,
) -> dict:
    """Write the recording (see the module doc) to ``out``; returns what was logged, by entity kind."""
    for name, value in (("depth_stride", depth_stride), ("max_faces", max_faces), ("frames", frames)):
        if value is not None and int(value) < 1:
            raise SystemExit(f"--{name.replace('_', '-')} must be >= 1, got {value}")
    root, out = Path(dataset), Path(out)
    if not (root / "manifest.csv").is_file():
        raise SystemExit(f"{root}: no manifest.csv (not an eden-pipe dataset root)")
    rows = select_job(root, garden, lighting)
    garden, lighting = str(rows["garden"].iloc[0]), str(rows["lighting"].iloc[0])
    if frames is not None:
        rows = rows[rows["frame"].isin(sorted(rows["frame"].unique())[:frames])]
    rr = _rerun()
    out.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream("eden_pipe", recording_id=f"{garden}/{lighting}")
    rec.save(out)
    facts: dict[str, Any] = {"garden": garden, "lighting": lighting, "frames": int(rows["frame"].nunique())}
    rec.log("/", annotation_context(rr), static=True)
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    geometry = locate_geometry(garden, dataset_root=root)
    if geometry is None:
        _log(f"no {garden}/{metadata.GEOMETRY_FILE} in {root}: the recording has no scene mesh")
    else:
        mesh, total, logged = mesh_archetype(rr, geometry, max_faces)
        rec.log("world/mesh", mesh, static=True)
        facts["mesh_faces"] = logged
        if logged < total:
            _log(f"mesh: {logged} of {total} faces logged (a seeded uniform subset; --max-faces {max_faces})")
    by_camera = _columns_by_camera()
    instances = instance_context(rr, root, garden)
    cameras: set[int] = set()
    annotated: set[str] = set()
    images = points = 0
    for rec_row in rows.to_dict("records"):
        frame, pair = int(rec_row["frame"]), int(rec_row["camera"])
        rec.set_time(FRAME_TIMELINE, sequence=frame)
        rec.set_time(TIME_TIMELINE, duration=float(rec_row["timestamp"]))
        K = np.array([[rec_row["fx"], 0, rec_row["cx"]], [0, rec_row["fy"], rec_row["cy"]], [0, 0, 1.0]])
        exposure = float(rec_row.get("exposure", 1.0))
        for side, camera_side in enumerate(("left", "right")):
            camera = metadata.camera_index(pair, side)
            entity = camera_entity(camera)
            pose = row_pose(rec_row, right=side == 1)
            if camera not in cameras:
                rec.log(
                    entity,
                    rr.Pinhole(
                        image_from_camera=K,
                        resolution=[int(rec_row["width"]), int(rec_row["height"])],
                        camera_xyz=rr.ViewCoordinates.RDF,
                        # Images are drawn on the frustum's far plane: near the rig, not scaled to the scene
                        # (the terrain's skirt makes the scene 100+ m wide).
                        image_plane_distance=IMAGE_PLANE_M,
                    ),
                    static=True,
                )
                cameras.add(camera)
            rec.log(entity, rr.Transform3D(translation=pose[:3, 3], mat3x3=pose[:3, :3]))
            decoded: dict[str, np.ndarray] = {}
            for column in by_camera[camera_side]:
                rel = rec_row.get(column.name, "")
                if not isinstance(rel, str) or not rel:
                    continue
                decoded[column.loader] = array = modalities.read_modality(root / rel, column.name)
                if column.loader == "ids" and f"{entity}/{column.name}" not in annotated:
                    rec.log(f"{entity}/{column.name}", instances, static=True)
                    annotated.add(f"{entity}/{column.name}")
                rec.log(f"{entity}/{column.name}", _pixel_archetype(rr, column, array, exposure))
                images += 1
            if "depth" in decoded:
                xyz, (v, u) = depth_points(decoded["depth"], K, pose, depth_stride)
                extra = {"class_ids": decoded["labels"][v, u]} if "labels" in decoded else {}
                colours = decoded["image"][v, u] if "image" in decoded else None
                rec.log(points_entity(camera), rr.Points3D(xyz, colors=colours, radii=0.01, **extra))
                points += len(xyz)
    written = [c.name for c in by_camera["left"] if c.name in rows and (rows[c.name].astype(str) != "").any()]
    rec.send_blueprint(blueprint(rr, _garden_size(root, garden), written, sorted(cameras)))
    rec.flush()
    facts.update(cameras=len(cameras), images=images, depth_points=points)
    return facts


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m eden_pipe.tools.view", description=__doc__.splitlines()[0])
    parser.add_argument("dataset", help="dataset root (holds manifest.csv)")
    parser.add_argument("--garden", help="garden id (default: the manifest's first)")
    parser.add_argument("--lighting", help="lighting (default: the garden's first)")
    parser.add_argument("--out", required=True, help="the .rrd file to write")
    parser.add_argument("--spawn", action="store_true", help="open the recording in the Rerun viewer")
    parser.add_argument("--frames", type=int, help="log only the first N frames (default: all)")
    parser.add_argument("--depth-stride", type=int, default=4, help="depth point cloud: every S-th pixel (4)")
    parser.add_argument("--max-faces", type=int, help="log a seeded subset of F mesh faces (default: every face)")
    args = parser.parse_args(argv)
    facts = write_recording(
        args.dataset,
        args.out,
        garden=args.garden,
        lighting=args.lighting,
        frames=args.frames,
        depth_stride=args.depth_stride,
        max_faces=args.max_faces,
    )
    _log(f"{args.out}: {facts}")
    if args.spawn:
        subprocess.Popen([sys.executable, "-m", "rerun", str(args.out)])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
