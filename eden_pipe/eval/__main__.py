"""``python -m eden_pipe.eval DATASET --pred DIR ...``: see :mod:`eden_pipe.eval.cli`."""

import sys

from eden_pipe.eval.cli import main

if __name__ == "__main__":
    sys.exit(main())
