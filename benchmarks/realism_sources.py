"""Where the default's per-pixel error comes from: the bake's visible sky against each point's own,
and the sun's direct and bounced light against traced ones (docs/realism.md, Where the plants'
error comes from).

At the realism protocol's pixels (``benchmarks/realism.py``: the same sets, gardens, frames, cameras
and pixel sample, and its cached path-traced reference), for one lighting:

- the default's shading, and the bake's cosine-weighted visible sky at each pixel (its probe's
  visible fraction times its face side's exposure, as the render reads them);
- each pixel's own visible sky, traced with ``--rays`` stratified cosine rays from its hit point
  (the robust offset), and its face's mean, over ``--face-points`` random points of the face;
- the same at the face's three corners (just inside it), blended by the pixel's barycentric
  coordinates: what a bake per vertex would give at best;
- the default's shading with its sky term rescaled by each of those over the bake's, nothing else
  changed: what the error would be with an exact visible sky per pixel, per face or per vertex;
- a screen-space estimate from the view's own depth (horizon-based, 8 directions, radii 4 mm to
  26 cm) and its correlation with the ratio of the pixel's own sky to the bake's: whether the image
  holds what hides a point's sky;
- how many pixels within ``render.pixel_sky_radius`` of each see its face (itself included): what
  ``render.pixel_sky_rays`` pools a pixel's rays over (docs/realism.md, Each pixel's own sky).

Under a lighting with a sun, also the sun's part of the shading:

- the default's direct sun at each pixel (its shadow rays) and a converged one (64 samples of the
  sun's disc, the reference's own shadow test);
- the bake's bounce of the sun (its probe's row times the pixel's cloud transmittance) and the
  one-bounce sun traced from the pixel (64 stratified cosine rays; at each surface they meet, the
  sun's light on the side they meet, or through it times its translucency, with a shadow ray,
  times its albedo): the bake's also holds the later bounces (its multi-bounce factor), so it may
  exceed the traced one by those, not by more.

And the shading split in two, the light's first bounce and the rest, each over the reference's
shading: the default's sky term (its probe's sky, open sky and exposure) against the reference's
paths cut at their first vertex (``reference_bounces=0``: the sky where they escape; under a sun
less its converged direct sun above), and the default's bounce of sky light against the
reference's later bounces (the whole reference less that cut one; under a sun also less the
traced one-bounce sun above, so it holds the sun's second and later bounces, and the split is
exact without a sun). The cut reference is cached beside the full one.

And the sky each pixel sees directly from its own visibility moments: its escaping rays' (the
pixel's own sky above) cosine-weighted means of the polynomials of order 0 to 2 in the direction,
times the least-squares fit of the sky's radiance over the upper hemisphere by the same
polynomials: against the reference's first bounce, what a renderer that knew each point's
visibility to that order (and not only its visible fraction) would give for the sky term.

Per semantic class: per-pixel error relative to the reference mean (and bias) of the shadings,
the bake's visible sky against the pixel's (relative mean absolute difference), the correlation and
the median count of same-face pixels; with a sun, each sun term over the reference's shading there.

    python benchmarks/realism_sources.py [--set held-out|tuning] [--gardens 101] [--lighting overcast] [overrides ...]
"""

from __future__ import annotations

import argparse
import sys
from argparse import Namespace
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from benchmarks.realism import (  # noqa: E402
    PROTOCOLS,
    cached,
    lighting_overrides,
    path_reference,
    pixel_sample,
    reference_file,
    reference_key,
    reference_tag,
    render_left,
)
from eden_pipe import labels  # noqa: E402
from eden_pipe.camera.rig import Intrinsics  # noqa: E402
from eden_pipe.config import make_cfg, to_config  # noqa: E402
from eden_pipe.pipeline import run_stages  # noqa: E402
from eden_pipe.render import baked_light, shading  # noqa: E402
from eden_pipe.render.backends.raytrace import cloud_map_regions, frame_settings  # noqa: E402
from eden_pipe.render.embree import RayTracer  # noqa: E402
from eden_pipe.render.offsets import leave  # noqa: E402
from eden_pipe.render.pathtrace import (  # noqa: E402
    cosine_directions,
    intersect_leaving,
    stratified_uniforms,
    sun_visible_leaving,
)
from eden_pipe.render.view import primary_rays  # noqa: E402
from eden_pipe.render.visibility.shadow_maps import hemisphere_directions, sky_basis  # noqa: E402
from eden_pipe.rng import rng_for  # noqa: E402
from eden_pipe.stages.cache import StageCache  # noqa: E402
from eden_pipe.stages.render import make_sky  # noqa: E402
from eden_pipe.stages.scene import load_scene  # noqa: E402
from eden_pipe.stages.sky_visibility import load_sky_visibility  # noqa: E402
from eden_pipe.stages.trajectory import load_poses  # noqa: E402

