"""OCCT helpers of the fixture designer: faces in file order, face meshes, analytic primitives and edge curves of
a B-rep in millimetres, turned into the VB-Rep's units (metres) where said."""

from __future__ import annotations

import numpy as np
from build123d import Shape
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve, BRepAdaptor_Surface
from OCP.GeomAbs import GeomAbs_Circle, GeomAbs_Cone, GeomAbs_Cylinder, GeomAbs_Line, GeomAbs_Plane, GeomAbs_Torus
from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
from OCP.TopExp import TopExp_Explorer
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS

M_PER_MM = 1e-3


def _xyz(p: object) -> np.ndarray:
    return np.array([p.X(), p.Y(), p.Z()])


def occt_faces(shape: Shape) -> list:
    """The faces of a shape in ``TopExp_Explorer`` order (the order of gt/faces.png)."""
    out = []
    exp = TopExp_Explorer(shape.wrapped, TopAbs_FACE)
    while exp.More():
        out.append(TopoDS.Face_s(exp.Current()))
        exp.Next()
    return out


def face_mesh(face: object) -> tuple[np.ndarray, np.ndarray]:
    """A meshed face's triangulation: (V, 3) vertices (its shape's units, mm for STEP parts) and (T, 3) vertex
    indices, wound along the face's outward normal (reversed for a reversed face); empty when not meshed."""
    loc = TopLoc_Location()
    tri = BRep_Tool.Triangulation_s(face, loc)
    if tri is None:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    trsf = loc.Transformation()
    v = np.array([_xyz(tri.Node(i).Transformed(trsf)) for i in range(1, tri.NbNodes() + 1)])
    t = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], np.int64) - 1
    if face.Orientation() == TopAbs_REVERSED:
        t = t[:, ::-1]
    return v, t


def face_primitive(face: object, curved: bool = False) -> dict | None:
    """Primitive dict (camera frame, metres) of a planar or cylindrical face; with ``curved`` also of a torus or
    cone face (the parameters of the scan generator's primitives.json: a cone's origin is its apex, its axis points
    from the apex towards the face); None for other types."""
    s = BRepAdaptor_Surface(face)
    if curved and s.GetType() == GeomAbs_Torus:
        t = s.Torus()
        return {
            "type": "torus",
            "params": {
                "origin": (_xyz(t.Axis().Location()) * M_PER_MM).tolist(),
                "axis": _xyz(t.Axis().Direction()).tolist(),
                "radius": t.MajorRadius() * M_PER_MM,
                "minor_radius": t.MinorRadius() * M_PER_MM,
            },
        }
    if curved and s.GetType() == GeomAbs_Cone:
        c = s.Cone()
        apex, axis = _xyz(c.Apex()), _xyz(c.Axis().Direction())
        # the axis from the apex towards the face (OCCT's cone runs through its apex onto the other nappe)
        mid = s.Value(
            0.5 * (s.FirstUParameter() + s.LastUParameter()), 0.5 * (s.FirstVParameter() + s.LastVParameter())
        )
        if (_xyz(mid) - apex) @ axis < 0:
            axis = -axis
        return {
            "type": "cone",
            "params": {"origin": (apex * M_PER_MM).tolist(), "axis": axis.tolist(), "half_angle": abs(c.SemiAngle())},
        }
    if s.GetType() == GeomAbs_Plane:
        ax = s.Plane().Axis()
        n = _xyz(ax.Direction())
        if face.Orientation() == TopAbs_REVERSED:
            n = -n
        return {"type": "plane", "params": {"origin": (_xyz(ax.Location()) * M_PER_MM).tolist(), "normal": n.tolist()}}
    if s.GetType() == GeomAbs_Cylinder:
        c = s.Cylinder()
        return {
            "type": "cylinder",
            "params": {
                "origin": (_xyz(c.Axis().Location()) * M_PER_MM).tolist(),
                "axis": _xyz(c.Axis().Direction()).tolist(),
                "radius": c.Radius() * M_PER_MM,
            },
        }
    return None


def camera_facing(v: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(T,) bool: which triangles of the mesh (camera frame, any unit; outward winding) face the camera at the
    origin."""
    t = np.asarray(t, np.int64).reshape(-1, 3)
    a, b, c = v[t[:, 0]], v[t[:, 1]], v[t[:, 2]]
    n = np.cross(b - a, c - a)
    return (n * (a + b + c) / 3).sum(axis=1) < 0


def faces_the_camera(v_mm: np.ndarray, t: np.ndarray) -> bool:
    """Whether any triangle of the mesh (camera frame, mm; outward winding) faces the camera at the origin."""
    return bool(len(t)) and bool(camera_facing(v_mm, t).any())


def edge_curve(edge: object, n: int = 24) -> tuple[np.ndarray, dict | None]:
    """(n, 3) polyline (mm) and analytic curve dict (camera frame, metres) of an edge."""
    c = BRepAdaptor_Curve(edge)
    ts = np.linspace(c.FirstParameter(), c.LastParameter(), n)
    poly = np.array([_xyz(c.Value(t)) for t in ts])
    if c.GetType() == GeomAbs_Line:
        d = poly[-1] - poly[0]
        return poly, {"kind": "line", "origin": poly[0] * M_PER_MM, "direction": d / np.linalg.norm(d)}
    if c.GetType() == GeomAbs_Circle:
        circ = c.Circle()
        return poly, {
            "kind": "circle",
            "center": _xyz(circ.Location()) * M_PER_MM,
            "axis": _xyz(circ.Axis().Direction()),
            "radius": circ.Radius() * M_PER_MM,
        }
    return poly, {"kind": "intersection"}
