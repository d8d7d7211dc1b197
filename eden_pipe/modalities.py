"""The modality table: the one place that says what each output layer is (docs/design.md, Image formation
and File formats).

Per modality: its name (the ``render.modalities`` choice), whether it is in the default set, and its manifest
columns. Per column, the whole array contract:

- the view pass it is written from (``key``) and the camera of the pair;
- the decoded array: ``channels``, ``dtype`` kind and value domain (:data:`VALUE_DOMAINS`), ``units``;
- its file format per storage option (``format``, chosen by ``chosen_by``), each format with its extension,
  codec and precision (``step``: the quantisation step, ``relative``: the relative rounding of floats);
- its role in the image-formation identity (:data:`ROLES`): ``composite = reflectance * irradiance + sum of
  additive``, and ``display = sRGB(exposure * composite)``;
- how the torch loader presents it (``loader``) and, for flow, the occlusion column that masks it;
- whether it needs a neighbouring frame (flow).

Which backends produce a modality is declared by the backends (``capabilities``,
:mod:`eden_pipe.render.backends`); a modality with a ``derive`` function is computed from other passes
after any backend's view, so every backend producing its ``inputs`` produces it too.

Everything else derives from :data:`TABLE`: the config choices (:data:`MODALITIES`,
:data:`DEFAULT_MODALITIES`), the manifest path columns (:data:`PATH_COLUMNS`), the files of a frame
(``io.layout.frame_files``), writing and reading, ``dataset.json``'s column table, the validator's checks,
the loader's keys and the shading layers. Adding a layer is one entry here (:func:`register` for a layer of
your own) plus the code that computes its pass.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np

from eden_pipe import labels
from eden_pipe.io.file_formats import (  # noqa: F401  (the table's formats, re-exported)
    DEFAULT_WRITE_OPTIONS,
    DEPTH_FORMATS,
    FLO,
    FLOAT32_RELATIVE,
    FLOAT_EXR,
    FLOAT_LAYER_FORMATS,
    FLOAT_NPY,
    FLOW_FORMATS,
    HALF_RELATIVE,
    HALF_SUBNORMAL_STEP,
    INSTANCE_PNG,
    KITTI_FLOW_PNG,
    MASK_PNG,
    MASK_PNG_MOVED,
    MOTION_FORMATS,
    NORMAL_PNG,
    RGB_PNG,
    SEMANTIC_PNG,
    STORAGE_MODES,
    FileFormat,
    WriteOptions,
)


# ------------------------------------------------------------------ value domains
@dataclass(frozen=True)
class ValueDomain:
    """What the values of a decoded array may be; ``problem(array)`` says why an array is outside, or None."""

    description: str
    problem: Callable[[np.ndarray], str | None]


def _count(mask: np.ndarray) -> int:
    return int(np.count_nonzero(mask))


def _class_ids(a: np.ndarray) -> str | None:
    top = int(a.max()) if a.size else 0
    return None if top < len(labels.NAMES) else f"class id {top} not in the label table (0..{len(labels.NAMES) - 1})"


def _binary(a: np.ndarray) -> str | None:
    top = int(a.max()) if a.size else 0
    return None if top <= 1 else f"value {top} not in {{0, 1}}"


def _depth(a: np.ndarray) -> str | None:
    if np.isnan(a).any():
        return f"{_count(np.isnan(a))} NaN depth pixels"
    if (a < 0).any():
        return f"depth < 0 ({float(a.min()):.4g} m)"
    return None


UNIT_TOLERANCE = 1e-3  # |n| of a decoded 16-bit normal is 1 within 2e-5; a wrong decoding is far off


def _unit_normals(a: np.ndarray) -> str | None:
    if not np.isfinite(a).all():
        return "non-finite normals"
    valid = np.any(a != 0, axis=-1)
    if not valid.any():
        return None
    n = a[valid].astype(np.float32, copy=False)
    err = np.abs(np.sqrt(np.einsum("ij,ij->i", n, n)) - 1.0)
    if err.max() > UNIT_TOLERANCE:
        return f"{_count(err > UNIT_TOLERANCE)} normals not unit length (max | |n|-1 | = {err.max():.3g})"
    return None


def _flow(a: np.ndarray) -> str | None:
    # NaN marks pixels a KITTI PNG declares invalid (beyond +-512 px): allowed; infinities are not.
    bad = np.isinf(a).any(axis=-1)
    return f"{_count(bad)} infinite flow pixels" if bad.any() else None


def _finite(a: np.ndarray) -> str | None:
    bad = ~np.isfinite(a)
    return f"{_count(bad.any(axis=-1) if a.ndim == 3 else bad)} non-finite pixels" if bad.any() else None


def _radiance(a: np.ndarray) -> str | None:
    if not np.isfinite(a).all():
        return f"{_count(~np.isfinite(a).all(axis=-1) if a.ndim == 3 else ~np.isfinite(a))} non-finite pixels"
    if (a < 0).any():
        return f"negative values (min {float(a.min()):.4g})"
    return None


VALUE_DOMAINS: dict[str, ValueDomain] = {
    "levels": ValueDomain("integer levels of the dtype", lambda a: None),
    "class_id": ValueDomain("class ids of eden_pipe.labels (0 = void)", _class_ids),
    "instance_id": ValueDomain("0 = none, else an instance id of <garden>/scene.json", lambda a: None),
    "depth": ValueDomain(">= 0 metres; inf = sky", _depth),
    "unit_vector": ValueDomain("unit vectors; 0,0,0 = sky", _unit_normals),
    "flow": ValueDomain("finite pixels; NaN where the file marks the flow invalid", _flow),
    "binary": ValueDomain("0 or 1", _binary),
    "radiance": ValueDomain("finite, >= 0", _radiance),
    "displacement": ValueDomain("finite metres; 0,0,0 = did not move (rigid, or sky)", _finite),
}

# Roles in the image formation (docs/design.md, Image formation): the composite is the sum of the product of
# the reflectance and irradiance layers and every additive layer; the display image is sRGB(exposure * it).
ROLES = ("reflectance", "irradiance", "additive", "composite", "display")
# How the torch loader presents a column (eden_pipe.data.dataset).
LOADERS = ("image", "labels", "ids", "depth", "normal", "flow", "mask", "layer")
DTYPES = {"uint8": np.uint8, "uint16": np.uint16, "float": np.floating}


@dataclass(frozen=True)
class Column:
    """One manifest path column: a file per frame and camera pair, and the array it holds."""

    name: str  # manifest column and folder name
    format: FileFormat | Mapping[str, FileFormat]  # or one per value of the option ``chosen_by``
    key: str | None = None  # the view pass written (default: ``name``)
    camera: str = "left"  # "left" or "right" camera of the pair
    needs: str | None = None  # "next"/"prev": only when that frame exists
    chosen_by: str = "depth_format"  # the WriteOptions field choosing among ``format``s
    channels: int = 1  # 1: (H, W); else (H, W, channels)
    dtype: str = "float"  # decoded dtype kind (DTYPES)
    values: str = "radiance"  # decoded value domain (VALUE_DOMAINS)
    units: str = ""
    role: str | None = None  # role in the image formation (ROLES)
    loader: str = "layer"  # how the loader presents it (LOADERS)
    mask: str | None = None  # the occlusion column that masks this flow
    zero_on: str | None = None  # "sky" or "surface": pixels where the layer is 0

    @property
    def source(self) -> str:
        return self.key or self.name

    def shape(self, height: int, width: int) -> tuple[int, ...]:
        return (height, width) if self.channels == 1 else (height, width, self.channels)

    def file_format(self, options: WriteOptions = DEFAULT_WRITE_OPTIONS) -> FileFormat:
        return self.format if isinstance(self.format, FileFormat) else self.format[getattr(options, self.chosen_by)]

    def formats(self) -> tuple[FileFormat, ...]:
        return (self.format,) if isinstance(self.format, FileFormat) else tuple(self.format.values())

    def format_of(self, path) -> FileFormat:
        """The format a file was written in, by its extension (every storage mode stays readable)."""
        suffix = Path(path).suffix.lstrip(".")
        for fmt in self.formats():
            if fmt.ext == suffix:
                return fmt
        raise ValueError(
            f"{path}: no {self.name} format has the extension {suffix!r}; "
            f"known: {', '.join(sorted({f.ext for f in self.formats()}))}"
        )

    def write(self, path, data: np.ndarray, options: WriteOptions = DEFAULT_WRITE_OPTIONS) -> None:
        self.file_format(options).write(path, data, options)

    def read(self, path) -> np.ndarray:
        array = self.format_of(path).read(path)
        if self.channels == 1 and array.ndim == 3 and array.shape[-1] == 1:
            array = array[..., 0]  # a one-channel image format (EXR Y) holds an (H, W) column
        return array

    def defined(self, has_next: bool, has_prev: bool) -> bool:
        return {"next": has_next, "prev": has_prev}.get(self.needs or "", True)

    def problem(self, array: np.ndarray, height: int, width: int) -> tuple[str, str] | None:
        """(check, detail) where a decoded array breaks this column's contract, else None."""
        shape = self.shape(height, width)
        if array.shape != shape:
            return "shape", f"{array.shape} != {shape}"
        want = DTYPES[self.dtype]
        if not np.issubdtype(array.dtype, want):
            return "dtype", f"{array.dtype} is not {self.dtype}"
        detail = VALUE_DOMAINS[self.values].problem(array)
        return ("range", detail) if detail else None


