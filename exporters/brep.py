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
   face's (u, v) space (iso line, segment, arc or spline fitted to the polyline moved along the camera rays
   onto the surface), so they lie on that face exactly, with the 3D curve built from it. One `TopoDS_Edge` per
   VB-Rep edge, shared by both faces; where an edge fitted on one face lies farther than ``join_tol`` off the
   other, that face gets a copy of its own on its surface (``BuiltBRep.copied_edges``).
5. Faces: the surface bounded by its loops (outer first), pcurves completed by ShapeFix_Face, oriented so the
   normal faces the camera (every face of one view is seen from its outside). Loops that do not bound a valid
   face are chained again or reduced (a warning). The file must be the reconstruction: a face whose loops
   bound no valid face, bound an area off its VB-Rep mesh's by more than ``area_tol_rel``, or reach outside
   the part's box is bounded by its mesh outline instead (`exporters.brep_outline`: every piece of the mesh,
   holes kept, as faces of the analytic surface; a warning), its outline edges named after the face's nearest
   VB-Rep edges.
6. Faces sharing edges are assembled into open shells (topologically: they share the very same edges, so no
   tolerance-based sewing can merge or split anything by mistake). Edges on no face are free edges, unless
   an outline carries their name or they lie outside the part's box (then they are dropped and listed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from OCP.Bnd import Bnd_Box
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBndLib import BRepBndLib
from OCP.BRepBuilderAPI import BRepBuilderAPI_Copy, BRepBuilderAPI_Transform
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepGProp import BRepGProp
from OCP.BRepMesh import BRepMesh_IncrementalMesh
from OCP.Geom import (
    Geom_ConicalSurface,
    Geom_CylindricalSurface,
    Geom_Plane,
    Geom_SphericalSurface,
    Geom_ToroidalSurface,
)
from OCP.gp import gp_Pnt, gp_Trsf, gp_Vec
from OCP.GProp import GProp_GProps
from OCP.TopAbs import TopAbs_REVERSED
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Compound, TopoDS_Edge, TopoDS_Face, TopoDS_Shape, TopoDS_Shell

from exporters.brep_config import BrepConfig
from exporters.brep_edges import EdgeBuilder
from exporters.brep_faces import FaceBuilder, edges_of
from exporters.brep_outline import (
    OutlineBuilder,
    OutlinePiece,
    area_element,
    mesh_area,
    mesh_centroid,
    reconstructed_area,
    signed_areas_2d,
)
from exporters.frames import FrameMap
from exporters.polygons import connected_groups
from v2c.labels import PrimitiveType

if TYPE_CHECKING:
    from v2c.vbrep.model import VBRep, VFace


@dataclass
class BuiltBRep:
    """The OCCT result of one VB-Rep (output frame, millimetres).

    shape: compound of the open shells and the free edges. faces: VFace id -> the face as placed in a shell.
    edges: VEdge id -> its edge(s) (one unless ShapeFix had to split it). free_edges: VEdge ids on no face.
    face_edges: VFace id -> the VEdge ids its boundary holds (the shared edge, or its own copy of it).
    copied_edges: VEdge id -> the faces bounded by a copy of their own (`EdgeBuilder._face_copies`: an edge
    fitted on its other face, farther than ``join_tol`` off theirs); ``edges`` lists the copies too.
    fallback_faces: faces bounded by their mesh outline (`exporters.brep_outline`); face_parts: for those, every
    piece of the outline as its own face (``faces`` holds the largest); outline_edges: VFace id -> its outline's
    edges, each with the VEdge id it is named after (-1: none). skipped_faces: faces that could not be built at
    all. dropped_edges: VEdge ids on no face that are not written (their faces' outlines carry their names, or
    they lie outside the part's box). mesh_area / built_area: VFace id -> the area of the VB-Rep mesh's region
    on the face's surface (`brep_outline.reconstructed_area`) and the built face's (all pieces), mm². box: the
    part's box (lo, hi) with its margin, mm. fmap: the camera -> output map the shape is in.
    """

    shape: TopoDS_Compound
    fmap: FrameMap | None = None
    faces: dict[int, TopoDS_Face] = field(default_factory=dict)
    edges: dict[int, list[TopoDS_Edge]] = field(default_factory=dict)
    free_edges: list[int] = field(default_factory=list)
    face_edges: dict[int, set[int]] = field(default_factory=dict)
    copied_edges: dict[int, list[int]] = field(default_factory=dict)
    fallback_faces: list[int] = field(default_factory=list)
    skipped_faces: list[int] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    face_parts: dict[int, list[TopoDS_Face]] = field(default_factory=dict)
    outline_edges: dict[int, list[tuple[TopoDS_Edge, int]]] = field(default_factory=dict)
    dropped_edges: list[int] = field(default_factory=list)
    mesh_area: dict[int, float] = field(default_factory=dict)
    built_area: dict[int, float] = field(default_factory=dict)
    box: tuple[np.ndarray, np.ndarray] | None = None


