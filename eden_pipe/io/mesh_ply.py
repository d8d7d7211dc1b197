"""The published scene mesh: binary little-endian PLY with per-face attributes (docs/design.md, Dataset layout).

One ``vertex`` element (``x y z`` float32, world frame, metres) and one ``face`` element whose records are
``vertex_indices`` (a list of 3 int32, count uchar) followed by the per-face properties of
:data:`FACE_PROPERTIES`: the instance id (as in the instance PNGs, 0 = none), the class id (the label
table), the material kind id and the material values the renderer shades the face with (linear albedo,
translucency, specular). PLY is the mesh format trimesh, Open3D, MeshLab and CloudCompare open with
per-face properties kept; the file is fixed-size records (no compression), written in one pass, and the
same arrays always give the same bytes.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from eden_pipe.io.atomic import write_bytes_atomic

# Per-face properties after vertex_indices: (PLY name, PLY type, numpy type), in file order.
FACE_PROPERTIES = (
    ("instance", "ushort", "<u2"),
    ("class", "uchar", "u1"),
    ("material", "uchar", "u1"),
    ("albedo_r", "float", "<f4"),
    ("albedo_g", "float", "<f4"),
    ("albedo_b", "float", "<f4"),
    ("translucency", "float", "<f4"),
    ("specular", "float", "<f4"),
)
VERTEX_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
FACE_DTYPE = np.dtype(
    [("count", "u1"), ("vertex_indices", "<i4", (3,))] + [(name, np_type) for name, _, np_type in FACE_PROPERTIES]
)
_PLY_TO_NUMPY = {
    "char": "i1",
    "uchar": "u1",
    "short": "<i2",
    "ushort": "<u2",
    "int": "<i4",
    "uint": "<u4",
    "float": "<f4",
    "double": "<f8",
    "int8": "i1",
    "uint8": "u1",
    "int16": "<i2",
    "uint16": "<u2",
    "int32": "<i4",
    "uint32": "<u4",
    "float32": "<f4",
    "float64": "<f8",
}


def bytes_per_face() -> int:
    return FACE_DTYPE.itemsize


def bytes_per_vertex() -> int:
    return VERTEX_DTYPE.itemsize


def mesh_ply_bytes(arrays: dict[str, np.ndarray], comments: tuple[str, ...] = ()) -> bytes:
    """The PLY file of ``arrays``: ``vertices`` (V, 3), ``faces`` (F, 3) and one (F,) array per per-face
    property (``albedo`` (F, 3) for ``albedo_r/g/b``); ``comments`` become header comment lines."""
    vertices = np.asarray(arrays["vertices"])
    faces = np.asarray(arrays["faces"])
    if vertices.ndim != 2 or vertices.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3:
        raise ValueError(f"vertices must be (V, 3) and faces (F, 3), got {vertices.shape} and {faces.shape}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise ValueError(f"face indices must lie in [0, {len(vertices)}), got [{faces.min()}, {faces.max()}]")
    vert = np.empty(len(vertices), VERTEX_DTYPE)
    vert["x"], vert["y"], vert["z"] = (vertices[:, i] for i in range(3))
    rec = np.empty(len(faces), FACE_DTYPE)
    rec["count"] = 3
    rec["vertex_indices"] = faces
    albedo = np.asarray(arrays["albedo"])
    per_face = {**arrays, "albedo_r": albedo[:, 0], "albedo_g": albedo[:, 1], "albedo_b": albedo[:, 2]}
    for name, _, _ in FACE_PROPERTIES:
        rec[name] = per_face[name]
    for line in comments:
        if "\n" in line or "\r" in line:
            raise ValueError(f"a PLY comment is one line, got {line!r}")
    header = ["ply", "format binary_little_endian 1.0", *(f"comment {c}" for c in comments)]
    header += [f"element vertex {len(vert)}", "property float x", "property float y", "property float z"]
    header += [f"element face {len(rec)}", "property list uchar int vertex_indices"]
    header += [f"property {ply_type} {name}" for name, ply_type, _ in FACE_PROPERTIES]
    return ("\n".join(header + ["end_header"]) + "\n").encode("ascii") + vert.tobytes() + rec.tobytes()


def write_mesh_ply(path: str | os.PathLike, arrays: dict[str, np.ndarray], comments: tuple[str, ...] = ()) -> int:
    """Write :func:`mesh_ply_bytes` atomically; returns the file's size in bytes."""
    data = mesh_ply_bytes(arrays, comments)
    write_bytes_atomic(path, data)
    return len(data)


