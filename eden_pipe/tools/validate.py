"""Check a published dataset against its contract (DESIGN sections 2-5, README "Output").

    python -m eden_pipe.tools.validate DATASET [--sample N] [--seed S] [--rgb-spp K] [--no-progress]

For every manifest row checked (all rows, or ``--sample N`` random ones):

* files: every path the row names exists, decodes through
  ``eden_pipe.io.formats.read_modality`` and has the row's height x width, the
  expected channels and dtype, and a valid range (semantic ids in the label
  table and the label palette, unit normals where valid, depth >= 0 / inf = sky,
  occlusion in {0, 1}, flow finite, float layers finite and >= 0);
* instances: every instance id is in the garden's instance table
  (``load_instance_classes``) and its class is what the semantic image shows on
  >= 99 % of its pixels (skipped with a "no metadata" warning when the table is
  missing);
* flow: forward (backward) flow equals the reprojection of the left depth
  through K and the poses of frame t and t+1 (t-1) of the same garden,
  lighting and camera, taken from the manifest: median error < 0.01 px on
  non-occluded pixels; sky pixels move by rotation only (same tolerance);
  pixels whose point clearly leaves the image are marked occluded;
* image formation: ``rgb_linear = albedo*shading + glossy + translucency +
  background`` where all are written (relative 2e-3 + absolute 1e-4, room for
  half floats), and ``rgb_left = sRGB(exposure * rgb_linear)`` within 2 levels:
  strictly (99.9 % of pixels) when ``rgb_spp`` is known to be 1, loosely
  (median <= 1 level, 90 % of pixels) when it is unknown, since anti-aliased
  PNGs differ from the pixel-centre layer along edges; skipped when > 1.

Each failure prints one line ``FAIL <file>: <check>: <detail>``; a summary
follows. Exit status 1 on any failure, 0 on a clean dataset (warnings do not
fail). ``check_dataset`` is the same as a function.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from eden_pipe import labels, metadata, modalities
from eden_pipe.data.manifest import load_manifest, row_pose
from eden_pipe.io import formats

INFO_COLUMNS = ["garden", "seed", "lighting", "frame", "camera", "width", "height", "fx", "fy", "cx", "cy",
                "qw", "qx", "qy", "qz", "tx", "ty", "tz"]
PATH_COLUMNS = list(modalities.PATH_COLUMNS)
FLOAT_LAYERS = tuple(name for name, c in modalities.COLUMNS.items() if c.format is modalities.FLOAT_LAYER_FORMATS)
# Where the per-garden instance table is published (eden_pipe.metadata), relative to the dataset root.
METADATA_CANDIDATES = ("{garden}/" + metadata.SCENE_FILE,)

FLOW_MEDIAN_PX = 0.01
INSTANCE_AGREEMENT = 0.99
NORMAL_TOL = 1e-3
COMPOSE_REL, COMPOSE_ABS = 2e-3, 1e-4
RGB_LEVELS = 2


# ------------------------------------------------------------------ metadata
def metadata_path(root, garden: str, lighting: str) -> Path | None:
    """The first existing metadata file of (garden, lighting), or None."""
    for pattern in METADATA_CANDIDATES:
        path = Path(root) / pattern.format(garden=garden, lighting=lighting)
        if path.is_file():
            return path
    return None


def _class_id(entry: dict) -> int:
    for key in ("class_id", "semantic"):
        if key in entry:
            return int(entry[key])
    cls = entry.get("class")
    if isinstance(cls, (int, np.integer)):
        return int(cls)
    if isinstance(cls, str) and cls in labels.BY_NAME:
        return labels.BY_NAME[cls]
    raise ValueError(f"instance {entry.get('id')!r} has no class_id")


def load_instance_classes(root, garden: str, lighting: str) -> dict[int, int] | None:
    """{instance id: class id} from the garden's metadata, or None when there is no metadata file.

    Format: ``{"instances": [{"id": int, "class_id": int, ...}, ...]}`` (``semantic`` or a
    class name in ``class`` are accepted in place of ``class_id``). Raises ValueError on a
    malformed file.
    """
    path = metadata_path(root, garden, lighting)
    if path is None:
        return None
    try:
        meta = json.loads(path.read_text())
        return {int(e["id"]): _class_id(e) for e in meta["instances"]}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{path}: cannot read the instance table ({exc})") from exc


def load_rgb_spp(root, garden: str, lighting: str) -> int | None:
    """Samples per pixel of the RGB PNGs, from the job's config recorded in dataset.json (None if absent)."""
    path = Path(root) / metadata.DATASET_FILE
    try:
        job = json.loads(path.read_text())["jobs"][f"{garden}/{lighting}"]
        return int(job["render"]["rgb_spp"])
    except (OSError, ValueError, KeyError, TypeError):
        return None


