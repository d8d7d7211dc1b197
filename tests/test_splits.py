"""EDEN garden split, the stable-hash split (same as the manifest stage's), the uniform test subsample."""

from __future__ import annotations

import random
from collections import Counter
from types import SimpleNamespace

import pytest

from eden_pipe import splits
from eden_pipe.splits import (
    EDEN_TEST_SEEDS,
    eden_split,
    hash_split,
    manifest_row_ids,
    read_sample_list,
    split_for,
    test_subsample,
    write_sample_list,
)


def test_eden_preset_is_127_train_20_test():
    counts = Counter(eden_split(s) for s in range(147))
    assert counts == {"train": 127, "test": 20}
    assert sorted(s for s in range(147) if eden_split(s) == "test") == sorted(EDEN_TEST_SEEDS)
    # frozen: the published test gardens never move
    assert sorted(EDEN_TEST_SEEDS) == [
        3,
        11,
        18,
        25,
        33,
        40,
        47,
        55,
        62,
        69,
        77,
        84,
        91,
        99,
        106,
        113,
        121,
        128,
        135,
        143,
    ]
    # spread evenly: every block of 15 consecutive seeds holds 2 or 3 test gardens (one per 7.35 seeds)
    assert all(2 <= sum(eden_split(s) == "test" for s in range(a, a + 15)) <= 3 for a in range(133))


def test_eden_preset_outside_range():
    assert eden_split(147) == eden_split(10_000) == "train"
    with pytest.raises(ValueError):
        eden_split(147, strict=True)
    with pytest.raises(ValueError):
        eden_split(-1)
    with pytest.raises(TypeError):
        eden_split(2.5)
    assert eden_split(146, strict=True) == "train" and eden_split(143, strict=True) == "test"


def _former_assign_split(garden_id, cfg):
    """The manifest stage's rule before eden_pipe.splits existed, frozen here: splits must not move."""
    from eden_pipe.rng import stable_hash

    if garden_id in cfg.overrides:
        return cfg.overrides[garden_id]
    u = stable_hash("split", garden_id) / 2**32
    return "train" if u < cfg.train else ("val" if u < cfg.train + cfg.val else "test")


def test_hash_split_matches_the_former_manifest_rule():
    from eden_pipe.stages.manifest import assign_split

    for fractions in ((0.8, 0.1, 0.1), (0.5, 0.25, 0.25), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0)):
        overrides = {"default-s7": "test", "small-s3": "val"}
        cfg = SimpleNamespace(train=fractions[0], val=fractions[1], test=fractions[2], overrides=overrides)
        for name in ("default", "small", "hedge maze"):
            for seed in range(60):
                gid = f"{name}-s{seed}"
                expect = _former_assign_split(gid, cfg)
                assert hash_split(gid, *fractions, overrides=overrides) == expect
                assert split_for(gid, seed, cfg) == expect == assign_split(gid, seed, cfg)


def test_hash_split_fractions_roughly_hold():
    counts = Counter(hash_split(f"default-s{s}") for s in range(3000))
    assert abs(counts["train"] / 3000 - 0.8) < 0.03 and abs(counts["val"] / 3000 - 0.1) < 0.02


def test_split_for_eden_preset_and_overrides():
    cfg = SimpleNamespace(train=0.8, val=0.1, test=0.1, overrides={"default-s3": "train"}, preset="eden")
    assert split_for("default-s3", 3, cfg) == "train"  # pinned beats the preset
    assert split_for("default-s11", 11, cfg) == "test"
    assert split_for("default-s12", 12, cfg) == "train"
    with pytest.raises(ValueError):
        split_for("x-s1", 1, SimpleNamespace(train=0.8, val=0.1, test=0.1, overrides={}, preset="kitti"))


def _ids(gardens=20, per_garden=3000):
    return [f"default-s{g}/clear/{f:05d}/cam{f % 10}" for g in range(gardens) for f in range(per_garden)]


def test_subsample_exact_deterministic_and_order_independent():
    ids = _ids(5, 400)
    a = test_subsample(ids, count=500, seed=0)
    assert len(a) == 500 and len(set(a)) == 500 and set(a) <= set(ids) and a == sorted(a)
    shuffled = ids[:]
    random.Random(1).shuffle(shuffled)
    assert test_subsample(shuffled, count=500, seed=0) == a
    assert test_subsample(tuple(reversed(ids)), count=500, seed=0) == a
    b = test_subsample(ids, count=500, seed=1)
    assert b != a and 0.15 < len(set(a) & set(b)) / 500 < 0.35  # independent draws overlap by ~500/2000
    assert len(test_subsample(ids, fraction=1 / 3)) == round(2000 / 3)
    assert test_subsample(ids, count=0) == [] and test_subsample(ids, count=2000) == sorted(ids)
    # growing the pool keeps earlier picks that still rank in the bottom k (bottom-k sampling)
    assert set(test_subsample(ids, count=100)) <= set(test_subsample(ids, count=200))


def test_subsample_is_uniform_over_gardens_and_frames():
    ids = _ids()  # 60,000 ids like EDEN's test set
    sample = test_subsample(ids, count=20_000, seed=0)
    assert len(sample) == 20_000
    per_garden = Counter(s.split("/")[0] for s in sample)
    assert len(per_garden) == 20
    expected = 1000  # binomial-ish sd ~ 26
    assert all(abs(c - expected) < 110 for c in per_garden.values()), per_garden
    chi2 = sum((c - expected) ** 2 / expected for c in per_garden.values())
    assert chi2 < 45  # 19 dof: p ~ 0.001
    per_camera = Counter(s[-1] for s in sample)
    assert all(abs(c - 2000) < 200 for c in per_camera.values())
    frames = [int(s.split("/")[2]) for s in sample]
    early = sum(f < 1500 for f in frames)
    assert abs(early - 10_000) < 350


def test_subsample_bad_inputs():
    with pytest.raises(ValueError):
        test_subsample(["a", "a", "b"], count=1)
    with pytest.raises(ValueError):
        test_subsample(["a", "b"], count=3)
    with pytest.raises(ValueError):
        test_subsample(["a", "b"])
    with pytest.raises(ValueError):
        test_subsample(["a", "b"], count=1, fraction=0.5)
    with pytest.raises(ValueError):
        test_subsample(["a", "b"], fraction=1.5)


def test_sample_list_file_and_manifest_ids(tmp_path):
    import pandas as pd

    frame = pd.DataFrame(
        {
            "garden": ["default-s3"] * 3,
            "lighting": ["clear", "clear", "sunset"],
            "frame": [0, 12, 0],
            "camera": [0, 9, 0],
        }
    )
    ids = manifest_row_ids(frame)
    assert ids == ["default-s3/clear/00000/cam0", "default-s3/clear/00012/cam9", "default-s3/sunset/00000/cam0"]
    sample = test_subsample(ids, count=2, seed=4)
    write_sample_list(tmp_path / "lists" / "test_sample.txt", sample)
    assert read_sample_list(tmp_path / "lists" / "test_sample.txt") == sample
    assert splits.EDEN_TEST_SUBSAMPLE == 20_000
