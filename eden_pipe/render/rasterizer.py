"""pybullet's TinyRenderer as a second backend: rgb, z-depth, semantic and instance.

A preview renderer and a test oracle for the Embree backend
(``eden_pipe.render.embree``): an independent rasteriser fed the same
renderer-agnostic scene (``SceneArrays``: the world mesh and per-face instance
ids) and the same cameras (OpenCV camera-to-world poses and ``Intrinsics``).

Conventions, all measured on pybullet 3.2.7 (``tests/test_oracle.py`` checks
them against Embree):

- Cameras. pybullet wants OpenGL view and projection matrices as column-major
  16-float lists. The view matrix is ``diag(1, -1, -1, 1) @ inv(pose)`` (OpenCV
  x right, y down, z forward -> OpenGL x right, y up, z backward). TinyRenderer
  samples every triangle at integer screen coordinates ``(x, y)`` with
  ``x = (x_ndc + 1) W / 2``, ``y = (y_ndc + 1) H / 2``, and returns row
  ``H - 1 - y`` as image row 0 at the top. So OpenCV pixel ``(u, v)``, whose
  centre is at coordinates ``(u, v)`` (``eden_pipe.camera.rig``), needs
  ``x_ndc = 2u/W - 1`` and ``y_ndc = 1 - 2(v + 1)/H``:
  ``P[0] = [2fx/W, 0, 1 - 2cx/W, 0]`` and ``P[1] = [0, 2fy/H, 2(cy + 1)/H - 1, 0]``.
  With these the rasteriser samples exactly the rays through the pixel
  centres that ``render.view.primary_rays`` traces (no half-pixel shift; the
  textbook OpenGL matrix, which assumes centres at ``u + 0.5``, would be off by
  half a pixel in x and half a pixel the other way in y).
- Depth. The returned buffer is OpenGL's non-linear depth ``d`` in [0, 1];
  z-depth (along the optical axis) is ``far*near / (far - (far - near) d)``.
  ``far`` is chosen per view beyond the farthest scene vertex, so nothing is
  clipped; sky pixels (segmentation -1) get ``inf``.
- Culling. TinyRenderer culls back faces whatever the visual-shape flags say
  (``VISUAL_SHAPE_DOUBLE_SIDED`` is ignored), while eden-pipe's thin surfaces
  are single-sided polygons seen from both sides. Every triangle is therefore
  uploaded twice, once per winding; the copy facing away is culled.
- Upload. Meshes go to pybullet as temporary binary STL files
  (``createVisualShape(GEOM_MESH, fileName=...)``), one per group chunk of at
  most ``MAX_FILE_FACES`` faces, written straight from numpy. The in-memory
  route (``vertices=``, ``indices=``, ``normals=`` lists) is worse on every
  count: at most 131072 vertices and 524288 indices per shape, and pybullet
  3.2.7 leaks a reference to every vertex and normal triple it is given, so
  a 1M-face garden kept ~2 GB of Python objects alive and took 7 s to upload
  (STL: ~0.4 GB, 3.5 s).
- Shading. pybullet's own normals for a mesh are meaningless for lighting, so
  each STL facet carries its face normal (the reversed copy the negated one):
  flat, two-sided shading. ``lightDirection`` points toward the light (the
  sky's sun direction). TinyRenderer's shading is 0.6 ambient + 0.35 diffuse +
  0.05 specular times the body colour; no shadows.
- Labels. Segmentation returns the body uid per pixel (-1 = background), and
  per-vertex colours are not supported, so the world mesh is split into one
  static visual body per (semantic, instance, material) group (and file).
  A body's uid maps back to its semantic and instance ids; its colour is the
  group's mean albedo (TinyRenderer is a preview: colour fidelity is
  secondary, labels and depth are exact up to rasterisation).

One ``TinyRenderer`` owns a private pybullet DIRECT client; building the
bodies costs about as much as rendering a few views (see
``docs/scale-out.md`` for measured timings), so build once per scene and
render every camera of every frame with it.
"""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import numpy as np
import pybullet as pb

from eden_pipe import labels
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.colour import linear_to_srgb, srgb_to_linear
from eden_pipe.render.backends.tinyrenderer import NEAR, TinyRendererBackend

SUPPORTED = TinyRendererBackend.capabilities  # the passes it makes: declared once, by the backend
MAX_FILE_FACES = 500_000  # faces per temporary STL file (two triangles each: both windings)
STL_RECORD = np.dtype([("normal", "<f4", (3,)), ("vertices", "<f4", (3, 3)), ("attribute", "<u2")])
OPENCV_TO_OPENGL = np.diag([1.0, -1.0, -1.0, 1.0])


# ------------------------------------------------------------------ cameras
def gl_view_matrix(pose: np.ndarray) -> list[float]:
    """Column-major OpenGL view matrix of an OpenCV camera-to-world pose."""
    view = OPENCV_TO_OPENGL @ np.linalg.inv(np.asarray(pose, dtype=np.float64))
    return view.T.ravel().tolist()