#: Relative precision of the adaptive area integration (`face_area`). OCCT's default, non-adaptive Gauss
#: integration is exact for faces bounded by lines and circles but not for boundaries of fitted B-spline (u, v)
#: curves: on a leave-out family scan (feat_block scan 8, oracle) it gave 2,533 mm² for a planar face whose
#: triangulation and reconstruction are 1,880 mm² (adaptive: 1,880), sending faces to their mesh outline and
#: counting written faces as off. 1e-3, not 1e-6: on the 202 faces written for three corpus-val scans (oracle)
#: the areas agree within 3e-10, and the integration takes a third of the time (0.063 s against 0.185 s).
AREA_REL_PRECISION = 1e-3


def face_area(face: TopoDS_Shape) -> float:
    """Area of a face (or of all faces of a shape), in its units squared: adaptive integration to
    ``AREA_REL_PRECISION``."""
    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props, AREA_REL_PRECISION)
    return float(props.Mass())


def face_centroid(face: TopoDS_Shape) -> np.ndarray:
    """Area-weighted centroid (3,) of a face (or of all faces of a shape), in its units."""
    props = GProp_GProps()
    BRepGProp.SurfaceProperties_s(face, props, AREA_REL_PRECISION)
    return np.array(props.CentreOfMass().Coord(), float)