SCREEN_RADII_M = (0.004, 0.008, 0.016, 0.032, 0.064, 0.128, 0.256)
MOMENT_ORDERS = {0: 1, 1: 4, 2: 9}  # order -> the columns of sky_basis up to it
SCREEN_DIRECTIONS = 8


class Captured:
    """The render's ``BakedIndirect`` of the last view, kept to read its lookups at the pixels, and
    its exposures as the bake gave them (before ``render.pixel_sky_rays`` scales them)."""

    def __init__(self):
        self.last = None
        self.bake_exposure = None
        original = baked_light.BakedIndirect.__init__

        def init(indirect, *args, **kwargs):
            original(indirect, *args, **kwargs)
            self.last, self.bake_exposure = indirect, indirect.exposure.copy()

        baked_light.BakedIndirect.__init__ = init


def load_garden(root: Path, overrides: list[str]):
    """(config, scene arrays, bake, poses, intrinsics) of the garden ``overrides`` name, its stages
    through the bake built or reused from the cache under ``root``."""
    cfg = to_config(make_cfg(root, overrides))
    arts = run_stages(cfg, StageCache(cfg.paths.stages, set()), through="sky_visibility")
    _, arrays = load_scene(arts["scene"])
    vis = load_sky_visibility(arts["sky_visibility"])
    return cfg, arrays, vis, load_poses(arts["trajectory"]), Intrinsics.from_config(cfg.camera)


def visible_moments(tracer, points, normals, prim, rays, rng, columns: int = 9) -> np.ndarray:
    """(N, columns) the cosine-weighted means over ``rays`` stratified rays from ``points`` of the
    first ``columns`` of the render's ``sky_basis`` (the constant, x, y, z, then order 2) where
    they escape: column 0 is the share that escapes."""
    moments = np.zeros((len(points), columns))
    origins = leave(points, normals, np.zeros(len(points), np.float32))
    for j in range(rays):
        u1, u2 = (u[0] for u in stratified_uniforms(len(points), j, 1, rays, rng))
        directions = cosine_directions(normals, u1, u2)
        escaped = ~intersect_leaving(tracer, origins, directions, prim).hit
        moments += escaped[:, None] * (sky_basis(directions)[:, :columns] if columns > 1 else 1.0)
    return moments / rays


def visible_sky(tracer, points, normals, prim, rays, rng) -> np.ndarray:
    """(N,) the cosine-weighted share of ``rays`` stratified rays from ``points`` that escape."""
    return visible_moments(tracer, points, normals, prim, rays, rng, columns=1)[:, 0]


def sky_fits(settings, sky, directions: int = 65536) -> dict[int, np.ndarray]:
    """Each order of ``MOMENT_ORDERS`` -> (columns, 3): the least-squares fit of the sky's radiance
    (``settings.sky_radiance``, read once) over the upper hemisphere by the first columns of the
    render's ``sky_basis`` (as its ``hemisphere_fit``, on a finer lattice): a point's sky light is
    then its :func:`visible_moments`' first columns times it."""
    d = hemisphere_directions(directions)
    radiance = np.asarray(settings.sky_radiance(sky, d), np.float64)
    basis = sky_basis(d)
    return {k: np.linalg.lstsq(basis[:, :n], radiance, rcond=None)[0] for k, n in MOMENT_ORDERS.items()}


def sky_term(b, at: np.ndarray) -> np.ndarray:
    """(N, 3) the render's sky term at its hits ``at``: the probe's sky, open sky and exposure, or
    where the face table's moments give it (``BakedIndirect.sides_sky``), the side's visible
    fraction times the mean radiance of the sky it sees."""
    probe_visible, exposure = b.rows.visible[at], b.exposure[at]
    term = (b.rows.sky[at] + probe_visible[:, None] * b.ambient(b.s.n_shade[at])) * exposure[:, None]
    if b.seen_sky is not None:
        light = b.sides_sky(np.array(b.bounce)) - b.bounce  # the sides' sky alone, zero elsewhere
        side = b.side_exposure[at]
        by_sides = (side >= 0) & np.isfinite(side)
        term[by_sides] = light[at][by_sides]
    return term