def _parse_header(path: Path, raw: bytes) -> tuple[int, list[tuple[str, int, list[tuple[str, str]]]], list[str]]:
    """(offset of the body, [(element, count, [(property, numpy type or 'list:<count>:<item>')])], comments)."""
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply\n") or end < 0:
        raise ValueError(f"{path}: not a PLY file (no 'ply' magic or no end_header)")
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    comments = []
    for line in raw[:end].decode("ascii").splitlines()[1:]:
        words = line.split()
        if not words:
            continue
        if words[0] == "format" and words[1] != "binary_little_endian":
            raise ValueError(f"{path}: PLY format {words[1]!r}: this reader reads binary_little_endian")
        if words[0] == "comment":
            comments.append(line[len("comment ") :])
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and words[1] == "list":
            elements[-1][2].append((words[4], f"list:{_PLY_TO_NUMPY[words[2]]}:{_PLY_TO_NUMPY[words[3]]}"))
        elif words[0] == "property":
            elements[-1][2].append((words[2], _PLY_TO_NUMPY[words[1]]))
    return end + len(b"end_header\n"), elements, comments


def read_mesh_ply(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The arrays of a mesh PLY with triangle faces and fixed-size per-face records: ``vertices`` (V, 3)
    float32, ``faces`` (F, 3) int32, and every other face property by name (``albedo`` (F, 3) when the
    file has ``albedo_r/g/b``). Raises ValueError on any other layout."""
    path = Path(path)
    raw = path.read_bytes()
    offset, elements, _ = _parse_header(path, raw)
    out: dict[str, np.ndarray] = {}
    for name, count, props in elements:
        fields = []
        for prop, kind in props:
            if kind.startswith("list:"):
                _, count_type, item_type = kind.split(":")
                fields += [(f"{prop}__count", count_type), (prop, item_type, (3,))]
            else:
                fields.append((prop, kind))
        dtype = np.dtype(fields)
        if offset + count * dtype.itemsize > len(raw):
            raise ValueError(f"{path}: truncated: element {name!r} needs {count * dtype.itemsize} bytes")
        rec = np.frombuffer(raw, dtype, count=count, offset=offset)
        offset += count * dtype.itemsize
        if name == "vertex":
            out["vertices"] = np.stack([rec["x"], rec["y"], rec["z"]], axis=1)
        elif name == "face":
            counts = [p for p, k in props if k.startswith("list:")]
            if len(counts) != 1 or not np.all(rec[f"{counts[0]}__count"] == 3):
                raise ValueError(f"{path}: faces must be triangles listed in one vertex_indices property")
            out["faces"] = np.ascontiguousarray(rec[counts[0]])
            for prop, kind in props:
                if not kind.startswith("list:"):
                    out[prop] = np.ascontiguousarray(rec[prop])
    if offset != len(raw):
        raise ValueError(f"{path}: {len(raw) - offset} bytes after the last element")
    if {"albedo_r", "albedo_g", "albedo_b"} <= out.keys():
        out["albedo"] = np.stack([out.pop("albedo_r"), out.pop("albedo_g"), out.pop("albedo_b")], axis=1)
    if "vertices" not in out or "faces" not in out:
        raise ValueError(f"{path}: a mesh PLY needs a vertex and a face element")
    return out