def part_box(vbrep: VBRep, fmap: FrameMap, margin_rel: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The part's box in the output frame (mm): the span of every face's mesh (the VB-Rep clips meshes to the
    measured part) plus ``margin_rel`` part sizes on every side; None without meshes."""
    pts = [np.asarray(f.mesh_vertices, float).reshape(-1, 3) for f in vbrep.faces]
    pts = [p for p in pts if len(p)]
    if not pts:
        return None
    xyz = fmap.points(np.concatenate(pts))
    xyz = xyz[np.all(np.isfinite(xyz), axis=1)]
    if len(xyz) == 0:
        return None
    pad = margin_rel * max(fmap.length(vbrep.scale), float(np.ptp(xyz, axis=0).max()))
    return xyz.min(0) - pad, xyz.max(0) + pad


def meshes(face: TopoDS_Face, deflection: float, angle_rad: float, min_share: float = 0.0) -> bool:
    """Whether OCCT triangulates a copy of ``face`` at this linear deflection (its units) and angle without
    errors: BRepMesh refuses a boundary wire that crosses itself once discretised (status SelfIntersectingWire),
    which BRepCheck passes when a vertex tolerance covers the crossing; such a face reads back from the STEP file
    with no triangles, so FreeCAD and every mesher show a hole where it is. With ``min_share`` > 0 the
    triangulation must also cover at least that share of the face's area: the mesher can draw a face whole at one
    deflection and as a sliver at another without any error (real frame ycb_video_000005 with its ROI: the box's
    top, 12,825 mm², drawn as 29 mm² at 0.2 mm)."""
    copy = BRepBuilderAPI_Copy(face, True, False).Shape()
    mesher = BRepMesh_IncrementalMesh(copy, deflection, False, angle_rad, True)
    if mesher.GetStatusFlags() != 0:
        return False
    tri = BRep_Tool.Triangulation_s(TopoDS.Face_s(copy), TopLoc_Location())
    if tri is None or tri.NbTriangles() == 0:
        return False
    if min_share <= 0:
        return True
    return drawn_area(TopoDS.Face_s(copy), deflection, angle_rad) >= min_share * face_area(copy)


def drawn_area(face: TopoDS_Face, deflection: float, angle_rad: float) -> float:
    """The area (its units squared) on its surface of OCCT's triangulation of ``face`` (meshed in place at this
    linear deflection, its units, and angle, as `face_triangulation`; 0 where the mesher leaves it bare): each
    triangle's (u, v) area times the surface's area element at its (u, v) centroid. The flat triangles are chords
    of a curved face and undercount it by its sagitta, with no hole anywhere (corpus training split, oracle: a
    0.3 mm cylinder drawn at 0.1 mm deflection came out 1.6 % short, and counted as drawn short); the region they
    cover on the surface is what a hole would shrink. Flat area where the triangulation has no (u, v) nodes."""
    BRepMesh_IncrementalMesh(face, deflection, False, angle_rad, True)
    loc = TopLoc_Location()
    tri = BRep_Tool.Triangulation_s(face, loc)
    if tri is None or tri.NbTriangles() == 0:
        return 0.0
    tris = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], int) - 1
    if not tri.HasUVNodes():
        pts = np.array([tri.Node(i).Coord() for i in range(1, tri.NbNodes() + 1)])
        return mesh_area(pts, tris)
    uv = np.array([tri.UVNode(i).Coord() for i in range(1, tri.NbNodes() + 1)])[tris]  # (M, 3, 2)
    a_uv = np.abs(signed_areas_2d(uv))
    return float(np.sum(a_uv * _area_element(BRep_Tool.Surface_s(face), uv.mean(axis=1))))


def _area_element(surface: object, uv: np.ndarray) -> np.ndarray:
    """|S_u x S_v| of an OCCT surface at the (u, v) points (K, 2): closed forms for the writer's five kinds (OCCT's
    parametrisations), the first derivatives of any other."""
    v = uv[:, 1]
    if isinstance(surface, Geom_Plane):
        return np.ones(len(uv))
    if isinstance(surface, Geom_CylindricalSurface):
        return area_element(PrimitiveType.CYLINDER, v, surface.Radius())
    if isinstance(surface, Geom_ConicalSurface):
        return area_element(PrimitiveType.CONE, v, surface.RefRadius(), half_angle=surface.SemiAngle())
    if isinstance(surface, Geom_SphericalSurface):
        return area_element(PrimitiveType.SPHERE, v, surface.Radius())
    if isinstance(surface, Geom_ToroidalSurface):
        return area_element(PrimitiveType.TORUS, v, surface.MajorRadius(), surface.MinorRadius())
    out = np.empty(len(uv))
    p, du, dv = gp_Pnt(), gp_Vec(), gp_Vec()
    for k, (a, b) in enumerate(uv):  # loop over the points (a surface of no closed form)
        surface.D1(float(a), float(b), p, du, dv)
        out[k] = du.Crossed(dv).Magnitude()
    return out


def face_triangulation(face: TopoDS_Face, deflection: float, angle_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """OCCT's triangulation of ``face`` (meshed in place at this linear deflection, its units, and angle): vertices
    (N, 3) and triangles (M, 3), wound along the face's orientation; empty when the mesher leaves it bare."""
    BRepMesh_IncrementalMesh(face, deflection, False, angle_rad, True)
    loc = TopLoc_Location()
    tri = BRep_Tool.Triangulation_s(face, loc)
    if tri is None:
        return np.zeros((0, 3)), np.zeros((0, 3), int)
    trsf = loc.Transformation()
    pts = np.array([tri.Node(i).Transformed(trsf).Coord() for i in range(1, tri.NbNodes() + 1)])
    tris = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], int) - 1
    if face.Orientation() == TopAbs_REVERSED:
        tris = tris[:, ::-1]
    return pts, tris