@dataclass(frozen=True)
class Modality:
    name: str
    columns: tuple[Column, ...]
    default: bool = True
    # A pass computed from other passes of the same view after the backend rendered it: ``derive(view)``
    # with the view's passes (keys as ``render.view.render_view``), needing the modalities ``inputs``.
    derive: Callable[[dict[str, np.ndarray]], np.ndarray] | None = None
    inputs: tuple[str, ...] = ()
    # Its columns are in a manifest only where a row has its files (the wind's layers: a dataset
    # without wind keeps the manifest it had before they existed).
    listed_when_written: bool = False

    @property
    def backends(self) -> tuple[str, ...]:
        """Names of the registered backends that produce this modality."""
        from eden_pipe.render import backends

        return backends.producing(self.name)


def _single(
    name: str, fmt, *, default: bool = True, key: str | None = None, chosen_by: str = "depth_format", **contract
) -> Modality:
    return Modality(name, (Column(name, fmt, key=key, chosen_by=chosen_by, **contract),), default)


def float_layer(
    name: str,
    role: str | None,
    *,
    default: bool = True,
    key: str | None = None,
    channels: int = 3,
    units: str = "linear RGB radiance (relative)",
    zero_on: str | None = None,
    derive=None,
    inputs: tuple[str, ...] = (),
) -> Modality:
    """A linear float layer, half-float EXR (compact) or float32 .npy (exact)."""
    column = Column(
        name,
        FLOAT_LAYER_FORMATS,
        key=key,
        chosen_by="storage",
        channels=channels,
        units=units,
        role=role,
        zero_on=zero_on,
    )
    return Modality(name, (column,), default, derive, inputs)