def face_sky(tracer, mesh, prim, normals, points_per_face, rays, rng) -> np.ndarray:
    """(N,) the mean visible sky of faces ``prim`` over ``points_per_face`` uniform points of each."""
    tri = mesh.vertices[mesh.faces[prim]].astype(np.float64)
    total = np.zeros(len(prim))
    for _ in range(points_per_face):
        a, b = rng.random(len(prim)), rng.random(len(prim))
        fold = a + b > 1
        a[fold], b[fold] = 1 - a[fold], 1 - b[fold]
        p = tri[:, 0] + a[:, None] * (tri[:, 1] - tri[:, 0]) + b[:, None] * (tri[:, 2] - tri[:, 0])
        total += visible_sky(tracer, p.astype(np.float32), normals, prim, rays, rng)
    return total / points_per_face


def bounced_sun(tracer, mesh, sky, points, normals, prim, rays, rng) -> np.ndarray:
    """(N, 3) irradiance/pi from one bounce of the sun: ``rays`` stratified cosine rays from each
    point; where one meets a surface, the sun on the side it meets (or on the other side times the
    face's translucency), a shadow ray from there, times the face's albedo."""
    to_sun = np.asarray(sky.sun_direction, np.float32)
    sun = np.asarray(sky.sun_irradiance, np.float32)
    origins = leave(points, normals, np.zeros(len(points), np.float32))
    total = np.zeros((len(points), 3))
    for j in range(rays):
        u1, u2 = (u[0] for u in stratified_uniforms(len(points), j, 1, rays, rng))
        d = cosine_directions(normals, u1, u2)
        hits = intersect_leaving(tracer, origins, d, prim)
        met = np.flatnonzero(hits.hit)
        n = hits.normal[met] / np.linalg.norm(hits.normal[met], axis=1, keepdims=True)
        n *= np.where(np.einsum("ij,ij->i", n, d[met]) > 0, -1.0, 1.0)[:, None]  # the side the ray meets
        cos = n @ to_sun
        lit_side = (n * np.sign(cos)[:, None]).astype(np.float32)
        at = (origins[met] + d[met] * hits.t[met, None]).astype(np.float32)
        shadow = intersect_leaving(
            tracer,
            leave(at, lit_side, hits.t[met]),
            np.ascontiguousarray(np.broadcast_to(to_sun, at.shape)),
            hits.prim[met],
        )
        face = hits.prim[met]
        weight = np.where(cos > 0, cos, -cos * mesh.translucency[face]) * ~shadow.hit
        total[met] += mesh.albedo[face] * weight[:, None]
    return total / rays * sun / np.pi


def corner_sky(tracer, mesh, prim, points, normals, rays, rng) -> np.ndarray:
    """(N,) the visible sky at each face's three corners (2 % of the way to its centroid, inside the
    face), blended by the barycentric coordinates of ``points`` in it: what a bake per vertex gives."""
    tri = mesh.vertices[mesh.faces[prim]].astype(np.float64)
    e1, e2, ep = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], points.astype(np.float64) - tri[:, 0]
    d11, d12, d22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d1, d2 = (ep * e1).sum(1), (ep * e2).sum(1)
    det = d11 * d22 - d12 * d12
    v, w = (d22 * d1 - d12 * d2) / det, (d11 * d2 - d12 * d1) / det
    weights = np.stack([1 - v - w, v, w], axis=1)
    centroid = tri.mean(axis=1)
    corners = [
        visible_sky(tracer, (tri[:, i] + 0.02 * (centroid - tri[:, i])).astype(np.float32), normals, prim, rays, rng)
        for i in range(3)
    ]
    return (weights * np.stack(corners, axis=1)).sum(axis=1)


def same_face_pixels(intr: Intrinsics, hits, pick: np.ndarray, radius: int) -> np.ndarray:
    """(N,) how many pixels within ``radius`` (a square window) of each pixel ``pick`` hit its face."""
    face = np.where(hits.hit, hits.prim, -1).reshape(intr.height, intr.width)
    padded = np.pad(face, radius, constant_values=-2)
    y, x = np.divmod(pick, intr.width)
    own = face[y, x]
    count = np.zeros(len(pick), np.int64)
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            count += padded[y + radius + dy, x + radius + dx] == own
    return count


