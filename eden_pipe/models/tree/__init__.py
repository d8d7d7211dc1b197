"""Weber & Penn parametric trees: 19 species as triangle meshes.

The model follows J. Weber and J. Penn, "Creation and Rendering of Realistic
Trees" (SIGGRAPH 1995), in the form popularised by Wolfram Diestel's Arbaro
(Java) and Blender's Sapling add-on; the species presets under
``conf/species/trees/`` take their numbers from the published Weber-Penn
tables, Arbaro's and Sapling's presets (re-entered by hand, adapted where
those tools use their own conventions).

A tree is a hierarchy of *stems*: the trunk (level 0) carries level-1
branches, which carry level-2 branches and so on up to ``Levels - 1``; the
last stem level carries the leaves. Every stem is ``nCurveRes`` straight
segments whose direction turns by ``nCurve`` (or ``nCurve`` then
``nCurveBack`` over the two halves) plus a random ``nCurveV`` part;
``AttractionUp`` turns stems of level >= 2 toward (or, negative, away from)
the sky. Segments may split into clones (``nSegSplits``, ``0BaseSplits``,
fractional counts carried as an error from stem to stem) that diverge by
``nSplitAngle`` less the stem's declination. Children sit along their parent
(the trunk above ``BaseSize``) with spiral ``nRotate`` (negative: alternating
sides) and ``nDownAngle`` (negative variation: a function of the position on
the parent); level-1 lengths follow the crown shape ratio (``Shape`` 0-7 or
the pruning envelope 8), deeper ones ``nLength * (L_parent - 0.6 offset)``;
counts follow ``nBranches`` with the Weber-Penn length/offset factors.
Radii follow ``Ratio``/``RatioPower`` with ``nTaper`` (0-1 conical, 1-2
rounded tip, 2-3 periodic, as in palm trunks), trunk ``Flare`` and ``Lobes``.
With ``PruneRatio`` > 0, stems leaving the envelope (``PruneWidth``,
``PruneWidthPeak``, ``PrunePowerLow/High``) are shortened, and every stem is
shortened where it would go below ground. Leaves are ``Leaves`` per stem of the
last level (scaled by shape ratio ``LeafDistrib`` of the stem's offset;
negative: a fan at the stem tip), sized ``LeafScale`` x ``LeafScaleX`` and
turned outward/upward by ``LeafBend``.

Small extensions (optional preset keys): ``SplitHeight`` (fraction of the
trunk where base splits happen), ``nAttractionUp`` (per-level override, as in
Sapling), ``nBaseSize`` (bare fraction at the base of level >= 1 parents),
``nWhorl`` (children in whorls of this many, as in pines and firs),
``FanAngle`` / ``FanTilt`` (degrees spanned by fan leaves, and the blade's
bend up from the petiole), ``LeafStart`` (bare fraction at
the base of leaf-bearing stems), ``leaf_color_alt`` / ``leaf_alt_fraction``
(a second leaf colour near stem tips, e.g. bottlebrush flowers).

Geometry: stems are open tubes (8+/6/4/3 sides by level, a flat two-sided
ribbon when the triangle budget forces it); leaves are small shaped polygons
(elliptic, ovate, deltoid, lobed, palmate, needle, palm leaflet, sphere, ...)
of 2-8 triangles. Everything is labelled ``labels.TREE``; stems use material
``bark`` and leaves ``leaf``. The whole tree is finally scaled uniformly so
that its height is drawn from the preset's garden height range.

Generation is level-synchronous and vectorised: all stems of one level are
grown together (a Python loop over segment index only), children and leaves
are placed with array operations, and tubes and leaves are emitted as batched
vertex/face arrays.

Limits that keep presets tractable (Weber-Penn splitting is exponential and
some tables ask for millions of leaves): a stem family holds at most
``MAX_FAMILY`` rows (``MAX_TRUNK_STEMS`` for the trunk); a level above
``MAX_CHILDREN`` stems is thinned evenly and each kept stem carries the
leaves of those it stands for; over the triangle budget, stems first lose
sides and rings (then whole deep levels) and leaves are merged into fewer,
larger ones, each at most ``MAX_LEAF_AREA_GROWTH`` times a preset leaf's area
(more under tight budgets), so very leafy presets end up somewhat sparser than
the tables imply. Clones split their radius (area-preserving), and split
trunks are half-corrected back toward the vertical.

The package, by job: :mod:`.parameters` (preset keys, defaults, shape ratio,
envelope, limits), :mod:`.stems` (growing one level's stems), :mod:`.skeleton`
(the hierarchy: child placement, radii, leaf counts), :mod:`.foliage` (leaf
placement and merging), :mod:`.meshing` (tubes with a budgeted level of detail,
leaf cards from :mod:`eden_pipe.models.leaves`, colours, garden height).
"""

from eden_pipe.models.tree.foliage import LeafSet, place_leaves
from eden_pipe.models.tree.meshing import build_tree
from eden_pipe.models.tree.parameters import TreeParams, envelope_inside, list_tree_species, shape_ratio, tree_params
from eden_pipe.models.tree.skeleton import Skeleton, grow_skeleton
from eden_pipe.models.tree.stems import StemLevel, carry_round

__all__ = [
    "LeafSet",
    "Skeleton",
    "StemLevel",
    "TreeParams",
    "build_tree",
    "carry_round",
    "envelope_inside",
    "grow_skeleton",
    "list_tree_species",
    "place_leaves",
    "shape_ratio",
    "tree_params",
]