def gl_projection_matrix(intr: Intrinsics, near: float, far: float) -> list[float]:
    """Column-major projection for TinyRenderer that samples OpenCV pixel centres exactly (module doc)."""
    w, h = float(intr.width), float(intr.height)
    p = np.zeros((4, 4))
    p[0, 0] = 2.0 * intr.fx / w
    p[0, 2] = 1.0 - 2.0 * intr.cx / w
    p[1, 1] = 2.0 * intr.fy / h
    p[1, 2] = 2.0 * (intr.cy + 1.0) / h - 1.0
    p[2, 2] = -(far + near) / (far - near)
    p[2, 3] = -2.0 * far * near / (far - near)
    p[3, 2] = -1.0
    return p.T.ravel().tolist()


def linearize_depth(d: np.ndarray, near: float, far: float) -> np.ndarray:
    """OpenGL depth-buffer values in [0, 1] -> z-depth in metres."""
    d = np.asarray(d, dtype=np.float64)
    return far * near / (far - (far - near) * d)


# ------------------------------------------------------------------- groups
def face_groups(semantic: np.ndarray, instance: np.ndarray, material: np.ndarray):
    """Faces grouped by (semantic, instance, material): (keys (G, 3), face order, group starts (G+1,))."""
    sem = np.asarray(semantic, np.int64)
    inst = np.asarray(instance, np.int64)
    mat = np.asarray(material, np.int64)
    code = (inst << 16) | (sem << 8) | mat
    order = np.argsort(code, kind="stable")
    if not len(code):
        return np.zeros((0, 3), np.int64), order, np.zeros(1, np.int64)
    sorted_code = code[order]
    starts = np.flatnonzero(np.r_[True, sorted_code[1:] != sorted_code[:-1]])
    first = order[starts]
    return np.stack([sem[first], inst[first], mat[first]], axis=1), order, np.r_[starts, len(code)]


def facet_normals(triangles: np.ndarray) -> np.ndarray:
    """(F, 3, 3) triangles -> (F, 3) unit normals as wound (+Z for degenerate faces)."""
    t = np.asarray(triangles, np.float64)
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-20, n / np.maximum(length, 1e-20), [0.0, 0.0, 1.0])


def write_stl(path: Path, triangles: np.ndarray, normals: np.ndarray) -> None:
    """Binary STL: 80-byte header (zeros, so never mistaken for ASCII), count, 50-byte records."""
    records = np.zeros(len(triangles), STL_RECORD)
    records["normal"] = normals
    records["vertices"] = triangles
    with open(path, "wb") as fh:
        fh.write(bytes(80))
        fh.write(np.uint32(len(records)).tobytes())
        fh.write(records.tobytes())


