"""Check a published dataset against its contract (docs/design.md and README "Output").

    python -m eden_pipe.tools.validate DATASET [--sample N] [--seed S] [--rgb-spp K] [--no-progress]

Every check derives from the modality table (:mod:`eden_pipe.modalities`): a column's shape, dtype and value
domain, its file format's precision and its role in the image formation. For every manifest row checked (all
rows, or ``--sample N`` random ones):

* files: every path the row names exists, decodes, and meets its column's contract (shape, dtype, values;
  the semantic palette is the label palette);
* instances: every instance id is in the garden's instance table (``<garden>/scene.json``) and its class is
  what the semantic image shows on >= 99 % of its pixels;
* flow: forward (backward) flow equals the reprojection of the left depth through K and the poses of frame
  t and t+1 (t-1) of the same garden, lighting and camera, pixel by pixel, within what the files can
  resolve: the flow format's quantisation (KITTI: 1/64 px steps) plus how far the reprojection moves when
  the stored depth moves by its own precision (png16: +-0.5 mm; a png16 "sky" pixel may be any point
  beyond 65.535 m) plus 2e-3 px of float32 arithmetic. A flow fails when any non-occluded pixel departs
  by more than its bound; the share of such pixels is reported. Pixels whose point clearly leaves the
  image must be marked occluded. With wind (the ``dynamic`` modality written), the expected flow is the
  projection of the depth's point plus its stored motion (``motion_fwd``/``motion_bwd``; 0 on rigid
  pixels, which are checked exactly as in still air), within the motion's rounding too; every pixel with
  a motion must be marked dynamic; a ``wind flow:`` line reports the error on rigid and moving pixels and
  how far the moving pixels' flow lies from the static reprojection;
* image formation: the composite column (``rgb_linear``) equals ``albedo*shading + translucency + glossy +
  background`` within the layers' stored precision, and the display PNG (``rgb_left``) equals
  sRGB(exposure * composite) to the 8-bit level, the composite taken from its column or, when that is not
  written, summed from the layers. The PNG is checked strictly when ``rgb_spp`` is 1 and loosely (median
  <= 1 level, 90 % of pixels within 2) when it is unknown; with ``rgb_spp`` > 1 the PNG averages sub-pixel
  samples no layer holds and the check cannot run.

A check that cannot run (a layer the dataset does not write, no metadata, ``rgb_spp`` > 1) is reported as
a finding with its reason (``not run: ...``), never skipped silently; so is every table column the dataset
does not write. Each failure prints one line ``FAIL <file>: <check>: <detail>``; a summary follows. Exit
status 1 on any failure, 0 on a clean dataset (findings and warnings do not fail). ``check_dataset`` is the
same as a function.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from eden_pipe import labels, metadata, modalities
from eden_pipe.colour import srgb_to_uint8
from eden_pipe.data.manifest_reader import load_manifest, row_pose
from eden_pipe.io import formats
from eden_pipe.tools import geometry_check
from eden_pipe.tools.camera_check import check_rgb_sensor, load_camera_effects
from eden_pipe.tools.consistency import Layer, composite_of, flow_tolerance, reprojection_flow
from eden_pipe.tools.job_metadata import (
    METADATA_CANDIDATES,
    backend_depth_error,
    load_instance_classes,
    load_rgb_spp,
    metadata_path,
)
from eden_pipe.tools.report import Report

INFO_COLUMNS = [
    "garden",
    "seed",
    "lighting",
    "frame",
    "camera",
    "width",
    "height",
    "fx",
    "fy",
    "cx",
    "cy",
    "qw",
    "qx",
    "qy",
    "qz",
    "tx",
    "ty",
    "tz",
]
PATH_COLUMNS = modalities.PATH_COLUMNS
INSTANCE_AGREEMENT = 0.99
LOOSE_RGB_LEVELS = 2


# ------------------------------------------------------------------ per-file checks
def _check_file(report: Report, rel: str, column: str, arr: np.ndarray, h: int, w: int) -> bool:
    """The column's contract (shape, dtype, values) on one decoded file; True when fit for the cross checks."""
    problem = modalities.COLUMNS[column].problem(arr, h, w)
    if problem:
        report.fail(rel, *problem)
        return False
    return True


