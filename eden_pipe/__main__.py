"""``python -m eden_pipe [overrides]``: the Hydra app over ``conf/``."""

from __future__ import annotations

import logging
import shutil
import sys
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from eden_pipe.config import ConfigError, register_schemas

register_schemas()
CONF_DIR = str(Path(__file__).resolve().parents[1] / "conf")


@hydra.main(version_base="1.3", config_path=CONF_DIR, config_name="config")
def main(cfg: DictConfig) -> None:
    from eden_pipe.pipeline import run_job

    try:
        run_job(cfg, echo=logging.getLogger("eden_pipe").info)
    except ConfigError as err:
        # A multirun job's config is only fully known here: drop the folder Hydra just made.
        shutil.rmtree(HydraConfig.get().runtime.output_dir, ignore_errors=True)
        print(f"eden-pipe: {err}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
