"""``python -m eden_pipe [overrides]``: the Hydra app over ``conf/``.

Exit status (docs/reliability.md):

===  ======================================================================
0    done
2    bad input (a config key or value, a preset, a destination folder, not enough
     free space): one line on stderr, stopped before any work, nothing written
74   an I/O failure mid-job (disk full, the dataset folder made read-only or
     removed): one line; finished frames are kept and a rerun resumes
130  interrupted by SIGINT (Ctrl-C), 143 by SIGTERM (SLURM preemption): one line;
     no half file is left under a final name and a rerun resumes
1    an unexpected error (a bug): Python's traceback
===  ======================================================================
"""

from __future__ import annotations

import logging
import os
import shutil
import signal
import sys
from contextlib import contextmanager

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from eden_pipe.config import CONF_DIR, ConfigError, register_schemas

register_schemas()
EXIT_BAD_INPUT = 2
EXIT_IO = 74  # sysexits.h EX_IOERR


class Interrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived: unwinds the job like Ctrl-C (``finally`` blocks remove temporaries)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def fail(message: str, status: int) -> None:
    print(f"eden-pipe: {message}", file=sys.stderr, flush=True)
    sys.exit(status)


@contextmanager
def stop_on_signals():
    """Turn the first SIGINT/SIGTERM into :class:`Interrupted`; a second one acts as it normally does."""

    def handler(signum, frame):
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, previous[sig])
        raise Interrupted(signum)

    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    for sig in previous:
        signal.signal(sig, handler)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


@hydra.main(version_base="1.3", config_path=str(CONF_DIR), config_name="config")
def main(cfg: DictConfig) -> None:
    from eden_pipe.cli_errors import io_error_line, with_source
    from eden_pipe.preflight import quiet_native_stderr

    with quiet_native_stderr():  # the stages import pybullet, which prints a build banner: stderr is for messages
        from eden_pipe.pipeline import run_job
    try:
        run_job(cfg, echo=logging.getLogger("eden_pipe").info)
    except ConfigError as err:
        # A multirun job's config is only fully known here: drop the folder Hydra just made.
        shutil.rmtree(HydraConfig.get().runtime.output_dir, ignore_errors=True)
        fail(with_source(str(err), cfg), EXIT_BAD_INPUT)
    except OSError as err:
        fail(io_error_line(err, f"a file under {cfg.paths.stages} or {cfg.paths.dataset}"), EXIT_IO)


def cli(argv: list[str] | None = None) -> None:
    """The command: Hydra's composition errors become the same one line (exit 2) as the checks'."""
    from eden_pipe.cli_errors import hydra_error_line

    argv = sys.argv[1:] if argv is None else argv
    user_wants_traces = "HYDRA_FULL_ERROR" in os.environ
    os.environ["HYDRA_FULL_ERROR"] = "1"  # Hydra re-raises instead of printing: we report it
    try:
        with stop_on_signals():
            main()
    except Interrupted as sig:
        fail(
            f"interrupted by {signal.Signals(sig.signum).name}: finished frames are kept and no half file "
            f"is left; rerun the same command to resume",
            128 + sig.signum,
        )
    except Exception as ex:
        line = None if user_wants_traces else hydra_error_line(ex, argv)
        if line is None:
            raise
        fail(line, EXIT_BAD_INPUT)


if __name__ == "__main__":
    cli()