def _check_palette(report: Report, path: Path, rel: str) -> None:
    try:
        pal = formats.read_palette(path)
    except Exception:  # noqa: BLE001 - the decode check reports unreadable files
        return
    n = len(labels.COLORS)
    if len(pal) < n or not np.array_equal(pal[:n], labels.COLORS):
        report.fail(rel, "palette", "semantic PNG palette differs from eden_pipe.labels.COLORS")


# ------------------------------------------------------------------ cross checks
def _check_instances(report, rel, inst, sem, classes: dict[int, int]) -> None:
    flat = inst.ravel().astype(np.intp, copy=False)
    counts = np.bincount(flat)
    ids = np.nonzero(counts)[0]
    missing = [int(i) for i in ids if i != 0 and int(i) not in classes]
    if missing:
        report.fail(rel, "instance-metadata", f"instance ids {missing[:10]} not in the metadata instance table")
    # Per id: pixels whose semantic class is the instance's class.
    lut = np.full(len(counts), -1, np.int64)
    for i in ids:
        lut[i] = classes.get(int(i), -1)
    agree = np.bincount(flat, weights=(sem.ravel() == lut[flat]), minlength=len(counts))
    for i in ids:
        cls, n, a = int(lut[i]), int(counts[i]), float(agree[i])
        if i == 0 or cls < 0:
            continue
        if a / n < INSTANCE_AGREEMENT:
            name = labels.NAMES[cls] if 0 <= cls < len(labels.NAMES) else "?"
            report.fail(
                rel,
                "instance-class",
                f"instance {int(i)} (class {cls} {name}) agrees with the semantic image on {a / n:.1%} of {n} px",
            )
    report.ran("instance")


def _check_flow(
    report, rel, flow, occ, depth, K, pose0, pose1, formats_of: tuple, occ_rel: str = "", motion=None
) -> None:
    """``motion``: the surface's own displacement (wind; (array, format)): the flow is then the reprojection
    of each moved point; rigid pixels (motion 0) are checked exactly as without wind."""
    moving, motion_format = (None, None) if motion is None else motion
    expected = reprojection_flow(depth, K, pose0, pose1, moving)
    ok = np.isfinite(expected).all(axis=-1) & np.isfinite(flow).all(axis=-1)
    if occ is not None:
        ok &= occ == 0
    err = np.hypot(flow[..., 0] - expected[..., 0], flow[..., 1] - expected[..., 1])
    bound = flow_tolerance(depth, formats_of[0], flow, formats_of[1], K, pose0, pose1, expected, moving, motion_format)
    if moving is not None:
        _note_motion(report, err, ok, moving, expected, reprojection_flow(depth, K, pose0, pose1))
    with np.errstate(invalid="ignore"):
        beyond = ok & ~(err <= bound)
    checked = int(ok.sum())
    if beyond.any():
        share = float(beyond.sum()) / max(checked, 1)
        worst = float(np.max((err - bound)[beyond]))
        report.fail(
            rel,
            "flow-reprojection",
            f"{share:.2%} of {checked} non-occluded px depart from the "
            f"reprojection of depth by more than the files resolve (worst by "
            f"{worst:.3g} px; median error {float(np.median(err[ok])):.3g} px)",
        )
    if occ is not None:
        # Pixels whose point clearly leaves the image (1 px margin) or goes behind the camera are occluded.
        h, w = depth.shape
        v, u = np.mgrid[0:h, 0:w]
        with np.errstate(invalid="ignore"):
            u1, v1 = u + expected[..., 0], v + expected[..., 1]
            leaves = ~np.isfinite(expected).all(axis=-1) | (u1 < -1.5) | (u1 > w + 0.5) | (v1 < -1.5) | (v1 > h + 0.5)
        missed = int((leaves & (occ == 0)).sum())
        if missed > max(2, 0.001 * leaves.sum()):
            report.fail(
                rel,
                "occlusion",
                f"{missed} of {int(leaves.sum())} px that leave the image are not marked occluded in {occ_rel}",
            )
    report.ran("flow")