# ------------------------------------------------------------------ geometry
def reprojection_flow(depth: np.ndarray, K: np.ndarray, pose0: np.ndarray, pose1: np.ndarray) -> np.ndarray:
    """(H, W, 2) flow of every pixel from pose0 to pose1: surface points from depth, sky (inf) by rotation."""
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
    with np.errstate(divide="ignore", invalid="ignore"):
        u1 = fx * cam1[..., 0] / cam1[..., 2] + cx
        v1 = fy * cam1[..., 1] / cam1[..., 2] + cy
    flow = np.stack([u1 - u, v1 - v], axis=-1)
    flow[cam1[..., 2] <= 1e-9] = np.nan  # behind the other camera: undefined
    return flow


# ------------------------------------------------------------------ results
@dataclass
class Report:
    failures: list[tuple[str, str, str]] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    rows: int = 0
    files: int = 0
    checks: dict[str, int] = field(default_factory=dict)
    skipped: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0

    def fail(self, path, check: str, detail: str = "") -> None:
        self.failures.append((str(path), check, detail))

    def ran(self, check: str, n: int = 1) -> None:
        self.checks[check] = self.checks.get(check, 0) + n

    def skip(self, check: str) -> None:
        self.skipped[check] = self.skipped.get(check, 0) + 1

    def warn(self, message: str) -> None:
        if message not in self.warnings:
            self.warnings.append(message)

    @property
    def ok(self) -> bool:
        return not self.failures

    def lines(self) -> list[str]:
        out = [f"FAIL {path}: {check}" + (f": {detail}" if detail else "") for path, check, detail in self.failures]
        out += [f"WARN {w}" for w in self.warnings]
        bad = len({p for p, _, _ in self.failures})
        rate = self.rows / self.seconds if self.seconds > 0 else float("inf")
        ran = ", ".join(f"{k} {v}" for k, v in sorted(self.checks.items()))
        out.append(f"validate: {self.rows} rows, {self.files} files, {len(self.failures)} failures in {bad} files "
                   f"({self.seconds:.1f} s, {rate:.2f} rows/s); checks: {ran}")
        if self.skipped:
            out.append("skipped: " + ", ".join(f"{k} {v}" for k, v in sorted(self.skipped.items())))
        out.append("OK" if self.ok else "FAILED")
        return out


# ------------------------------------------------------------------ per-file checks
def _check_file(report: Report, rel: str, column: str, arr: np.ndarray, h: int, w: int) -> bool:
    """Shape, dtype and range of one decoded file; True when it is fit for the cross checks."""
    def bad(check, detail):
        report.fail(rel, check, detail)
        return False

    shape: tuple[int, ...]
    if column in ("rgb_left", "rgb_right", "normal") or column in FLOAT_LAYERS:
        shape = (h, w, 3)
    elif column.startswith("flow"):
        shape = (h, w, 2)
    else:
        shape = (h, w)
    if arr.shape != shape:
        return bad("shape", f"{arr.shape} != {shape}")
    kind = column.split("_")[0]
    if column in ("rgb_left", "rgb_right"):
        if arr.dtype != np.uint8:
            return bad("dtype", f"{arr.dtype} != uint8")
    elif column == "semantic":
        if arr.dtype != np.uint8:
            return bad("dtype", f"{arr.dtype} != uint8")
        top = int(arr.max()) if arr.size else 0
        if top >= len(labels.NAMES):
            return bad("range", f"semantic id {top} not in the label table (0..{len(labels.NAMES) - 1})")
    elif column == "instance":
        if arr.dtype != np.uint16:
            return bad("dtype", f"{arr.dtype} != uint16")
    elif kind == "occ":
        if arr.dtype != np.uint8:
            return bad("dtype", f"{arr.dtype} != uint8")
        if arr.size and int(arr.max()) > 1:
            return bad("range", f"occlusion value {int(arr.max())} not in {{0, 1}}")
    else:  # float modalities
        if not np.issubdtype(arr.dtype, np.floating):
            return bad("dtype", f"{arr.dtype} is not floating point")
        if kind == "depth":
            if np.isnan(arr).any():
                return bad("range", f"{int(np.isnan(arr).sum())} NaN depth pixels")
            if (arr < 0).any():
                return bad("range", f"depth < 0 ({float(arr.min()):.4g} m)")
        elif column == "normal":
            if not np.isfinite(arr).all():
                return bad("range", "non-finite normals")
            valid = np.any(arr != 0, axis=-1)
            if valid.any():
                n = arr[valid].astype(np.float32, copy=False)
                err = np.abs(np.sqrt(np.einsum("ij,ij->i", n, n)) - 1.0)
                if err.max() > NORMAL_TOL:
                    return bad("range", f"{int((err > NORMAL_TOL).sum())} normals not unit length "
                                        f"(max | |n|-1 | = {err.max():.3g})")
        elif kind == "flow":
            # KITTI PNG flow marks flow beyond +-512 px invalid (NaN when read): allowed, checked against depth.
            if not rel.endswith(".png") and not np.isfinite(arr).all():
                return bad("range", f"{int((~np.isfinite(arr)).any(axis=-1).sum())} non-finite flow pixels")
        else:
            if not np.isfinite(arr).all():
                return bad("range", f"{int((~np.isfinite(arr)).any(axis=-1).sum())} non-finite pixels")
            if (arr < 0).any():
                return bad("range", f"negative values (min {float(arr.min()):.4g})")
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
            report.fail(rel, "instance-class", f"instance {int(i)} (class {cls} {name}) agrees with the semantic "
                                               f"image on {a / n:.1%} of {n} px")
    report.ran("instance")


