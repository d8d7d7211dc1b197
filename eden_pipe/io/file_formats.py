"""The file formats of the modality table (docs/design.md, File formats): one :class:`FileFormat` per
encoding, with its writer and reader, what it holds and its precision, and the render config's file options
(:class:`WriteOptions`). :mod:`eden_pipe.modalities` puts them in each column's mapping."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from eden_pipe.io import exr, formats, kitti


@dataclass(frozen=True)
class WriteOptions:
    """The render config's file options (``render.depth_format``, ``render.storage``, ``render.png_compression``)."""

    depth_format: str = "png16"
    storage: str = "compact"
    compression: int = 1

    @classmethod
    def from_config(cls, render_cfg) -> WriteOptions:
        return cls(
            depth_format=str(render_cfg.depth_format),
            storage=str(getattr(render_cfg, "storage", "compact")),
            compression=int(render_cfg.png_compression),
        )


DEFAULT_WRITE_OPTIONS = WriteOptions()


@dataclass(frozen=True)
class FileFormat:
    """One file encoding: extension, writer ``(path, array, WriteOptions)`` and reader ``(path) -> array``."""

    ext: str
    write: Callable[[Path, np.ndarray, WriteOptions], None]
    read: Callable[[Path], np.ndarray]
    encoding: str = ""  # what the file holds and in which units (published in dataset.json)
    # File bytes per pixel, to estimate a job's disk need before it starts (preflight): exact for
    # uncompressed formats (.npy, .flo); for compressed ones the most measured on rendered frames
    # (small garden, 96x72 and 640x480), rounded up.
    pixel_bytes: float = 12.0
    # Precision of the stored values, in the column's units: ``step`` the quantisation step (a stored
    # value is within step/2 of the rendered one), ``relative`` the relative rounding of float formats
    # (half float 2^-11, float32 2^-24). 0 and 0: exact (integers written as integers).
    step: float = 0.0
    relative: float = 0.0
    # The largest value the format stores; beyond it a value is written as "none" (depth: sky).
    largest: float = float("inf")

    def error_bound(self, values: np.ndarray) -> np.ndarray:
        """The most a stored finite value can differ from the rendered one (the same shape as ``values``)."""
        magnitude = np.abs(np.asarray(values, np.float32))
        magnitude = np.where(np.isfinite(magnitude), magnitude, np.float32(0.0))
        return np.float32(self.step / 2) + np.float32(self.relative) * magnitude


HALF_RELATIVE = 2.0**-11  # half float: 10 mantissa bits, rounding to nearest
HALF_SUBNORMAL_STEP = 2.0**-24  # half float's spacing below 2^-14 (subnormals)
FLOAT32_RELATIVE = 2.0**-24

RGB_PNG = FileFormat(
    "png",
    lambda p, a, o: formats.write_rgb(p, a, o.compression),
    formats.read_rgb,
    "PNG uint8 RGB, sRGB(exposure * linear)",
    pixel_bytes=2,
    step=1.0,
)
SEMANTIC_PNG = FileFormat(
    "png",
    lambda p, a, o: formats.write_semantic(p, a, o.compression),
    formats.read_semantic,
    "PNG palette uint8: class id (labels), palette = label colours",
    pixel_bytes=0.3,
)
INSTANCE_PNG = FileFormat(
    "png",
    lambda p, a, o: formats.write_instance(p, a, o.compression),
    formats.read_instance,
    "PNG uint16 instance id, 0 = none",
    pixel_bytes=0.2,
)
DEPTH_FORMATS = {  # by render.depth_format
    "png16": FileFormat(
        "png",
        lambda p, a, o: formats.write_depth(p, a, "png16", o.compression),
        formats.read_depth,
        "PNG uint16 z-depth in millimetres, 0 = sky or beyond 65.535 m",
        pixel_bytes=0.8,
        step=1e-3,
        largest=65.535,
    ),
    "float": FileFormat(
        "npy",
        lambda p, a, o: formats.write_depth(p, a, "float", o.compression),
        formats.read_depth,
        ".npy float32 z-depth in metres, inf = sky",
        pixel_bytes=4,
        relative=FLOAT32_RELATIVE,
    ),
}
NORMAL_PNG = FileFormat(
    "png",
    lambda p, a, o: formats.write_normal(p, a, o.compression),
    formats.read_normal,
    "PNG uint16 x3, (n+1)/2*65535, unit normal in the camera frame; 0,0,0 = sky",
    pixel_bytes=1.6,
    step=2.0 / 65535,
)
FLO = FileFormat(
    "flo",
    lambda p, a, o: formats.write_flo(p, a),
    formats.read_flo,
    "Middlebury .flo float32 (dx, dy) pixels",
    pixel_bytes=8,
    relative=FLOAT32_RELATIVE,
)
# KITTI's 16-bit PNG: 1/64 px steps within +-512 px; the reader gives NaN where the file marks a pixel invalid.
KITTI_FLOW_PNG = FileFormat(
    "png",
    lambda p, a, o: kitti.write_kitti_flow(p, a, compression=o.compression),
    kitti.read_kitti_flow_nan,
    "KITTI 16-bit PNG: R,G = dx,dy*64 + 2^15, B = valid (pixels, 1/64 px steps)",
    pixel_bytes=1.4,
    step=1.0 / 64,
)
MASK_PNG = FileFormat(
    "png",
    lambda p, a, o: formats.write_mask(p, a, o.compression),
    formats.read_mask,
    "PNG uint8, 1 = occluded or leaves the image",
    pixel_bytes=0.15,
)
FLOAT_NPY = FileFormat(
    "npy",
    lambda p, a, o: formats.write_float(p, a),
    formats.read_float,
    ".npy float32 (H, W, 3) linear RGB",
    pixel_bytes=12,
    relative=FLOAT32_RELATIVE,
)
# Half-float OpenEXR with lossless ZIP (what Cycles writes): relative error <= 2^-11, 5-10x smaller than .npy.
FLOAT_EXR = FileFormat(
    "exr",
    lambda p, a, o: exr.write_exr(p, a),
    exr.read_exr,
    "OpenEXR half float, ZIP (lossless), channels R,G,B: linear RGB",
    pixel_bytes=3,
    step=HALF_SUBNORMAL_STEP,
    relative=HALF_RELATIVE,
)
# The wind's layers (surface motion in metres, not radiance): the codecs and precision above, their own contents.
MASK_PNG_MOVED = replace(
    MASK_PNG, encoding="PNG uint8, 1 = the surface seen moves between this frame and a neighbouring one"
)
MOTION_FORMATS = {
    "compact": replace(
        FLOAT_EXR, encoding="OpenEXR half float, ZIP (lossless), channels R,G,B: x,y,z metres in the camera frame"
    ),
    "exact": replace(FLOAT_NPY, encoding=".npy float32 (H, W, 3): x,y,z metres in the camera frame"),
}
# render.storage: compact (the default) or exact (float32, lossless).
STORAGE_MODES = ("compact", "exact")
FLOAT_LAYER_FORMATS = {"compact": FLOAT_EXR, "exact": FLOAT_NPY}
FLOW_FORMATS = {"compact": KITTI_FLOW_PNG, "exact": FLO}
