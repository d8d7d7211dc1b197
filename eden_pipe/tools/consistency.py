"""The numbers the validator compares against (docs/design.md, File formats and Image formation): the flow a
depth map and two poses imply, how far a correct written flow may depart from it given the files' precision, and
the image formation's sum of the written layers with its error bound."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from eden_pipe import modalities

# float32 arithmetic of the renderer's flow (points of a few tens of metres projected to ~600 px): its
# residual against a float64 reprojection from exact (float32) depth is below 1e-4 px; 2e-3 leaves room.
FLOW_ARITHMETIC_PX = 2e-3
# float32 sums of up to five layers, relative.
COMPOSE_ARITHMETIC = 1e-5


def other_camera_points(
    depth: np.ndarray, K: np.ndarray, pose0: np.ndarray, pose1: np.ndarray, motion: np.ndarray | None = None
) -> np.ndarray:
    """(H, W, 3) float64: every pixel's point in pose1's camera frame: surface points from depth (moved by
    ``motion`` (H, W, 3), each point's own displacement to the other frame in pose0's camera frame, metres:
    wind), sky pixels (inf) as directions turned by the rotation alone."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    x, y = (u - cx) / fx, (v - cy) / fy  # camera ray with z = 1
    sky = ~np.isfinite(depth)
    z = np.where(sky, 0.0, depth).astype(np.float64)
    # world = R0 [x z, y z, z] + t0; cam1 = R1^T (world - t1) = M [x,y,1] z + R1^T (t0 - t1)
    M = pose1[:3, :3].T @ pose0[:3, :3]
    t = pose1[:3, :3].T @ (pose0[:3, 3] - pose1[:3, 3])
    ray = np.stack([x, y, np.ones_like(x)], axis=-1).astype(np.float64)
    rot = ray @ M.T
    cam1 = np.where(sky[..., None], rot, rot * z[..., None] + t)
    if motion is not None:
        cam1 = cam1 + np.where(sky[..., None], 0.0, np.nan_to_num(motion.astype(np.float64)) @ M.T)
    return cam1


def reprojection_flow(
    depth: np.ndarray, K: np.ndarray, pose0: np.ndarray, pose1: np.ndarray, motion: np.ndarray | None = None
) -> np.ndarray:
    """(H, W, 2) flow of every pixel from pose0 to pose1 (:func:`other_camera_points` projected); ``motion``:
    each surface point's own displacement (wind); none: a rigid scene."""
    h, w = depth.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float32)
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    cam1 = other_camera_points(depth, K, pose0, pose1, motion)
    with np.errstate(divide="ignore", invalid="ignore"):
        u1 = fx * cam1[..., 0] / cam1[..., 2] + cx
        v1 = fy * cam1[..., 1] / cam1[..., 2] + cy
    flow = np.stack([u1 - u, v1 - v], axis=-1)
    flow[cam1[..., 2] <= 1e-9] = np.nan  # behind the other camera: undefined
    return flow


def flow_tolerance(
    depth: np.ndarray,
    depth_format: modalities.FileFormat,
    flow: np.ndarray,
    flow_format: modalities.FileFormat,
    K: np.ndarray,
    pose0: np.ndarray,
    pose1: np.ndarray,
    expected: np.ndarray,
    motion: np.ndarray | None = None,
    motion_format: modalities.FileFormat | None = None,
) -> np.ndarray:
    """(H, W) the most a correct written flow can differ from ``expected`` (the reprojection of the stored
    depth, and of the stored ``motion`` where the surface moves), in pixels: the flow format's quantisation,
    the reprojection's change over the depths the stored value stands for, the image of the motion's
    rounding (``motion_format``), and float32 arithmetic."""
    finite = np.isfinite(depth)
    z = np.where(finite, depth, np.float32(0.0))
    dz = depth_format.error_bound(z)
    # Depth moves each point along its ray, so its image moves monotonically along the epipolar line:
    # the ends of the depth interval bound the change. A stored "none" (sky) may be any point beyond the
    # format's largest value, or a direction at infinity.
    near = np.where(finite, np.maximum(z - dz, np.float32(1e-6)), np.float32(depth_format.largest))
    far = np.where(finite, z + dz, np.float32(np.inf))
    moved = np.zeros(depth.shape, np.float64)
    for end in (near, far):
        other = reprojection_flow(end, K, pose0, pose1, motion)
        with np.errstate(invalid="ignore"):
            moved = np.fmax(moved, np.hypot(*np.moveaxis(other - expected, -1, 0)))
    quantum = np.hypot(*np.moveaxis(flow_format.error_bound(np.nan_to_num(flow)), -1, 0))
    if motion is not None and motion_format is not None:
        moved = moved + _motion_rounding_px(depth, K, pose0, pose1, motion, motion_format)
    return moved + quantum + FLOW_ARITHMETIC_PX


def _motion_rounding_px(depth, K, pose0, pose1, motion, motion_format) -> np.ndarray:
    """How far a point's image can move when its stored motion is off by the format's rounding: a
    displacement e at camera-frame point (X, Y, Z) moves u by fx/Z (e_x - X/Z e_z), so by at most
    fx/Z |e| (1 + |X/Z|) (and v alike)."""
    e = np.linalg.norm(motion_format.error_bound(np.nan_to_num(motion)), axis=-1)
    fx, fy = K[0, 0], K[1, 1]
    cam1 = other_camera_points(depth, K, pose0, pose1, motion)
    with np.errstate(divide="ignore", invalid="ignore"):
        zc = np.maximum(cam1[..., 2], 1e-6)
        du = fx / zc * e * (1.0 + np.abs(cam1[..., 0] / zc))
        dv = fy / zc * e * (1.0 + np.abs(cam1[..., 1] / zc))
    return np.where(np.isfinite(depth) & (e > 0), np.hypot(du, dv), 0.0)


@dataclass
class Layer:
    """A decoded float layer and the most its stored values can differ from the rendered ones; ``open_above``
    (H, W) marks pixels where an additive layer that was not written may add an unknown amount >= 0."""

    values: np.ndarray
    error: np.ndarray
    open_above: np.ndarray | None = None


def composite_of(layers: dict[str, Layer], sky: np.ndarray | None = None) -> Layer:
    """The image formation's sum, reflectance * irradiance + every additive layer, with its error bound.
    An additive layer not in ``layers`` counts as 0 where the table says it is (its ``zero_on``, with ``sky``
    the pixels without a surface) and leaves the sum open above elsewhere."""
    (a,), (s,) = (tuple(layers[c] for c in modalities.formation_columns(r)) for r in ("reflectance", "irradiance"))
    value = a.values * s.values
    error = np.abs(a.values) * s.error + np.abs(s.values) * a.error + a.error * s.error
    open_above = None
    for column in modalities.formation_columns("additive"):
        if column in layers:
            value = value + layers[column].values
            error = error + layers[column].error
            continue
        zero_on = modalities.COLUMNS[column].zero_on
        maybe = (
            np.ones(value.shape[:2], bool) if sky is None or zero_on is None else (~sky if zero_on == "sky" else sky)
        )
        open_above = maybe if open_above is None else open_above | maybe
    return Layer(value, error + np.float32(COMPOSE_ARITHMETIC) * np.abs(value), open_above)
