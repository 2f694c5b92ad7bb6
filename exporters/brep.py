"""VB-Rep -> OCCT topology: analytic faces trimmed by shared, typed edges, assembled into open shells.

Output frame millimetres (see `exporters.frames`). Steps 1-4 are `exporters.brep_edges.EdgeBuilder`, step 5
`exporters.brep_faces.FaceBuilder`, step 6 `build_brep` here:

1. `make_surface` for every face (`exporters.occ_surfaces`).
2. Intersection edges: the exact intersection curve of their two faces' surfaces (GeomAPI_IntSS), the branch
   nearest the edge's polyline (or the VB-Rep's own line/circle where IntSS approximates and that curve lies
   on both surfaces).
3. Vertices: moved onto their incident intersection curves (alternating projection, which converges to the
   exact corner where three surfaces meet), else onto their faces' surfaces; each vertex's tolerance covers
   the gap left to every edge end (an empty gap for exact corners).
4. Edges: intersection curves trimmed at their vertices' parameters (the polyline decides which arc of a
   closed curve); other edges (and intersection edges whose curve could not be found) as a 2D curve in their
   face's (u, v) space (iso line, segment, arc or spline fitted to the polyline's projection onto the
   surface), so they lie on that face exactly, with the 3D curve built from it. One `TopoDS_Edge` per VB-Rep
   edge, shared by both faces.
5. Faces: the surface bounded by its loops (outer first), pcurves completed by ShapeFix_Face, oriented so the
   normal faces the camera (every face of one view is seen from its outside). Loops that do not bound a valid
   face are chained again or reduced (a warning); failing that the face is bounded by its mesh outline
   projected onto its surface (a warning), and the VB-Rep edges it no longer holds become free edges.
6. Faces sharing edges are assembled into open shells (topologically: they share the very same edges, so no
   tolerance-based sewing can merge or split anything by mistake). Edges on no face are free edges.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRepBndLib import BRepBndLib
from OCP.BRepBuilderAPI import BRepBuilderAPI_Transform
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.gp import gp_Trsf, gp_Vec
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Edge, TopoDS_Face, TopoDS_Shape, TopoDS_Shell

from exporters.brep_edges import EdgeBuilder
from exporters.brep_faces import FaceBuilder, edges_of
from exporters.frames import FrameMap
from exporters.polygons import connected_groups

if TYPE_CHECKING:
    from v2c.vbrep.model import VBRep


@dataclass(frozen=True)
class BrepConfig:
    """Tolerances of the topology build (millimetres unless said otherwise)."""

    intss_tol: float = 1e-6  # GeomAPI_IntSS tolerance
    branch_tol_abs: float = 2.0  # an intersection branch must pass within this of every polyline sample ...
    branch_tol_rel: float = 0.03  # ... or within this fraction of the part size, whichever is larger
    fit_tol_abs: float = 0.05  # B-spline fit tolerance of polylines ...
    fit_tol_rel: float = 0.002  # ... or this fraction of the part size, whichever is larger
    max_fit_points: int = 120  # polylines are subsampled to at most this many points before fitting
    branch_samples: int = 16  # polyline samples used to pick and trim an intersection branch
    vertex_iterations: int = 30  # alternating-projection steps placing a vertex on its curves/surfaces
    min_tolerance: float = 1e-4  # smallest vertex tolerance set
    fix_precision: float = 1e-4  # ShapeFix working precision
    fix_max_tolerance: float = 5.0  # ShapeFix may raise tolerances up to this
    analytic_tol: float = 1e-4  # a VB-Rep line/circle counts as the exact intersection within this


@dataclass
class BuiltBRep:
    """The OCCT result of one VB-Rep (output frame, millimetres).

    shape: compound of the open shells and the free edges. faces: VFace id -> the face as placed in a shell.
    edges: VEdge id -> its edge(s) (one unless ShapeFix had to split it). free_edges: VEdge ids on no face.
    face_edges: VFace id -> the VEdge ids its boundary holds.
    fallback_faces: faces rebuilt from their mesh boundary; skipped_faces: faces that could not be built at
    all. fmap: the camera -> output map the shape is in.
    """

    shape: TopoDS_Compound
    fmap: FrameMap | None = None
    faces: dict[int, TopoDS_Face] = field(default_factory=dict)
    edges: dict[int, list[TopoDS_Edge]] = field(default_factory=dict)
    free_edges: list[int] = field(default_factory=list)
    face_edges: dict[int, set[int]] = field(default_factory=dict)
    fallback_faces: list[int] = field(default_factory=list)
    skipped_faces: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def build_brep(vbrep: VBRep, fmap: FrameMap, config: BrepConfig | None = None) -> BuiltBRep:
    """The OCCT topology of a VB-Rep in the output frame of ``fmap`` (millimetres); see the module doc."""
    eb = EdgeBuilder(vbrep, fmap, config or BrepConfig()).run()
    fb = FaceBuilder(eb)
    out = BuiltBRep(shape=TopoDS_Compound(), fmap=fmap)
    faces: dict[int, TopoDS_Face] = {}
    face_edges: dict[int, set[int]] = {}
    for f in vbrep.faces:
        if f.id not in eb.surfaces:
            out.skipped_faces.append(f.id)
            continue
        made = fb.build_face(f, eb.edges)
        if made is not None:
            faces[f.id] = fb.done[f.id] = made[0]
            face_edges[f.id] = {eid for lp in made[1] for eid, _ in lp}
            continue
        face = fb.build_fallback_face(f)
        if face is None:
            eb.warnings.append(f"face {f.id}: no valid face could be built; skipped")
            out.skipped_faces.append(f.id)
            continue
        eb.warnings.append(f"face {f.id}: boundary wire invalid; bounded by its mesh outline instead")
        out.fallback_faces.append(f.id)
        faces[f.id] = fb.done[f.id] = face
        face_edges[f.id] = set()
    # ShapeFix may have replaced edges (recorded in the shared context): follow the replacements.
    for eid, ed in eb.edges.items():
        out.edges[eid] = edges_of(fb.ctx.Apply(ed))
    eb.bb.MakeCompound(out.shape)
    for shell_faces in connected_groups(face_edges):
        shell = TopoDS_Shell()
        eb.bb.MakeShell(shell)
        for fid in shell_faces:
            face = TopoDS.Face_s(fb.ctx.Apply(faces[fid]))
            eb.bb.Add(shell, face)
            out.faces[fid] = face
        shell.Closed(False)
        eb.bb.Add(out.shape, shell)
    used = set().union(*face_edges.values()) if face_edges else set()
    for eid in sorted(out.edges):
        if eid not in used:
            out.free_edges.append(eid)
            for ed in out.edges[eid]:
                eb.bb.Add(out.shape, ed)
    out.face_edges = face_edges
    out.warnings = eb.warnings
    return out


def translate_built(built: BuiltBRep, shift: np.ndarray) -> BuiltBRep:
    """The same build moved by ``shift`` (3,) millimetres: a copy of the geometry, its face/edge maps and
    frame map following it."""
    trsf = gp_Trsf()
    trsf.SetTranslation(gp_Vec(*map(float, shift)))
    tr = BRepBuilderAPI_Transform(built.shape, trsf, True)
    fmap = built.fmap.shifted(shift) if built.fmap is not None else None
    return BuiltBRep(
        shape=TopoDS.Compound_s(tr.Shape()),
        fmap=fmap,
        faces={fid: TopoDS.Face_s(tr.ModifiedShape(f)) for fid, f in built.faces.items()},
        edges={eid: [TopoDS.Edge_s(tr.ModifiedShape(e)) for e in es] for eid, es in built.edges.items()},
        free_edges=list(built.free_edges),
        face_edges={k: set(v) for k, v in built.face_edges.items()},
        fallback_faces=list(built.fallback_faces),
        skipped_faces=list(built.skipped_faces),
        warnings=list(built.warnings),
    )


def bounding_box(shape: TopoDS_Shape) -> tuple[np.ndarray, np.ndarray]:
    """(min corner, max corner) of a shape's exact bounding box (its own units, no gap)."""
    box = Bnd_Box()
    box.SetGap(0.0)
    BRepBndLib.AddOptimal_s(shape, box, False, False)
    return np.array(box.CornerMin().Coord()), np.array(box.CornerMax().Coord())


def check_faces(built: BuiltBRep) -> dict[int, bool]:
    """BRepCheck_Analyzer validity of every built face (VFace id -> valid)."""
    return {fid: BRepCheck_Analyzer(face).IsValid() for fid, face in built.faces.items()}
