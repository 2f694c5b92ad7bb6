"""Writing fixtures: the fixture as STEP and STL, and an assembly STEP of part plus fixture.

The part in the assembly is either the reconstructed part (the VB-Rep's faces as open shells, from
`exporters.build_brep`, or its face meshes when that fails) or the true part (e.g. a synthetic scan's
gt/part.step, camera frame, millimetres), moved into the fixture's output frame. The three files are one
`v2c.io_safe.OutputSet`: exclusive temporaries in the output folder, committed together. Millimetres throughout.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from build123d import Color, Compound, Shape, export_step, export_stl, import_step
from OCP.BRep import BRep_Builder
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeFace, BRepBuilderAPI_MakePolygon, BRepBuilderAPI_Sewing
from OCP.gp import gp_Pnt
from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL
from OCP.TopoDS import TopoDS_Compound, TopoDS_Iterator

from fixtures_design.frames import FrameMap, camera_mm_matrix
from fixtures_design.model import Fixture, transformed
from v2c.errors import OutputError
from v2c.io_safe import OutputSet, v2c_origin
from v2c.vbrep.model import VBRep

FIXTURE_COLOR = (0.85, 0.55, 0.1)
PART_COLOR = (0.6, 0.65, 0.75)


@dataclass(frozen=True)
class FixtureFiles:
    """Paths written by `write_fixture`."""

    step: Path
    stl: Path
    assembly: Path


def true_part(step_path: str | Path, fmap: FrameMap) -> Shape:
    """A true part STEP in the camera frame (millimetres, as gt/part.step), moved into ``fmap``'s output frame."""
    shape = import_step(str(step_path))
    solids = shape.solids()
    if len(solids) == 1:  # the solid itself, not a compound around it (one product in the assembly, not two)
        shape = solids[0]
    return transformed(shape, camera_mm_matrix(fmap))


def _mesh_shells(vbrep: VBRep, fmap: FrameMap) -> TopoDS_Compound:
    """The VB-Rep face meshes as sewn triangle shells (output frame, mm): the fallback part geometry."""
    comp = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(comp)
    for f in vbrep.faces:
        v = fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        t = np.asarray(f.mesh_triangles, int).reshape(-1, 3)
        if not len(t):
            continue
        sew = BRepBuilderAPI_Sewing(1e-3)
        for a, b, c in t:
            poly = BRepBuilderAPI_MakePolygon(*(gp_Pnt(*map(float, v[i])) for i in (a, b, c)), True)
            face = BRepBuilderAPI_MakeFace(poly.Wire(), True)
            if face.IsDone():
                sew.Add(face.Face())
        sew.Perform()
        builder.Add(comp, sew.SewedShape())
    return comp


def reconstructed_part(vbrep: VBRep, fmap: FrameMap) -> Shape:
    """The reconstructed part's faces (open shells, output frame of ``fmap``, mm), without free edges.

    Uses the STEP exporter's topology (`exporters.build_brep`); falls back to the face meshes if that fails.
    """
    comp = TopoDS_Compound()
    builder = BRep_Builder()
    builder.MakeCompound(comp)
    try:
        from exporters import build_brep

        built = build_brep(vbrep, fmap)
        it = TopoDS_Iterator(built.shape)
        n = 0
        while it.More():
            if it.Value().ShapeType() in (TopAbs_SHELL, TopAbs_FACE):
                builder.Add(comp, it.Value())
                n += 1
            it.Next()
        if n == 0:
            raise ValueError("no faces built")
    except Exception:  # noqa: BLE001 - any failure of the exporter's build falls back to the meshes
        comp = _mesh_shells(vbrep, fmap)
    return Compound(comp)


def assembly(fixture: Fixture, part: Shape | None, part_label: str = "part") -> Compound:
    """A two-child assembly (part, fixture) with labels and colours; ``part`` None gives the fixture alone."""
    fx = copy.copy(fixture.solid)
    fx.label = f"fixture_{fixture.kind.value}"
    fx.color = Color(*FIXTURE_COLOR)
    children = [fx]
    if part is not None:
        part = copy.copy(part)
        part.label = part_label
        part.color = Color(*PART_COLOR)
        children.insert(0, part)
    return Compound(children=children, label=f"{fixture.kind.value}_assembly")


def _mark(tmp: Path) -> None:
    """Put v2c's mark (`v2c.io_safe.written_by_v2c`) into a written temporary: a STEP's originating system
    (build123d writes its own name there), a binary STL's 80-byte header."""
    if tmp.suffix.lower() == ".stl":
        with open(tmp, "r+b") as fp:
            fp.write(f"{v2c_origin()} fixture".encode()[:80].ljust(80, b" "))
        return
    text = tmp.read_bytes()
    end = text.find(b"ENDSEC;")
    head = text[:end].replace(b"'build123d'", f"'{v2c_origin()}'".encode(), 1)
    tmp.write_bytes(head + text[end:])


def _export(out: OutputSet, path: Path, write: Callable[[Path], bool]) -> Path:
    """Write one file of the set through its exclusive temporary, marked as v2c's; the exporter's False is an
    error."""
    tmp = out.temp(path)
    if not write(tmp):
        raise OutputError(f"{path}: the exporter reported a failure; the previous files were left as they were")
    _mark(tmp)
    return path


def write_fixture(
    fixture: Fixture, out_dir: str | Path, part: Shape | None = None, stem: str | None = None, part_label: str = "part"
) -> FixtureFiles:
    """Write ``<stem>.step``, ``<stem>.stl`` and ``<stem>_assembly.step`` (part + fixture) into ``out_dir``.

    stem: default ``fixture_<kind>``. part: the part for the assembly, already in the fixture's output frame
    (`reconstructed_part` or `true_part`); None writes the fixture alone into the assembly file.
    """
    out = Path(out_dir)
    stem = stem or f"fixture_{fixture.kind.value}"
    with OutputSet() as files:  # the three files are committed together: all new or all old
        step = _export(files, out / f"{stem}.step", lambda p: export_step(fixture.solid, p))
        stl = _export(files, out / f"{stem}.stl", lambda p: export_stl(fixture.solid, p, tolerance=0.05))
        asm = _export(
            files, out / f"{stem}_assembly.step", lambda p: export_step(assembly(fixture, part, part_label), p)
        )
    return FixtureFiles(step, stl, asm)
