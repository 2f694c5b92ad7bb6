"""``python -m v2c``: the `v2c` command.

Ctrl-C while the command itself is still being imported exits like Ctrl-C later on: "interrupted", status 130,
no traceback (`v2c.cli_support` takes over once the command runs).
"""

import signal
import sys


def _interrupted_early(signum: int, frame: object) -> None:
    print("interrupted", file=sys.stderr)
    raise SystemExit(130)


signal.signal(signal.SIGINT, _interrupted_early)

from v2c.cli import run  # after the handler, so that an early Ctrl-C is handled too

run()
