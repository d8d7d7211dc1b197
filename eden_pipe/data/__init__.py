"""PyTorch access to eden-pipe datasets (needs the ``[torch]`` extra).

``from eden_pipe.data import EdenDataset`` imports torch; the manifest helpers
in :mod:`eden_pipe.data.manifest_reader` (load, filter, poses, intrinsics) do not, so
numpy-only tools can use them without torch installed.
"""

from __future__ import annotations

__all__ = ["DEFAULT_IGNORE_INDEX", "EdenDataset", "EdenShards", "filter_manifest", "load_manifest"]


def __getattr__(name: str):
    if name in ("EdenDataset", "DEFAULT_IGNORE_INDEX"):
        try:
            from eden_pipe.data import dataset
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("eden_pipe.data.EdenDataset needs PyTorch: pip install 'eden-pipe[torch]'") from exc
        return getattr(dataset, name)
    if name == "EdenShards":
        try:
            from eden_pipe.data import shards
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise ImportError("eden_pipe.data.EdenShards needs PyTorch: pip install 'eden-pipe[torch]'") from exc
        return shards.EdenShards
    if name in ("load_manifest", "filter_manifest"):
        from eden_pipe.data import manifest_reader

        return getattr(manifest_reader, name)
    raise AttributeError(f"module 'eden_pipe.data' has no attribute {name!r}")