def _note_motion(report, err, ok, motion, expected, rigid) -> None:
    """Collect the wind's flow figures: the error against the reprojection on rigid and moving pixels, and
    how far the moving pixels' flow is from the static reprojection (what a rigid-scene flow would get wrong)."""
    moves = np.any(motion != 0, axis=-1)
    with np.errstate(invalid="ignore"):
        apart = np.hypot(*np.moveaxis(expected - rigid, -1, 0))
    for name, values in (
        ("rigid", err[ok & ~moves]),
        ("moving", err[ok & moves]),
        ("moving_vs_static", apart[ok & moves]),
    ):
        report.motion.setdefault(name, []).append(values.astype(np.float32))


def _check_dynamic(report, rel, dynamic, motions) -> None:
    """A pixel whose stored motion is not 0 must be marked dynamic (the converse need not hold: a motion
    below the format's smallest step is stored as 0)."""
    for motion in motions:
        unmarked = int((np.any(motion != 0, axis=-1) & (dynamic == 0)).sum())
        if unmarked:
            report.fail(rel, "dynamic", f"{unmarked} px move (motion != 0) but are not marked dynamic")
    report.ran("dynamic")


def _check_compose(report, rel, composite: Layer, formed: Layer) -> None:
    err = np.abs(formed.values - composite.values)
    bad = err > formed.error + composite.error
    if bad.any():
        report.fail(
            rel,
            "image-formation",
            f"{modalities.formation_identity().split(';')[0]} broken on "
            f"{int(bad.any(axis=-1).sum())} px (max error {float(err.max()):.4g})",
        )
    report.ran("compose")


def _check_rgb(report, rel, rgb, linear: Layer, exposure: float, spp: int | None) -> None:
    e = np.float32(exposure)
    if spp == 1:
        # sRGB and rounding are monotone: a correct PNG lies between the levels of the composite's bounds
        # (only above the lower one where a layer that was not written may add light).
        lo = srgb_to_uint8(np.maximum(linear.values - linear.error, 0) * e).astype(np.int16)
        hi = srgb_to_uint8((linear.values + linear.error) * e).astype(np.int16)
        if linear.open_above is not None:
            hi[linear.open_above] = 255
        png = rgb.astype(np.int16)
        outside = ((png < lo) | (png > hi)).any(axis=-1)
        if outside.any():
            report.fail(
                rel,
                "rgb-srgb",
                f"sRGB(exposure * composite) outside the PNG's level on "
                f"{int(outside.sum())} px ({float(outside.mean()):.2%})",
            )
    elif linear.open_above is not None:
        report.cannot_run("rgb", "rgb_spp unknown and a layer not written: no bound to check")
        return
    else:
        diff = np.abs(srgb_to_uint8(linear.values * e).astype(np.int16) - rgb.astype(np.int16)).max(axis=-1)
        within = float((diff <= LOOSE_RGB_LEVELS).mean())
        med = float(np.median(diff))
        if within < 0.9 or med > 1:
            report.fail(
                rel,
                "rgb-srgb",
                f"sRGB(exposure * composite): median diff {med:.0f} levels, {within:.1%} px "
                f"within {LOOSE_RGB_LEVELS} (rgb_spp unknown: loose check)",
            )
    report.ran("rgb")


