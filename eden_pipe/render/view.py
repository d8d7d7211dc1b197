"""One camera view: every ground-truth pass from Embree hits, vectorised per image.

Label-like passes (semantic, instance, depth, normal, flow, occlusion) come from
the pixel-centre ray only. Flow is exact reprojection: the 3-D point seen at a
pixel in frame t, where it stands at frame t+1 (forward) or t-1 (backward), is
projected with that frame's pose and K; in still air the point stays put, with
wind it moves with its face (``Motion``, docs/design.md "Wind"). Sky pixels are
directions at infinity and move by rotation only. A pixel is occluded when its
point leaves the image, falls behind the other camera, or an occlusion ray from
it to the other camera's centre is blocked by the geometry of that frame (for
sky: the other camera sees geometry in that direction).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any

import numpy as np

from eden_pipe import labels, modalities
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.render import kernels, vec, wind
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.pathtrace import reference_shade
from eden_pipe.render.pixel_sky import PairSky, SkyShare
from eden_pipe.render.shading import EPS, LAYERS, ShadingSettings, shade
from eden_pipe.scene.arrays import SceneArrays

# The passes that need the shading pass (``shade``): its layers, the composite and RGB.
SHADED = frozenset(LAYERS) | {"linear", "rgb_linear", "rgb"}
# The passes a tie cannot change beyond a pixel's colour: two faces at exactly the closest distance
# give the same depth, and either one's colour is the surface's there. A view asking for no more (the
# right camera) keeps the packet's pick of a tied face; labels, normals and the per-face layers take
# the single ray's (RayTracer.intersect, docs/design.md, Ray tracing).
TIE_FREE = frozenset({"rgb", "rgb_linear", "linear", "depth"})
# The key of a view's own-sky factors in its output (``render.pixel_sky_rays``): a ``SkyShare`` that
# the other camera of the pair takes where it sees the same face side (``partner``). Not a pass.
PIXEL_SKY = "pixel_sky"
# The same for the soft sun's shares of the disc (``render.soft_shadow_radius``). Not a pass.
PIXEL_SUN = "pixel_sun"


@dataclass
class Motion:
    """The mesh in motion (wind, docs/design.md "Wind"): its faces, where its vertices stand now (the
    tracer the view's rays are cast against holds them), and the tracers holding them at the next
    and previous frames (None past the trajectory's ends)."""

    faces: np.ndarray
    now: np.ndarray  # (V, 3) float32
    next: RayTracer | None
    prev: RayTracer | None


@functools.lru_cache(maxsize=8)
def pixel_centre_rays(intr: Intrinsics) -> np.ndarray:
    """(H * W, 3) float64 camera-frame directions (z = 1) through the pixel centres, row-major,
    read-only: the same for every view of a camera, so made once (made afresh for each view, they
    took about half of ``primary_rays``: 9.1-12.4 against 5.2 ms a view, docs/scale-out.md)."""
    u, v = intr.pixel_grid()
    dirs = intr.camera_rays(u, v).reshape(-1, 3)
    dirs.flags.writeable = False
    return dirs


def primary_rays(intr: Intrinsics, pose: np.ndarray, offset=None) -> tuple[np.ndarray, np.ndarray]:
    """World origins and directions (camera z component 1) for every pixel, row-major; ``offset``
    (H, W, 2): sub-pixel offsets of the rays from the pixel centres."""
    if offset is None:
        dirs_cam = pixel_centre_rays(intr)
    else:
        u, v = intr.pixel_grid(offset)
        dirs_cam = intr.camera_rays(u, v).reshape(-1, 3)
    dirs = dirs_cam @ pose[:3, :3].T
    origins = np.broadcast_to(pose[:3, 3], dirs.shape)
    return np.ascontiguousarray(origins), dirs


def flow_to(
    intr: Intrinsics,
    tracer: RayTracer,
    points: np.ndarray,
    sky_dirs: np.ndarray,
    hit: np.ndarray,
    pose_other: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Flow (N, 2) from this view's pixels to ``pose_other`` and occlusion (N,) uint8."""
    rot, centre = pose_other[:3, :3], pose_other[:3, 3]
    # World -> other camera frame: surface points relative to its centre; sky directions by rotation only.
    cam = kernels.flow_relative(points, sky_dirs, hit, centre) @ rot
    flow, inside = kernels.reproject(cam, intr.fx, intr.fy, intr.cx, intr.cy, intr.width, intr.height)
    occluded = ~inside
    check = np.nonzero(inside)[0]
    if len(check):
        # Surface points: a segment from the point (nudged toward the other camera) to that camera.
        # Sky directions: a ray from the other camera to infinity. (Rays are float32 for Embree.)
        origins, dirs, tmax = kernels.occlusion_rays(
            points, sky_dirs, hit, check, centre, np.float32(2.0 * EPS), np.float32(1.0 - 2.0 * EPS), np.float32(3.0e37)
        )
        occluded[check] = tracer.occluded(origins, dirs, tmax, image=(intr.height, intr.width), pixels=check)
    return flow, occluded.astype(np.uint8)


def render_view(
    tracer: RayTracer,
    scene: SceneArrays,
    intr: Intrinsics,
    pose: np.ndarray,
    sky,
    *,
    want: set[str],
    pose_next: np.ndarray | None = None,
    pose_prev: np.ndarray | None = None,
    settings: ShadingSettings | None = None,
    rng: np.random.Generator | None = None,
    rgb_spp: int = 1,
    motion: Motion | None = None,
    partner: dict | None = None,
) -> dict:
    """Every requested pass of one camera as (H, W[, C]) arrays.

    ``want`` holds names among: rgb, semantic, instance, depth, normal, flow, dynamic,
    albedo, shading, translucency, glossy, background, linear. ``motion``: the mesh moves
    (``tracer`` holds it at this frame); flow then follows each surface point's own motion.
    ``partner``: the output of the other camera of the pair, rendered before; with
    ``pixel_sky_rays`` its own-sky factors are taken where this view sees the same face side, and
    this view's are returned under ``PIXEL_SKY`` for the next; with ``soft_shadow_radius`` the
    same for the sun's shares of its disc, under ``PIXEL_SUN``.
    """
    settings = settings or ShadingSettings()
    rng = rng if rng is not None else np.random.default_rng(0)
    h, w = intr.height, intr.width
    mesh = scene.mesh
    origins, dirs = primary_rays(intr, pose)
    hits = tracer.intersect(origins, dirs, image=(h, w), settle_ties=not want <= TIE_FREE)
    hit = hits.hit
    prim = np.where(hit, hits.prim, 0)
    out: dict[str, Any] = {}
    out["depth"] = hits.t.reshape(h, w)  # z-depth because camera-frame dirs have z = 1
    if "semantic" in want:
        sem = np.where(hit, vec.take(mesh.semantic, prim) if mesh.n_faces else 0, labels.BACKGROUND)
        out["semantic"] = sem.astype(np.uint8).reshape(h, w)
    if "instance" in want:
        inst = np.where(hit, vec.take(scene.instance, prim) if mesh.n_faces else 0, 0)
        out["instance"] = inst.astype(np.uint16).reshape(h, w)
    unit = vec.normalize(dirs)
    if "normal" in want:
        n = vec.facing(hits.normal, unit.astype(np.float32))
        out["normal"] = (n @ pose[:3, :3].astype(np.float32)).reshape(h, w, 3)  # world -> camera
    if want & {"flow", "dynamic"}:
        points = kernels.hit_points(origins, dirs, hits.t, hit)
        moved = np.zeros(len(points), bool)
        for name, other, tracer_other in (
            ("fwd", pose_next, motion.next if motion else None),
            ("bwd", pose_prev, motion.prev if motion else None),
        ):
            if other is None:
                continue
            target, occluders = points, tracer
            if motion is not None and tracer_other is not None:
                # The point's own motion: its barycentric coordinates carried to the other frame's
                # vertices; exactly 0 on rigid faces, whose flow stays the camera's reprojection. Its
                # occlusion is tested against the geometry as it stands in the other frame.
                delta = wind.surface_motion(points, prim, hit, motion.faces, motion.now, tracer_other.vertices)
                moved |= np.any(delta != 0.0, axis=1)
                target, occluders = points + delta, tracer_other
            else:
                delta = np.zeros_like(points)
            if "dynamic" in want:
                out[f"motion_{name}"] = (delta @ pose[:3, :3]).astype(np.float32).reshape(h, w, 3)  # world -> camera
            if "flow" in want:
                flow, occ = flow_to(intr, occluders, target, unit, hit, other)
                out[f"flow_{name}"] = flow.reshape(h, w, 2)
                out[f"occ_{name}"] = occ.reshape(h, w)
        if "dynamic" in want:
            out["dynamic"] = moved.astype(np.uint8).reshape(h, w)
    if want & SHADED:
        if settings.mode == "reference":
            layers = reference_shade(
                tracer, mesh, hits, origins, dirs, sky, settings, rng, layers=want & set(LAYERS), image_width=w
            )
        else:
            pair_sky = PairSky(partner=(partner or {}).get(PIXEL_SKY), sun_partner=(partner or {}).get(PIXEL_SUN))
            layers = shade(
                tracer, mesh, hits, origins, dirs, sky, settings, rng, layers=want & set(LAYERS), image_width=w,
                pair_sky=pair_sky,
            )  # fmt: skip
            if pair_sky.estimated is not None:
                out[PIXEL_SKY] = SkyShare.of(pose, intr, *pair_sky.estimated)
            if pair_sky.sun_estimated is not None:
                out[PIXEL_SUN] = SkyShare.of(pose, intr, *pair_sky.sun_estimated)
        for key, value in layers.items():
            out[key] = value.reshape(h, w, modalities.pass_channels(key))
        shade_fn = reference_shade if settings.mode == "reference" else shade
        if "rgb" in want and rgb_spp > 1:
            # Anti-aliased RGB: average jittered sub-pixel samples (the centre sample included).
            acc = layers["linear"].copy()
            for _ in range(rgb_spp - 1):
                o2, d2 = primary_rays(intr, pose, rng.uniform(-0.5, 0.5, size=(h, w, 2)))
                h2 = tracer.intersect(o2, d2, image=(h, w))
                acc += shade_fn(tracer, mesh, h2, o2, d2, sky, settings, rng, layers=(), image_width=w)["linear"]
            out["rgb_linear"] = (acc / rgb_spp).astype(np.float32).reshape(h, w, 3)
        else:
            out["rgb_linear"] = out["linear"]
    return out
