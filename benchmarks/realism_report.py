"""Scoring and tables of ``benchmarks/realism.py``: errors per lighting and class, the render stage's rate."""

from __future__ import annotations

import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from eden_pipe import labels

LAYERS = ("linear", "shading")
MIN_SHARE = 0.01  # classes with fewer of a lighting's pixels are listed but not ranked


@dataclass
class Pool:
    """Sampled pixels of every view: per lighting, the classes and each source's values."""

    by_lighting: dict[str, dict[str, list[np.ndarray]]] = field(default_factory=dict)

    def add(self, record: dict) -> None:
        slot = self.by_lighting.setdefault(record["lighting"], {})
        for key, value in record.items():
            if key in ("lighting", "garden"):
                continue
            slot.setdefault(key, []).append(np.asarray(value))

    def arrays(self, lighting: str) -> dict[str, np.ndarray]:
        return {k: np.concatenate(v) for k, v in self.by_lighting[lighting].items()}


def relative_mae(a: np.ndarray, ref: np.ndarray) -> float:
    return float(np.abs(a - ref).mean() / max(float(ref.mean()), 1e-12))


def bias(a: np.ndarray, ref: np.ndarray) -> float:
    return float(a.mean() / max(float(ref.mean()), 1e-12) - 1.0)


def bias_standard_error(a: np.ndarray, ref: np.ndarray) -> float:
    """The standard error of ``bias(a, ref)`` over the sampled pixels (rows): the spread of the pixels'
    differences over the square root of their number, relative to the reference mean. Both renderers'
    noise and their per-pixel disagreement are in it, so a bias within about twice it is what another
    draw of pixels and seeds could give."""
    if len(a) < 2:
        return float("nan")
    diff = (np.asarray(a, np.float64) - np.asarray(ref, np.float64)).reshape(len(a), -1).mean(axis=1)
    return float(diff.std(ddof=1) / np.sqrt(len(a)) / max(float(ref.mean()), 1e-12))


def score(pool: Pool, variants: list[str], reference: str, compare_cycles: bool = False) -> dict:
    """{lighting: {"share": {class: share}, (variant, layer, class or "all"): (error, bias),
    ("halves", layer, class): halves' error, ("path_vs_cycles", layer, class): (bias, error, cycles noise,
    the bias's standard error) over the pixels whose Cycles footprint sees one face, ("one_face", class):
    their share}}."""
    out = {}
    for lighting in pool.by_lighting:
        a = pool.arrays(lighting)
        classes = a["classes"]
        names = {c: labels.NAMES[c] for c in np.unique(classes)}
        row: dict = {"share": {names[c]: float(np.mean(classes == c)) for c in names}, "pixels": len(classes)}
        masks = {"all": np.ones(len(classes), bool)} | {names[c]: classes == c for c in names}
        for layer in LAYERS:
            h1, h2 = a[f"{reference}_half1/{layer}"], a[f"{reference}_half2/{layer}"]
            ref = 0.5 * (h1 + h2)
            for cls, m in masks.items():
                row["halves", layer, cls] = relative_mae(h1[m], h2[m])
                for name in variants:
                    v = a[f"{name}/{layer}"][m]
                    row[name, layer, cls] = (relative_mae(v, ref[m]), bias(v, ref[m]))
                if compare_cycles:
                    one = m & a["one_face"]
                    row["one_face", cls] = float(one.sum() / max(1, m.sum()))
                    for key, sel in (("path_vs_cycles", one), ("path_vs_cycles_all", m)):
                        if not sel.any():  # a class none of whose pixels sees one face
                            row[key, layer, cls] = (float("nan"),) * 4
                            continue
                        c1, c2 = a[f"cycles_half1/{layer}"][sel], a[f"cycles_half2/{layer}"][sel]
                        cyc = 0.5 * (c1 + c2)
                        path = 0.5 * (a[f"path_half1/{layer}"][sel] + a[f"path_half2/{layer}"][sel])
                        row[key, layer, cls] = (
                            bias(path, cyc),
                            relative_mae(path, cyc),
                            relative_mae(c1, c2),
                            bias_standard_error(path, cyc),
                        )
        out[lighting] = row
    return out


def headline(results: dict, variant: str = "current") -> tuple[float, float, str]:
    """(worst lighting's overall error, worst (lighting, class, layer) error over classes with at least
    MIN_SHARE of the lighting's pixels, its name)."""
    overall = max(row[variant, layer, "all"][0] for row in results.values() for layer in LAYERS)
    worst, name = -1.0, ""
    for lighting, row in results.items():
        for cls, share in row["share"].items():
            if share < MIN_SHARE:
                continue
            for layer in LAYERS:
                err = row[variant, layer, cls][0]
                if err > worst:
                    worst, name = err, f"{cls}, {lighting}, {layer}"
    return overall, worst, name


def cycles_headline(results: dict) -> tuple[tuple[float, str, float], tuple[float, str]]:
    """The path tracer against Cycles over (lighting, layer, class) with at least MIN_SHARE of the pixels:
    (the largest mean bias, its name, its standard error), (the largest per-pixel error over Cycles'
    seed-to-seed error, its name): the realism issue's two targets for the reference (docs/realism.md,
    The path tracer against Cycles)."""
    bias_worst: tuple[float, str, float] = (0.0, "", 0.0)
    noise_worst = (0.0, "")
    for lighting, row in results.items():
        for cls, share in row["share"].items():
            if share < MIN_SHARE:
                continue
            for layer in LAYERS:
                b, e, n, se = row["path_vs_cycles", layer, cls]
                name = f"{cls}, {lighting}, {layer}"
                if abs(b) > abs(bias_worst[0]):
                    bias_worst = (b, name, se)
                if e / max(n, 1e-12) > noise_worst[0]:
                    noise_worst = (e / max(n, 1e-12), name)
    return bias_worst, noise_worst