def _check_flow(report, rel, flow, occ, depth, K, pose0, pose1, occ_rel: str = "") -> None:
    expected = reprojection_flow(depth, K, pose0, pose1)
    ok = np.isfinite(expected).all(axis=-1) & np.isfinite(flow).all(axis=-1)
    if occ is not None:
        ok &= occ == 0
    surface = ok & np.isfinite(depth)
    sky = ok & ~np.isfinite(depth)
    err = np.hypot(flow[..., 0] - expected[..., 0], flow[..., 1] - expected[..., 1])
    for name, mask in (("flow-reprojection", surface), ("flow-sky-rotation", sky)):
        if mask.sum() < 10:
            continue
        med = float(np.median(err[mask]))
        if not med < FLOW_MEDIAN_PX:
            report.fail(rel, name, f"median error {med:.4g} px over {int(mask.sum())} non-occluded px "
                                   f"(limit {FLOW_MEDIAN_PX})")
    if occ is not None:
        # Pixels whose point clearly leaves the image (1 px margin) or goes behind the camera are occluded.
        h, w = depth.shape
        v, u = np.mgrid[0:h, 0:w]
        with np.errstate(invalid="ignore"):
            u1, v1 = u + expected[..., 0], v + expected[..., 1]
            leaves = ~np.isfinite(expected).all(axis=-1) | (u1 < -1.5) | (u1 > w + 0.5) | (v1 < -1.5) | (v1 > h + 0.5)
        missed = int((leaves & (occ == 0)).sum())
        if missed > max(2, 0.001 * leaves.sum()):
            report.fail(rel, "occlusion", f"{missed} of {int(leaves.sum())} px that leave the image are not "
                                          f"marked occluded in {occ_rel}")
    report.ran("flow")


def _check_compose(report, rel, layers: dict[str, np.ndarray]) -> None:
    f = {k: v.astype(np.float32, copy=False) for k, v in layers.items()}
    comp = f["albedo"] * f["shading"] + f["glossy"] + f["translucency"] + f["background"]
    err = np.abs(comp - f["rgb_linear"])
    tol = COMPOSE_REL * np.maximum(np.abs(comp), np.abs(f["rgb_linear"])) + COMPOSE_ABS
    bad = err > tol
    if bad.any():
        report.fail(rel, "image-formation", f"rgb_linear != albedo*shading+glossy+translucency+background on "
                                            f"{int(bad.any(axis=-1).sum())} px (max error {float(err.max()):.4g})")
    report.ran("compose")


def _check_rgb(report, rel, rgb, linear, exposure: float, spp: int | None) -> None:
    srgb = np.clip(np.asarray(linear, np.float32) * np.float32(exposure), 0.0, 1.0)
    srgb = np.where(srgb <= 0.0031308, 12.92 * srgb, 1.055 * np.power(srgb, 1.0 / 2.4) - 0.055)
    diff = np.abs(np.round(srgb * 255.0) - rgb.astype(np.float32)).max(axis=-1)
    within = float((diff <= RGB_LEVELS).mean())
    med = float(np.median(diff))
    if spp == 1:
        if within < 0.999:
            report.fail(rel, "rgb-srgb", f"sRGB(exposure*rgb_linear) within {RGB_LEVELS} levels on only {within:.2%} px")
    elif within < 0.9 or med > 1:
        report.fail(rel, "rgb-srgb", f"sRGB(exposure*rgb_linear): median diff {med:.0f} levels, "
                                     f"{within:.1%} px within {RGB_LEVELS} (rgb_spp unknown: loose check)")
    report.ran("rgb")