def screen_sky(intr: Intrinsics, origins, directions, hits) -> np.ndarray:
    """(H*W,) a horizon-based estimate of each pixel's visible sky from the view's own hits: per
    image direction the highest elevation over the pixel's tangent plane of the points
    ``SCREEN_RADII_M`` away (projected at its depth), visible share ``1 - sin^2`` of it, averaged."""
    h, w = intr.height, intr.width
    depth = np.where(hits.hit, hits.t, np.inf).reshape(h, w)
    points = (origins + directions * np.where(hits.hit, hits.t, 0)[:, None]).reshape(h, w, 3)
    normals = hits.normal * np.where(np.einsum("ij,ij->i", hits.normal, directions) > 0, -1, 1)[:, None]
    normals = normals.reshape(h, w, 3)
    rows, cols = np.mgrid[0:h, 0:w]
    total = np.zeros((h, w))
    for j in range(SCREEN_DIRECTIONS):
        phi = 2 * np.pi * (j + 0.5) / SCREEN_DIRECTIONS
        highest = np.zeros((h, w))
        for radius in SCREEN_RADII_M:
            step = np.maximum(intr.fx * radius / np.where(np.isfinite(depth), depth, 1e9), 1.0)
            qx = np.clip(np.rint(cols + step * np.cos(phi)).astype(int), 0, w - 1)
            qy = np.clip(np.rint(rows + step * np.sin(phi)).astype(int), 0, h - 1)
            v = points[qy, qx] - points
            dist = np.linalg.norm(v, axis=2)
            near = np.isfinite(depth[qy, qx]) & np.isfinite(depth) & (dist < 2 * radius) & (dist > 1e-5)
            sine = np.einsum("hwk,hwk->hw", normals, v) / np.maximum(dist, 1e-9)
            highest = np.maximum(highest, np.where(near, sine, 0.0))
        total += 1 - highest**2
    return (total / SCREEN_DIRECTIONS).ravel()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--set", default="held-out", choices=tuple(PROTOCOLS))
    ap.add_argument("--gardens", default="", help="garden seeds (default: the set's)")
    ap.add_argument("--lighting", default="overcast")
    ap.add_argument("--pixels", type=int, default=0, help="sampled pixels per view (0: the set's)")
    ap.add_argument("--rays", type=int, default=256, help="rays per pixel for its own visible sky")
    ap.add_argument("--face-points", type=int, default=8, help="points per face for its mean sky (36 rays each)")
    ap.add_argument("--samples", type=int, default=2048, help="the cached reference's paths per pixel")
    ap.add_argument("--bounces", type=int, default=6, help="the cached reference's bounces")
    ap.add_argument("--root", default=str(REPO / "outputs" / "bench_realism"), help="realism.py's stage cache")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, e.g. render.sky_visibility.sun_multi_bounce=true")
    args = ap.parse_args()

    protocol = PROTOCOLS[args.set]
    if args.pixels:
        protocol = replace(protocol, pixels=args.pixels)
    if args.gardens:
        protocol = replace(protocol, seeds=tuple(int(s) for s in args.gardens.split(",")))
    root = Path(args.root)
    captured = Captured()
    columns: dict[str, list[np.ndarray]] = {}
    for seed in protocol.seeds:
        gbase = [
            "progress=false",
            "camera.trajectory.share_across_lightings=true",
            f"garden.seed={seed}",
            *args.overrides,
        ]
        cfg, arrays, vis, poses, intr = load_garden(root, gbase)
        lcfg = to_config(make_cfg(root, gbase + lighting_overrides(args.lighting, root, protocol)))
        sky, _ = make_sky(lcfg.lighting, seed)
        tag = reference_tag("path", arrays.mesh, poses, intr, lcfg.lighting)
        regions = cloud_map_regions(arrays.mesh)
        with RayTracer(arrays.mesh) as tracer:
            for f in protocol.frame_indices(len(poses)):
                settings = frame_settings(lcfg.render, sky, f / float(cfg.camera.trajectory.fps), regions, vis)
                for k in range(poses.shape[1]):
                    pose = poses[f, k, 0]
                    o, d = primary_rays(intr, pose)
                    hits = tracer.intersect(o, d)
                    pick = pixel_sample(seed, f, k, hits.hit, protocol.pixels)
                    screen = screen_sky(intr, o, d, hits)[pick]
                    out = render_left(tracer, arrays, intr, poses, f, k, sky, settings, seed, args.lighting)
                    b = captured.last
                    at = np.searchsorted(b.s.idx, pick)
                    key = reference_key(seed, args.lighting, f, k, protocol.pixels, intr)
                    with np.load(reference_file(root, "path", key, tag, args.samples, args.bounces)) as ref:
                        reference = 0.5 * (ref["path_half1|shading"] + ref["path_half2|shading"])
                    # No bounce: the reference counts bounces as Cycles does, each vertex gathering
                    # the sky its continuation escapes to (pathtrace.radiance_along), so one bounce
                    # would hold the first bounce's sky light too.
                    first = cached(
                        reference_file(root, "path", key, tag, args.samples, 0),
                        partial(
                            path_reference, tracer, arrays.mesh, o[pick], d[pick], sky, settings,
                            Namespace(samples=args.samples, bounces=0), (seed, args.lighting, f, k),
                        ),
                    )  # fmt: skip
                    probe_visible, exposure = b.rows.visible[at], b.exposure[at]
                    prim, normals = b.s.prim[at], b.s.n[at]
                    own_rng = rng_for(seed, "realism", "sources", f, k)
                    row = {
                        "class": arrays.mesh.semantic[prim],
                        "reference": reference,
                        "first_bounce": 0.5 * (first["path_half1/shading"] + first["path_half2/shading"]),
                        "bounce_sky": b.vis.bounce_light(b.rows, None)[at],
                        "default": out["shading"].reshape(-1, 3)[pick],
                        "sky_term": sky_term(b, at),
                        "bake": np.clip(probe_visible * exposure, 0, 1),
                        "moments": visible_moments(tracer, b.s.points[at], normals, prim, args.rays, own_rng),
                        "face": face_sky(tracer, arrays.mesh, prim, normals, args.face_points, 36, own_rng),
                        "corners": corner_sky(tracer, arrays.mesh, prim, b.s.points[at], normals, args.rays, own_rng),
                        "screen": screen,
                        "same_face": same_face_pixels(intr, hits, pick, int(cfg.render.pixel_sky_radius)),
                    }
                    row["pixel"] = row["moments"][:, 0]
                    for k, fit in sky_fits(settings, sky).items():
                        row[f"order{k}"] = row["moments"][:, : len(fit)] @ fit
                    if np.any(np.asarray(sky.sun_irradiance) > 0):
                        points, shading_n = b.s.points[at], b.s.n_shade[at]
                        cloud = np.ones(len(at), np.float32) if b.cloud is None else b.cloud[at]
                        front, _ = shading.direct_sun(
                            tracer,
                            points,
                            shading_n,
                            sky,
                            settings,
                            own_rng,
                            geometric=normals,
                            back_lit=b.s.trans[at] > 0,
                            cloud=cloud,
                        )
                        converged, _ = shading.direct_sun(
                            tracer,
                            points,
                            shading_n,
                            sky,
                            replace(settings, soft_shadow_samples=64),
                            own_rng,
                            geometric=normals,
                            back_lit=b.s.trans[at] > 0,
                            cloud=cloud,
                            visible=sun_visible_leaving(tracer, points, normals, prim, hits.t[pick]),
                        )
                        row |= {
                            "sun": front,
                            "sun_converged": converged,
                            "sun_bounce": b.rows.bounce_sun[at] * cloud[:, None],
                            "sun_bounce_traced": bounced_sun(
                                tracer, arrays.mesh, sky, points, normals, prim, 64, own_rng
                            )
                            * cloud[:, None],
                        }
                    for name, values in row.items():
                        columns.setdefault(name, []).append(values)
                    print(f"garden {seed} frame {f} camera {k}", flush=True)
    report({name: np.concatenate(parts) for name, parts in columns.items()}, args)


