"""A VB-Rep back from a STEP written by ``v2c to-step`` (`exporters.write`), for designing fixtures from it.

The file's faces come back with their analytic surfaces and a mesh; its edges with the VB-Rep type,
confidence and 1-sigma position error (`VEdge.sigma_mm`) carried in their names
(``"<type>:<confidence>:e<id>:s<sigma>"``, docs/step.md), or else their layer (``edge_<type>``; confidence then
unknown, taken as 0); faces get `VFace.sigma_mm` from their names' ``:s<sigma>`` field (None without one). Faces
are oriented towards the camera in such a file, so their normals are outward: the VB-Rep is marked
``meta["outward_normals"] = True`` and the reference selection uses
them as they are. The file's frame (millimetres) becomes the VB-Rep's frame (metres) with identity axes: a
``--frame part`` STEP keeps its axes (and, up to the footprint origin, its origin); with a ``--frame camera``
STEP use ``frame="camera"`` when designing.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from build123d import Shape
from OCP.BRep import BRep_Tool
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.TopAbs import TopAbs_EDGE, TopAbs_FACE
from OCP.TopExp import TopExp
from OCP.TopoDS import TopoDS
from OCP.TopTools import TopTools_IndexedDataMapOfShapeListOfShape

from fixtures_design.occ import M_PER_MM, edge_curve, face_mesh, face_primitive
from v2c.labels import axis_class
from v2c.vbrep.model import EdgeType, VBRep, VEdge, VertexKind, VFace, VVertex


def _edge_type(name: str | None, layers: tuple[str, ...]) -> tuple[EdgeType, float, float | None] | None:
    """(type, confidence, sigma_mm) from the edge's name (`exporters.parse_edge_name`; sigma None when the name has
    no ``:s`` field), else from its layer (confidence 0, sigma None)."""
    from exporters import parse_edge_name

    _, etype, conf, sigma, _ = parse_edge_name(name)
    if conf is not None:
        return (etype, conf, sigma) if etype is not None else None
    for layer in layers:
        if layer.startswith("edge_"):
            try:
                return EdgeType(layer[len("edge_") :]), 0.0, None
            except ValueError:
                continue
    return None


def vbrep_from_step(path: str | Path, deflection_mm: float = 0.2) -> VBRep:
    """Read a ``v2c to-step`` STEP back as a VB-Rep (metres, the file's frame; see the module docstring).

    Planar and cylindrical faces keep their primitive; other faces are left out (they take no part in the
    references). Edges without a VB-Rep type in their name or layer are left out.
    """
    from exporters import parse_face_name, read_xcaf_step

    rs = read_xcaf_step(Path(path))
    shape = rs.shape
    BRepMesh_IncrementalMesh(shape, deflection_mm, False, 0.3, True)
    faces: list[VFace] = []
    face_ids: list[tuple[object, int]] = []
    for sub in rs.faces:
        f = TopoDS.Face_s(sub.shape)
        prim = face_primitive(f)
        if prim is None:
            continue
        v, t = face_mesh(f)
        d = np.asarray(prim["params"].get("normal", prim["params"].get("axis")), float)
        face_ids.append((f, len(faces)))
        sigma = parse_face_name(sub.name)[3]  # VFace.sigma_mm from the name's :s field (None without one)
        faces.append(
            VFace(
                len(faces),
                len(faces) + 1,
                prim,
                axis_class(d, np.eye(3)).value,
                [],
                v * M_PER_MM,
                t,
                1.0,
                sigma_mm=sigma,
            )
        )
    anc = TopTools_IndexedDataMapOfShapeListOfShape()
    TopExp.MapShapesAndAncestors_s(shape, TopAbs_EDGE, TopAbs_FACE, anc)
    edges: list[VEdge] = []
    vertices: list[VVertex] = []
    for sub in rs.edges:
        typed = _edge_type(sub.name, sub.layers)
        edge = TopoDS.Edge_s(sub.shape)
        if typed is None or BRep_Tool.Degenerated_s(edge):
            continue
        owners: list[int] = []
        if anc.Contains(edge):
            for face in anc.FindFromKey(edge):
                for f, fid in face_ids:
                    if face.IsSame(f) and fid not in owners:
                        owners.append(fid)
        etype, conf, sigma = typed
        if etype is EdgeType.INTERSECTION and len(owners) != 2:
            etype = EdgeType.VISIBILITY if owners else etype  # lost a face: no longer a shared edge
        if not owners:
            continue
        poly_mm, curve = edge_curve(edge)
        poly = poly_mm * M_PER_MM
        v0 = len(vertices)
        closed = bool(np.linalg.norm(poly[0] - poly[-1]) < 1e-9)
        for p in poly[:1] if closed else (poly[0], poly[-1]):
            vertices.append(VVertex(len(vertices), VertexKind.OTHER, np.asarray(p).reshape(3), np.zeros(2)))
        edges.append(
            VEdge(
                len(edges),
                etype,
                conf,
                tuple(sorted(owners)),
                poly,
                v0,
                v0 if closed else v0 + 1,
                curve if etype is EdgeType.INTERSECTION else None,
                sigma_mm=sigma,
            )
        )
    pts = np.concatenate([f.mesh_vertices for f in faces]) if faces else np.zeros((1, 3))
    return VBRep(
        faces,
        edges,
        vertices,
        frame=np.eye(3),
        K=np.eye(3),
        image_size=(0, 0),
        scale=float(np.ptp(pts, axis=0).max()),
        meta={"source": str(path), "products": rs.products, "outward_normals": True},
    )


def step_shape(path: str | Path) -> Shape:
    """The STEP's shape as a build123d object (millimetres, the file's frame)."""
    from build123d import import_step

    return import_step(str(path))
