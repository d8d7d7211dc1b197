"""Dataset statistics and figures in the manner of the EDEN paper.

    python -m eden_pipe.tools.stats DATASET --out DIR [--sample N] [--seed S] [--frames K] [--no-progress]

Writes to DIR (PNG figures via matplotlib's Agg backend, numbers as CSV):

| file | content |
|---|---|
| class_pixels.png / .csv | pixels per semantic class (bar, log scale, 3DRMS colours) |
| class_share.png / .csv | per-image class share (boxplot: quartiles, whiskers 1.5 IQR); CSV one row per image |
| depth_pixels.png / .csv | pixels per depth range, half-open bins [0,1), ..., [9,10), [10,inf); sky apart |
| luminance.png, luminance.csv, luminance_by_lighting.csv | mean relative luminance of each RGB image, per lighting |
| contact_<garden>_<lighting>.png | a few frames per garden and lighting, one row each: every modality colour-coded |

Pixel counts cover every checked row (all, or ``--sample N`` random rows): the
class counts and the depth counts (sky included) each sum to rows*H*W.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from eden_pipe import labels
from eden_pipe.colour import srgb_to_linear
from eden_pipe.io import formats
from eden_pipe.tools.validate import read_manifest

DEPTH_EDGES = tuple(float(e) for e in range(11))  # [0,1), ..., [9,10), then [10, inf)
N_CLASSES = len(labels.NAMES)
CLASS_COLORS = labels.COLORS.astype(float) / 255.0


def depth_bin_labels(edges=DEPTH_EDGES) -> list[str]:
    out = [f"[{edges[i]:g},{edges[i + 1]:g})" for i in range(len(edges) - 1)]
    return out + [f"[{edges[-1]:g},inf)", "sky"]


def depth_histogram(depth: np.ndarray, edges=DEPTH_EDGES) -> np.ndarray:
    """Pixels per half-open depth bin [e_i, e_i+1), then [e_last, inf), then sky (non-finite) apart."""
    d = depth.ravel()
    sky = ~np.isfinite(d)
    bins = np.searchsorted(np.asarray(edges), d[~sky], side="right") - 1  # index i: e_i <= d < e_i+1
    bins = np.clip(bins, 0, len(edges) - 1)  # negative depth (invalid) counts in the first bin
    counts = np.bincount(bins, minlength=len(edges)).astype(np.int64)
    return np.append(counts, int(sky.sum()))


def luminance(rgb8: np.ndarray) -> float:
    """Mean relative luminance (Rec. 709, linear) of an sRGB uint8 image."""
    lin = srgb_to_linear(np.float32(1 / 255.0) * rgb8)
    return float((lin @ np.array([0.2126, 0.7152, 0.0722], np.float32)).mean())


# ------------------------------------------------------------------ colour coding
def colour_semantic(sem: np.ndarray) -> np.ndarray:
    return labels.palette_rgb()[sem]


def colour_instance(inst: np.ndarray) -> np.ndarray:
    pal = np.random.default_rng(12345).integers(40, 256, size=(65536, 3), dtype=np.uint8)
    pal[0] = 0
    return pal[inst]


def colour_depth(depth: np.ndarray) -> np.ndarray:
    """Log depth through the turbo colormap (near = red, far = blue), sky black."""
    finite = np.isfinite(depth) & (depth > 0)
    out = np.zeros(depth.shape + (3,), np.uint8)
    if finite.any():
        logd = np.log(np.where(finite, depth, 1.0))
        lo, hi = np.log(0.2), np.log(max(float(depth[finite].max()), 1.0))
        t = 1.0 - np.clip((logd - lo) / max(hi - lo, 1e-6), 0, 1)
        out[finite] = (plt.get_cmap("turbo")(t[finite])[:, :3] * 255).astype(np.uint8)
    return out


def colour_normal(n: np.ndarray) -> np.ndarray:
    valid = np.any(n != 0, axis=-1, keepdims=True)
    return (np.where(valid, (np.clip(n, -1, 1) + 1) * 0.5, 0) * 255).astype(np.uint8)


def colour_flow(flow: np.ndarray, max_mag: float | None = None) -> np.ndarray:
    """Colour wheel: hue = direction, saturation = magnitude (normalised by the 99th percentile)."""
    import cv2

    u, v = flow[..., 0].astype(np.float32), flow[..., 1].astype(np.float32)
    mag, ang = cv2.cartToPolar(u, v, angleInDegrees=True)
    scale = max_mag or max(float(np.percentile(mag, 99)), 1e-6)
    hsv = np.zeros(flow.shape[:2] + (3,), np.uint8)
    hsv[..., 0] = (ang / 2).astype(np.uint8)  # OpenCV hue in [0, 180)
    hsv[..., 1] = (np.clip(mag / scale, 0, 1) * 255).astype(np.uint8)
    hsv[..., 2] = 255
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def colour_linear(x: np.ndarray, exposure: float = 1.0) -> np.ndarray:
    c = np.clip(np.asarray(x, np.float32) * exposure, 0, 1)
    return (np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055) * 255).astype(np.uint8)


def colour_shading(x: np.ndarray) -> np.ndarray:
    """Shading with its 99th percentile at 0.8 (it is an irradiance, not a colour)."""
    x = np.asarray(x, np.float32)
    return colour_linear(0.8 * x / max(float(np.percentile(x, 99)), 1e-6))


SHEET_PANELS = [  # (title, manifest column, colour coder)
    ("rgb", "rgb_left", lambda a: a),
    ("semantic", "semantic", colour_semantic),
    ("instance", "instance", colour_instance),
    ("depth", "depth", colour_depth),
    ("normal", "normal", colour_normal),
    ("flow fwd", "flow_fwd", colour_flow),
    ("occ fwd", "occ_fwd", lambda a: np.repeat((a * 255).astype(np.uint8)[..., None], 3, axis=-1)),
    ("albedo", "albedo", colour_linear),
    ("shading", "shading", colour_shading),
]


def _read(root: Path, row, column: str):
    rel = row.get(column, "")
    if not isinstance(rel, str) or not rel:
        return None
    try:
        return formats.read_modality(root / rel, column)
    except Exception:  # noqa: BLE001 - a bad file shows as n/a; validate names it
        return None


def contact_sheet(root: Path, rows: pd.DataFrame, out: Path, title: str) -> Path:
    n = len(rows)
    h, w = int(rows.iloc[0]["height"]), int(rows.iloc[0]["width"])
    aspect = h / w
    fig, axes = plt.subplots(
        n, len(SHEET_PANELS), figsize=(2.0 * len(SHEET_PANELS), 2.0 * aspect * n + 0.6), squeeze=False
    )
    for r, (_, row) in enumerate(rows.iterrows()):
        for c, (name, column, coder) in enumerate(SHEET_PANELS):
            ax = axes[r, c]
            ax.set_xticks([]), ax.set_yticks([])
            arr = _read(root, row, column)
            if arr is None:
                ax.imshow(np.full((h, w, 3), 235, np.uint8))
                ax.text(0.5, 0.5, "n/a", ha="center", va="center", transform=ax.transAxes, color="grey")
            else:
                ax.imshow(coder(arr), interpolation="nearest")
            if r == 0:
                ax.set_title(name, fontsize=9)
            if c == 0:
                ax.set_ylabel(f"f{int(row['frame'])} cam{int(row['camera'])}", fontsize=8)
    fig.suptitle(title, fontsize=10)
    _save(fig, out)
    return out


def sheet_rows(group: pd.DataFrame, frames: int) -> pd.DataFrame:
    """Up to ``frames`` rows spread over the trajectory, cycling through the cameras."""
    with_flow = group[group["flow_fwd"].astype(str) != ""] if "flow_fwd" in group else group
    group = with_flow if len(with_flow) else group  # prefer frames that have every modality
    frame_ids = np.sort(group["frame"].unique())
    picks = frame_ids[np.unique(np.linspace(0, len(frame_ids) - 1, min(frames, len(frame_ids))).round().astype(int))]
    cams = np.sort(group["camera"].unique())
    out = []
    for i, f in enumerate(picks):
        at = group[group["frame"] == f]
        cam = cams[i % len(cams)]
        out.append(at[at["camera"] == cam].iloc[0] if (at["camera"] == cam).any() else at.iloc[0])
    return pd.DataFrame(out)


# ------------------------------------------------------------------ figures
def _save(fig, out: Path) -> None:
    fig.tight_layout()
    fig.savefig(out, dpi=100)
    plt.close(fig)


def plot_class_pixels(counts: np.ndarray, out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    x = np.arange(N_CLASSES)
    ax.bar(x, np.maximum(counts, 0), color=CLASS_COLORS, edgecolor="black", linewidth=0.5)
    ax.set_yscale("log")
    ax.set_xticks(x, labels.NAMES, rotation=45, ha="right")
    ax.set_ylabel("pixels")
    ax.set_title("Pixels per class")
    _save(fig, out)


def plot_class_share(shares: np.ndarray, out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    box = ax.boxplot(
        [shares[:, i] * 100 for i in range(N_CLASSES)],
        whis=1.5,
        patch_artist=True,
        showfliers=True,
        flierprops={"markersize": 2},
    )
    for patch, colour in zip(box["boxes"], CLASS_COLORS, strict=True):  # a box and a colour per class
        patch.set_facecolor(colour)
    ax.set_xticks(np.arange(1, N_CLASSES + 1), labels.NAMES, rotation=45, ha="right")
    ax.set_ylabel("share of image pixels (%)")
    ax.set_title("Per-image class share (quartiles, whiskers 1.5 IQR)")
    _save(fig, out)


def plot_depth(counts: np.ndarray, out: Path) -> None:
    fig, ax = plt.subplots(figsize=(7, 4))
    names = depth_bin_labels()
    colours = ["tab:blue"] * (len(names) - 1) + ["tab:gray"]
    ax.bar(np.arange(len(names)), counts, color=colours)
    ax.set_xticks(np.arange(len(names)), [f"{n} m" if n != "sky" else n for n in names], rotation=45, ha="right")
    ax.set_yscale("log")
    ax.set_ylabel("pixels")
    ax.set_title("Pixels per depth range (sky apart)")
    _save(fig, out)


def plot_luminance(lum: pd.DataFrame, out: Path) -> None:
    fig, ax = plt.subplots(figsize=(6, 4))
    groups = list(lum.groupby("lighting", sort=True))
    ax.boxplot([g["luminance"].to_numpy() for _, g in groups], whis=1.5)
    means = [g["luminance"].mean() for _, g in groups]
    ax.plot(np.arange(1, len(groups) + 1), means, "o", color="tab:red", label="mean")
    ax.set_xticks(np.arange(1, len(groups) + 1), [name for name, _ in groups])
    ax.set_ylabel("mean relative luminance (linear)")
    ax.set_title("Image luminance per lighting")
    ax.legend()
    _save(fig, out)


# ------------------------------------------------------------------ driver
def compute_stats(
    root, out, sample: int | None = None, seed: int = 0, frames: int = 3, progress: bool | None = None
) -> dict:
    """Compute every statistic and write the figures and CSVs; returns {name: path}."""
    from tqdm import tqdm

    root, out = Path(root), Path(out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = read_manifest(root)
    order = np.arange(len(manifest))
    if sample is not None and sample < len(manifest):
        order = np.sort(np.random.default_rng(seed).choice(len(manifest), size=sample, replace=False))
    rows = manifest.iloc[order].reset_index(drop=True)

    class_counts = np.zeros(N_CLASSES, np.int64)
    depth_counts = np.zeros(len(DEPTH_EDGES) + 1, np.int64)
    share_rows, lum_rows = [], []
    show = (len(rows) > 20) if progress is None else progress
    for _, row in tqdm(rows.iterrows(), total=len(rows), desc="stats", unit="row", disable=not show, file=sys.stderr):
        key = {k: row[k] for k in ("garden", "lighting", "frame", "camera")}
        hw = int(row["height"]) * int(row["width"])
        sem = _read(root, row, "semantic")
        if sem is not None:
            c = np.bincount(sem.ravel(), minlength=N_CLASSES)[:N_CLASSES].astype(np.int64)
            class_counts += c
            share_rows.append({**key, **{name: c[i] / hw for i, name in enumerate(labels.NAMES)}})
        depth = _read(root, row, "depth")
        if depth is not None:
            depth_counts += depth_histogram(depth)
        rgb = _read(root, row, "rgb_left")
        if rgb is not None:
            lum_rows.append({**key, "luminance": luminance(rgb)})

    files = {}
    pd.DataFrame(
        {
            "class_id": np.arange(N_CLASSES),
            "name": labels.NAMES,
            "pixels": class_counts,
            "share": class_counts / max(class_counts.sum(), 1),
        }
    ).to_csv(out / "class_pixels.csv", index=False)
    files["class_pixels.csv"] = out / "class_pixels.csv"
    shares = pd.DataFrame(share_rows, columns=["garden", "lighting", "frame", "camera", *labels.NAMES])
    shares.to_csv(out / "class_share.csv", index=False, float_format="%.6g")
    files["class_share.csv"] = out / "class_share.csv"
    names = depth_bin_labels()
    lo = list(DEPTH_EDGES) + [np.nan]
    hi = list(DEPTH_EDGES[1:]) + [np.inf, np.nan]
    pd.DataFrame({"bin": names, "lo_m": lo, "hi_m": hi, "pixels": depth_counts}).to_csv(
        out / "depth_pixels.csv", index=False
    )
    files["depth_pixels.csv"] = out / "depth_pixels.csv"
    lum = pd.DataFrame(lum_rows, columns=["garden", "lighting", "frame", "camera", "luminance"])
    lum.to_csv(out / "luminance.csv", index=False, float_format="%.6g")
    files["luminance.csv"] = out / "luminance.csv"
    by_light = lum.groupby("lighting")["luminance"].agg(["count", "mean", "std", "median"]).reset_index()
    by_light.to_csv(out / "luminance_by_lighting.csv", index=False, float_format="%.6g")
    files["luminance_by_lighting.csv"] = out / "luminance_by_lighting.csv"

    plot_class_pixels(class_counts, out / "class_pixels.png")
    files["class_pixels.png"] = out / "class_pixels.png"
    if len(shares):
        plot_class_share(shares[list(labels.NAMES)].to_numpy(), out / "class_share.png")
        files["class_share.png"] = out / "class_share.png"
    plot_depth(depth_counts, out / "depth_pixels.png")
    files["depth_pixels.png"] = out / "depth_pixels.png"
    if len(lum):
        plot_luminance(lum, out / "luminance.png")
        files["luminance.png"] = out / "luminance.png"
    groups = list(rows.groupby(["garden", "lighting"], sort=True))
    for (garden, lighting), group in tqdm(groups, desc="contact sheets", disable=not show, file=sys.stderr):
        name = f"contact_{garden}_{lighting}.png"
        contact_sheet(root, sheet_rows(group, frames), out / name, f"{garden} / {lighting}")
        files[name] = out / name
    return {"files": files, "rows": len(rows), "class_pixels": class_counts, "depth_pixels": depth_counts}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m eden_pipe.tools.stats", description=__doc__.splitlines()[0])
    parser.add_argument("dataset", type=Path, help="dataset root (holds manifest.csv)")
    parser.add_argument("--out", type=Path, required=True, help="folder for the figures and CSVs")
    parser.add_argument("--sample", type=int, default=None, help="use N random rows (default: all)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the row sample")
    parser.add_argument("--frames", type=int, default=3, help="frames per contact sheet")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    result = compute_stats(
        args.dataset, args.out, args.sample, args.seed, args.frames, False if args.no_progress else None
    )
    print(
        f"stats: {result['rows']} rows, {int(result['class_pixels'].sum())} labelled pixels; "
        f"wrote {len(result['files'])} files to {args.out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
