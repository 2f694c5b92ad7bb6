"""``python -m v2c``: the `v2c` command.

Ctrl-C while the command itself is still being imported exits like Ctrl-C later on: "interrupted", status 130,
no traceback (`v2c.cli_support` takes over once the command runs).
"""

import os
import signal
import sys


def _interrupted_early(signum: int, frame: object) -> None:
    # No output is open before the command runs (nor after it finished): exit at once. An exception raised here
    # could surface inside a C extension's import as a different error.
    sys.stdout.flush()
    print("interrupted", file=sys.stderr, flush=True)
    os._exit(130)


signal.signal(signal.SIGINT, _interrupted_early)

from v2c.cli import run  # noqa: E402 - after the handler, so that an early Ctrl-C is handled too

run()