def report(c: dict[str, np.ndarray], args) -> None:
    def error(shading: np.ndarray, m: np.ndarray) -> str:
        ref = c["reference"][m]
        return f"{np.abs(shading[m] - ref).sum() / np.abs(ref).sum():.3f} ({shading[m].sum() / ref.sum() - 1:+.1%})"

    def rescaled(sky: np.ndarray) -> np.ndarray:
        ratio = np.where(c["bake"] > 1e-4, sky / np.maximum(c["bake"], 1e-4), 1.0)
        return c["default"] + c["sky_term"] * (ratio[:, None] - 1)

    own, per_face, per_corner = rescaled(c["pixel"]), rescaled(c["face"]), rescaled(c["corners"])
    print(f"\n{args.set} {args.lighting}, shading: per-pixel error relative to the reference mean (bias)")
    print(
        "| class | pixels | default | the face's own sky | its corners' sky, blended | the pixel's own sky "
        "| bake vs pixel sky | corr(screen, pixel/bake) | same-face pixels in the window |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for cls in np.unique(c["class"]):
        m = c["class"] == cls
        if m.sum() < 30:
            continue
        pixel, bake = c["pixel"][m], c["bake"][m]
        gap = np.abs(bake - pixel).mean() / max(pixel.mean(), 1e-9)
        corr = np.corrcoef(c["screen"][m], pixel / np.maximum(bake, 1e-3))[0, 1]
        print(
            f"| {labels.NAMES[cls]} | {int(m.sum())} | {error(c['default'], m)} | {error(per_face, m)} | "
            f"{error(per_corner, m)} | "
            f"{error(own, m)} | {gap:.3f} | {corr:+.2f} | {np.median(c['same_face'][m]):.0f} |"
        )
    print(f"\n{args.set} {args.lighting}, the first bounce and the rest, each over the reference's shading there")
    print(
        "| class | pixels | bias | sky term | reference's first bounce | bounce of sky light "
        "| reference's later bounces |"
    )
    print("|---|---|---|---|---|---|---|")
    first = c["first_bounce"] - (c["sun_converged"] if "sun" in c else 0.0)  # the sky where paths escape
    later = c["reference"] - c["first_bounce"] - (c["sun_bounce_traced"] if "sun" in c else 0.0)
    for cls in np.unique(c["class"]):
        m = c["class"] == cls
        if m.sum() < 30:
            continue
        ref = c["reference"][m].sum()
        terms = [c["sky_term"][m].sum(), first[m].sum(), c["bounce_sky"][m].sum(), later[m].sum()]
        print(
            f"| {labels.NAMES[cls]} | {int(m.sum())} | {c['default'][m].sum() / ref - 1:+.1%} | "
            + " | ".join(f"{t / ref:.3f}" for t in terms)
            + " |"
        )
    print(
        f"\n{args.set} {args.lighting}, the sky seen directly from each pixel's own visibility moments (its escaping "
        "rays' means of the polynomials of order 0-2) times the sky's fit of the same order, each over the "
        "reference's shading there; then the per-pixel error against the reference's first bounce"
    )
    orders = [f"order {k}" for k in MOMENT_ORDERS]
    head = orders + ["error, sky term"] + [f"error, {o}" for o in orders]
    print("| class | pixels | reference's first bounce | sky term | " + " | ".join(head) + " |")
    print("|---|---|---|---|" + "---|" * (2 * len(orders) + 1))
    for cls in np.unique(c["class"]):
        m = c["class"] == cls
        if m.sum() < 30:
            continue
        ref, truth = c["reference"][m].sum(), first[m]
        estimates = [c["sky_term"][m]] + [c[f"order{k}"][m] for k in MOMENT_ORDERS]
        means = " | ".join(f"{e.sum() / ref:.3f}" for e in estimates)
        errors = " | ".join(f"{np.abs(e - truth).sum() / np.abs(truth).sum():.3f}" for e in estimates)
        print(f"| {labels.NAMES[cls]} | {int(m.sum())} | {truth.sum() / ref:.3f} | {means} | {errors} |")
    if "sun" not in c:
        return
    print(f"\n{args.set} {args.lighting}, the sun's part of the shading, each over the reference's shading there")
    print(
        "| class | pixels | bias | direct sun | converged | bounce of the sun | traced, one bounce "
        "| error, converged sun | error, converged sun and own sky |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    soft = c["default"] + c["sun_converged"] - c["sun"]  # the direct sun's disc sampled, nothing else
    soft_own = own + c["sun_converged"] - c["sun"]
    for cls in np.unique(c["class"]):
        m = c["class"] == cls
        if m.sum() < 30:
            continue
        ref = c["reference"][m].sum()
        terms = " | ".join(
            f"{c[k][m].sum() / ref:.3f}" for k in ("sun", "sun_converged", "sun_bounce", "sun_bounce_traced")
        )
        print(
            f"| {labels.NAMES[cls]} | {int(m.sum())} | {c['default'][m].sum() / ref - 1:+.1%} | {terms} | "
            f"{error(soft, m)} | {error(soft_own, m)} |"
        )


if __name__ == "__main__":
    main()
