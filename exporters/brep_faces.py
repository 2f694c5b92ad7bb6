"""Step 5 of `exporters.brep`: each VB-Rep face as an OCCT face on its analytic surface, bounded by the shared
edges of `exporters.brep_edges` (its loops, or a repaired version of them), else by its mesh outline."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np
import shapely
from OCP.BRep import BRep_Tool
from OCP.BRepAdaptor import BRepAdaptor_Curve2d
from OCP.BRepCheck import BRepCheck_Analyzer, BRepCheck_NoError, BRepCheck_Wire
from OCP.Geom2d import Geom2d_TrimmedCurve
from OCP.Geom2dAPI import Geom2dAPI_InterCurveCurve
from OCP.ShapeBuild import ShapeBuild_ReShape
from OCP.ShapeFix import ShapeFix_Face
from OCP.TopAbs import TopAbs_EDGE, TopAbs_REVERSED, TopAbs_WIRE
from OCP.TopExp import TopExp, TopExp_Explorer
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Face, TopoDS_Shape, TopoDS_Vertex, TopoDS_Wire
from OCP.TopTools import TopTools_IndexedMapOfShape

from exporters.occ_curves import pcurve_points
from exporters.occ_surfaces import AnalyticSurface, distance_to_surface
from exporters.polygons import polygon_crossings
from v2c.vbrep.mesh import triangle_areas

if TYPE_CHECKING:
    from exporters.brep_edges import EdgeBuilder, EdgeGeom
    from v2c.vbrep.model import VFace

Loop = list[tuple[int, bool]]


def edges_of(shape: TopoDS_Shape) -> list[TopoDS_Edge]:
    """The edges of a shape (the shape itself when it is one)."""
    if shape.ShapeType() == TopAbs_EDGE:
        return [TopoDS.Edge_s(shape)]
    out = []
    exp = TopExp_Explorer(shape, TopAbs_EDGE)
    while exp.More():
        out.append(TopoDS.Edge_s(exp.Current()))
        exp.Next()
    return out


def _first_crossing(a: np.ndarray, b: np.ndarray) -> tuple[tuple[int, float], tuple[int, float]] | None:
    """Where polyline ``b`` (M, 2) first properly crosses polyline ``a`` (N, 2), both starting at one point: the
    segment index and fraction along it on each (the crossing with the smallest index sum); None without one."""
    p, r = a[:-1], np.diff(a, axis=0)
    q, s_ = b[:-1], np.diff(b, axis=0)
    den = r[:, None, 0] * s_[None, :, 1] - r[:, None, 1] * s_[None, :, 0]
    qp = q[None, :, :] - p[:, None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (qp[..., 0] * s_[None, :, 1] - qp[..., 1] * s_[None, :, 0]) / den
        u = (qp[..., 0] * r[:, None, 1] - qp[..., 1] * r[:, None, 0]) / den
    ok = (np.abs(den) > 1e-15) & (t > 1e-9) & (t < 1 - 1e-9) & (u > 1e-9) & (u < 1 - 1e-9)
    ok[0, 0] = False  # the two first segments meet at the shared start
    if not ok.any():
        return None
    i, j = np.nonzero(ok)
    k = int(np.argmin(i + j))
    return (int(i[k]), float(t[i[k], j[k]])), (int(j[k]), float(u[i[k], j[k]]))


def _from_end(g: EdgeGeom, end: int, span: float, n: int) -> np.ndarray:
    """(n,) parameters of edge geometry ``g`` from its end ``end`` (0: t0, 1: t1) over ``span`` of its range."""
    start = g.t1 if end else g.t0
    return np.linspace(start, g.t0 + (1 - span if end else span) * (g.t1 - g.t0), n)


class FaceBuilder:
    """Step 5 on the result of an `EdgeBuilder`: `build_face`, else `build_fallback_face`. ShapeFix's edge
    replacements are kept in the shared context ``ctx`` (apply it to faces and edges at the end); ``done``
    holds the faces built so far."""

    def __init__(self, eb: EdgeBuilder) -> None:
        self.vb = eb.vb
        self.fmap = eb.fmap
        self.cfg = eb.cfg
        self.fit_tol = eb.fit_tol
        self.surfaces = eb.surfaces
        self.geoms = eb.geoms
        self.copy_geoms = eb.copy_geoms
        self.copies = eb.copies
        # ShapeFix raises no tolerance past what the file may join (`BrepConfig.join_tol_*`; a face it cannot
        # close within that is not bounded by its loops)
        self.max_tolerance = min(self.cfg.fix_max_tolerance, 1.05 * eb.join_tol + self.cfg.min_tolerance)
        self.vpos = eb.vpos
        self.edges = eb.edges
        self.vid = eb.vid
        self.eb = eb
        self.loop_area_uv = eb.loop_area_uv
        self.degenerate = eb.degenerate
        self.warnings = eb.warnings
        self.bb = eb.bb
        self.ctx = ShapeBuild_ReShape()
        self.done: dict[tuple[int, int], TopoDS_Face] = {}  # (VFace id, piece) -> the face built so far

    def _wire(self, loop: Loop, edges: dict[int, TopoDS_Edge]) -> TopoDS_Wire | None:
        w = TopoDS_Wire()
        self.bb.MakeWire(w)
        for eid, rev in loop:
            if eid not in edges:
                return None
            ed = TopoDS.Edge_s(self.ctx.Apply(edges[eid]))
            self.bb.Add(w, ed.Reversed() if rev else ed)
        w.Closed(True)
        return w

    def _loop_uv_polygon(
        self,
        s: AnalyticSurface,
        loop: Loop,
        n: int = 40,
        fid: int | None = None,
    ) -> tuple[np.ndarray, float] | None:
        """The loop's built edges sampled in the surface's (u, v) ((M, 2), periodic parameters made
        continuous) and their largest distance off the surface (mm, for edges carried by the other face); None
        when an edge is missing or the loop winds around a periodic surface (no closed polygon)."""
        pts, dev = [], 0.0
        for eid, rev in loop:
            g = self.copy_geoms.get((fid, eid), self.geoms.get(eid))  # face ``fid``'s own copy, if it has one
            if g is None:
                return None
            uv, xyz = self._geom_samples(s, g, np.linspace(g.t0, g.t1, n))
            if xyz is not None:
                dev = max(dev, float(distance_to_surface(s, xyz).max()))
            pts.append((uv[::-1] if rev else uv)[:-1])
        poly = np.concatenate(pts)
        for k, periodic in ((0, s.u_periodic), (1, s.v_periodic)):
            if periodic:
                poly[:, k] = np.unwrap(poly[:, k])
                if abs(poly[-1, k] - poly[0, k]) > np.pi / 2:  # winds around: the closing jump is a period
                    return None
        return poly, dev

    def _vertex_reach(self, sampled: list[tuple[np.ndarray, float]]) -> float:
        """How far from a vertex (mm) its loop edges may cross and still meet there: ``vertex_reach_fit_tols`` fit
        tolerances, ``vertex_reach_rel`` of the part size, or twice the farthest a sampled loop edge lies off the
        face's surface (edges off the surface get that much tolerance once fixed), whichever is largest."""
        return max(
            self.cfg.vertex_reach_fit_tols * self.fit_tol,
            self.cfg.vertex_reach_rel * self.fmap.length(self.vb.scale),
            2 * max((d for _, d in sampled), default=0.0),
        )

    def _boundaries_cross(self, s: AnalyticSurface, loops: list[Loop], fid: int | None = None) -> tuple[bool, float]:
        """Whether the loops' edges cross each other away from their vertices (sampled in (u, v)), and the
        vertices' reach (mm, `_vertex_reach`); crossings within a vertex's reach (as BRepCheck tolerates them
        once `_cover_vertex_crossings` has run) and loops that cannot be sampled do not count."""
        sampled = [self._loop_uv_polygon(s, lp, fid=fid) for lp in loops]
        if any(p is None for p in sampled):
            return False, self._vertex_reach([])
        reach = self._vertex_reach(sampled)
        pts = polygon_crossings([p for p, _ in sampled])
        if len(pts) == 0:
            return False, reach
        ends = np.array(
            [self.vpos[v] for lp in loops for eid, _ in lp for v in (self.vb.edges[eid].v0, self.vb.edges[eid].v1)]
        )
        dist = np.linalg.norm(s.evaluate(pts)[:, None] - ends[None], axis=2).min(1)
        return bool(np.any(dist > reach)), reach

    def _adjacent_crossing(self, face: TopoDS_Face) -> tuple[TopoDS_Vertex, float] | None:
        """The first pair of edges of one of the face's wires that BRepCheck finds crossing, when they share a
        vertex: that vertex and the distance (mm) from it to the farthest point where their pcurves cross; None
        when no wire self-intersects, the crossing edges share no vertex, or their crossings cannot be found."""
        exp = TopExp_Explorer(face, TopAbs_WIRE)
        while exp.More():
            wire = TopoDS.Wire_s(exp.Current())
            exp.Next()
            e1, e2 = TopoDS_Edge(), TopoDS_Edge()
            if BRepCheck_Wire(wire).SelfIntersect(face, e1, e2, False) == BRepCheck_NoError:
                continue
            if e1.IsNull() or e2.IsNull() or e1.IsSame(e2):
                return None
            ends2 = [TopExp.FirstVertex_s(e2), TopExp.LastVertex_s(e2)]
            common = [v for v in (TopExp.FirstVertex_s(e1), TopExp.LastVertex_s(e1)) if any(v.IsSame(w) for w in ends2)]
            if not common:
                return None
            curves = []
            for e in (e1, e2):
                ad = BRepAdaptor_Curve2d(e, face)
                c = BRep_Tool.CurveOnSurface_s(e, face, 0.0, 0.0)
                if c is None:
                    return None
                curves.append(Geom2d_TrimmedCurve(c, ad.FirstParameter(), ad.LastParameter()))
            inter = Geom2dAPI_InterCurveCurve(curves[0], curves[1], self.cfg.fix_precision)
            if inter.NbPoints() == 0:
                return None
            surf = BRep_Tool.Surface_s(face)
            pts = [surf.Value(inter.Point(k).X(), inter.Point(k).Y()) for k in range(1, inter.NbPoints() + 1)]
            vx = min(common, key=lambda v: max(BRep_Tool.Pnt_s(v).Distance(p) for p in pts))
            return vx, max(BRep_Tool.Pnt_s(vx).Distance(p) for p in pts)
        return None

    def _cover_vertex_crossings(self, face: TopoDS_Face, reach: float) -> bool:
        """Whether the face is valid once every pair of adjacent wire edges that BRepCheck finds crossing near
        their shared vertex (within ``reach`` mm: an edge trimmed a little past the corner, its exact curve kept)
        has that vertex's tolerance raised to cover the crossing; at most ``max_vertex_repairs`` repairs."""
        for _ in range(self.cfg.max_vertex_repairs):
            if BRepCheck_Analyzer(face).IsValid():
                return True
            found = self._adjacent_crossing(face)
            if found is None or found[1] > reach:
                return False
            vx, dist = found
            tol = 1.05 * dist + self.cfg.min_tolerance
            if tol <= BRep_Tool.Tolerance_s(vx):
                return False  # covered already: BRepCheck objects to something else
            self.bb.UpdateVertex(vx, tol)
        return BRepCheck_Analyzer(face).IsValid()

    def _fix_face(self, face: TopoDS_Face, ctx: ShapeBuild_ReShape | None = None) -> TopoDS_Face:
        fix = ShapeFix_Face(face)
        # Only the fixes that complete a boundary (pcurves, seams, periodic shifts, same-parameter, vertex
        # tolerances, order): the repairs that cut, drop or re-route edges and wires are off. They would
        # change the VB-Rep's edges (losing their attributes) and cost seconds on a wire that is wrong anyway;
        # such a face fails BRepCheck and gets its fallback instead.
        fix.FixIntersectingWiresMode = 0
        fix.FixLoopWiresMode = 0
        fix.FixSplitFaceMode = 0
        fix.FixSmallAreaWireMode = 0
        wire = fix.FixWireTool()
        wire.FixSelfIntersectionMode = 0
        wire.FixIntersectingEdgesMode = 0
        wire.FixNonAdjacentIntersectingEdgesMode = 0
        wire.FixSmallMode = 0
        wire.FixNotchedEdgesMode = 0
        wire.FixTailMode = 0
        wire.FixLackingMode = 0
        fix.SetContext(ctx if ctx is not None else self.ctx)
        fix.SetPrecision(self.cfg.fix_precision)
        fix.SetMaxTolerance(self.max_tolerance)
        fix.Perform()
        return fix.Face()

    def _loop_closed(self, loop: Loop) -> bool:
        """True when the loop's edges chain end to start through shared vertices back to the start."""
        ends = []
        for eid, rev in loop:
            e = self.vb.edges[eid]
            v0, v1 = self.vid(e.v0), self.vid(e.v1)
            ends.append((v1, v0) if rev else (v0, v1))
        return all(ends[i][1] == ends[(i + 1) % len(ends)][0] for i in range(len(ends)))

    def orient_to_camera(self, face: TopoDS_Face, f: VFace) -> TopoDS_Face:
        """``face``, reversed if needed so its normal at the mesh centroid faces the camera centre (every face of
        one view is seen from its outside)."""
        s = self.surfaces[f.id]
        pts = self.fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        if len(pts) == 0:
            return face
        uv = s.uv(pts.mean(0)[None])
        p = s.evaluate(uv)[0]
        n = s.normal(uv)[0] * (-1.0 if face.Orientation() == TopAbs_REVERSED else 1.0)
        if n @ (self.fmap.camera_center - p) < 0:
            face = TopoDS.Face_s(face.Reversed())
        return face

    def _try_face(
        self,
        f: VFace,
        loops: list[Loop],
        edges: dict[int, TopoDS_Edge],
    ) -> TopoDS_Face | None:
        """The face bounded by ``loops`` (outer first) if ShapeFix makes it valid; edge replacements ShapeFix
        made are kept (in the shared context) only when it does."""
        s = self.surfaces[f.id]
        wires = [self._wire(lp, edges) for lp in loops]
        if not wires or any(w is None for w in wires):
            return None
        crossed, reach = self._boundaries_cross(s, loops, f.id)
        if crossed:
            return None  # BRepCheck would say so too, at a hundred times the cost
        face = TopoDS_Face()
        self.bb.MakeFace(face, s.geom, self.cfg.fix_precision)
        for k, (w, lp) in enumerate(zip(wires, loops)):
            # OCCT wants the outer wire counter-clockwise in (u, v), holes clockwise.
            area = self.loop_area_uv(s, lp)
            self.bb.Add(face, w.Reversed() if (area < 0) == (k == 0) else w)
        local = ShapeBuild_ReShape()
        try:
            face = self._fix_face(face, local)
        except Exception as exc:  # noqa: BLE001 - any OCCT failure: try without broken loops, then the mesh
            self.warnings.append(f"face {f.id}: ShapeFix_Face failed ({exc})")
            return None
        try:
            covered = self._cover_vertex_crossings(face, reach)
        except Exception as exc:  # noqa: BLE001 - OCCT's checks raise on extreme curves (Cosh overflow on a
            # hyperbola's parameter in BRepCheck_Wire.SelfIntersect): the face is not built from these loops
            self.warnings.append(f"face {f.id}: its boundary check failed ({exc})")
            return None
        if not covered:
            return None
        # ShapeFix may drop a wire it finds inconsistent and return a valid face of the rest: the face must
        # still hold every loop edge (or what ShapeFix replaced it with).
        held = TopTools_IndexedMapOfShape()
        TopExp.MapShapes_s(face, TopAbs_EDGE, held)
        replaced = []
        for lp in loops:
            for eid, _ in lp:
                old = self.ctx.Apply(edges[eid])
                new = local.Value(old)
                if not all(held.Contains(x) for x in edges_of(new)):
                    return None
                if not new.IsSame(old):
                    replaced.append((old, new))
        if replaced and not self._replacements_keep_faces_valid(replaced):
            return None
        for old, new in replaced:
            self.ctx.Replace(old, new)
        return self.orient_to_camera(face, f)

    def _try_cut(
        self,
        f: VFace,
        loops: list[Loop],
        edges: dict[int, TopoDS_Edge],
        cut_edges: dict[int, TopoDS_Edge],
        cut_geoms: dict[int, EdgeGeom],
    ) -> TopoDS_Face | None:
        """`_try_face` with the face's own cut copies of some loop edges (`_corner_cuts`); kept as this face's
        copies (``copies``, ``copy_geoms``) when the face is valid, else forgotten."""
        saved = {eid: self.copy_geoms.get((f.id, eid)) for eid in cut_geoms}
        for eid, g in cut_geoms.items():
            self.copy_geoms[(f.id, eid)] = g
        face = self._try_face(f, loops, {**edges, **cut_edges})
        if face is None:
            for eid, g in saved.items():
                if g is None:
                    self.copy_geoms.pop((f.id, eid), None)
                else:
                    self.copy_geoms[(f.id, eid)] = g
            return None
        for eid, ed in cut_edges.items():
            self.copies[(f.id, eid)] = ed
        self.warnings.append(f"face {f.id}: its edges {sorted(cut_edges)} cut at the corners where they cross")
        return face

    def _replacements_keep_faces_valid(self, replaced: list[tuple[TopoDS_Shape, TopoDS_Shape]]) -> bool:
        """Whether the faces built so far stay valid when ShapeFix's replacements of shared edges (made while
        fixing another face) are applied to them."""
        trial = ShapeBuild_ReShape()
        for old, new in replaced:
            trial.Replace(old, new)
        for face in self.done.values():
            current = self.ctx.Apply(face)
            moved = trial.Apply(current)
            if not moved.IsSame(current) and not BRepCheck_Analyzer(moved).IsValid():
                return False
        return True

    def _rechain(self, loops: list[Loop]) -> list[Loop] | None:
        """The loops' edges chained again through their shared vertex ids (orientations recomputed), when they
        form closed loops that way; None when some chain does not close."""
        todo = [eid for lp in loops for eid, _ in lp if eid in self.geoms]
        at: dict[int, list[int]] = defaultdict(list)
        ends = {eid: (self.vid(self.vb.edges[eid].v0), self.vid(self.vb.edges[eid].v1)) for eid in todo}
        for eid in todo:
            v0, v1 = ends[eid]
            at[v0].append(eid)
            if v1 != v0:
                at[v1].append(eid)
        used: set[int] = set()
        out = []
        for first in todo:
            if first in used:
                continue
            loop, used_here = [(first, False)], {first}
            start, cur = ends[first]
            while cur != start:
                nxt = next((x for x in at[cur] if x not in used and x not in used_here), None)
                if nxt is None:
                    return None
                n0, n1 = ends[nxt]
                rev = n1 == cur and n0 != cur
                loop.append((nxt, rev))
                used_here.add(nxt)
                cur = n0 if rev else n1
            used |= used_here
            out.append(loop)
        return out

    def _geom_samples(self, s: AnalyticSurface, g: EdgeGeom, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """An edge geometry at its parameters ``ts`` (N,) in the (u, v) of surface ``s`` ((N, 2)), and its 3D points
        (mm) when they were needed to get there (an exact curve, or a pcurve on another face's surface; None for a
        pcurve on ``s``)."""
        if g.curve is None and self.surfaces[g.face] is s:
            return pcurve_points(g.pcurve, ts), None
        xyz = self.eb.geom_at(g, ts)
        return s.uv(xyz), xyz

    def _geom_point(self, g: EdgeGeom, t: float) -> np.ndarray:
        """(3,) mm: an edge geometry's point at parameter ``t``."""
        return self.eb.geom_at(g, np.array([t]))[0]

    def _corner_cuts(
        self, f: VFace, loops: list[Loop], edges: dict[int, TopoDS_Edge]
    ) -> tuple[dict[int, TopoDS_Edge], dict[int, EdgeGeom]] | None:
        """Face ``f``'s own copies of the loop edges that cross the next edge of their loop near the vertex they
        share, each cut where they cross: each edge sampled ``cfg.corner_cut_samples`` times over the
        ``cfg.corner_cut_span`` of it nearest the vertex, where the crossing must lie on both, beyond the vertex's
        reach (`_vertex_reach`: nearer, the vertex's tolerance covers the crossing), the two curves there within
        ``join_tol``: the corner the two edges make on this face. A vertex placed off that corner (solved on three
        surfaces, or an occlusion vertex of the image) leaves the two edges running past each other to it, and the
        face's boundary crosses itself. Returns the copies (oriented v0 -> v1) and their geometries, or None when
        no corner is cut."""
        s = self.surfaces[f.id]
        n = self.cfg.corner_cut_samples
        if n < 4:
            return None
        geom = {eid: self.copy_geoms.get((f.id, eid), self.geoms.get(eid)) for lp in loops for eid, _ in lp}
        reach = self._vertex_reach([])
        cuts: dict[int, dict[int, tuple[float, int]]] = defaultdict(dict)  # eid -> {end: (parameter, corner)}
        corners: list[tuple[np.ndarray, float]] = []
        for lp in loops:
            for k in range(len(lp)):
                (ea, ra), (eb, rb) = lp[k], lp[(k + 1) % len(lp)]
                ga, gb = geom.get(ea), geom.get(eb)
                if ea == eb or ga is None or gb is None or ea not in edges or eb not in edges:
                    continue  # an edge OCCT could not make leaves the loop unbuildable anyway
                end_a, end_b = (0 if ra else 1), (1 if rb else 0)  # each edge's end at the shared vertex
                va = self.vb.edges[ea].v1 if end_a else self.vb.edges[ea].v0
                vb_ = self.vb.edges[eb].v1 if end_b else self.vb.edges[eb].v0
                if self.vid(va) != self.vid(vb_) or end_a in cuts[ea] or end_b in cuts[eb]:
                    continue
                # both parametrised from the shared vertex outwards, over corner_cut_span of their range
                span = self.cfg.corner_cut_span
                ta, tb = _from_end(ga, end_a, span, n), _from_end(gb, end_b, span, n)
                hit = _first_crossing(
                    s.unwrap(self._geom_samples(s, ga, ta)[0]), s.unwrap(self._geom_samples(s, gb, tb)[0])
                )
                if hit is None:
                    continue
                (ia, fa), (ib, fb) = hit
                txa = ta[ia] + fa * (ta[ia + 1] - ta[ia])
                tyb = tb[ib] + fb * (tb[ib + 1] - tb[ib])
                pa, pb = self._geom_point(ga, txa), self._geom_point(gb, tyb)
                gap = float(np.linalg.norm(pa - pb))
                if gap > self.eb.join_tol or np.linalg.norm(0.5 * (pa + pb) - self.vpos[self.vid(va)]) <= reach:
                    continue  # the curves do not meet there, or meet within the vertex's reach (its tolerance)
                cuts[ea][end_a] = (txa, len(corners))
                cuts[eb][end_b] = (tyb, len(corners))
                corners.append((0.5 * (pa + pb), 0.5 * gap))
        if not corners:
            return None
        vertices = [self.eb.vertex(x, 1.05 * half + self.cfg.min_tolerance) for x, half in corners]
        out_edges: dict[int, TopoDS_Edge] = {}
        out_geoms: dict[int, EdgeGeom] = {}
        for eid, ends in ((eid, ends) for eid, ends in cuts.items() if ends):
            g = geom[eid]
            t0, t1 = ends[0][0] if 0 in ends else g.t0, ends[1][0] if 1 in ends else g.t1
            cut = replace(g, t0=t0, t1=t1, end0=self._geom_point(g, t0), end1=self._geom_point(g, t1))
            old = TopoDS.Edge_s(self.ctx.Apply(edges[eid]))
            va = vertices[ends[0][1]] if 0 in ends else TopExp.FirstVertex_s(old, True)
            vb_ = vertices[ends[1][1]] if 1 in ends else TopExp.LastVertex_s(old, True)
            made = self.eb.make_edge(self.vb.edges[eid], cut, va, vb_)
            if made is None:
                return None
            out_edges[eid], out_geoms[eid] = made[1], cut
        return out_edges, out_geoms

    def _outer_groups(self, f: VFace, loops: list[Loop]) -> list[list[Loop]] | None:
        """The loops grouped as the boundaries of separate pieces, when the face is seen in several (an occluder or
        a gap in the segmentation cuts it in two): each loop that lies inside no other (in the face's (u, v)) is a
        piece's outer loop, largest first, followed by the loops inside it (in the smallest outer loop holding
        them). None when a loop cannot be sampled, its polygon is degenerate, or only one loop is outermost (one
        piece: the loops as given)."""
        s = self.surfaces[f.id]
        sampled = [self._loop_uv_polygon(s, lp, fid=f.id) for lp in loops]
        if any(p is None or len(p[0]) < 3 for p in sampled):
            return None
        centre = np.array([s.u_center, s.v_center])
        polys = []
        for p, _ in sampled:
            q = p.copy()
            for k, periodic in ((0, s.u_periodic), (1, s.v_periodic)):
                if periodic:  # each loop within half a period of the face's centre
                    q[:, k] -= 2 * np.pi * np.round((q[:, k].mean() - centre[k]) / (2 * np.pi))
            poly = shapely.Polygon(q)
            if not poly.is_valid or poly.area <= 0:
                return None
            polys.append(poly)
        inside = [
            [j for j in range(len(polys)) if j != i and polys[j].area > polys[i].area and polys[j].contains(polys[i])]
            for i in range(len(polys))
        ]
        outers = sorted((i for i in range(len(polys)) if not inside[i]), key=lambda i: -polys[i].area)
        if len(outers) < 2:
            return None
        groups = {i: [i] for i in outers}
        for i in range(len(polys)):
            if inside[i]:
                holder = min((j for j in inside[i] if j in groups), key=lambda j: polys[j].area, default=None)
                if holder is None:  # inside a hole only: an island, which these pieces do not hold
                    return None
                groups[holder].append(i)
        # a piece that holds none of the face's mesh is not in the reconstruction (its pixels' mesh was dropped as
        # a stray island, or lay where the sensor read nothing): not written
        support = self._mesh_support(
            f, s, [shapely.Polygon(polys[g[0]].exterior, [polys[h].exterior for h in g[1:]]) for g in groups.values()]
        )
        kept = []
        for members, share in zip(groups.values(), support):
            if share > self.cfg.area_tol_rel:
                kept.append([loops[k] for k in members])
            else:
                self.warnings.append(
                    f"face {f.id}: a piece of it bounded by {len(members)} loop(s) holds {100 * share:.2g} % of its "
                    "mesh; not written"
                )
        return kept or None

    def _mesh_support(self, f: VFace, s: AnalyticSurface, pieces: list[shapely.Polygon]) -> list[float]:
        """The share of face ``f``'s mesh area (its triangles' 3D areas) whose triangles' centroids lie in each
        piece (polygons in the surface's (u, v); `AnalyticSurface.uv` puts periodic parameters within half a period
        of the face's centre, as `_outer_groups` puts the pieces)."""
        pts = self.fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        tri = np.asarray(f.mesh_triangles, int).reshape(-1, 3)
        areas = triangle_areas(pts, tri)
        total = float(areas.sum())
        if total <= 0:
            return [0.0] * len(pieces)
        uv = s.uv(pts[tri].mean(axis=1))
        return [float(areas[shapely.contains_xy(p, uv[:, 0], uv[:, 1])].sum()) / total for p in pieces]

    def build_face(
        self,
        f: VFace,
        edges: dict[int, TopoDS_Edge],
    ) -> list[tuple[TopoDS_Face, list[Loop]]] | None:
        """The face trimmed by its loops, as one or more pieces (each an OCCT face and the loops it kept), trying in
        turn: the VB-Rep's loops as separate pieces where they are (`_outer_groups`: the face seen in several
        pieces, which one face with holes cannot hold); the VB-Rep's loops; their edges chained again through
        shared vertices (when the given loops do not close); only the loops that close; the largest closed loop
        with each other closed loop that leaves it a valid face (largest first); only the largest closed loop.
        Anything after the VB-Rep's loops is reported as a warning. None if all fail."""
        # degenerate edges (dropped by the EdgeBuilder, their vertices merged) leave their loops
        given = [[(eid, rev) for eid, rev in lp if eid not in self.degenerate] for lp in f.loops]
        given = [lp for lp in given if lp]
        if not given:
            return None
        s = self.surfaces[f.id]
        # edges this face holds its own copy of (`EdgeBuilder._face_copies`): those, not the shared ones
        edges = {**edges, **{eid: ed for (fid, eid), ed in self.copies.items() if fid == f.id}}

        def by_area(loops: list[Loop]) -> list[Loop]:
            return sorted(loops, key=lambda lp: -abs(self.loop_area_uv(s, lp)))

        given_closed = all(self._loop_closed(lp) for lp in given)
        if len(given) > 1 and given_closed:
            groups = self._outer_groups(f, given)
            if groups is not None:
                parts = []
                for group in groups:
                    face = self._try_face(f, group, edges)
                    if face is None:
                        break
                    parts.append((face, group))
                else:
                    return parts
        attempts: list[tuple[str, list[Loop]]] = [("", given)]
        if not given_closed:
            chained = self._rechain(given)
            if chained:
                attempts.append(("its edges chained again through shared vertices", by_area(chained)))
        closed = by_area([lp for lp in given if self._loop_closed(lp)])
        if closed and len(closed) < len(given):
            attempts.append(("only its closed loops", closed))
        tried: list[list[Loop]] = []
        for why, loops in attempts:
            if loops in tried:
                continue
            tried.append(loops)
            face = self._try_face(f, loops, edges)
            if face is not None:
                return [self._report(f, why, face, loops)]
            if why == "" and given_closed:  # the VB-Rep's own loops
                try:
                    cut = self._corner_cuts(f, loops, edges)
                except Exception as exc:  # noqa: BLE001 - OCCT evaluation or projection failures: no cut
                    self.warnings.append(f"face {f.id}: its corners could not be cut ({type(exc).__name__}: {exc})")
                    cut = None
                if cut is not None:
                    face = self._try_cut(f, loops, edges, *cut)
                    if face is not None:
                        return [self._report(f, why, face, loops)]
        if len(closed) > 1:
            # the largest loop with each hole that leaves it a valid face, largest first (one hole whose wire
            # crosses the outer one in (u, v) no longer costs the face its other holes); tried only now, as every
            # valid trial keeps ShapeFix's edge replacements
            kept, face = closed[:1], None
            for hole in closed[1:]:
                if [*kept, hole] in tried:  # refused above (a refused trial changes nothing)
                    continue
                got = self._try_face(f, [*kept, hole], edges)
                if got is not None:
                    kept, face = [*kept, hole], got
            if face is not None:
                return [self._report(f, "its largest loop and the holes it can take", face, kept)]
            face = self._try_face(f, closed[:1], edges)
            if face is not None:
                return [self._report(f, "only its largest loop", face, closed[:1])]
        return None

    def _report(self, f: VFace, why: str, face: TopoDS_Face, loops: list[Loop]) -> tuple[TopoDS_Face, list[Loop]]:
        """``face`` and ``loops``, with a warning naming ``why`` when the face is not bounded by all its loops."""
        if why:
            self.warnings.append(f"face {f.id}: its loops do not bound a valid face; bounded by {why}")
        return face, loops