class _Shared(TypedDict, total=False):
    """:class:`Column` fields that the columns of one modality share (``Column(name, fmt, **shared)``)."""

    channels: int
    dtype: str
    values: str
    units: str
    role: str | None
    loader: str
    chosen_by: str


_DEPTH: _Shared = dict(
    channels=1, dtype="float", values="depth", units="metres (z along the optical axis)", loader="depth"
)
_RGB: _Shared = dict(channels=3, dtype="uint8", values="levels", units="sRGB levels", role="display", loader="image")
_FLOW: _Shared = dict(
    channels=2, dtype="float", values="flow", units="pixels (dx, dy)", loader="flow", chosen_by="storage"
)
_OCC: _Shared = dict(dtype="uint8", values="binary", units="1 = occluded or leaves the image", loader="mask")
_MOTION: _Shared = dict(
    channels=3,
    dtype="float",
    values="displacement",
    units="metres, camera frame: the surface point's displacement to that frame",
    chosen_by="storage",
)
_BUILTIN: tuple[Modality, ...] = (
    Modality(
        "rgb",
        (
            Column("rgb_left", RGB_PNG, key="rgb", **_RGB),
            Column("rgb_right", RGB_PNG, key="rgb", camera="right", **_RGB),
        ),
    ),
    _single("semantic", SEMANTIC_PNG, dtype="uint8", values="class_id", units="class id", loader="labels"),
    _single("instance", INSTANCE_PNG, dtype="uint16", values="instance_id", units="instance id", loader="ids"),
    Modality(
        "depth",
        (
            Column("depth", DEPTH_FORMATS, **_DEPTH),
            Column("depth_right", DEPTH_FORMATS, key="depth", camera="right", **_DEPTH),
        ),
    ),
    _single("normal", NORMAL_PNG, channels=3, values="unit_vector", units="unit vector, camera frame", loader="normal"),
    # Flow is undefined past the ends of the trajectory.
    Modality(
        "flow",
        (
            Column("flow_fwd", FLOW_FORMATS, needs="next", mask="occ_fwd", **_FLOW),
            Column("flow_bwd", FLOW_FORMATS, needs="prev", mask="occ_bwd", **_FLOW),
            Column("occ_fwd", MASK_PNG, needs="next", **_OCC),
            Column("occ_bwd", MASK_PNG, needs="prev", **_OCC),
        ),
    ),
    # Linear float layers: rgb_linear (the pixel-centre composite I, before exposure)
    # = albedo*shading + translucency + glossy + background.
    float_layer("albedo", "reflectance", units="reflectance (Dcol), linear RGB", zero_on="sky"),
    float_layer("shading", "irradiance", zero_on="sky"),
    float_layer("translucency", "additive", zero_on="sky"),
    float_layer("glossy", "additive", default=False, zero_on="sky"),
    float_layer("background", "additive", default=False, zero_on="surface"),
    float_layer("rgb_linear", "composite", default=False, key="linear"),
    # Wind (docs/design.md, "Wind"): which pixels' surfaces move, and by how much (the surface point's
    # own displacement to the next and previous frames, which the flow projects). Written whenever
    # the wind blows (lighting.wind_mps > 0).
    Modality(
        "dynamic",
        (
            Column(
                "dynamic",
                MASK_PNG_MOVED,
                dtype="uint8",
                values="binary",
                units="1 = the surface seen moves (wind)",
                loader="mask",
            ),
            Column("motion_fwd", MOTION_FORMATS, needs="next", **_MOTION),
            Column("motion_bwd", MOTION_FORMATS, needs="prev", **_MOTION),
        ),
        default=False,
        listed_when_written=True,
    ),
)

