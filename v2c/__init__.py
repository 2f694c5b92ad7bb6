"""v2c: view-centric CAD (VB-Rep, STEP) from a single RGB-D scan, after View2CAD (Noeckel et al.).

Scripting entry points (imported lazily, so `import v2c` stays cheap):

    >>> import v2c
    >>> vbrep = v2c.reconstruct("samples/bracket_planes_cylinders")    # -> v2c.vbrep.model.VBRep
    >>> scan = v2c.load_scan("samples/bracket_planes_cylinders")
"""

from __future__ import annotations

from importlib import metadata as _metadata
from typing import Any

__all__ = ["__version__", "load_scan", "reconstruct"]

try:
    __version__: str = _metadata.version("v2c")
except _metadata.PackageNotFoundError:  # a source tree on sys.path without an installed distribution
    __version__ = "0.0.0+unknown"


def __getattr__(name: str) -> Any:
    if name == "reconstruct":
        from v2c.pipeline import reconstruct

        return reconstruct
    if name == "load_scan":
        from v2c.scan import load_scan

        return load_scan
    raise AttributeError(f"module 'v2c' has no attribute {name!r}")
