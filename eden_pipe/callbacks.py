"""Hydra callbacks: check the job before Hydra creates any folder; merge manifests after a sweep."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from eden_pipe.config import ConfigError


class EdenCallback(Callback):
    def on_run_start(self, config: DictConfig, **kwargs: Any) -> None:
        # Runs before Hydra makes the run folder: bad input leaves nothing behind.
        _check(config)

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        _check(config)

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        from eden_pipe.stages.manifest import merge_manifests

        root = Path(config.paths.dataset)
        if root.is_dir():
            rows, _ = merge_manifests(root)
            print(f"[eden-pipe] multirun   {root}/manifest.csv: {rows} rows merged")


def _check(config: DictConfig) -> None:
    """Every pre-flight check (``preflight.check_job``); a failure is one line and exit 2."""
    from eden_pipe.cli_errors import with_source
    from eden_pipe.preflight import check_job

    try:
        check_job(config)
    except ConfigError as err:
        print(f"eden-pipe: {with_source(str(err), config)}", file=sys.stderr)
        sys.exit(2)