# The table and what derives from it. ``register`` changes them in place, so every module that
# imported them sees a registered layer.
TABLE: list[Modality] = []
BY_NAME: dict[str, Modality] = {}
MODALITIES: list[str] = []
DEFAULT_MODALITIES: list[str] = []
COLUMNS: dict[str, Column] = {}
PATH_COLUMNS: list[str] = []
LISTED_WHEN_WRITTEN: set[str] = set()  # columns of modalities with ``listed_when_written``


def _derive_all(table: Iterable[Modality]) -> None:
    table = list(table)
    names = [m.name for m in table]
    columns = [c for m in table for c in m.columns]
    problems = [f"duplicate modality {n!r}" for n in set(names) if names.count(n) > 1]
    problems += [f"duplicate column {c.name!r}" for c in columns if [d.name for d in columns].count(c.name) > 1]
    for c in columns:
        for field_name, value, allowed in (
            ("values", c.values, VALUE_DOMAINS),
            ("role", c.role, ROLES),
            ("loader", c.loader, LOADERS),
            ("dtype", c.dtype, DTYPES),
            ("camera", c.camera, ("left", "right")),
            ("zero_on", c.zero_on, ("sky", "surface")),
        ):
            if value is not None and value not in allowed:
                problems.append(f"column {c.name!r}: {field_name}={value!r}; allowed: {', '.join(allowed)}")
    if problems:
        raise ValueError("modality table: " + "; ".join(sorted(set(problems))))
    TABLE[:] = table
    BY_NAME.clear()
    BY_NAME.update({m.name: m for m in table})
    MODALITIES[:] = names
    DEFAULT_MODALITIES[:] = [m.name for m in table if m.default]
    COLUMNS.clear()
    COLUMNS.update({c.name: c for c in columns})
    PATH_COLUMNS[:] = list(COLUMNS)
    LISTED_WHEN_WRITTEN.clear()
    LISTED_WHEN_WRITTEN.update(c.name for m in table if m.listed_when_written for c in m.columns)


_derive_all(_BUILTIN)


