"""v2c: view-centric CAD (VB-Rep, STEP) from a single RGB-D scan, after View2CAD (Noeckel et al.).

Scripting entry points (imported lazily, so `import v2c` stays cheap):

    >>> import v2c
    >>> vbrep = v2c.reconstruct("samples/bracket_planes_cylinders")    # -> v2c.vbrep.model.VBRep
    >>> scan = v2c.load_scan("samples/bracket_planes_cylinders")

`reconstruct` is `v2c.pipeline.reconstruct`, the one pipeline entry point; `v2c.pipeline.PipelineConfig` carries
every stage's settings.
"""

from __future__ import annotations

from typing import Any

__all__ = ["PipelineConfig", "__version__", "load_scan", "reconstruct"]


def __getattr__(name: str) -> Any:
    if name == "__version__":  # the installed distribution's version, looked up on first use
        from v2c.version import version

        return version()
    if name in ("reconstruct", "PipelineConfig"):
        from v2c import pipeline

        return getattr(pipeline, name)
    if name == "load_scan":
        from v2c.scan import load_scan

        return load_scan
    raise AttributeError(f"module 'v2c' has no attribute {name!r}")
