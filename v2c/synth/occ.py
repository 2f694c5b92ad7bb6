"""Thin OCCT layer of the generator: posing a shape, deterministic STEP I/O, per-face tessellation and the exact
analytic surface of every face.

Frames and units: shapes are in millimetres in whatever frame they were built in; `face_primitives` converts to
metres (the caller passes the mm -> m factor). Face indices are positions in a `TopExp_Explorer(shape, TopAbs_FACE)`
walk, the order SCAN_FORMAT.md fixes for gt/faces.png.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from OCP.APIHeaderSection import APIHeaderSection_MakeHeader
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Surface
from OCP.BRepBndLib import BRepBndLib
from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.GeomAbs import (
    GeomAbs_BezierSurface,
    GeomAbs_BSplineSurface,
    GeomAbs_Cone,
    GeomAbs_Cylinder,
    GeomAbs_OffsetSurface,
    GeomAbs_Plane,
    GeomAbs_Sphere,
    GeomAbs_SurfaceOfExtrusion,
    GeomAbs_SurfaceOfRevolution,
    GeomAbs_Torus,
)
from OCP.gp import gp_Dir, gp_Pnt, gp_Trsf
from OCP.IFSelect import IFSelect_RetDone
from OCP.Interface import Interface_Static
from OCP.Message import Message, Message_Gravity
from OCP.STEPControl import STEPControl_AsIs, STEPControl_Reader, STEPControl_Writer
from OCP.TCollection import TCollection_HAsciiString
from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
from OCP.TopExp import TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Face, TopoDS_Shape

#: Fixed STEP header values: OCCT writes the wall-clock time and a per-process write counter otherwise.
STEP_TIMESTAMP = "2000-01-01T00:00:00"
STEP_PRODUCT_NAME = "v2c_part"
_PRODUCT_COUNTER = re.compile(rf"'{STEP_PRODUCT_NAME} \d+'")

_NON_ANALYTIC_NAMES = {
    GeomAbs_BezierSurface: "bezier",
    GeomAbs_BSplineSurface: "bspline",
    GeomAbs_SurfaceOfRevolution: "revolution",
    GeomAbs_SurfaceOfExtrusion: "extrusion",
    GeomAbs_OffsetSurface: "offset",
}


def silence_occt() -> None:
    """Keep OCCT's STEP translator statistics off stdout (they would garble the progress bar)."""
    printers = Message.DefaultMessenger_s().Printers()
    for i in range(1, printers.Length() + 1):
        printers.Value(i).SetTraceLevel(Message_Gravity.Message_Fail)


def transform_shape(shape: TopoDS_Shape, matrix: np.ndarray) -> TopoDS_Shape:
    """Copy of `shape` under the similarity `matrix` ((3, 4): s * R | t, s > 0), geometry baked in (no location)."""
    m = np.asarray(matrix, float)
    trsf = gp_Trsf()
    trsf.SetValues(*m[0], *m[1], *m[2])
    return BRepBuilderAPI_Transform(shape, trsf, True).Shape()


def bounding_box(shape: TopoDS_Shape) -> tuple[np.ndarray, np.ndarray]:
    """Tight axis-aligned bounding box (lo, hi), shape units."""
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)
    lo = box.CornerMin()
    hi = box.CornerMax()
    return np.array([lo.X(), lo.Y(), lo.Z()]), np.array([hi.X(), hi.Y(), hi.Z()])


#: STEP writer settings of gt/part.step (OCCT's defaults, pinned so the file does not depend on what else ran).
_STEP_WRITE_STATICS = {
    "write.step.schema": "AP214IS",
    "write.step.unit": "MM",
    "write.surfacecurve.mode": "On",
    "write.precision.mode": "Average",
    "write.step.assembly": "Auto",
    "write.step.nonmanifold": "Off",
    "write.step.vertex.mode": "Compound",
}


def write_step(shape: TopoDS_Shape, path: Path) -> None:
    """Write `shape` (millimetres) to `path` as STEP with a byte-reproducible header.

    OCCT stamps FILE_NAME with the wall-clock time and numbers products by a per-process counter; both are fixed
    here (timestamp through the header API, product name by rewriting the counter away).
    """
    silence_occt()
    writer = STEPControl_Writer()
    # Every writer setting that shapes the bytes is set here: these statics are process-global, and another
    # writer in the same process (the XCAF exporter sets AP242DIS) would otherwise change part.step.
    for key, value in _STEP_WRITE_STATICS.items():
        if not Interface_Static.SetCVal_s(key, value):
            raise RuntimeError(f"OCCT does not know the STEP writer setting {key!r}")
    Interface_Static.SetCVal_s("write.step.product.name", STEP_PRODUCT_NAME)
    if writer.Transfer(shape, STEPControl_AsIs) != IFSelect_RetDone:
        raise RuntimeError("OCCT could not translate the part to STEP")
    header = APIHeaderSection_MakeHeader(writer.Model())
    header.SetName(TCollection_HAsciiString("part.step"))
    header.SetTimeStamp(TCollection_HAsciiString(STEP_TIMESTAMP))
    if writer.Write(str(path)) != IFSelect_RetDone:
        raise RuntimeError(f"{path}: OCCT could not write the STEP file")
    text = path.read_text()
    path.write_text(_PRODUCT_COUNTER.sub(f"'{STEP_PRODUCT_NAME}'", text))


def read_step(path: Path) -> TopoDS_Shape:
    """Read a STEP file into one shape (millimetres, OCCT's default unit)."""
    silence_occt()
    reader = STEPControl_Reader()
    if reader.ReadFile(str(path)) != IFSelect_RetDone:
        raise ValueError(f"{path}: not a readable STEP file")
    reader.TransferRoots()
    shape = reader.OneShape()
    if shape.IsNull():
        raise ValueError(f"{path}: the STEP file holds no shape")
    return shape


