"""A face side's visible sky in the bake: few bundle rays reach a small face, so its hit fraction is
shrunk toward its part's (the faces it shares vertices with) within its probe, and the part's
toward the probe's (docs/realism.md, the bake). Checked against each face's sky traced with many
rays, on two tiles of tiny faces in one probe, one of them under a black cap."""

from __future__ import annotations

import numpy as np
import pytest

from eden_pipe.models.mesh import Mesh
from eden_pipe.render import sh
from eden_pipe.render.embree import RayTracer
from eden_pipe.render.visibility.bake import bake, face_frames
from tests.sky_scenes import closed_box, grid
from tests.test_sky_visibility import traced_visible_sky

TILE = 0.04  # two tiles of 8 x 8 cells (128 faces each), 1 cm apart: one probe cell holds both


@pytest.fixture(scope="module")
def capped_tiles():
    """The two tiles, the cap (1 cm above the first, 1 cm wider on each side) and each tile face's
    upper side's visible sky, traced with 2,048 cosine rays from its centroid."""
    tiles = [grid(x, x + TILE, 0.0, TILE, 0.0, 8, albedo=0.5) for x in (0.0, TILE + 0.01)]
    cap = closed_box([-0.01, -0.01, 0.01], [TILE + 0.01, TILE + 0.01, 0.02])
    mesh = Mesh.concatenate([*tiles, cap])
    tracer = RayTracer(mesh, 1)
    faces = np.arange(2 * tiles[0].n_faces)
    _, _, centroids = face_frames(mesh)
    true = traced_visible_sky(tracer, centroids[faces], rays=2048)
    yield mesh, tracer, faces, true
    tracer.close()


def face_sky(mesh: Mesh, tracer: RayTracer, faces: np.ndarray, **priors) -> tuple[np.ndarray, np.ndarray]:
    """(each face's upper side's visible sky as the render reads it, its probe), from a bake whose
    bundles' rays are 2 cm apart: about two of them reach a tile face from the open sky (many
    directions, so that the tiles' own sums are not off by the few directions a face sees)."""
    vis = bake(
        mesh,
        tracer,
        np.random.default_rng(0),
        directions=256,
        spacing_m=0.02,
        rays=4,
        cell_m=0.1,
        cell_height_m=0.03,
        ground_rays=0,
        **priors,
    )
    probe = vis.face_probe[faces, 0]
    probe_visible = vis.transfer[probe, 0] / sh.basis(np.zeros((1, 3)))[0, 0]
    return vis.exposure[faces, 0] * probe_visible, probe


def test_pooling_over_parts_gives_small_faces_their_own_sky(capped_tiles):
    """The tiles share a probe; under the cap a face sees about a tenth of the sky, beside it most.
    Shrunk toward the probe, which mixes both, a face under the cap is pulled halfway to the open
    tile's sky; shrunk toward its tile (its part), it keeps its own."""
    mesh, tracer, faces, true = capped_tiles
    capped = faces < len(faces) // 2
    assert true[capped].mean() < 0.2 and true[~capped].mean() > 0.8, true
    to_probe, probe = face_sky(mesh, tracer, faces, part_prior_hits=0.0, prior_hits=4.0)
    pooled, _ = face_sky(mesh, tracer, faces)  # the defaults: 64 pseudo-hits toward the part, 32 toward the probe
    assert len(np.unique(probe)) == 1  # one probe holds both tiles
    error_to_probe, error_pooled = np.abs(to_probe - true), np.abs(pooled - true)
    assert error_to_probe.mean() > 0.2, (to_probe, true)
    assert error_pooled.mean() < 0.5 * error_to_probe.mean(), (error_pooled.mean(), error_to_probe.mean())
    # the capped tile's mean is its own, not halfway to the probe's
    assert abs(to_probe[capped].mean() - true[capped].mean()) > 0.3, (to_probe[capped].mean(), true[capped].mean())
    assert abs(pooled[capped].mean() - true[capped].mean()) < 0.1, (pooled[capped].mean(), true[capped].mean())