def register(modality: Modality) -> None:
    """Add a modality (a layer of your own) after the built-in ones; its name becomes a ``render.modalities``
    choice, its columns manifest columns. Raises ValueError on a clash or a contract outside the domains."""
    _derive_all([*TABLE, modality])


def unregister(name: str) -> None:
    if name not in BY_NAME:
        raise KeyError(f"unknown modality {name!r}; known: {', '.join(MODALITIES)}")
    if any(m.name == name for m in _BUILTIN):
        raise ValueError(f"{name!r} is a built-in modality")
    _derive_all([m for m in TABLE if m.name != name])


@contextmanager
def registered(modality: Modality) -> Iterator[Modality]:
    """``register`` for the duration of a block (tests, one-off jobs)."""
    register(modality)
    try:
        yield modality
    finally:
        unregister(modality.name)


# ------------------------------------------------------------------ what derives from the table
def columns_for(modalities: Iterable[str], has_next: bool = True, has_prev: bool = True) -> list[Column]:
    """The columns written for a set of modalities, in table order (those needing a missing frame left out)."""
    wanted = set(modalities)
    return [c for m in TABLE if m.name in wanted for c in m.columns if c.defined(has_next, has_prev)]


def camera_passes(modalities: Iterable[str], camera: str) -> set[str]:
    """The enabled modalities with a column from ``camera`` ("left"/"right")."""
    wanted = set(modalities)
    return {m.name for m in TABLE if m.name in wanted and any(c.camera == camera for c in m.columns)}


def producible(capabilities: Iterable[str]) -> frozenset[str]:
    """What a backend with these ``capabilities`` produces: them and every derived modality whose inputs it
    produces (derived modalities may build on each other, in table order)."""
    out = set(capabilities)
    for m in TABLE:
        if m.derive is not None and set(m.inputs) <= out:
            out.add(m.name)
    return frozenset(out)


def derived_inputs(modalities: Iterable[str]) -> set[str]:
    """The modalities a view must render for the derived ones among ``modalities``."""
    wanted = set(modalities)
    return {i for m in TABLE if m.name in wanted and m.derive is not None for i in m.inputs}


def add_derived(view: dict[str, np.ndarray], modalities: Iterable[str], camera: str) -> None:
    """Compute the derived passes of ``modalities`` with a column on ``camera`` into ``view``."""
    wanted = set(modalities)
    for m in TABLE:
        if m.name in wanted and m.derive is not None and any(c.camera == camera for c in m.columns):
            for column in m.columns:
                view[column.source] = np.asarray(m.derive(view))


def shading_passes() -> tuple[str, ...]:
    """The passes of the image formation's layers (reflectance, irradiance, additive), in table order."""
    return tuple(c.source for c in COLUMNS.values() if c.role in ("reflectance", "irradiance", "additive"))


def pass_channels(source: str) -> int:
    """Channels of the view pass ``source`` (as written to its columns)."""
    counts = {c.channels for c in COLUMNS.values() if c.source == source}
    if len(counts) != 1:
        raise KeyError(f"no single channel count for the pass {source!r}: {sorted(counts)}")
    return counts.pop()


def formation_columns(role: str) -> tuple[str, ...]:
    """The left-camera columns with ``role`` in the image formation, in table order."""
    if role not in ROLES:
        raise KeyError(f"unknown image-formation role {role!r}; known: {', '.join(ROLES)}")
    return tuple(c.name for c in COLUMNS.values() if c.role == role and c.camera == "left")


def formation_identity() -> str:
    """The image-formation identity in the table's column names, e.g. for ``dataset.json``."""
    product = "*".join(formation_columns("reflectance") + formation_columns("irradiance"))
    composite = " + ".join((product,) + formation_columns("additive"))
    display = ", ".join(formation_columns("display"))
    return f"{', '.join(formation_columns('composite'))} = {composite}; {display} = sRGB(exposure * composite)"


def write_column(path, column: str, data: np.ndarray, options: WriteOptions = DEFAULT_WRITE_OPTIONS) -> None:
    COLUMNS[column].write(path, data, options)


def read_modality(path, column: str) -> np.ndarray:
    """Read any manifest path column's file."""
    if column not in COLUMNS:
        raise KeyError(f"unknown modality column {column!r}; known: {', '.join(COLUMNS)}")
    return COLUMNS[column].read(path)