# ------------------------------------------------------------------ driver
class _Context:
    def __init__(self, root: Path, manifest: pd.DataFrame, report: Report, rgb_spp: int | None, seed: int = 0):
        self.root, self.manifest, self.report, self.rgb_spp, self.seed = root, manifest, report, rgb_spp, seed
        self.geometry: dict[str, geometry_check.Samples] = {}
        self.index = {
            (r.garden, r.lighting, int(r.camera), int(r.frame)): i
            for i, r in enumerate(manifest[["garden", "lighting", "camera", "frame"]].itertuples(index=False))
        }
        self.classes: dict[tuple[str, str], dict | None] = {}
        self.spp: dict[tuple[str, str], int | None] = {}
        self.depth_errors: dict[tuple[str, str], object] = {}
        self.effects: dict[tuple[str, str], dict | None] = {}

    def camera_effects(self, garden, lighting) -> dict | None:
        key = (garden, lighting)
        if key not in self.effects:
            try:
                self.effects[key] = load_camera_effects(self.root, garden, lighting)
            except ValueError as exc:
                self.report.fail(f"{garden}/{lighting}/{metadata.CAMERA_FILE}", "metadata", str(exc))
                self.effects[key] = None
        return self.effects[key]

    def instance_classes(self, garden, lighting):
        key = (garden, lighting)
        if key not in self.classes:
            try:
                self.classes[key] = load_instance_classes(self.root, garden, lighting)
            except ValueError as exc:
                path = metadata_path(self.root, garden, lighting)
                self.report.fail(path.relative_to(self.root) if path else f"{garden}/{lighting}", "metadata", str(exc))
                self.classes[key] = None
            if self.classes[key] is None and metadata_path(self.root, garden, lighting) is None:
                self.report.warn(
                    f"no metadata for {garden}/{lighting} (looked for "
                    f"{', '.join(p.format(garden=garden, lighting=lighting) for p in METADATA_CANDIDATES)}):"
                    " instance-id check skipped"
                )
        return self.classes[key]

    def depth_error(self, garden, lighting):
        """The job's backend's own z-depth error (``job_metadata.backend_depth_error``)."""
        key = (garden, lighting)
        if key not in self.depth_errors:
            self.depth_errors[key] = backend_depth_error(self.root, garden, lighting)
        return self.depth_errors[key]

    def row_spp(self, garden, lighting):
        if self.rgb_spp is not None:
            return self.rgb_spp
        key = (garden, lighting)
        if key not in self.spp:
            self.spp[key] = load_rgb_spp(self.root, garden, lighting)
        return self.spp[key]


def _float_layer(root: Path, rel: str, column: str, values: np.ndarray) -> Layer:
    fmt = modalities.COLUMNS[column].format_of(root / rel)
    values = np.asarray(values, np.float32)
    return Layer(values, fmt.error_bound(values))


def _check_formation(ctx: _Context, row: pd.Series, data: dict[str, np.ndarray]) -> None:
    """The composite against the layers, and the display PNG against the composite."""
    report = ctx.report
    (composite_column,) = modalities.formation_columns("composite")
    layer_columns = [c for r in ("reflectance", "irradiance", "additive") for c in modalities.formation_columns(r)]
    layers = {c: _float_layer(ctx.root, row[c], c, data[c]) for c in layer_columns if c in data}
    missing = [c for c in layer_columns if c not in data]
    formed = None if missing else composite_of(layers)
    # Without every additive layer the layers' sum still bounds the PNG from below (they only add light).
    products = [c for r in ("reflectance", "irradiance") for c in modalities.formation_columns(r)]
    partial = None
    if missing and all(c in data for c in products) and "depth" in data:
        partial = composite_of(layers, sky=~np.isfinite(data["depth"]))
    composite = (
        _float_layer(ctx.root, row[composite_column], composite_column, data[composite_column])
        if composite_column in data
        else None
    )
    if formed is not None and composite is not None:
        _check_compose(report, row[composite_column], composite, formed)
    elif formed is not None:
        report.cannot_run("compose", f"{composite_column} not written (the PNG is checked against the layers' sum)")
    else:
        absent = missing + ([] if composite is not None else [composite_column])
        report.cannot_run("compose", f"{', '.join(absent)} not readable or not written")
    linear = composite if composite is not None else formed if formed is not None else partial
    for display in modalities.formation_columns("display"):
        if display not in data:
            continue
        spp = ctx.row_spp(row["garden"], row["lighting"])
        exposure = float(row["exposure"]) if "exposure" in row else float("nan")
        effects = ctx.camera_effects(row["garden"], row["lighting"]) or {}
        if effects.get("readout_s") or effects.get("exposure_s"):
            # docs/design.md, Camera effects: the layers hold the sharp mid-exposure frame only.
            report.cannot_run(
                "rgb",
                "rolling shutter or motion blur on (camera.json): the PNG integrates poses over the "
                "readout and exposure, the layers hold the sharp global-shutter frame",
            )
        elif linear is None:
            report.cannot_run("rgb", f"neither {composite_column} nor every layer ({', '.join(missing)} absent)")
        elif not np.isfinite(exposure):
            report.cannot_run("rgb", "the manifest has no exposure")
        elif spp is not None and spp > 1:
            report.cannot_run("rgb", f"rgb_spp = {spp}: the PNG averages sub-pixel samples no layer holds")
        else:
            if linear is partial and partial.open_above is not None and partial.open_above.any():
                unwritten = ", ".join(c for c in missing if modalities.COLUMNS[c].role == "additive")
                report.cannot_run(
                    "rgb upper bound",
                    f"{unwritten} not written: they only add light, so the PNG is "
                    f"checked from below where they may be non-zero",
                )
            sensor = effects.get("sensor")
            if sensor is None:
                _check_rgb(report, row[display], data[display], linear, exposure, spp)
            else:
                check_rgb_sensor(report, row[display], row, data[display], linear, exposure, sensor)