def report(results: dict, set_name: str, rate: dict, job: dict | None, views: int) -> None:
    variants = list(rate)
    print()
    print(f"## {set_name}: per-pixel error relative to the reference mean (bias in brackets)")
    for layer in LAYERS:
        print()
        print(f"### {layer}")
        print("| lighting | class | share | " + " | ".join(variants) + " | reference halves |")
        print("|---|---|---|" + "---|" * len(variants) + "---|")
        for lighting, row in results.items():
            for cls in ["all"] + sorted(row["share"], key=lambda c: -row["share"][c]):
                share = 1.0 if cls == "all" else row["share"][cls]
                cells = " | ".join(f"{row[v, layer, cls][0]:.3f} ({row[v, layer, cls][1]:+.1%})" for v in variants)
                mark = "" if share >= MIN_SHARE else " *"
                print(f"| {lighting} | {cls}{mark} | {share:.1%} | {cells} | {row['halves', layer, cls]:.3f} |")
    print("(* under 1 % of the lighting's pixels: listed, not ranked)")
    if any(("path_vs_cycles", "shading", "all") in row for row in results.values()):
        print()
        print(
            "## path-traced reference vs Cycles (bias, per-pixel error, Cycles' seed-to-seed error), on the "
            "pixels whose Cycles footprint sees one face"
        )
        print(
            "| lighting | layer | class | share | one face | bias | its standard error | error | Cycles seeds differ "
            "| error / seeds | all pixels: bias, error / seeds |"
        )
        print("|---|---|---|---|---|---|---|---|---|---|---|")
        for lighting, row in results.items():
            for layer in LAYERS:
                for cls in ["all"] + sorted(row["share"], key=lambda c: -row["share"][c]):
                    b, e, n, se = row["path_vs_cycles", layer, cls]
                    b_all, e_all, n_all, _ = row["path_vs_cycles_all", layer, cls]
                    share = 1.0 if cls == "all" else row["share"][cls]
                    print(
                        f"| {lighting} | {layer} | {cls} | {share:.1%} | {row['one_face', cls]:.1%} | {b:+.2%} "
                        f"| {se:.2%} | {e:.3f} | {n:.3f} | {e / max(n, 1e-12):.2f} "
                        f"| {b_all:+.2%}, {e_all / max(n_all, 1e-12):.2f} |"
                    )
        bias_worst, noise_worst = cycles_headline(results)
        print(
            f"path-traced reference vs Cycles, classes with at least {MIN_SHARE:.0%} of the pixels, on the "
            f"{min(row['one_face', 'all'] for row in results.values()):.1%} of them whose Cycles footprint sees "
            f"one face: worst mean "
            f"bias {bias_worst[0]:+.2%} ({bias_worst[1]}; standard error {bias_worst[2]:.2%}), worst per-pixel "
            f"error {noise_worst[0]:.2f} times Cycles' seed-to-seed ({noise_worst[1]})"
        )
    print()
    first = variants[0]
    print(
        f"latency, full left-camera stack, {views} views each: "
        + ", ".join(f"{v} {rate[v]:.3f} views/s ({rate[v] / rate[first]:.3f} of {first})" for v in variants)
    )
    if job:
        print(
            "render stage (frame threads, left and right views, files written), seconds a frame: "
            + ", ".join(f"{v} {s:.3f}" for v, s in job.items())
            + "; throughput vs "
            + first
            + ": "
            + ", ".join(f"{v} {job[first] / s:.3f}" for v, s in job.items())
        )
    overall, worst, name = headline(results)
    if set_name == "held-out":
        print(f"held-out per-pixel error vs reference: overall {overall:.3f}, worst class {worst:.3f} ({name})")
    else:
        print(f"{set_name} per-pixel error vs reference: overall {overall:.3f}, worst class {worst:.3f} ({name})")


def job_throughput(
    root: Path, base: list[str], lightings: list[str], frames: int, variants: dict, lighting_overrides: list[list[str]]
) -> dict:
    """{variant: seconds a frame} of the render stage itself (``render_frames``) on a ``frames``-frame
    trajectory of the garden of ``base``, the variants in turn (reversed on every other lighting)."""
    from eden_pipe.config import make_cfg, to_config
    from eden_pipe.pipeline import run_stages
    from eden_pipe.stages.cache import StageCache
    from eden_pipe.stages.render import render_frames

    base = [o for o in base if not o.startswith("camera.trajectory.frames")] + [
        f"camera.trajectory.frames=[{frames},{frames}]"
    ]
    seconds: dict[str, float] = dict.fromkeys(variants, 0.0)
    for i, extra in enumerate(lighting_overrides):
        names = list(variants) if i % 2 == 0 else list(variants)[::-1]
        for name in names:
            cfg = to_config(make_cfg(root, base + extra + variants[name]))
            staged = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="sky_visibility")
            vis = staged.get("sky_visibility") if cfg.render.sky_visibility.enabled else None
            with tempfile.TemporaryDirectory(dir=root) as folder:
                facts = render_frames(Path(folder), cfg, staged["scene"], staged["trajectory"], False, vis)
            seconds[name] += facts["seconds_per_frame"] / len(lightings)
    return seconds