def _inside(shape: TopoDS_Shape, box: tuple[np.ndarray, np.ndarray] | None, deflection_rel: float = 1e-3) -> bool:
    """Whether a shape lies inside ``box`` (lo, hi), mm: the cheap, loose bounding box first (it contains the
    exact one), then the optimal one, then the box of a triangulation of a copy at ``deflection_rel`` of the box's
    largest extent, padded by that deflection. OCCT's optimal box of a curved face spans its surface over the
    rectangle of its (u, v) bounds: a torus blend wrapped 300 degrees round its axis (in-family validation seed
    9000, scan 2) got a box 18 mm past its own mesh, beyond the part's box, and the 5,715 mm² face was not
    written."""
    if box is None:
        return True

    def within(lo: np.ndarray, hi: np.ndarray) -> bool:
        return bool(np.all(lo >= box[0]) and np.all(hi <= box[1]))

    def corners(b: Bnd_Box) -> tuple[np.ndarray, np.ndarray]:
        return np.array(b.CornerMin().Coord()), np.array(b.CornerMax().Coord())

    loose = Bnd_Box()
    BRepBndLib.Add_s(shape, loose, False)
    if within(*corners(loose)) or within(*bounding_box(shape)):
        return True
    deflection = deflection_rel * float(np.max(box[1] - box[0]))
    copy = BRepBuilderAPI_Copy(shape, True, False).Shape()
    BRepMesh_IncrementalMesh(copy, deflection, False, 0.2, True)
    meshed = Bnd_Box()
    BRepBndLib.Add_s(copy, meshed, True)
    if meshed.IsVoid():
        return False
    lo, hi = corners(meshed)
    return within(lo - deflection, hi + deflection)


def _edge_off_face(eb: EdgeBuilder, f: VFace) -> tuple[int, float] | None:
    """(VEdge id, mm) of an edge of ``f``'s loops fitted on its other face and lying farther than ``join_tol``
    off ``f``'s surface (`EdgeBuilder.off_surface`: a gap between the two faces), else None. Such a face is not
    bounded by its loops: OCCT would take the edge onto it by raising its tolerance to that gap (a sugar box's side
    bounded across 8.5 mm), so the file would join what the reconstruction leaves apart."""
    for lp in f.loops:
        for eid, _ in lp:
            other, dist = eb.off_surface.get(eid, (None, 0.0))
            if other == f.id and dist > eb.join_tol and (f.id, eid) not in eb.copies:
                return eid, dist
    return None


def _add_shell(bb: BRep_Builder, compound: TopoDS_Compound, faces: list[TopoDS_Face]) -> None:
    shell = TopoDS_Shell()
    bb.MakeShell(shell)
    for face in faces:
        bb.Add(shell, face)
    shell.Closed(False)
    bb.Add(compound, shell)


def _placed(
    pieces: list[OutlinePiece], fb: FaceBuilder, f: VFace
) -> tuple[list[OutlinePiece], list[TopoDS_Face], float]:
    """Outline ``pieces`` of face ``f``, largest first, their faces turned to the camera (`FaceBuilder`), and those
    faces' total area (mm²)."""
    pieces = sorted(pieces, key=lambda p: -face_area(p.face))
    oriented = [fb.orient_to_camera(p.face, f) for p in pieces]
    return pieces, oriented, sum(face_area(p) for p in oriented)