def check_row(ctx: _Context, row: pd.Series) -> None:
    report, root = ctx.report, ctx.root
    h, w = int(row["height"]), int(row["width"])
    data: dict[str, np.ndarray] = {}
    for column in PATH_COLUMNS:
        rel = row.get(column, "")
        if not isinstance(rel, str) or not rel:
            continue
        path = root / rel
        report.files += 1
        if not path.is_file():
            report.fail(rel, "exists", "file named in the manifest is missing")
            continue
        try:
            arr = modalities.read_modality(path, column)
        except Exception as exc:  # noqa: BLE001 - any decoder error is a bad file
            report.fail(rel, "decode", f"{type(exc).__name__}: {exc}".splitlines()[0][:200])
            continue
        if _check_file(report, rel, column, arr, h, w):
            data[column] = arr
        if column == "semantic":
            _check_palette(report, path, rel)
    report.ran("file", len(data))

    # Instances against the metadata and the semantic image.
    if "instance" in data:
        classes = ctx.instance_classes(row["garden"], row["lighting"])
        if classes is None:
            report.cannot_run("instance", "no instance table (<garden>/scene.json)")
        elif "semantic" in data:
            _check_instances(report, row["instance"], data["instance"], data["semantic"], classes)

    # Flow against the reprojection of depth through the two poses.
    K = np.array([[row["fx"], 0, row["cx"]], [0, row["fy"], row["cy"]], [0, 0, 1.0]], np.float64)
    for flow in (c for c in modalities.COLUMNS.values() if c.loader == "flow"):
        if flow.name not in data:
            continue
        if "depth" not in data:
            report.cannot_run("flow", "no readable depth")
            continue
        step = 1 if flow.needs == "next" else -1
        key = (row["garden"], row["lighting"], int(row["camera"]), int(row["frame"]) + step)
        if key not in ctx.index:
            report.fail(row[flow.name], "flow-partner", f"no manifest row for frame {key[3]} (camera {key[2]})")
            continue
        other = ctx.manifest.iloc[ctx.index[key]]
        fmts = (modalities.COLUMNS["depth"].format_of(row["depth"]), flow.format_of(row[flow.name]))
        motion_column = f"motion_{flow.name.split('_')[-1]}"  # the surface's own motion (wind), when written
        motion = None
        if motion_column in data:
            motion = (data[motion_column], modalities.COLUMNS[motion_column].format_of(row[motion_column]))
        _check_flow(
            report,
            row[flow.name],
            data[flow.name],
            data.get(flow.mask or ""),
            data["depth"],
            K,
            row_pose(row),
            row_pose(other),
            fmts,
            row.get(flow.mask or "", ""),
            motion,
        )
    if "dynamic" in data:
        _check_dynamic(
            report, row["dynamic"], data["dynamic"], [data[c] for c in ("motion_fwd", "motion_bwd") if c in data]
        )

    _check_formation(ctx, row, data)
    _sample_geometry(ctx, row, data, K)


def _sample_geometry(ctx: _Context, row: pd.Series, data: dict[str, np.ndarray], K: np.ndarray) -> None:
    """Sample the row's pixels for the garden's geometry check (run once per garden, :func:`_check_geometry`)."""
    if "depth" not in data or "instance" not in data:
        ctx.report.cannot_run("geometry", "needs the left depth and instance images (not both readable)")
        return
    rng = np.random.default_rng([ctx.seed, int(row.name)])
    fmt = modalities.COLUMNS["depth"].format_of(row["depth"])
    # With wind, moving pixels lie on the moved mesh, not the published one: their flow is checked against
    # their motion instead.
    still = None if "dynamic" not in data else data["dynamic"] == 0
    error = ctx.depth_error(row["garden"], row["lighting"])  # a rasteriser's depth is coarser than its file
    sample = geometry_check.sample_row(
        data["depth"], data["instance"], fmt, K, row_pose(row), rng, still=still, depth_error=error
    )
    ctx.geometry.setdefault(row["garden"], geometry_check.Samples()).add(*sample, row["instance"])


