"""Dataset splits: EDEN's garden split, the stable-hash split, and the uniform test subsample.

Splits are by garden, never by frame (docs/design.md, Splits).

EDEN preset (``eden_split``)
    EDEN has 147 gardens: 127 train and 20 test. Here the gardens are the
    seeds 0..146 and the 20 test seeds are spread evenly over that range:

        EDEN_TEST_SEEDS = {(147 * i + 73) // 20 for i in range(20)}
                        = {3, 11, 18, 25, 33, 40, 47, 55, 62, 69,
                           77, 84, 91, 99, 106, 113, 121, 128, 135, 143}

    (the middle seed of each of 20 equal slices), every other seed in 0..146
    is train. Spreading the test gardens means any prefix of seeds 0..N
    already holds its share (about N/7.35) of test gardens, so a partial
    generation still has a test set. Seeds above 146 are outside EDEN's
    garden set: they are ``train`` (extra training data never changes the
    20-garden test set, so results stay comparable), or a ``ValueError``
    with ``strict=True``. Negative seeds are always a ``ValueError`` (no
    garden has one).

Hash-fraction split (``hash_split``)
    The rule of ``eden_pipe.stages.manifest.assign_split``, same results:
    ``overrides`` pins a garden id; otherwise u = stable_hash("split", id) / 2**32
    gives train if u < train, val if u < train + val, else test.

Test subsample (``test_subsample``)
    EDEN evaluates on a uniform random 20,000-image subsample of its test
    images, released as a list. ``test_subsample`` ranks every row id by a
    keyed hash (BLAKE2b of seed and id) and keeps the ``count`` smallest
    (bottom-k sampling): a uniformly random subset of exactly ``count`` ids,
    the same for the same ids and seed whatever their order. The list is
    returned sorted by id; ``write_sample_list``/``read_sample_list`` store
    it as text, one id per line.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

from eden_pipe.rng import stable_hash

EDEN_GARDENS = 147
EDEN_TEST_GARDENS = 20
EDEN_TEST_SUBSAMPLE = 20_000  # images in EDEN's evaluation subsample of its test set
EDEN_TEST_SEEDS = frozenset(
    (EDEN_GARDENS * i + EDEN_GARDENS // 2) // EDEN_TEST_GARDENS for i in range(EDEN_TEST_GARDENS)
)


def eden_split(garden_seed: int, strict: bool = False) -> str:
    """EDEN's split of a garden seed: "test" for the 20 seeds of ``EDEN_TEST_SEEDS``, else "train".

    Seeds above 146 give "train" (or ``ValueError`` when ``strict``); negative seeds raise ``ValueError``.
    """
    if isinstance(garden_seed, bool) or int(garden_seed) != garden_seed:
        raise TypeError(f"a garden seed is an integer, got {garden_seed!r}")
    seed = int(garden_seed)
    if seed < 0:
        raise ValueError(f"garden seeds are >= 0, got {seed}")
    if seed >= EDEN_GARDENS and strict:
        raise ValueError(f"seed {seed} is outside EDEN's gardens 0..{EDEN_GARDENS - 1}")
    return "test" if seed in EDEN_TEST_SEEDS else "train"


def hash_split(
    garden_id: str, train: float = 0.8, val: float = 0.1, test: float = 0.1, overrides: Mapping[str, str] | None = None
) -> str:
    """Stable-hash split of a garden id (the manifest stage's ``assign_split`` rule; ``test`` is the remainder).

    ``test`` is accepted for symmetry with the ``split`` config and not used (u >= train + val is test).
    """
    overrides = dict(overrides or {})
    if garden_id in overrides:
        return str(overrides[garden_id])
    u = stable_hash("split", garden_id) / 2**32
    if u < train:
        return "train"
    return "val" if u < train + val else "test"


def split_for(garden_id: str, seed: int, split_cfg) -> str:
    """Split from a ``split`` config node: overrides, then ``preset: eden`` (by seed) or the hash fractions.

    ``split_cfg`` has ``train``, ``val``, ``test``, ``overrides`` and optionally ``preset`` ("eden" or none).
    """
    overrides = dict(getattr(split_cfg, "overrides", None) or {})
    if garden_id in overrides:
        return str(overrides[garden_id])
    preset = getattr(split_cfg, "preset", None)
    if preset == "eden":
        return eden_split(seed)
    if preset not in (None, "", "hash"):
        raise ValueError(f"unknown split preset {preset!r}; known: eden, hash")
    return hash_split(garden_id, float(split_cfg.train), float(split_cfg.val), float(split_cfg.test))


def _rank_key(seed: int, row_id: str) -> bytes:
    return hashlib.blake2b(
        row_id.encode(), digest_size=16, key=str(int(seed)).encode(), person=b"eden-subsample"
    ).digest()


def test_subsample(
    row_ids: Iterable[str], count: int | None = None, fraction: float | None = None, seed: int = 0
) -> list[str]:
    """A seeded uniform subsample of exactly ``count`` (or round(fraction * n)) ids, sorted by id.

    Independent of the order of ``row_ids`` (ids must be unique). Give exactly one of ``count`` and ``fraction``.
    """
    ids = [str(r) for r in row_ids]
    n = len(ids)
    if len(set(ids)) != n:
        raise ValueError("row ids must be unique")
    if (count is None) == (fraction is None):
        raise ValueError("give exactly one of count and fraction")
    if fraction is not None:
        if not 0.0 <= float(fraction) <= 1.0:
            raise ValueError(f"fraction must be in [0, 1], got {fraction}")
        count = int(round(float(fraction) * n))
    assert count is not None  # exactly one of count and fraction (checked above)
    count = int(count)
    if not 0 <= count <= n:
        raise ValueError(f"cannot draw {count} of {n} rows")
    ranked = sorted(ids, key=lambda r: (_rank_key(seed, r), r))
    return sorted(ranked[:count])


test_subsample.__test__ = False  # type: ignore[attr-defined]  # a library function, not a pytest test


def manifest_row_ids(frame) -> list[str]:
    """Row ids of a manifest DataFrame: ``<garden>/<lighting>/<frame:05d>/cam<camera>`` (unique per row)."""
    return [
        f"{g}/{lighting}/{int(f):05d}/cam{int(c)}"
        for g, lighting, f, c in zip(frame["garden"], frame["lighting"], frame["frame"], frame["camera"], strict=True)
    ]


def write_sample_list(path, row_ids: Sequence[str]) -> bool:
    """Text file, one id per line, in the given order (atomic; unchanged content is not rewritten).
    Returns True if the file was written."""
    from eden_pipe.io.atomic import write_if_changed

    return write_if_changed(Path(path), "".join(f"{r}\n" for r in row_ids).encode("utf-8"))


def read_sample_list(path) -> list[str]:
    return [line for line in Path(path).read_text(encoding="utf-8").splitlines() if line]