def build_brep(
    vbrep: VBRep,
    fmap: FrameMap,
    config: BrepConfig | None = None,
    force_outline: frozenset[int] = frozenset(),
    raw_outline: frozenset[int] = frozenset(),
) -> BuiltBRep:
    """The OCCT topology of a VB-Rep in the output frame of ``fmap`` (millimetres); see the module doc.

    force_outline: VFace ids bounded by their mesh outline whatever their loops (`exporters.step.write` uses
    it for faces that a STEP round trip changed); raw_outline: VFace ids whose outline is taken as the mesh gives
    it, not simplified (`exporters.step.write`: outline faces OCCT's mesher drew short)."""
    cfg = config or BrepConfig()
    eb = EdgeBuilder(vbrep, fmap, cfg).run()
    fb = FaceBuilder(eb)
    ob = OutlineBuilder(
        vbrep,
        fmap,
        eb.fit_tol,
        cfg.outline_tol_area_rel,
        cfg.outline_min_piece_rel,
        cfg.fix_precision,
        max_stretch=cfg.outline_max_stretch,
        min_piece_tris=cfg.outline_min_piece_tris,
        speck_budget_rel=cfg.outline_speck_budget_rel,
        hole_budget_rel=cfg.outline_hole_budget_rel,
    )
    out = BuiltBRep(shape=TopoDS_Compound(), fmap=fmap, box=part_box(vbrep, fmap, cfg.box_margin_rel))
    faces: dict[int, TopoDS_Face] = {}
    face_edges: dict[int, set[int]] = {}
    # VFace id -> (piece, the VEdge ids its loops hold) for a face built from its loops in several pieces
    loop_parts: dict[int, list[tuple[TopoDS_Face, set[int]]]] = {}
    mesh_deflection = max(cfg.mesh_check_deflection_abs, cfg.mesh_check_deflection_rel * fmap.length(vbrep.scale))
    # instances whose curved fit missed their readings and that the extraction wrote as their readings' plane
    replaced = set((vbrep.meta.get("extract") or {}).get("planes_for_unseen_surfaces") or [])
    for f in vbrep.faces:
        if f.instance in replaced:
            eb.warnings.append(
                f"face {f.id}: its curved fit missed its own readings; written as the plane through them"
            )
        if f.id not in eb.surfaces:
            out.skipped_faces.append(f.id)
            continue
        if not len(f.mesh_triangles):  # the reconstruction holds no area for it (v2c.vbrep: its mesh was
            # left empty, e.g. its readings contradict its surface): a face built from its loops would add
            # geometry the reconstruction does not have
            eb.warnings.append(f"face {f.id}: no mesh in the reconstruction; skipped")
            out.skipped_faces.append(f.id)
            continue
        mesh_pts = fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        target = reconstructed_area(eb.surfaces[f.id], mesh_pts, f.mesh_triangles, cfg.outline_max_stretch)
        out.mesh_area[f.id] = target
        centre = mesh_centroid(mesh_pts, f.mesh_triangles)
        if f.id in force_outline:
            made, why = None, "the STEP round trip changed its face"
        elif (off := _edge_off_face(eb, f)) is not None:
            made, why = None, f"its edge {off[0]} lies {off[1]:.3g} mm off its surface (more than {eb.join_tol:.3g} mm)"
        else:
            made, why = fb.build_face(f, eb.edges), "boundary wire invalid"
        if made is not None:
            built = [face for face, _ in made]
            areas = [face_area(face) for face in built]
            area = sum(areas)
            shift = 0.0
            if centre is not None and area > 0:
                middle = sum(a * face_centroid(face) for a, face in zip(areas, built)) / area
                shift = float(np.linalg.norm(middle - centre))
            if target > 0 and abs(area - target) > cfg.area_tol_rel * target:
                why = f"its loops bound {area:.4g} mm² of a {target:.4g} mm² reconstruction"
            elif target > 0 and shift > cfg.placement_tol_rel * np.sqrt(target):
                why = f"its loops bound its area {shift:.3g} mm away from its reconstruction"
            elif not all(_inside(face, out.box) for face in built):
                why = "its loops reach outside the part's box"
            elif not all(
                meshes(face, k * mesh_deflection, cfg.mesh_check_angle_rad, 1.0 - cfg.area_tol_rel)
                for face in built
                for k in cfg.mesh_check_scales
            ):
                why = "OCCT's mesher does not draw it whole (its boundary wire crosses itself once discretised)"
            else:
                for k, face in enumerate(built):
                    fb.done[(f.id, k)] = face
                faces[f.id] = built[0]
                if len(built) > 1:  # seen in pieces: each its own OCCT face, all named after it
                    loop_parts[f.id] = [(face, {eid for lp in loops for eid, _ in lp}) for face, loops in made]
                face_edges[f.id] = {eid for _, loops in made for lp in loops for eid, _ in lp}
                out.built_area[f.id] = area
                continue
        pieces = [p for p in ob.build(f, eb.surfaces[f.id], f.id in raw_outline) if _inside(p.face, out.box)]
        if not pieces:
            eb.warnings.append(f"face {f.id}: {why}, and no face could be built from its mesh outline; skipped")
            out.skipped_faces.append(f.id)
            continue
        pieces, oriented, area = _placed(pieces, fb, f)
        if target > 0 and abs(area - target) > cfg.area_tol_rel * target:
            # the simplification, the specks dropped and the shrink that parts touching rings each stay within
            # their budget, yet together took the face past the tolerance (a 4.4 mm² torus strip of the corpus
            # training split read back 2.7 % short; the shrink alone takes a thin blend's perimeter times the ring
            # gap): the outline as the mesh gives it, every piece kept, its rings parted by cuts at their pinches
            # (`brep_outline._cut_pinches`), if closer
            alt = _placed(
                [p for p in ob.build(f, eb.surfaces[f.id], raw=True, whole=True) if _inside(p.face, out.box)], fb, f
            )
            if alt[1] and abs(alt[2] - target) < abs(area - target):
                pieces, oriented, area = alt
        out.built_area[f.id] = area
        eb.warnings.append(
            f"face {f.id}: {why}; bounded by its mesh outline instead ({out.built_area[f.id]:.4g} of {target:.4g} mm²)"
        )
        out.fallback_faces.append(f.id)
        faces[f.id] = oriented[0]
        out.face_parts[f.id] = oriented
        out.outline_edges[f.id] = [e for p in pieces for e in p.edges]
        face_edges[f.id] = set()
    # ShapeFix may have replaced edges (recorded in the shared context): follow the replacements.
    for eid, ed in eb.edges.items():
        out.edges[eid] = edges_of(fb.ctx.Apply(ed))
    copied = sorted((fid, eid) for (fid, eid) in eb.copies if eid in face_edges.get(fid, ()))
    for fid, eid in copied:
        out.copied_edges.setdefault(eid, []).append(fid)
    # shells join faces through the edges they share, not through copies; a face in pieces joins through each
    # piece's own edges, and an outline face's pieces share no edge (a shell must be connected)
    shared = {fid: {eid for eid in es if (fid, eid) not in eb.copies} for fid, es in face_edges.items()}
    nodes: list[tuple[int, TopoDS_Face, bool]] = []  # (VFace id, face, built from loops)
    node_edges: dict[int, set[int]] = {}
    for fid in shared:
        if fid in out.face_parts:
            pieces = [(part, set()) for part in out.face_parts[fid]]
        else:
            pieces = loop_parts.get(fid, [(faces[fid], shared[fid])])
        for face, es in pieces:
            node_edges[len(nodes)] = {eid for eid in es if (fid, eid) not in eb.copies}
            nodes.append((fid, face, fid not in out.face_parts))
    eb.bb.MakeCompound(out.shape)
    placed: dict[int, list[TopoDS_Face]] = {}
    for group in connected_groups(node_edges):
        shell = []
        for k in group:
            fid, face, from_loops = nodes[k]
            if from_loops:
                face = TopoDS.Face_s(fb.ctx.Apply(face))
            placed.setdefault(fid, []).append(face)
            shell.append(face)
        _add_shell(eb.bb, out.shape, shell)
    for fid, pieces in placed.items():
        out.faces[fid] = pieces[0]
        if fid in loop_parts:
            out.face_parts[fid] = pieces
    used = set().union(*shared.values()) if shared else set()
    outlined = set(out.fallback_faces)
    faces_by_edge = {e.id: set(e.faces) for e in vbrep.edges}
    # the VEdge names the outline faces' edges carry (`brep_outline`: each after the face's nearest VB-Rep edge)
    carried = {name for fid in outlined for _, name in out.outline_edges.get(fid, [])}
    for eid in sorted(out.edges):
        if eid in used:
            continue
        if faces_by_edge.get(eid, set()) & outlined and eid in carried:
            out.dropped_edges.append(eid)  # the outline's edges carry its name
            continue
        if eid in out.copied_edges:
            out.dropped_edges.append(eid)  # a face's copy of it carries its name
            continue
        if not all(_inside(ed, out.box) for ed in out.edges[eid]):
            out.dropped_edges.append(eid)
            eb.warnings.append(f"edge {eid}: lies outside the part's box; not written")
            continue
        out.free_edges.append(eid)
        for ed in out.edges[eid]:
            eb.bb.Add(out.shape, ed)
    for eid in out.dropped_edges:
        out.edges.pop(eid, None)
    for fid, eid in copied:
        out.edges.setdefault(eid, []).extend(edges_of(fb.ctx.Apply(eb.copies[(fid, eid)])))
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
        copied_edges={k: list(v) for k, v in built.copied_edges.items()},
        fallback_faces=list(built.fallback_faces),
        skipped_faces=list(built.skipped_faces),
        warnings=list(built.warnings),
        face_parts={fid: [TopoDS.Face_s(tr.ModifiedShape(f)) for f in fs] for fid, fs in built.face_parts.items()},
        outline_edges={
            fid: [(TopoDS.Edge_s(tr.ModifiedShape(e)), eid) for e, eid in es] for fid, es in built.outline_edges.items()
        },
        dropped_edges=list(built.dropped_edges),
        mesh_area=dict(built.mesh_area),
        built_area=dict(built.built_area),
        box=None if built.box is None else (built.box[0] + shift, built.box[1] + shift),
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
