"""The realism benchmark's comparison of the path tracer with Cycles (``benchmarks/realism.py``): it
compares only pixels whose Cycles footprint sees one face, and says how many that leaves
(docs/realism.md, The path tracer against Cycles)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchmarks.realism import one_face_pixels
from benchmarks.realism_report import Pool, bias, bias_standard_error, score
from eden_pipe.camera.rig import Intrinsics
from eden_pipe.config import to_config
from eden_pipe.render.backends.cycles import FOOTPRINT_REACH_PX
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.view import primary_rays
from tests.conftest import make_cfg
from tests.sky_scenes import grid


def test_one_face_pixels_are_those_whose_footprint_meets_no_edge():
    """A floor of 2 x 2 squares (each two triangles) seen from straight above: a pixel is one-face
    exactly where its centre is farther than the footprint's reach from every edge of the triangle
    its centre ray meets, and the floor's rim against the sky counts as an edge."""
    floor = grid(-1.0, 1.0, -1.0, 1.0, 0.0, 2, albedo=0.3)
    intr = Intrinsics(96, 96, 60.0, 60.0, 47.002, 47.9)  # column 47 0.002 px beside the seam x = 0
    pose = np.eye(4)
    pose[:3, :3] = np.diag([1.0, -1.0, -1.0])  # looking down
    pose[2, 3] = 1.5
    tracer = RayTracer(floor)
    try:
        o, d = primary_rays(intr, pose)
        hits = tracer.intersect(o, d)
        pick = np.arange(intr.width * intr.height)
        prim = np.where(hits.hit, hits.prim, -1)
        got = one_face_pixels(tracer, intr, pose, pick, prim, FOOTPRINT_REACH_PX)
        wide = one_face_pixels(tracer, intr, pose, pick, prim, 0.6)
    finally:
        tracer.close()
    # Where each pixel's footprint edges land on the floor, in metres: the reach at 1.5 m over fx = 60.
    reach_m = FOOTPRINT_REACH_PX * 1.5 / intr.fx
    v, u = np.divmod(pick, intr.width)
    x = (u - intr.cx) / intr.fx * 1.5
    y = -(v - intr.cy) / intr.fy * 1.5
    cell_x, cell_y = np.mod(x, 1.0), np.mod(y, 1.0)  # within a 1 m square of the grid
    diagonal = np.abs(cell_x - cell_y) / np.sqrt(2.0)  # each square's two triangles meet on x = y
    to_edge = np.minimum.reduce([cell_x, 1.0 - cell_x, cell_y, 1.0 - cell_y, diagonal])
    inside = (np.abs(x) < 1.0) & (np.abs(y) < 1.0)
    far = inside & (to_edge > 1.5 * reach_m)  # the eight probes reach sqrt(2) times as far on diagonals
    near = inside & (to_edge < 0.5 * reach_m)
    sky = (np.abs(x) > 1.0 + 1.5 * reach_m) | (np.abs(y) > 1.0 + 1.5 * reach_m)
    assert far.sum() > 5000 and near.sum() > 0
    assert np.all(got[far]) and np.all(got[sky]) and not np.any(got[near])
    assert np.all(to_edge[~got & inside] < 1.5 * reach_m)  # every pixel left out sits on a seam
    assert (~wide).sum() > 3 * (~got).sum()  # a wider footprint meets more edges


def test_cycles_scores_skip_pixels_whose_footprint_sees_two_faces():
    """Two views' pixels of one class: the scores over one-face pixels ignore a pixel where Cycles blended
    two faces; the all-pixel scores keep it."""
    pool = Pool()
    rng = np.random.default_rng(0)
    for _view in range(2):
        truth = rng.uniform(0.2, 0.4, (50, 3)).astype(np.float32)
        cycles = truth.copy()
        one_face = np.ones(50, bool)
        cycles[7] *= 3.0  # this pixel's footprint also saw a bright face
        one_face[7] = False
        record = {"lighting": "clear", "garden": 101, "classes": np.full(50, 4), "one_face": one_face}
        for source, value in (("path", truth), ("cycles", cycles), ("current", truth)):
            record[f"{source}_half1/linear"] = record[f"{source}_half2/linear"] = value
            record[f"{source}_half1/shading"] = record[f"{source}_half2/shading"] = value
        record["current/linear"] = record["current/shading"] = truth
        pool.add(record)
    row = score(pool, ["current"], "path", compare_cycles=True)["clear"]
    cls = next(iter(row["share"]))
    assert row["one_face", cls] == 0.98
    bias, error, noise, standard_error = row["path_vs_cycles", "linear", cls]
    assert bias == 0.0 and error == 0.0 and noise == 0.0 and standard_error == 0.0
    bias_all, error_all, _, _ = row["path_vs_cycles_all", "linear", cls]
    assert bias_all < -0.03 and error_all > 0.03