# ------------------------------------------------------------------ driver
class _Context:
    def __init__(self, root: Path, manifest: pd.DataFrame, report: Report, rgb_spp: int | None):
        self.root, self.manifest, self.report, self.rgb_spp = root, manifest, report, rgb_spp
        self.index = {(r.garden, r.lighting, int(r.camera), int(r.frame)): i
                      for i, r in enumerate(manifest[["garden", "lighting", "camera", "frame"]].itertuples(index=False))}
        self.classes: dict[tuple[str, str], dict | None] = {}
        self.spp: dict[tuple[str, str], int | None] = {}

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
                self.report.warn(f"no metadata for {garden}/{lighting} (looked for "
                                 f"{', '.join(p.format(garden=garden, lighting=lighting) for p in METADATA_CANDIDATES)}):"
                                 " instance-id check skipped")
        return self.classes[key]

    def row_spp(self, garden, lighting):
        if self.rgb_spp is not None:
            return self.rgb_spp
        key = (garden, lighting)
        if key not in self.spp:
            self.spp[key] = load_rgb_spp(self.root, garden, lighting)
        return self.spp[key]


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
            arr = formats.read_modality(path, column)
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
            report.skip("instance (no metadata)")
        elif "semantic" in data:
            _check_instances(report, row["instance"], data["instance"], data["semantic"], classes)

    # Flow against the reprojection of depth through the two poses.
    K = np.array([[row["fx"], 0, row["cx"]], [0, row["fy"], row["cy"]], [0, 0, 1.0]], np.float64)
    for direction, step in (("fwd", 1), ("bwd", -1)):
        column = f"flow_{direction}"
        if column not in data:
            continue
        if "depth" not in data:
            report.skip("flow (no depth)")
            continue
        key = (row["garden"], row["lighting"], int(row["camera"]), int(row["frame"]) + step)
        if key not in ctx.index:
            report.fail(row[column], "flow-partner", f"no manifest row for frame {key[3]} (camera {key[2]})")
            continue
        other = ctx.manifest.iloc[ctx.index[key]]
        _check_flow(report, row[column], data[column], data.get(f"occ_{direction}"), data["depth"], K,
                    row_pose(row), row_pose(other), row.get(f"occ_{direction}", ""))

    if all(layer in data for layer in FLOAT_LAYERS):
        _check_compose(report, row["rgb_linear"], {k: data[k] for k in FLOAT_LAYERS})
    else:
        report.skip("compose (layers absent)")
    if "rgb_left" in data and "rgb_linear" in data and "exposure" in row and np.isfinite(float(row["exposure"])):
        spp = ctx.row_spp(row["garden"], row["lighting"])
        if spp is not None and spp > 1:
            report.skip("rgb (rgb_spp > 1)")
        else:
            _check_rgb(report, row["rgb_left"], data["rgb_left"], data["rgb_linear"], float(row["exposure"]), spp)
    else:
        report.skip("rgb (no rgb_linear)")


def read_manifest(root: Path) -> pd.DataFrame:
    return load_manifest(root)


def check_dataset(root, sample: int | None = None, seed: int = 0, rgb_spp: int | None = None,
                  progress: bool | None = None) -> Report:
    """Validate the dataset at ``root`` (all rows, or ``sample`` random ones); returns a Report."""
    root = Path(root)
    report = Report()
    start = time.perf_counter()
    if not (root / "manifest.csv").is_file():
        report.fail(root / "manifest.csv", "exists", "no manifest")
        return report
    try:
        manifest = read_manifest(root)
    except Exception as exc:  # noqa: BLE001
        report.fail("manifest.csv", "decode", str(exc).splitlines()[0][:200])
        return report
    missing = [c for c in INFO_COLUMNS if c not in manifest.columns]
    if missing:
        report.fail("manifest.csv", "columns", f"missing columns {missing}")
        return report
    dup = manifest.duplicated(["garden", "lighting", "frame", "camera"])
    if dup.any():
        report.fail("manifest.csv", "unique", f"{int(dup.sum())} duplicate (garden, lighting, frame, camera) rows")
    ctx = _Context(root, manifest, report, rgb_spp)
    order = np.arange(len(manifest))
    if sample is not None and sample < len(manifest):
        order = np.sort(np.random.default_rng(seed).choice(len(manifest), size=sample, replace=False))
    from tqdm import tqdm

    show = (len(order) > 20) if progress is None else progress
    for i in tqdm(order, desc="validate", unit="row", disable=not show, file=sys.stderr):
        check_row(ctx, manifest.iloc[i])
        report.rows += 1
    report.seconds = time.perf_counter() - start
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m eden_pipe.tools.validate", description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="dataset root (holds manifest.csv)")
    parser.add_argument("--sample", type=int, default=None, help="check N random rows (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the row sample")
    parser.add_argument("--rgb-spp", type=int, default=None,
                        help="RGB samples per pixel of the dataset (1: strict PNG check; >1: skip; default: "
                             "from the metadata, else a loose check)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    report = check_dataset(args.dataset, args.sample, args.seed, args.rgb_spp, False if args.no_progress else None)
    for line in report.lines():
        print(line)
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
