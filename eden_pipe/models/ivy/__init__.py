"""Ivy growth on analytic skeletons (after Thomas Luft's Ivy Generator).

Hedges and topiaries are grown, as in EDEN, by letting ivy climb a hidden
skeleton shape: a (rounded) box trellis for hedges, a sphere, cone, stacked
spheres or a helix tube for topiaries. The skeleton is never rendered; it only
answers nearest-surface queries (:meth:`Skeleton.query`, an SDF-like
closest point, outward normal and signed distance, vectorised over points).

Growth (:func:`grow_ivy`) follows Luft's rules with the Blender IvyGen
defaults: every live root takes one step per iteration,

    grow    = ivy_size * (wp * primary + wr * random + wa * adhesion)
    gravity = ivy_size * wg * (0, 0, -1) * (floating / max_float) ** 0.7

where random = normalize(U(-.5, .5)^3 + (0, 0, .2)) and adhesion points to the
nearest skeleton point, scaled by 1 - d / max_adhesion (zero beyond). A step
that enters the skeleton is reflected off its surface (the mirror image of
the penetrating part) and marks the node climbing, which resets the floating
length; roots die when they float too long, reach the maximum length, or
(the gardener's shears, an addition for clipped shapes) leave the trim shell
``trim_distance`` outside the skeleton. Live roots branch with a probability
peaking at half the maximum length, for at most ``max_generations``
generations. All live roots advance together (no per-root Python loop).

:func:`ivy_leaves` distributes leaves along the grown segments, with an
acceptance weight growing with relative length along the root and blades
oriented from the smoothed adhesion vector; :func:`eden_pipe.models.tubes.tube_mesh` sweeps thin
tubes along all polylines at once (stems, branches, trunks).

Modules: :mod:`.skeletons` (the shapes, one class per kind in ``SKELETONS``),
:mod:`.growth` (parameters and growth), :mod:`.foliage` (leaf sites),
:mod:`.stems` (stem tubes and branch paths).
"""

from eden_pipe.models.ivy.foliage import LeafSites, ivy_leaves
from eden_pipe.models.ivy.growth import IvyGrowth, IvyParams, grow_ivy, surface_directions
from eden_pipe.models.ivy.skeletons import (
    SKELETONS,
    BoxSkeleton,
    ConeSkeleton,
    HelixTubeSkeleton,
    Skeleton,
    SphereSkeleton,
    StackedSpheresSkeleton,
    draw_skeleton_spec,
    make_skeleton,
    skeleton_preset_keys,
)
from eden_pipe.models.ivy.stems import branch_paths, ivy_stems
from eden_pipe.models.tubes import tube_mesh

__all__ = [
    "SKELETONS",
    "BoxSkeleton",
    "ConeSkeleton",
    "HelixTubeSkeleton",
    "IvyGrowth",
    "IvyParams",
    "LeafSites",
    "Skeleton",
    "SphereSkeleton",
    "StackedSpheresSkeleton",
    "branch_paths",
    "draw_skeleton_spec",
    "grow_ivy",
    "ivy_leaves",
    "ivy_stems",
    "make_skeleton",
    "skeleton_preset_keys",
    "surface_directions",
    "tube_mesh",
]
