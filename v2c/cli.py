"""The `v2c` command. Each sub-command lives in its own module under `v2c.commands` and exposes `command`."""

from __future__ import annotations

import importlib
import pkgutil

import click

from v2c import commands as _commands


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="v2c")
def main() -> None:
    """v2c: CAD geometry (VB-Rep, STEP) from a single RGB-D scan of a mechanical part."""


for _info in sorted(pkgutil.iter_modules(_commands.__path__), key=lambda m: m.name):
    _mod = importlib.import_module(f"v2c.commands.{_info.name}")
    main.add_command(_mod.command)

if __name__ == "__main__":
    main()
