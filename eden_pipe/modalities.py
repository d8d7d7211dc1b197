"""The modality table: the one place that says what each modality is (DESIGN section 4).

Per modality: its name (the ``render.modalities`` choice), whether it is in the
default set, and its manifest columns; per column: the file format (extension,
writer, reader; depth's depends on ``render.depth_format``), the camera of the
pair and the view pass it is written from, and whether it needs a neighbouring
frame (flow). Which backends produce a modality is declared by the backends
(``capabilities``, :mod:`eden_pipe.render.backends`) and read back here as
:attr:`Modality.backends`.

Everything else derives from :data:`TABLE`: the config choices
(``config.MODALITIES``/``DEFAULT_MODALITIES``), the manifest path columns
(``stages.manifest.PATH_COLUMNS``: table order, column by column), the files of
a frame (``io.layout.frame_files``), the writer dispatch and ``read_modality``.
Adding a modality is one entry here plus the code that computes the pass.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass
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
        return cls(depth_format=str(render_cfg.depth_format), storage=str(getattr(render_cfg, "storage", "compact")),
                   compression=int(render_cfg.png_compression))


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


RGB_PNG = FileFormat("png", lambda p, a, o: formats.write_rgb(p, a, o.compression), formats.read_rgb,
                     "PNG uint8 RGB, sRGB(exposure * linear)", pixel_bytes=2)
SEMANTIC_PNG = FileFormat("png", lambda p, a, o: formats.write_semantic(p, a, o.compression), formats.read_semantic,
                          "PNG palette uint8: class id (labels), palette = label colours", pixel_bytes=0.3)
INSTANCE_PNG = FileFormat("png", lambda p, a, o: formats.write_instance(p, a, o.compression), formats.read_instance,
                          "PNG uint16 instance id, 0 = none", pixel_bytes=0.2)
DEPTH_FORMATS = {  # by render.depth_format
    "png16": FileFormat("png", lambda p, a, o: formats.write_depth(p, a, "png16", o.compression), formats.read_depth,
                        "PNG uint16 z-depth in millimetres, 0 = sky or beyond 65.535 m", pixel_bytes=0.8),
    "float": FileFormat("npy", lambda p, a, o: formats.write_depth(p, a, "float", o.compression), formats.read_depth,
                        ".npy float32 z-depth in metres, inf = sky", pixel_bytes=4),
}
NORMAL_PNG = FileFormat("png", lambda p, a, o: formats.write_normal(p, a, o.compression), formats.read_normal,
                        "PNG uint16 x3, (n+1)/2*65535, unit normal in the camera frame; 0,0,0 = sky", pixel_bytes=1.6)
FLO = FileFormat("flo", lambda p, a, o: formats.write_flo(p, a), formats.read_flo, "Middlebury .flo float32 (dx, dy) pixels", pixel_bytes=8)
# KITTI's 16-bit PNG: 1/64 px steps within +-512 px; the reader gives NaN where the file marks a pixel invalid.
KITTI_FLOW_PNG = FileFormat("png", lambda p, a, o: kitti.write_kitti_flow(p, a, compression=o.compression),
                            kitti.read_kitti_flow_nan,
                            "KITTI 16-bit PNG: R,G = dx,dy*64 + 2^15, B = valid (pixels, 1/64 px steps)", pixel_bytes=1.4)
MASK_PNG = FileFormat("png", lambda p, a, o: formats.write_mask(p, a, o.compression), formats.read_mask,
                      "PNG uint8, 1 = occluded or leaves the image", pixel_bytes=0.15)
FLOAT_NPY = FileFormat("npy", lambda p, a, o: formats.write_float(p, a), formats.read_float,
                       ".npy float32 (H, W, 3) linear RGB", pixel_bytes=12)
# Half-float OpenEXR with lossless ZIP (what Cycles writes): relative error <= 2^-11, 5-10x smaller than .npy.
FLOAT_EXR = FileFormat("exr", lambda p, a, o: exr.write_exr(p, a), exr.read_exr,
                       "OpenEXR half float, ZIP (lossless), channels R,G,B: linear RGB", pixel_bytes=3)
# render.storage: compact (the default) or exact (float32, lossless).
STORAGE_MODES = ("compact", "exact")
FLOAT_LAYER_FORMATS = {"compact": FLOAT_EXR, "exact": FLOAT_NPY}
FLOW_FORMATS = {"compact": KITTI_FLOW_PNG, "exact": FLO}


@dataclass(frozen=True)
class Column:
    """One manifest path column: a file per frame and camera pair."""

    name: str                                             # manifest column and folder name
    format: FileFormat | Mapping[str, FileFormat]   # or one per value of the option ``chosen_by``
    key: str | None = None                                # the view pass written (default: ``name``)
    camera: str = "left"                                  # "left" or "right" camera of the pair
    needs: str | None = None                              # "next"/"prev": only when that frame exists
    chosen_by: str = "depth_format"                       # the WriteOptions field choosing among ``format``s

    @property
    def source(self) -> str:
        return self.key or self.name

    def file_format(self, options: WriteOptions = WriteOptions()) -> FileFormat:
        return self.format if isinstance(self.format, FileFormat) else self.format[getattr(options, self.chosen_by)]

    def formats(self) -> tuple[FileFormat, ...]:
        return (self.format,) if isinstance(self.format, FileFormat) else tuple(self.format.values())

    def write(self, path, data: np.ndarray, options: WriteOptions = WriteOptions()) -> None:
        self.file_format(options).write(path, data, options)

    def read(self, path) -> np.ndarray:
        """Decode with the format whose extension the file has (every storage mode stays readable)."""
        suffix = Path(path).suffix.lstrip(".")
        for fmt in self.formats():
            if fmt.ext == suffix:
                return fmt.read(path)
        raise ValueError(f"{path}: no {self.name} format has the extension {suffix!r}; "
                         f"known: {', '.join(sorted({f.ext for f in self.formats()}))}")

    def defined(self, has_next: bool, has_prev: bool) -> bool:
        neighbours: dict[str | None, bool] = {"next": has_next, "prev": has_prev}
        return neighbours.get(self.needs, True)


@dataclass(frozen=True)
class Modality:
    name: str
    columns: tuple[Column, ...]
    default: bool = True

    @property
    def backends(self) -> tuple[str, ...]:
        """Names of the registered backends that produce this modality."""
        from eden_pipe.render import backends

        return backends.producing(self.name)


def _single(name: str, fmt, *, default: bool = True, key: str | None = None, chosen_by: str = "depth_format") -> Modality:
    return Modality(name, (Column(name, fmt, key=key, chosen_by=chosen_by),), default)


def _float_layer(name: str, *, default: bool = True, key: str | None = None) -> Modality:
    return _single(name, FLOAT_LAYER_FORMATS, default=default, key=key, chosen_by="storage")


TABLE: tuple[Modality, ...] = (
    Modality("rgb", (Column("rgb_left", RGB_PNG, key="rgb"), Column("rgb_right", RGB_PNG, key="rgb", camera="right"))),
    _single("semantic", SEMANTIC_PNG),
    _single("instance", INSTANCE_PNG),
    Modality("depth", (Column("depth", DEPTH_FORMATS), Column("depth_right", DEPTH_FORMATS, key="depth", camera="right"))),
    _single("normal", NORMAL_PNG),
    # Flow is undefined past the ends of the trajectory.
    Modality("flow", (Column("flow_fwd", FLOW_FORMATS, needs="next", chosen_by="storage"),
                      Column("flow_bwd", FLOW_FORMATS, needs="prev", chosen_by="storage"),
                      Column("occ_fwd", MASK_PNG, needs="next"), Column("occ_bwd", MASK_PNG, needs="prev"))),
    # Linear float layers. glossy, background (B) and rgb_linear (the pixel-centre composite I, before
    # exposure) are optional: with them I = albedo*shading + glossy + translucency + background.
    _float_layer("albedo"),
    _float_layer("shading"),
    _float_layer("translucency"),
    _float_layer("glossy", default=False),
    _float_layer("background", default=False),
    _float_layer("rgb_linear", default=False, key="linear"),
)

BY_NAME: dict[str, Modality] = {m.name: m for m in TABLE}
MODALITIES: tuple[str, ...] = tuple(m.name for m in TABLE)
DEFAULT_MODALITIES: tuple[str, ...] = tuple(m.name for m in TABLE if m.default)
COLUMNS: dict[str, Column] = {c.name: c for m in TABLE for c in m.columns}
PATH_COLUMNS: list[str] = list(COLUMNS)


def columns_for(modalities: Iterable[str], has_next: bool = True, has_prev: bool = True) -> list[Column]:
    """The columns written for a set of modalities, in table order (those needing a missing frame left out)."""
    wanted = set(modalities)
    return [c for m in TABLE if m.name in wanted for c in m.columns if c.defined(has_next, has_prev)]


def camera_passes(modalities: Iterable[str], camera: str) -> set[str]:
    """The enabled modalities with a column from ``camera`` ("left"/"right")."""
    wanted = set(modalities)
    return {m.name for m in TABLE if m.name in wanted and any(c.camera == camera for c in m.columns)}


def write_column(path, column: str, data: np.ndarray, options: WriteOptions = WriteOptions()) -> None:
    COLUMNS[column].write(path, data, options)


def read_modality(path, column: str) -> np.ndarray:
    """Read any manifest path column's file."""
    if column not in COLUMNS:
        raise KeyError(f"unknown modality column {column!r}; known: {', '.join(COLUMNS)}")
    return COLUMNS[column].read(path)
