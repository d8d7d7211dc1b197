"""Seeded random generators derived from the job seed and a stable name.

Every random draw in eden-pipe comes from ``rng_for(seed, "tree", 3)``-style
generators, so adding an object never shifts another object's parameters
(docs/design.md, Randomness and reproducibility). Names are hashed with a stable hash (not Python's salted
``hash``) so that runs are byte-identical across processes.
"""

from __future__ import annotations

import hashlib

import numpy as np


def stable_hash(*parts: object) -> int:
    """A 32-bit hash of the parts' string forms, identical in every process."""
    text = "\x1f".join(str(p) for p in parts).encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=4).digest(), "little")


def rng_for(seed: int, *names: object) -> np.random.Generator:
    """Generator for the object named by ``names`` within the job ``seed``."""
    if int(seed) < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    key = tuple(stable_hash(n) for n in names)
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence(int(seed), spawn_key=key)))


def child_seed(seed: int, *names: object) -> int:
    """A derived integer seed (for caching per object, e.g. one tree model)."""
    return int(rng_for(seed, *names).integers(0, 2**31 - 1))