def _check_geometry(ctx: _Context) -> None:
    report = ctx.report
    for garden, samples in sorted(ctx.geometry.items()):
        rel = f"{garden}/{metadata.GEOMETRY_FILE}"
        if not (ctx.root / rel).is_file():
            for _ in samples.rows:
                report.cannot_run("geometry", f"no published scene mesh ({rel})")
            continue
        try:
            result = geometry_check.check_garden(ctx.root / rel, samples)
        except (OSError, ValueError, KeyError) as exc:
            report.fail(rel, "decode", f"{type(exc).__name__}: {exc}".splitlines()[0][:200])
            continue
        for row_rel, (agree, checked) in result.rows.items():
            if checked and agree < geometry_check.AGREEMENT * checked:
                report.fail(
                    row_rel,
                    "geometry",
                    f"{agree} of {checked} sampled px lie on a face of their instance in {rel} "
                    f"(below {geometry_check.AGREEMENT:.1%})",
                )
        report.ran("geometry", len(result.rows))
        report.notes.append(
            f"geometry {garden}: {result.agree} of {result.checked} sampled px "
            f"({result.agree / max(result.checked, 1):.3%}) lie on a face of their instance in {rel} "
            f"({result.near / max(result.checked, 1):.3%} on any face; {result.faces} faces)"
        )


def read_manifest(root: Path) -> pd.DataFrame:
    return load_manifest(root)


def check_dataset(
    root, sample: int | None = None, seed: int = 0, rgb_spp: int | None = None, progress: bool | None = None
) -> Report:
    """Validate the dataset at ``root`` (all rows, or ``sample`` random ones); returns a Report."""
    root = Path(root)
    report = Report()
    start = time.perf_counter()
    if not (root / "manifest.csv").is_file():
        report.fail(root / "manifest.csv", "exists", "no manifest")
        return report
    try:
        manifest = read_manifest(root)
    except Exception as exc:  # noqa: BLE001 - an unreadable manifest is reported, not raised
        report.fail("manifest.csv", "decode", str(exc).splitlines()[0][:200])
        return report
    missing = [c for c in INFO_COLUMNS if c not in manifest.columns]
    if missing:
        report.fail("manifest.csv", "columns", f"missing columns {missing}")
        return report
    dup = manifest.duplicated(["garden", "lighting", "frame", "camera"])
    if dup.any():
        report.fail("manifest.csv", "unique", f"{int(dup.sum())} duplicate (garden, lighting, frame, camera) rows")
    ctx = _Context(root, manifest, report, rgb_spp, seed)
    order = np.arange(len(manifest))
    if sample is not None and sample < len(manifest):
        order = np.sort(np.random.default_rng(seed).choice(len(manifest), size=sample, replace=False))
    rows = manifest.iloc[order]
    # (Columns listed only when written, the wind's, are not "not written" in a dataset without them.)
    report.absent = [
        c
        for c in PATH_COLUMNS
        if c not in modalities.LISTED_WHEN_WRITTEN and (c not in rows.columns or not (rows[c].astype(str) != "").any())
    ]
    from tqdm import tqdm

    show = (len(order) > 20) if progress is None else progress
    for i in tqdm(order, desc="validate", unit="row", disable=not show, file=sys.stderr):
        check_row(ctx, manifest.iloc[i])
        report.rows += 1
    _check_geometry(ctx)
    report.seconds = time.perf_counter() - start
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m eden_pipe.tools.validate", description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="dataset root (holds manifest.csv)")
    parser.add_argument("--sample", type=int, default=None, help="check N random rows (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the row sample")
    parser.add_argument(
        "--rgb-spp",
        type=int,
        default=None,
        help="RGB samples per pixel of the dataset (1: strict PNG check; >1: skip; default: "
        "from the metadata, else a loose check)",
    )
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    report = check_dataset(args.dataset, args.sample, args.seed, args.rgb_spp, False if args.no_progress else None)
    for line in report.lines():
        print(line)
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
