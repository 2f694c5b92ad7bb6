"""VB-Rep -> CAD: STEP AP242 with typed, named edges (OCCT XCAF), B-rep shapes for scripting, the result figure.

The public API is the names below; the submodules are internals (the fixtures_design layer and v2c's
application layer use only these names, a contract `lint-imports` checks). Millimetres in every output; the
frame is the recovered part frame or the camera frame (`frames`).

    >>> import exporters
    >>> report = exporters.write(vbrep, "part.step")            # STEP AP242, part frame, mm
    >>> typed = exporters.read_typed("part.step")               # faces and typed edges read back
    >>> solid = exporters.to_build123d(vbrep)                   # or to_cadquery, or build (OCCT shapes)

Importing this package is cheap (numpy only): the frame names load at once, every name that needs OCCT (the
STEP writer and reader, the topology build, the shapes) loads on first use.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from exporters import frames
from exporters.brep_config import BrepConfig
from exporters.frames import MM_PER_M, Frame, FrameMap, frame_map, proper_rotation

if TYPE_CHECKING:
    from exporters.brep import BuiltBRep, build_brep
    from exporters.figure import render_vbrep, result_figure
    from exporters.readback import Readback, ReadbackConfig, check_written
    from exporters.shapes import to_build123d, to_cadquery
    from exporters.step import (
        StepExportError,
        StepReport,
        TypedEdge,
        TypedFace,
        TypedStep,
        build,
        parse_edge_name,
        parse_face_name,
        quiet_occt,
        read_typed,
        write,
    )
    from exporters.xcaf import ReadStep, ReadSubShape, XcafError, read_xcaf_step

#: Public name -> the submodule that defines it; loaded on first access (these import OCCT, cv2 or build123d).
_LAZY = {
    # STEP AP242 export and read-back (exporters.step)
    "write": "exporters.step",
    "read_typed": "exporters.step",
    "build": "exporters.step",
    "quiet_occt": "exporters.step",
    "StepReport": "exporters.step",
    "StepExportError": "exporters.step",
    "TypedStep": "exporters.step",
    "TypedFace": "exporters.step",
    "TypedEdge": "exporters.step",
    "parse_edge_name": "exporters.step",
    "parse_face_name": "exporters.step",
    # the topology build in a given frame map (exporters.brep)
    "build_brep": "exporters.brep",
    "BuiltBRep": "exporters.brep",
    # any STEP file through OCCT XCAF, names / layers / colours kept (exporters.xcaf)
    "read_xcaf_step": "exporters.xcaf",
    "ReadStep": "exporters.xcaf",
    "ReadSubShape": "exporters.xcaf",
    "XcafError": "exporters.xcaf",
    # build123d / cadquery shapes (exporters.shapes)
    "to_build123d": "exporters.shapes",
    "to_cadquery": "exporters.shapes",
    # the written file checked against the VB-Rep (exporters.readback)
    "check_written": "exporters.readback",
    "Readback": "exporters.readback",
    "ReadbackConfig": "exporters.readback",
    # the result figure (exporters.figure)
    "result_figure": "exporters.figure",
    "render_vbrep": "exporters.figure",
}

__all__ = [  # the eager names and every name of _LAZY
    "MM_PER_M",
    "BrepConfig",
    "BuiltBRep",
    "Frame",
    "FrameMap",
    "ReadStep",
    "ReadSubShape",
    "Readback",
    "ReadbackConfig",
    "StepExportError",
    "StepReport",
    "TypedEdge",
    "TypedFace",
    "TypedStep",
    "XcafError",
    "build",
    "build_brep",
    "check_written",
    "frame_map",
    "frames",
    "parse_edge_name",
    "parse_face_name",
    "proper_rotation",
    "quiet_occt",
    "read_typed",
    "read_xcaf_step",
    "render_vbrep",
    "result_figure",
    "to_build123d",
    "to_cadquery",
    "write",
]


def __getattr__(name: str) -> Any:
    """Load a public name that needs OCCT (or cv2, build123d) from its submodule on first access."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'exporters' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later accesses skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
