"""Each point's own sky from the bake's bundles kept as depth maps (``render.sky_visibility.shadow_maps``,
:mod:`eden_pipe.render.visibility.shadow_maps`).

The store against its layout (every texel written and read back where its tile puts it), the
estimate against the exact sky of a floor beside a black roof (a view factor in closed form), the
bake's other tables untouched by keeping the maps, the file round trip, and the whole render: with
the maps, the floor's shading follows the exact sky inside the probe cells, where the bake holds a
cell's mean, and a stereo pair's right camera takes the left's factors where it sees the same face.
"""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.render.embree import RayTracer
from eden_pipe.render.pixel_sky import map_phase
from eden_pipe.render.shading import shade
from eden_pipe.render.view import PIXEL_SKY, render_view
from eden_pipe.render.visibility import shadow_maps
from eden_pipe.render.visibility.face_sky import SIDE_COLUMNS, face_sky_exposure
from eden_pipe.render.visibility.shadow_maps import BLOCK, LAST_STEP, MISS, MOMENTS, ShadowMaps, strata, subset_of
from eden_pipe.render.visibility.store import SkyVisibility
from tests.sky_scenes import ROOF_HALF, ROOF_HEIGHT, UniformSky, parallel_rectangle_factor, uniform_settings
from tests.test_pixel_sky import ROOF_EDGE_SIDE, roof_edge_bake, roof_edge_mesh, roof_edge_pair, roof_edge_view