def faces_of(shape: TopoDS_Shape) -> list:
    """The faces of `shape` in TopExp_Explorer order (the face index of SCAN_FORMAT.md)."""
    out = []
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        out.append(TopoDS.Face_s(explorer.Current()))
        explorer.Next()
    return out


@dataclass
class FaceMesh:
    """Triangles of all faces of a shape, each tagged with its face index."""

    vertices: np.ndarray  # (n, 3) float64, shape units
    triangles: np.ndarray  # (m, 3) int32, counter-clockwise seen from outside the material
    face_of_triangle: np.ndarray  # (m,) int32 face index


def tessellate(shape: TopoDS_Shape, faces: list, linear_deflection: float, angular_deflection: float) -> FaceMesh:
    """Mesh every face separately (linear deflection in shape units, angular in radians)."""
    BRepMesh_IncrementalMesh(shape, linear_deflection, False, angular_deflection, True)
    verts, tris, owner = [], [], []
    offset = 0
    for index, face in enumerate(faces):
        loc = TopLoc_Location()
        poly = BRep_Tool.Triangulation_s(face, loc)
        if poly is None:
            continue
        n_nodes, n_tris = poly.NbNodes(), poly.NbTriangles()
        nodes = np.array([poly.Node(i).Coord() for i in range(1, n_nodes + 1)], float).reshape(n_nodes, 3)
        if not loc.IsIdentity():
            m = loc.Transformation()
            mat = np.array([[m.Value(r, c) for c in range(1, 5)] for r in range(1, 4)])
            nodes = nodes @ mat[:, :3].T + mat[:, 3]
        idx = np.array([poly.Triangle(i).Get() for i in range(1, n_tris + 1)], np.int32).reshape(n_tris, 3)
        idx -= 1
        if face.Orientation() == TopAbs_REVERSED:
            idx = idx[:, ::-1]
        verts.append(nodes)
        tris.append(idx + offset)
        owner.append(np.full(n_tris, index, np.int32))
        offset += n_nodes
    if not tris:
        raise ValueError("the part has no triangulated face")
    return FaceMesh(np.concatenate(verts), np.concatenate(tris), np.concatenate(owner))


def _xyz(p: gp_Pnt | gp_Dir) -> list[float]:
    """[x, y, z] of an OCCT point or direction (the shape's units for a point)."""
    return [p.X(), p.Y(), p.Z()]


def face_primitive(face: TopoDS_Face, to_m: float) -> dict:
    """SCAN_FORMAT.md primitives.json `type` and `params` of one face (params scaled by `to_m` to metres).

    Cone: origin = apex, axis from the apex towards growing radius, half_angle in radians. Plane normal points out
    of the material. Non-analytic faces give the OCCT type name and empty params.
    """
    surf = BRepAdaptor_Surface(face)
    kind = surf.GetType()
    if kind == GeomAbs_Plane:
        pln = surf.Plane()
        normal = np.array(_xyz(pln.Axis().Direction()))
        # The surface normal is X x Y of the plane's frame: minus the axis when that frame is left-handed (a
        # revolved solid's end faces have such frames); the face's orientation flips it once more.
        if (face.Orientation() == TopAbs_REVERSED) != (not pln.Position().Direct()):
            normal = -normal
        return {"type": "plane", "params": {"origin": _scaled(pln.Location(), to_m), "normal": normal.tolist()}}
    if kind == GeomAbs_Cylinder:
        cyl = surf.Cylinder()
        return {
            "type": "cylinder",
            "params": {
                "origin": _scaled(cyl.Location(), to_m),
                "axis": _xyz(cyl.Axis().Direction()),
                "radius": cyl.Radius() * to_m,
            },
        }
    if kind == GeomAbs_Cone:
        cone = surf.Cone()
        apex = np.array(_xyz(cone.Apex()))
        axis = np.array(_xyz(cone.Axis().Direction()))
        # The face may lie on either nappe (OCCT allows v beyond the apex): orient the axis from the apex
        # towards the face's own points, i.e. towards growing radius on the material side.
        mid = surf.Value(
            0.5 * (surf.FirstUParameter() + surf.LastUParameter()),
            0.5 * (surf.FirstVParameter() + surf.LastVParameter()),
        )
        if (np.array(_xyz(mid)) - apex) @ axis < 0:
            axis = -axis
        return {
            "type": "cone",
            "params": {"origin": (apex * to_m).tolist(), "axis": axis.tolist(), "half_angle": abs(cone.SemiAngle())},
        }
    if kind == GeomAbs_Sphere:
        sph = surf.Sphere()
        return {"type": "sphere", "params": {"origin": _scaled(sph.Location(), to_m), "radius": sph.Radius() * to_m}}
    if kind == GeomAbs_Torus:
        tor = surf.Torus()
        return {
            "type": "torus",
            "params": {
                "origin": _scaled(tor.Location(), to_m),
                "axis": _xyz(tor.Axis().Direction()),
                "radius": tor.MajorRadius() * to_m,
                "minor_radius": tor.MinorRadius() * to_m,
            },
        }
    return {"type": _NON_ANALYTIC_NAMES.get(kind, "other"), "params": {}}


def _scaled(p: gp_Pnt, to_m: float) -> list[float]:
    """[x, y, z] of an OCCT point times ``to_m`` (metres from the shape's millimetres)."""
    return [c * to_m for c in _xyz(p)]
