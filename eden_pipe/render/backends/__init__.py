"""Render backends: one interface, found by name in a registry (after Kubric's ``core.View``).

A backend turns the renderer-agnostic scene (:class:`eden_pipe.scene.arrays.SceneArrays`)
and the sky of one lighting into the passes of one camera view. It declares

- ``capabilities``: the modalities it produces (names of :data:`eden_pipe.modalities.TABLE`);
  the render stage drops the others (their manifest paths stay empty);
- ``max_frame_threads``: how many frames may render at once on one instance (0 = no limit);

and implements ``frame(time, prev_time, next_time)`` (per-frame state, e.g. the sky tabulated at that time; private
to the frame's thread), ``render_view(state, intr, pose, ...)`` and ``close()``.

Registry entries name a module and class, imported only when asked for: the
backends' libraries (embreex, pybullet) are slow to load. A third backend is one
module with a :class:`Backend` subclass plus one line in :data:`REGISTRY`.
"""

from __future__ import annotations

import importlib
from typing import ClassVar

import numpy as np

REGISTRY: dict[str, str] = {
    "raytrace": "eden_pipe.render.backends.raytrace:RaytraceBackend",
    "tinyrenderer": "eden_pipe.render.backends.tinyrenderer:TinyRendererBackend",
    "cycles": "eden_pipe.render.backends.cycles:CyclesBackend",
}


class Backend:
    """The interface every backend implements (see the module doc)."""

    name: ClassVar[str]
    capabilities: ClassVar[frozenset[str]]
    max_frame_threads: ClassVar[int] = 0  # 0 = any number of frames at once
    moves_geometry: ClassVar[bool] = False  # renders a moving mesh (wind: ``wind``, ``frame``'s neighbours)
    # Whether ``render_exposed`` is implemented (rolling shutter, motion blur; docs/design.md, Camera effects).
    exposure_effects: ClassVar[bool] = False

    @classmethod
    def depth_error(cls, z: np.ndarray) -> np.ndarray:
        """(N,) metres the backend's z-depth ``z`` (N,) may be off its surface before the depth file
        stores it (the validator's geometry check adds it to the file's own precision): 0 for a ray
        tracer, whose depth is the hit's."""
        return np.zeros(np.shape(z))

    def __init__(self, scene, sky, render_cfg, *, modalities: set[str], threads: int = 0, wind=None):
        """Build the backend's scene (BVH, uploaded bodies) for ``scene`` under ``sky``. ``modalities``
        are the ones that will be asked for; ``threads`` the threads it may use per frame thread;
        ``wind`` the mesh's motion (a ``render.wind.WindField``; only where ``moves_geometry``)."""
        raise NotImplementedError

    @classmethod
    def unavailable(cls, render_cfg) -> str | None:
        """Why this backend cannot run with ``render_cfg`` here (a missing library), or None; checked
        before any work (``preflight.check_job``)."""
        return None

    def frame(self, time: float, prev_time: float | None = None, next_time: float | None = None) -> object:
        """Per-frame state at ``time`` seconds, passed back to ``render_view`` for the frame's views
        (``prev_time``/``next_time``: the neighbouring frames', which a moving mesh needs)."""
        return None

    def render_view(
        self,
        state,
        intr,
        pose: np.ndarray,
        *,
        want: set[str],
        pose_next: np.ndarray | None = None,
        pose_prev: np.ndarray | None = None,
        rng: np.random.Generator | None = None,
        rgb_spp: int = 1,
        partner: dict | None = None,
    ) -> dict:
        """The passes of one camera (keys as ``render.view.render_view``: ``depth`` always, ``rgb_linear``
        for rgb, ``semantic``, ``flow_fwd``, ...), each (H, W[, C]). ``partner``: what this call returned
        for the other camera of the pair, rendered before (a backend may reuse view-independent work
        from it, as ``render.view.render_view`` does; others ignore it)."""
        raise NotImplementedError

    def render_exposed(
        self,
        state,
        intr,
        pose_samples: np.ndarray,
        sample_offsets: np.ndarray,
        *,
        rng: np.random.Generator,
        rgb_spp: int = 1,
    ) -> np.ndarray:
        """(H, W, 3) linear RGB over an exposure: row v of sub-frame sample j seen from
        ``pose_samples[j, v]`` (S, H, 4, 4), the scene as at ``sample_offsets[j]`` seconds from the
        frame time (``render.exposure.render_exposed_rgb``); only where ``exposure_effects``."""
        raise NotImplementedError(f"backend {self.name!r} renders no rolling shutter or motion blur")

    def render_exposed_views(
        self, state, intr, views: list[tuple[np.ndarray, np.random.Generator]], sample_offsets, *, rgb_spp: int = 1
    ) -> list[np.ndarray]:
        """``render_exposed`` of several views of one frame (each its pose samples and generator) over
        the same sub-frame times; a backend whose scene moves renders them sample by sample."""
        return [
            self.render_exposed(state, intr, poses, sample_offsets, rng=rng, rgb_spp=rgb_spp) for poses, rng in views
        ]

    def close(self) -> None:
        pass

    def __enter__(self) -> Backend:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def names() -> tuple[str, ...]:
    """Registered backend names (the choices of ``render.backend``)."""
    return tuple(REGISTRY)


def module_of(name: str) -> str:
    """The module that implements backend ``name`` (its code is part of the render cache key)."""
    if name not in REGISTRY:
        raise KeyError(f"unknown render backend {name!r}; known: {', '.join(REGISTRY)}")
    return REGISTRY[name].split(":")[0]


def get(name: str) -> type[Backend]:
    """The backend class registered as ``name`` (its module is imported now)."""
    module = importlib.import_module(module_of(name))
    return getattr(module, REGISTRY[name].split(":")[1])


def producing(modality: str) -> tuple[str, ...]:
    """Names of the backends whose capabilities include ``modality``."""
    return tuple(n for n in REGISTRY if modality in get(n).capabilities)