def test_store_writes_every_texel_where_its_tile_puts_it():
    """Rows stored in pieces, distances (misses included) read back from the tiled layout: each
    texel holds its distance in depth steps, rounded, or ``MISS``; maps whose sides are not whole
    tiles keep their padding untouched."""
    rng = np.random.default_rng(2)
    grids = [(0.1, -0.2, 13, 10), (0.0, 0.0, 9, 17)]
    maps = ShadowMaps.allocate(np.zeros(3), 5.0, 0.01, [np.eye(3).ravel()] * 2, grids)
    step = maps.params[5]
    assert step == pytest.approx(10.0 / LAST_STEP)
    written = np.zeros(len(maps.depth), bool)
    for k, (_, _, across, down) in enumerate(grids):
        t = rng.uniform(0.0, 10.0, (down, across)).astype(np.float32)
        t[rng.random((down, across)) < 0.2] = np.inf
        for first_row in range(0, down, 4):  # a wave of up to four rows at a time
            maps.store(k, first_row, t[first_row : first_row + 4].ravel())
        tiles_across = -(-across // BLOCK)
        for v in range(down):
            for u in range(across):
                tile = (v // BLOCK) * tiles_across + u // BLOCK
                at = maps.start[k] + tile * BLOCK * BLOCK + (v % BLOCK) * BLOCK + u % BLOCK
                want = MISS if np.isinf(t[v, u]) else min(int(t[v, u] / step + 0.5), LAST_STEP)
                assert maps.depth[at] == want
                written[at] = True
    assert np.all(maps.depth[~written] == MISS)  # the tiles' padding
    assert maps.start[-1] == sum(-(-a // BLOCK) * -(-d // BLOCK) * BLOCK * BLOCK for _, _, a, d in grids)


def test_subsets_share_every_elevation_and_pixel_blocks_hold_every_subset():
    """``subset_of``: equal shares, each with directions in every row of the strata; ``map_phase``:
    every 2 x 2 block of pixels reads all four subsets (every 4 x 2 block all eight)."""
    rows, cols = strata(128)
    assert (rows, cols) == (8, 16)
    for subsets in (1, 2, 4, 8):
        s = subset_of(128, subsets)
        assert np.array_equal(np.bincount(s, minlength=subsets), np.full(subsets, 128 // subsets))
        for k in range(subsets):
            assert set(np.flatnonzero(s == k) // cols) == set(range(rows))
    width = 10
    pixels = np.arange(60, dtype=np.int64)
    phase = map_phase(pixels, width, 4).reshape(6, width)
    for y in range(0, 6, 2):
        for x in range(0, width, 2):
            assert set(phase[y : y + 2, x : x + 2].ravel()) == {0, 1, 2, 3}
    phase8 = map_phase(pixels, width, 8).reshape(6, width)
    assert set(phase8[0:2, 0:4].ravel()) == set(range(8))
    assert np.all(map_phase(pixels, width, 1) == 0)


@pytest.fixture(scope="module")
def roof_bakes():
    """The roof-edge scene baked with and without its depth maps (the same generator seed)."""
    mesh = roof_edge_mesh()
    with RayTracer(mesh, 1) as tracer:
        plain = roof_edge_bake(mesh, tracer)
    with RayTracer(mesh, 1) as tracer:
        mapped = roof_edge_bake(mesh, tracer, shadow_maps=True)
    return mesh, plain, mapped


def test_keeping_the_maps_changes_no_other_table(roof_bakes, tmp_path):
    """The maps are the bundles' own rays: every other table of the bake is bit-identical with or
    without them; the file holds them exactly and a bake without them loads with none."""
    _, plain, mapped = roof_bakes
    assert mapped.shadow_maps.present and not plain.shadow_maps.present
    for name in SkyVisibility.FIELDS + SkyVisibility.EXACT:
        assert np.array_equal(getattr(plain, name), getattr(mapped, name)), name
    assert mapped.shadow_maps.depth.dtype == np.uint16 and np.any(mapped.shadow_maps.depth != MISS)
    mapped.save(tmp_path / "mapped.npz")
    plain.save(tmp_path / "plain.npz")
    back = SkyVisibility.load(tmp_path / "mapped.npz").shadow_maps
    for name in ShadowMaps.FIELDS:
        assert np.array_equal(getattr(back, name), getattr(mapped.shadow_maps, name)), name
    assert not SkyVisibility.load(tmp_path / "plain.npz").shadow_maps.present
    with np.load(tmp_path / "plain.npz") as data:
        assert not any(key.startswith("shadow_map") for key in data.files)


def floor_points():
    """(points, up normals, exact visible sky, x) of floor points across the roof's edge."""
    x, y = np.meshgrid(np.linspace(0.25, 0.75, 41), np.linspace(-0.25, 0.25, 21))
    points = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)
    up = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    exact = 1.0 - parallel_rectangle_factor(
        (x.ravel(), y.ravel()), -ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT
    )
    return points, up, exact, x.ravel()


def test_maps_give_a_floor_point_the_sky_the_roof_leaves_it(roof_bakes, monkeypatch):
    """Floor points across the roof's edge (the sky changes within every 10 cm probe cell). A
    point's nearest texel lies within half a diagonal of a spacing beside it, so with a slope of
    that much its own plane never hides it: the maps' cosine-weighted visible fraction is then
    within 0.03 of the exact one (1 - the roof's view factor) on average and never off by more
    than 0.12 (64 directions); far from the roof, 1. With the slope chosen on the gardens' leaves
    (a leaf lies millimetres over the next) a plane is darkened at grazing directions, by under 8 %."""
    _, _, mapped = roof_bakes
    default = mapped.shadow_maps.visible_fraction(*floor_points()[:2])
    monkeypatch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
    points, up, exact, x = floor_points()
    got = mapped.shadow_maps.visible_fraction(points, up)
    assert np.abs(got - exact).mean() < 0.03, np.abs(got - exact).mean()
    assert np.abs(got - exact).max() < 0.12
    assert got[x < 0.4].mean() < 0.75 < got[x > 0.6].mean()  # under the roof, beside it
    assert -0.08 < default.mean() / exact.mean() - 1 < 0.0
    far = np.array([[1.8, 1.8, 0.0], [-1.8, 1.7, 0.0]])
    assert np.all(mapped.shadow_maps.visible_fraction(far, up[:2]) > 0.97)
    # Four subsets, each point reading its own: every point's four estimates average to the full one.
    phases = [mapped.shadow_maps.visible_fraction(points, up, np.full(len(points), k), 4) for k in range(4)]
    assert np.allclose(np.mean(phases, axis=0), got, atol=1e-5)


def test_a_points_sky_does_not_depend_on_the_points_read_beside_it(roof_bakes):
    """The kernel takes the points in blocks (``OPEN_SKY_BLOCK`` rows, every direction of a block's
    subset before the next block): over three blocks of points at random heights, with random
    normals (some directions behind them) and phases, each point's estimate is, bit for bit, the one
    it gets read alone, with every direction and with its own subset."""
    _, _, mapped = roof_bakes
    maps = mapped.shadow_maps
    rng = np.random.default_rng(7)
    n = 3 * shadow_maps.OPEN_SKY_BLOCK + 17
    points = np.column_stack([rng.uniform(-0.9, 0.9, (n, 2)), rng.uniform(0.0, 0.4, n)]).astype(np.float32)
    normals = rng.normal(size=(n, 3))
    normals[:, 2] += 0.5
    normals = (normals / np.linalg.norm(normals, axis=1, keepdims=True)).astype(np.float32)
    phase = rng.integers(0, 4, n).astype(np.int32)
    every = maps.visible_fraction(points, normals)
    own = maps.visible_fraction(points, normals, phase, 4)
    assert 0.05 < every.mean() < 0.95 and np.any(normals[:, 2] < 0.0)
    for i in rng.choice(n, 300, replace=False):
        alone = maps.visible_fraction(points[i : i + 1], normals[i : i + 1])
        assert alone.view(np.uint32)[0] == every.view(np.uint32)[i]
        alone = maps.visible_fraction(points[i : i + 1], normals[i : i + 1], phase[i : i + 1], 4)
        assert alone.view(np.uint32)[0] == own.view(np.uint32)[i]


def floor_shading(mesh, bakes: dict, seeds: dict | None = None):
    """(the floor's shading under a unit sky across the roof's edge, from a camera under the roof, for
    each named bake in ``bakes`` (with its generator seed in ``seeds``, default 0); the exact sky
    there, 1 - the roof's view factor)."""
    side = ROOF_EDGE_SIDE
    o, d, targets = roof_edge_view()
    exact = 1.0 - parallel_rectangle_factor(
        (targets[:, 0], targets[:, 1]), -ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT
    )
    shaded = {}
    with RayTracer(mesh, 1) as tracer:
        hits = tracer.intersect(o, d)
        for name, vis in bakes.items():
            out = shade(
                tracer, mesh, hits, o, d, UniformSky(), uniform_settings(sky_visibility=vis),
                np.random.default_rng((seeds or {}).get(name, 0)), layers=("shading",), image_width=side,
            )  # fmt: skip
            shaded[name] = out["shading"][:, 1]
    return shaded, exact


def test_render_follows_the_exact_sky_with_the_maps(roof_bakes, monkeypatch):
    """The floor's shading under a unit sky across the roof's edge, from a camera under the roof,
    with the slope that keeps a plane from hiding itself (above): with the maps (no rays; every one of
    their 64 directions a pixel, pooled within a pixel over its face) its mean error against the exact sky is
    under 0.75 of the bake's and 0.03, without bias beyond 2 %, and the same on every render."""
    mesh, plain, mapped = roof_bakes
    monkeypatch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
    shaded, exact = floor_shading(mesh, {"bake": plain, "maps": mapped, "again": mapped}, {"again": 1})
    bake_error = np.abs(shaded["bake"] - exact).mean()
    map_error = np.abs(shaded["maps"] - exact).mean()
    assert bake_error > 0.03, bake_error
    assert map_error < min(0.75 * bake_error, 0.03), (map_error, bake_error)
    assert abs(shaded["maps"].mean() / exact.mean() - 1) < 0.02
    assert np.array_equal(shaded["maps"], shaded["again"])  # no random draw: the maps are the bake's


def test_right_camera_takes_the_left_factors_from_the_maps(roof_bakes, monkeypatch):
    """A stereo pair over the roof's edge with the maps: the right view takes the left's factor,
    exactly, where its point projects to a left pixel of the same face side, reads the maps only
    for the other pixels, and its shading stays within 0.03 of the exact sky, like a right view
    that reads the maps for every pixel."""
    mesh, _, mapped = roof_bakes
    monkeypatch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
    scene, intr, poses = roof_edge_pair(mesh)
    read: list[int] = []  # the points each call reads the maps for
    estimate = ShadowMaps.visible_fraction

    def counted(maps, points, *args, **kwargs):
        read.append(len(points))
        return estimate(maps, points, *args, **kwargs)

    monkeypatch.setattr(ShadowMaps, "visible_fraction", counted)
    with RayTracer(mesh, 1) as tracer:

        def view(pose, partner=None):
            settings = uniform_settings(sky_visibility=mapped)
            want = {"rgb", "shading", "depth"}
            rng = np.random.default_rng(0)
            return render_view(
                tracer, scene, intr, pose, UniformSky(), want=want, settings=settings, rng=rng, partner=partner
            )

        left = view(poses[0])
        alone = view(poses[1])
        paired = view(poses[1], partner=left)
    share, right = left[PIXEL_SKY], paired[PIXEL_SKY]
    estimated = np.flatnonzero(right.side >= 0)
    assert read[0] == read[1] == len(estimated) == intr.width * intr.height
    u, v = estimated % intr.width, estimated // intr.width
    z = paired["depth"].ravel()[estimated].astype(np.float64)
    points = np.stack([(u - intr.cx) / intr.fx * z, (v - intr.cy) / intr.fy * z, z], axis=1)
    points = points @ poses[1][:3, :3].T + poses[1][:3, 3]
    expected = share.lookup(points, right.side[estimated])
    taken = np.isfinite(expected)
    assert taken.mean() > 0.8, taken.mean()
    assert np.array_equal(right.factor[estimated][taken], expected[taken])
    assert read[2] == int(np.count_nonzero(~taken))
    exact = 1.0 - parallel_rectangle_factor(
        (points[:, 0], points[:, 1]), -ROOF_HALF, ROOF_HALF, -ROOF_HALF, ROOF_HALF, ROOF_HEIGHT
    )
    for out in (paired, alone):
        assert np.abs(out["shading"][..., 1].ravel()[estimated] - exact).mean() < 0.03


def run_beside_the_tiny_job(tmp_path_factory, tmp_path, overrides: list[str]):
    """The shared tiny job's garden rendered again with ``overrides``: every ground-truth file must
    hold the tiny job's content (an image's decoded array: ISA-L's deflate from the writer threads
    may give another stream of the same rows, docs/design.md, File formats), at least half the
    shading layers differ and the dataset validates. Returns the new dataset's folder."""
    import pandas as pd

    from eden_pipe.pipeline import run_job
    from eden_pipe.tools.validate import check_dataset
    from scripts.dataset_fingerprint import content_digest
    from tests.conftest import TINY, make_cfg
    from tests.tiny_dataset import ALL_MODALITIES, tiny_root

    root = tiny_root(tmp_path_factory)
    out = tmp_path / "again"
    cfg = make_cfg(root, [*TINY, ALL_MODALITIES, *overrides, f"paths.dataset={out}"])
    run_job(cfg, echo=lambda *_: None)
    rows = pd.read_csv(out / "manifest.csv", keep_default_na=False)
    assert len(rows) == 20
    truth = ("semantic", "instance", "depth", "depth_right", "normal", "flow_fwd", "flow_bwd", "occ_fwd", "occ_bwd")
    compared = 0
    for column in truth:
        for rel in rows[column]:
            if rel:
                assert content_digest(out / rel) == content_digest(root / "dataset" / rel), rel
                compared += 1
    assert compared > 100
    changed = [rel for rel in rows["shading"] if (out / rel).read_bytes() != (root / "dataset" / rel).read_bytes()]
    assert len(changed) >= len(rows) // 2
    assert check_dataset(out, progress=False).ok
    return out


def test_the_accurate_preset_changes_the_light_alone(tmp_path_factory, tmp_path):
    """``render=raytrace_accurate`` (the depth maps and traced glossy mirrors) on the shared tiny
    job's garden: every ground-truth file is the default render's byte for byte, the light layers
    differ, the dataset validates and its published config names both options."""
    from omegaconf import OmegaConf

    out = run_beside_the_tiny_job(tmp_path_factory, tmp_path, ["render=raytrace_accurate"])
    published = OmegaConf.load(next(out.glob("*/*/config.yaml")))
    assert published.render.glossy_mirror == "traced" and published.render.sky_visibility.shadow_maps is True
    # the maps give each pixel its own fraction, the face table its side's sky directions
    assert published.render.sky_visibility.face_sky_moments is True


def test_the_face_table_changes_the_light_alone(tmp_path_factory, tmp_path):
    """The default reads each face side's sky from the bake's table; without it (``face_sky=false``,
    the bake alone) every ground-truth file is the same byte for byte and only the light differs."""
    from omegaconf import OmegaConf

    out = run_beside_the_tiny_job(tmp_path_factory, tmp_path, ["render.sky_visibility.face_sky=false"])
    assert OmegaConf.load(next(out.glob("*/*/config.yaml"))).render.sky_visibility.face_sky is False


@pytest.fixture(scope="module")
def roof_face_sky():
    """The roof-edge scene baked with each face side's sky at three points (the maps not kept), with
    the maps' default slope and with the one that keeps a plane from hiding itself (above)."""
    mesh = roof_edge_mesh()
    with RayTracer(mesh, 1) as tracer:
        default = roof_edge_bake(mesh, tracer, face_sky=True)
    with pytest.MonkeyPatch.context() as patch, RayTracer(mesh, 1) as tracer:
        patch.setattr(shadow_maps, "SLOPE", np.sqrt(0.5))
        return default, roof_edge_bake(mesh, tracer, face_sky=True)


def test_the_face_table_reads_the_maps_at_three_points_of_each_side(roof_bakes, roof_face_sky, tmp_path):
    """Each face side's three values are the maps' visible fraction at V_k / 2 + (V_0 + V_1 + V_2) / 6
    with the side's normal (the winding's for side 0), in steps of 1/65535. The bundles are the same
    rays: every other table is bit-identical, the maps are dropped once read, and the table survives
    the file exactly; a bake without it writes no entry."""
    mesh, plain, mapped = roof_bakes
    roof_face_sky = roof_face_sky[0]
    table = roof_face_sky.face_sky
    assert table.shape == (mesh.n_faces, 2, 3) and table.dtype == np.uint16
    assert not roof_face_sky.shadow_maps.present
    for name in SkyVisibility.FIELDS + SkyVisibility.EXACT:
        assert np.array_equal(getattr(plain, name), getattr(roof_face_sky, name)), name
    faces = np.random.default_rng(3).choice(mesh.n_faces, 200, replace=False)
    corners = mesh.vertices[mesh.faces[faces]].astype(np.float64)  # (200, 3, 3)
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    for k in range(3):
        points = (corners[:, k] / 2 + corners.sum(axis=1) / 6).astype(np.float32)
        for side, sign in ((0, 1.0), (1, -1.0)):
            seen = mapped.shadow_maps.visible_fraction(points, (sign * normal).astype(np.float32))
            assert np.array_equal(table[faces, side, k], np.rint(seen * 65535).astype(np.uint16)), (k, side)
    up = table[: 160 * 160 * 2, 0]  # the floor's faces: up, under the roof or beside it
    assert 0.2 < up.min() / 65535 < 0.8 < up.max() / 65535 and table[: 160 * 160 * 2, 1].max() == 0
    roof_face_sky.save(tmp_path / "face.npz")
    assert np.array_equal(SkyVisibility.load(tmp_path / "face.npz").face_sky, table)
    plain.save(tmp_path / "plain.npz")
    assert len(SkyVisibility.load(tmp_path / "plain.npz").face_sky) == 0
    with np.load(tmp_path / "plain.npz") as data:
        assert "face_sky" not in data.files


def test_a_hit_blends_its_sides_three_values_by_where_it_lies():
    """At each of the three points a hit gets that point's value (to float32), at the centroid
    their mean, on the edges no value outside the three's range, and each side its own values."""
    vertices = np.array([[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.1, 0.2, 0.05]], np.float32)
    faces = np.array([[0, 1, 2]], np.int32)
    table = np.array([[[6553, 32768, 52428], [100, 200, 300]]], np.uint16)
    c = vertices.astype(np.float64)
    points = [c[k] / 2 + c.sum(axis=0) / 6 for k in range(3)] + [c.mean(axis=0), c[0], (c[1] + c[2]) / 2]
    points = np.array(points, np.float32)
    prim = np.zeros(len(points), np.int64)
    ones = np.ones(len(points), np.float32)

    def blended(back):  # a probe seeing the whole sky, exposure 1: the exposure becomes the hit's value
        return face_sky_exposure(
            table, vertices, faces, prim, back, points, ones, ones, ones.copy(), np.float32(1e-6),
            np.zeros((9, 3), np.float32), np.zeros((0, 3), np.float32),
        )  # fmt: skip

    front, back = blended(np.zeros(len(points), bool)), blended(np.ones(len(points), bool))
    values = table[0].astype(np.float64) / 65535
    assert np.allclose(front[:3], values[0], atol=1e-6) and np.allclose(back[:3], values[1], atol=1e-6)
    assert np.isclose(front[3], values[0].mean(), atol=1e-6) and np.isclose(back[3], values[1].mean(), atol=1e-6)
    # a corner's blend (4/3 of its own point's value less the others' sixths) is kept within the range
    assert np.isclose(front[4], values[0].min(), atol=1e-6)
    assert np.isclose(front[5], min((values[0][1] + values[0][2]) * 2 / 3 - values[0][0] / 3, values[0].max()))
    assert np.isclose(back[5], (values[1][1] + values[1][2]) * 2 / 3 - values[1][0] / 3, atol=1e-6)  # within range
    assert np.all((front >= values[0].min() - 1e-6) & (front <= values[0].max() + 1e-6))


def test_face_table_pass_is_each_hits_own_in_any_order():
    """The pass keeps what depends on a face side alone from the hit before and asks for faces' rows
    hits ahead: over hits on a few faces in runs and at random, both sides, some not lit through a
    probe, every exposure and mean radiance equals the same hit's alone, bit for bit."""
    rng = np.random.default_rng(11)
    n_faces, n_hits = 40, 2_000
    vertices = rng.normal(size=(3 * n_faces, 3)).astype(np.float32)
    faces = np.arange(3 * n_faces, dtype=np.int32).reshape(n_faces, 3)
    faces[3] = faces[2]  # a degenerate face
    table = rng.integers(0, 65536, (n_faces, 2, SIDE_COLUMNS)).astype(np.uint16)
    prim = np.repeat(rng.integers(0, n_faces, n_hits // 4), 4)  # runs of four on one face...
    scattered = rng.random(n_hits) < 0.3  # ...and hits anywhere between
    prim[scattered] = rng.integers(0, n_faces, scattered.sum())
    prim = prim.astype(np.int64)
    back = rng.random(n_hits) < 0.3  # ...whose side changes within a run
    weights = rng.dirichlet(np.ones(3), n_hits).astype(np.float32)
    points = np.einsum("hk,hkc->hc", weights, vertices[faces[prim]]).astype(np.float32)
    side_exposure = rng.uniform(0.2, 2.0, n_hits).astype(np.float32)
    side_exposure[rng.random(n_hits) < 0.2] = -5.0  # a lightmap's side
    side_exposure[rng.random(n_hits) < 0.1] = np.inf  # the ground map's
    probe_visible = rng.uniform(0.05, 1.0, n_hits).astype(np.float32)
    exposure = rng.uniform(0.0, 1.5, n_hits).astype(np.float32)
    fit = rng.normal(size=(1 + MOMENTS, 3)).astype(np.float32)

    def run(at):
        seen = np.zeros((len(at), 3), np.float32)
        out = face_sky_exposure(
            table, vertices, faces, prim[at], back[at], points[at], side_exposure[at], probe_visible[at],
            exposure[at].copy(), np.float32(1e-6), fit, seen,
        )  # fmt: skip
        return out, seen

    together, seen = run(np.arange(n_hits))
    alone = [run(np.array([i])) for i in range(n_hits)]
    assert np.array_equal(together, np.concatenate([a[0] for a in alone]))
    assert np.array_equal(seen, np.concatenate([a[1] for a in alone]))
    assert not np.array_equal(together, exposure)  # the pass did change exposures


def test_render_follows_the_exact_sky_with_the_face_table(roof_bakes, roof_face_sky):
    """The floor under the roof's edge, as with the maps above (with the slope that keeps a plane
    from hiding itself): with each face side's three values blended per pixel (no rays, no maps at
    render time) its mean error against the exact sky is under 0.75 of the bake's alone and under
    0.03, without bias beyond 3 %."""
    mesh, plain, _ = roof_bakes
    shaded, exact = floor_shading(mesh, {"bake": plain, "table": roof_face_sky[1]})
    bake_error = np.abs(shaded["bake"] - exact).mean()
    table_error = np.abs(shaded["table"] - exact).mean()
    assert table_error < min(0.75 * bake_error, 0.03), (table_error, bake_error)
    assert abs(shaded["table"].mean() / exact.mean() - 1) < 0.03
