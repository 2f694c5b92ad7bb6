"""The installed v2c's version, looked up once from the distribution's metadata."""

from __future__ import annotations

from functools import cache


@cache
def version() -> str:
    """The installed distribution's version; ``"0.0.0+unknown"`` for a source tree on sys.path without one."""
    from importlib import metadata

    try:
        return metadata.version("v2c")
    except metadata.PackageNotFoundError:
        return "0.0.0+unknown"