# ----------------------------------------------------------------- renderer
class TinyRenderer:
    """A scene uploaded to a private pybullet client, ready to render any camera."""

    def __init__(
        self,
        scene,
        *,
        light_direction=None,
        shade: bool = True,
        near: float = NEAR,
        max_file_faces: int = MAX_FILE_FACES,
    ):
        """Upload ``scene`` (``SceneArrays``). ``shade=False`` writes no facet normals: labels and depth
        are unchanged, RGB shading is then meaningless."""
        mesh = scene.mesh
        self.near = float(near)
        self.shade = bool(shade)
        self.light_direction = None if light_direction is None else [float(c) for c in light_direction]
        self.client = pb.connect(pb.DIRECT)
        vertices = np.asarray(mesh.vertices, np.float32)
        self.bounds = (
            (vertices.min(axis=0).astype(np.float64), vertices.max(axis=0).astype(np.float64))
            if len(vertices)
            else (np.zeros(3), np.zeros(3))
        )
        sem_of: list[int] = []  # per pybullet body: its semantic class and instance id
        inst_of: list[int] = []
        self.n_faces = int(mesh.n_faces)
        keys, order, starts = face_groups(mesh.semantic, scene.instance, mesh.material)
        folder = Path(tempfile.mkdtemp(prefix="eden-tinyrenderer-"))
        try:
            for g, (sem, inst, _mat) in enumerate(keys):
                idx = order[starts[g] : starts[g + 1]]
                rgba = _rgba(mesh.albedo[idx])
                for a in range(0, len(idx), max_file_faces):
                    tri = vertices[mesh.faces[idx[a : a + max_file_faces]]]
                    normals = facet_normals(tri) if self.shade else np.zeros((len(tri), 3))
                    path = folder / f"{len(sem_of):06d}.stl"  # a fresh name per body: pybullet caches by name
                    write_stl(path, np.concatenate([tri, tri[:, ::-1]]), np.concatenate([normals, -normals]))
                    shape = pb.createVisualShape(
                        pb.GEOM_MESH, fileName=str(path), rgbaColor=rgba, physicsClientId=self.client
                    )
                    body = pb.createMultiBody(
                        baseMass=0, baseCollisionShapeIndex=-1, baseVisualShapeIndex=shape, physicsClientId=self.client
                    )
                    path.unlink()
                    if body != len(sem_of):
                        raise RuntimeError(f"pybullet gave body uid {body}, expected {len(sem_of)}")
                    sem_of.append(sem)
                    inst_of.append(inst)
        except BaseException:
            self.close()
            raise
        finally:
            shutil.rmtree(folder, ignore_errors=True)
        # uid -> ids; index -1 (background) reads the last entry.
        self.semantic_of = np.array(sem_of + [labels.BACKGROUND], np.uint8)
        self.instance_of = np.array(inst_of + [0], np.uint16)
        self.n_bodies = len(sem_of)
        self.n_groups = len(keys)

    def close(self) -> None:
        if self.client is not None and pb.isConnected(self.client):
            pb.disconnect(self.client)
        self.client = None

    def __enter__(self) -> TinyRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def far_for(self, pose: np.ndarray) -> float:
        """A far plane beyond every scene vertex seen from this camera centre."""
        lo, hi = self.bounds
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        return float(np.max(np.linalg.norm(corners - np.asarray(pose)[:3, 3], axis=1))) * 1.05 + 1.0

    def render(self, intr: Intrinsics, pose: np.ndarray, want=SUPPORTED) -> dict[str, np.ndarray]:
        """Passes of one camera: ``depth`` (H, W) float32 metres (inf = sky), ``semantic`` uint8,
        ``instance`` uint16, ``rgb`` (H, W, 3) uint8 as TinyRenderer shades it, ``hit`` bool."""
        h, w = intr.height, intr.width
        far = self.far_for(pose)
        kwargs = {}
        if self.light_direction is not None:
            kwargs["lightDirection"] = self.light_direction
        _, _, rgba, depth, seg = pb.getCameraImage(
            w,
            h,
            gl_view_matrix(pose),
            gl_projection_matrix(intr, self.near, far),
            renderer=pb.ER_TINY_RENDERER,
            physicsClientId=self.client,
            **kwargs,
        )
        seg = np.asarray(seg, np.int64).reshape(h, w)
        hit = seg >= 0
        seg = np.where(hit, seg, -1)
        out: dict[str, np.ndarray] = {"hit": hit}
        z = linearize_depth(np.asarray(depth, np.float64).reshape(h, w), self.near, far)
        out["depth"] = np.where(hit, z, np.inf).astype(np.float32)
        if "semantic" in want:
            out["semantic"] = self.semantic_of[seg]
        if "instance" in want:
            out["instance"] = self.instance_of[seg]
        if "rgb" in want:
            out["rgb"] = np.asarray(rgba, np.uint8).reshape(h, w, 4)[..., :3].copy()
        return out


def _rgba(albedo: np.ndarray) -> list[float]:
    """A group's display colour: its mean linear albedo in sRGB."""

    mean = np.asarray(albedo, np.float64).reshape(-1, 3).mean(axis=0) if len(albedo) else np.full(3, 0.5)
    return [float(c) for c in linear_to_srgb(mean)] + [1.0]


def light_direction_for(sky) -> list[float] | None:
    """TinyRenderer's ``lightDirection`` for a sky: the unit direction toward the sun (measured:
    a face whose vertex normals equal it is lit fully); a sun below the horizon lights from
    straight above."""
    sun = getattr(sky, "sun_direction", None)
    if sun is None:
        return None
    sun = np.asarray(sun, np.float64)
    if sun[2] <= 0.0:
        sun = np.array([0.0, 0.0, 1.0])
    return (sun / np.linalg.norm(sun)).tolist()


def render_view_tinyrenderer(
    renderer: TinyRenderer,
    scene,
    intr: Intrinsics,
    pose: np.ndarray,
    sky,
    *,
    want: set[str],
    pose_next=None,
    pose_prev=None,
    settings=None,
    rng=None,
    rgb_spp: int = 1,
) -> dict[str, np.ndarray]:
    """``render.view.render_view`` for the passes TinyRenderer supports (same keys, same dtypes).

    ``rgb_linear`` is TinyRenderer's 8-bit image taken back to linear RGB and
    divided by the sky's exposure, so the render stage's
    ``srgb_to_uint8(rgb_linear * sky.exposure)`` writes exactly TinyRenderer's
    pixels; sky pixels show the sky model's background radiance. Flow,
    normals and intrinsic layers are not available (the arguments for them are
    accepted and ignored).
    """
    passes = renderer.render(intr, pose, want=set(want) | {"depth"})
    out: dict[str, np.ndarray] = {k: passes[k] for k in ("depth", "semantic", "instance") if k in passes}
    if "rgb" in want:
        exposure = float(getattr(sky, "exposure", 1.0)) if sky is not None else 1.0
        linear = srgb_to_linear(passes["rgb"] / 255.0)
        sky_px = ~passes["hit"]
        if sky is not None and sky_px.any():
            from eden_pipe.render.shading import sky_and_background
            from eden_pipe.render.view import primary_rays

            _, dirs = primary_rays(intr, pose)
            linear[sky_px] = np.clip(sky_and_background(sky, dirs[sky_px.ravel()]) * exposure, 0.0, 1.0)
        out["rgb_linear"] = (linear / exposure).astype(np.float32)
    return out
