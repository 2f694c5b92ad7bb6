"""The `v2c` command. Each sub-command lives in its own module under `v2c.commands` and exposes `command`.

Errors, Ctrl-C and logging follow `v2c.cli_support`: ``error: <message>`` and exit 1 for bad input,
``interrupted`` and exit 130 for Ctrl-C, never a traceback.
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import sys
from typing import Any

import click

from v2c import commands as _commands
from v2c.cli_support import (
    EXIT_INTERRUPTED,
    configure_logging,
    ignore_sigint_from_now_on,
    run_with_error_policy,
)
from v2c.version import version


class V2cGroup(click.Group):
    """A click group that applies v2c's error policy (`v2c.cli_support.run_with_error_policy`)."""

    def main(
        self,
        args: Any = None,
        prog_name: str | None = None,
        complete_var: str | None = None,
        standalone_mode: bool = True,
        **extra: Any,
    ) -> Any:
        """Run the command line like `click.Group.main`, with v2c's error policy in standalone mode."""
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
        code = run_with_error_policy(
            lambda: super(V2cGroup, self).main(args, prog_name, complete_var, standalone_mode=False, **extra)
        )
        raise SystemExit(code)


@click.group(cls=V2cGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(version(), "-V", "--version", prog_name="v2c")
@click.option("-v", "--verbose", count=True, help="More messages on stderr (-v: progress, -vv: debug).")
@click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")
def main(verbose: int, quiet: bool) -> None:
    """v2c: CAD geometry (VB-Rep, STEP) from a single RGB-D scan of a mechanical part."""
    configure_logging(verbose, quiet)


for _info in sorted(pkgutil.iter_modules(_commands.__path__), key=lambda m: m.name):
    _mod = importlib.import_module(f"v2c.commands.{_info.name}")
    main.add_command(_mod.command)


def run() -> None:
    """The console entry point (``v2c``, ``python -m v2c``): `main`, then Ctrl-C ignored while the process exits,
    so a late Ctrl-C cannot turn a finished command's exit status into death by SIGINT."""
    try:
        main(prog_name="v2c")
    except SystemExit as e:
        ignore_sigint_from_now_on()
        if e.code == EXIT_INTERRUPTED:
            # after Ctrl-C: leave now with 130. Interpreter shutdown could still turn it into death by SIGINT
            # (-2; seen once in many runs), and there is nothing left to finish: the outputs are committed or not.
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(EXIT_INTERRUPTED)
        raise
    finally:
        ignore_sigint_from_now_on()


if __name__ == "__main__":
    run()