def test_bias_standard_error_is_the_spread_of_biases_over_draws():
    """Pixels whose two renders differ by zero-mean noise: the standard error is the pixels' spread of
    differences over sqrt(n), relative to the reference mean, and over 2000 draws of 80 pixels it is the
    spread of the measured biases; about 5 % of the draws show a bias beyond twice it."""
    ref = np.array([[0.2, 0.3, 0.4], [0.4, 0.5, 0.6]])
    a = ref + np.array([[0.1], [-0.1]])
    assert np.isclose(bias_standard_error(a, ref), np.std([0.1, -0.1], ddof=1) / np.sqrt(2) / 0.4)
    rng = np.random.default_rng(3)
    biases, errors = [], []
    for _draw in range(2000):
        truth = rng.uniform(0.1, 0.5, (80, 3))
        path = truth * (1 + rng.normal(0.0, 0.1, (80, 1)))
        cycles = truth * (1 + rng.normal(0.0, 0.1, (80, 1)))
        biases.append(bias(path, cycles))
        errors.append(bias_standard_error(path, cycles))
    biases, errors = np.array(biases), np.array(errors)
    assert abs(np.std(biases) / np.median(errors) - 1.0) < 0.1
    beyond = np.mean(np.abs(biases) > 2 * errors)
    assert 0.03 < beyond < 0.08


def test_reference_tag_follows_the_code_scene_views_and_light(tmp_path, monkeypatch):
    """A cached reference is read back only for the same renderer source, mesh, poses, intrinsics,
    lighting and environment map's bytes: changing any one gives another tag (benchmarks/realism.py, reference_file)."""
    import benchmarks.realism as realism

    module = tmp_path / "tagdemo_renderer.py"
    module.write_text("GAIN = 1.0\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(realism.REFERENCE_CODE, "path", ("tagdemo_renderer",))
    mesh = grid(-1.0, 1.0, -1.0, 1.0, 0.0, 2, albedo=0.3)
    poses = np.tile(np.eye(4), (2, 5, 2, 1, 1))
    intr = Intrinsics(96, 96, 60.0, 60.0, 47.5, 47.5)
    light = to_config(make_cfg(tmp_path, ["lighting=clear"])).lighting

    def tag(**change):
        args = {"mesh": mesh, "poses": poses, "intr": intr, "lighting": light} | change
        return realism.reference_tag("path", args["mesh"], args["poses"], args["intr"], args["lighting"])

    base = tag()
    assert tag() == base and len(base) == 12
    brighter = grid(-1.0, 1.0, -1.0, 1.0, 0.0, 2, albedo=0.31)
    moved = poses.copy()
    moved[1, 3, 0, 0, 3] += 1e-6
    others = [
        tag(mesh=brighter),
        tag(poses=moved),
        tag(intr=Intrinsics(96, 96, 61.0, 60.0, 47.5, 47.5)),
        tag(lighting=replace(light, sun_elevation_deg=[36, 60])),
    ]
    module.write_text("GAIN = 1.01\n")
    others.append(tag())
    assert len({base, *others}) == 6
    assert realism.reference_tag("cycles", mesh, poses, intr, light) != base  # another renderer's source
    assert realism.reference_tag("path", mesh, poses, intr, light, settings={"bounces": 7}) != tag()
    sky_map = tmp_path / "sky.hdr"
    sky_map.write_bytes(b"one map")
    mapped = tag(lighting=replace(light, environment=str(sky_map)))
    sky_map.write_bytes(b"another map, same path")
    assert len({tag(), mapped, tag(lighting=replace(light, environment=str(sky_map)))}) == 3


def test_cycles_reference_ends_paths_where_the_path_tracer_does():
    """With the path tracer's bounce limit, Cycles' total, diffuse and transmission limits are all that
    limit (a translucent scattering is a transmission bounce in Cycles); without, the backend's defaults."""
    from benchmarks.realism import cycles_settings
    from eden_pipe.config.schema import CyclesConfig

    matched = cycles_settings(256, 1, 9)
    assert (matched["max_bounces"], matched["diffuse_bounces"], matched["transmission_bounces"]) == (9, 9, 9)
    assert matched["samples"] == 256 and matched["seed"] == 1
    defaults = cycles_settings(64, 0)
    assert defaults["transmission_bounces"] == CyclesConfig().transmission_bounces
    assert defaults["glossy_bounces"] == matched["glossy_bounces"] == CyclesConfig().glossy_bounces
