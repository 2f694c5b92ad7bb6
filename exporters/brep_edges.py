"""Steps 1-4 of `exporters.brep`: surfaces, intersection curves, vertices and the shared `TopoDS_Edge` of
every VB-Rep edge (output frame, millimetres)."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from OCP.BRep import BRep_Builder, BRep_Tool
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
from OCP.BRepLib import BRepLib
from OCP.Geom import Geom_Curve
from OCP.Geom2d import Geom2d_Curve
from OCP.GeomAbs import GeomAbs_C2
from OCP.GeomAPI import GeomAPI_PointsToBSpline
from OCP.gp import gp_Pnt
from OCP.TColgp import TColgp_Array1OfPnt
from OCP.TopLoc import TopLoc_Location
from OCP.TopoDS import TopoDS, TopoDS_Edge, TopoDS_Vertex

from exporters.frames import FrameMap
from exporters.occ_curves import (
    curve_from_dict,
    curve_points,
    fit_pcurve,
    intersection_curves,
    is_elementary,
    iso_curve,
    nearest_branch,
    pcurve_points,
    project_on_curve,
)
from exporters.occ_surfaces import AnalyticSurface, distance_to_surface, make_surface
from exporters.polygons import signed_area, subsample
from v2c.labels import PrimitiveType
from v2c.vbrep.model import EdgeType
from v2c.vbrep.raycast import as_primitive, intersect, sheet_depth

if TYPE_CHECKING:
    from exporters.brep_config import BrepConfig
    from v2c.vbrep.model import VBRep, VEdge


@dataclass
class EdgeGeom:
    """Geometry of one edge before it becomes a TopoDS_Edge: a trimmed 3D curve, or a pcurve on a face."""

    curve: Geom_Curve | None = None
    face: int | None = None  # the face whose surface carries the pcurve
    pcurve: Geom2d_Curve | None = None
    t0: float = 0.0  # parameter at the VB-Rep edge's v0 ...
    t1: float = 0.0  # ... and at v1 (t1 < t0: the curve runs v1 -> v0)
    end0: np.ndarray | None = None  # 3D end points (mm) at t0 and t1
    end1: np.ndarray | None = None


def _unwrap_params(t: np.ndarray, period: float) -> np.ndarray:
    """Curve parameters made continuous along a polyline (jumps over half a period removed)."""
    d = np.diff(t)
    d -= period * np.round(d / period)
    return np.concatenate([[t[0]], t[0] + np.cumsum(d)])


def _near(t: float, ref: float, period: float | None) -> float:
    """``t`` shifted by whole periods to lie nearest ``ref``."""
    return t if period is None else t + period * np.round((ref - t) / period)


class EdgeBuilder:
    """Steps 1-4 for one VB-Rep: `run` fills ``surfaces`` (VFace id -> AnalyticSurface), ``curves``
    (intersection VEdge id -> untrimmed exact curve), ``vpos`` (VVertex id -> position, mm), ``geoms`` (VEdge
    id -> EdgeGeom) and ``edges`` (VEdge id -> TopoDS_Edge oriented from v0 to v1); problems go to
    ``warnings``.

    Guards: an edge whose polyline and end vertices span no more than ``fit_tol`` (a zero-length edge, or a
    closed edge shrunk to a point) gets no geometry and no TopoDS_Edge (``degenerate``); the two vertices of a
    degenerate open edge become one (``vertex_alias``: VVertex id -> the id standing for it), so the loops through
    it still close without it. An intersection edge without an exact intersection curve is fitted on the face
    whose surface its polyline lies nearer (``fit_face``); how far the fitted edge then lies off the other face's
    surface is measured (``off_surface``: VEdge id -> (face id, mm)) and reported as a warning: covered by the
    edge's tolerance up to ``join_tol``, a gap between the faces beyond it. A thin face's loop of two exact
    edges between the same two vertices is fitted so too (`refit_lens_loops`; ``lens_vertices``: VVertex id ->
    the face whose surface alone places it). Where the gap is wider than ``join_tol``, the other face gets a copy
    of the edge of its own, on its surface (``copies``: (VFace id, VEdge id) -> edge; `_face_copies`). A vertex
    joins only the edge ends within ``join_tol`` of it (its tolerance covers them); an end farther off gets a
    vertex of its own (shared with the other such ends on the same face's surface, `_own_vertices`) and a warning
    (`build_edges`), so no join of the file spans more than ``join_tol`` (max(0.5 mm, 1 % of the part),
    `BrepConfig.join_tol_*`); a vertex's alternating projection stops within ``vertex_move_*`` of the VB-Rep's
    vertex (`place_vertices`).
    """

    def __init__(self, vbrep: VBRep, fmap: FrameMap, config: BrepConfig) -> None:
        self.vb = vbrep
        self.fmap = fmap
        self.cfg = config
        size = fmap.length(vbrep.scale) if vbrep.scale > 0 else 100.0
        self.branch_tol = max(config.branch_tol_abs, config.branch_tol_rel * size)
        self.join_tol = max(config.join_tol_abs, config.join_tol_rel * size)
        self.fit_tol = max(config.fit_tol_abs, config.fit_tol_rel * size)
        self.pcurve_tol = max(config.pcurve_tol_abs, config.pcurve_tol_rel * size)
        self.warnings: list[str] = []
        self.surfaces: dict[int, AnalyticSurface] = {}
        self.curves: dict[int, Geom_Curve] = {}
        self.vpos: dict[int, np.ndarray] = {}
        self.geoms: dict[int, EdgeGeom] = {}
        self.edges: dict[int, TopoDS_Edge] = {}
        self.degenerate: set[int] = set()
        self.vertex_alias: dict[int, int] = {}
        self.fit_face: dict[int, int] = {}
        self.off_surface: dict[int, tuple[int, float]] = {}
        self.lens_vertices: dict[int, int] = {}
        self.vfaces = {f.id: f for f in vbrep.faces}
        # (VFace id, VEdge id) -> that face's own copy of an edge fitted on its other face and lying farther than
        # join_tol off this one (`build_edges`): on this face's surface, where its loop mesh has it
        self.copy_geoms: dict[tuple[int, int], EdgeGeom] = {}
        self.copies: dict[tuple[int, int], TopoDS_Edge] = {}
        self.bb = BRep_Builder()

    def run(self) -> EdgeBuilder:
        """All four steps, in order."""
        self.build_surfaces()
        self.find_degenerate_edges()
        self.build_intersection_curves()
        self.place_vertices()
        self.build_edge_geometry()
        self.refit_lens_loops()
        self.edges = self.build_edges()
        return self

    def build_surfaces(self) -> None:
        """Step 1: every face's analytic OCCT surface (output frame, mm); a face without one is skipped (a
        warning)."""
        for f in self.vb.faces:
            try:
                self.surfaces[f.id] = make_surface(f.primitive, self.fmap, f.mesh_vertices)
            except (ValueError, KeyError, TypeError) as exc:
                self.warnings.append(f"face {f.id}: no surface ({exc}); face skipped")

    def vid(self, v: int) -> int:
        """The VVertex id standing for ``v`` (itself unless merged through a degenerate edge)."""
        return self.vertex_alias.get(v, v)

    def find_degenerate_edges(self) -> None:
        """Edges spanning no more than ``fit_tol`` mm (polyline and end vertices): dropped; the ends of an open
        one merged into one vertex."""
        vpos = {v.id: self.fmap.points(v.position) for v in self.vb.vertices}
        parent: dict[int, int] = {}

        def find(v: int) -> int:
            while parent.get(v, v) != v:
                v = parent[v]
            return v

        for e in self.vb.edges:
            pts = [self.fmap.points(np.asarray(e.polyline, float).reshape(-1, 3))]
            pts += [vpos[v][None] for v in (e.v0, e.v1) if v in vpos]
            pts = np.concatenate(pts)
            span = float(np.linalg.norm(pts - pts[0], axis=1).max()) if len(pts) else 0.0
            if span > self.fit_tol:
                continue
            self.degenerate.add(e.id)
            kind = "closed" if e.v0 == e.v1 else "zero-length"
            self.warnings.append(
                f"edge {e.id}: degenerate {kind} edge (spans {span:.3g} mm); dropped"
                + ("" if e.v0 == e.v1 else f", vertices {e.v0} and {e.v1} merged")
            )
            a, b = find(e.v0), find(e.v1)
            if a != b:
                parent[max(a, b)] = min(a, b)
        self.vertex_alias = {v: find(v) for v in parent if find(v) != v}

    def build_intersection_curves(self) -> None:
        """Step 2: each intersection edge's exact, untrimmed curve (``curves``): the GeomAPI_IntSS branch nearest
        its polyline, the VB-Rep's own line/circle where that lies on both surfaces, or none (then ``fit_face``
        names the face its geometry will be fitted on)."""
        for e in self.vb.edges:
            if EdgeType(e.type) is not EdgeType.INTERSECTION or len(e.faces) != 2 or e.id in self.degenerate:
                continue
            fa, fb = e.faces
            if fa not in self.surfaces or fb not in self.surfaces:
                continue
            poly = subsample(self.fmap.points(e.polyline), self.cfg.branch_samples)
            if e.tangent:
                # a tangent junction: the surfaces barely cross, so GeomAPI_IntSS finds no curve or a wandering
                # one; the VB-Rep's line of contact is used when it lies within branch_tol of both surfaces
                c = curve_from_dict(e.curve, self.fmap)
                if c is not None:
                    t, d = project_on_curve(c, poly)
                    on = curve_points(c, t)
                    off = max(float(distance_to_surface(self.surfaces[f], on).max()) for f in (fa, fb))
                    if np.all(np.isfinite(d)) and d.max() <= self.branch_tol and off <= self.branch_tol:
                        self.curves[e.id] = c
                        continue
            try:
                cands = intersection_curves(self.surfaces[fa], self.surfaces[fb], self.cfg.intss_tol)
            except Exception as exc:  # noqa: BLE001 - OCCT raises Standard_Failure subclasses
                cands = []
                self.warnings.append(f"edge {e.id}: GeomAPI_IntSS failed ({exc})")
            curve, dist = nearest_branch(cands, poly)
            if curve is None or dist > self.branch_tol or not is_elementary(curve):
                # IntSS approximates some exact pairs (nearly coaxial surfaces of revolution): the VB-Rep's
                # own line/circle is used instead when it lies on both surfaces.
                exact = self._verified_dict_curve(e, poly)
                if exact is not None:
                    curve, dist = exact, 0.0
            if curve is None or dist > self.branch_tol:
                pts = self.fmap.points(np.asarray(e.polyline, float).reshape(-1, 3))
                off = {f: float(np.mean(distance_to_surface(self.surfaces[f], pts))) for f in (fa, fb)}
                near = min((fa, fb), key=lambda f: off[f])
                self.fit_face[e.id] = near
                self.warnings.append(
                    f"edge {e.id}: no intersection branch within {self.branch_tol:.2f} mm of the polyline "
                    f"({len(cands)} branches, nearest {dist:.2f} mm); fitted on face {near} instead (polyline "
                    f"{off[fa]:.2f} mm off face {fa}, {off[fb]:.2f} mm off face {fb})"
                )
                continue
            self.curves[e.id] = curve

    def _verified_dict_curve(self, e: VEdge, poly: np.ndarray) -> Geom_Curve | None:
        """The edge's analytic ``curve`` dict as an OCCT curve, if it runs along the polyline and lies on both
        faces' surfaces within ``analytic_tol``."""
        c = curve_from_dict(e.curve, self.fmap)
        if c is None:
            return None
        t, d = project_on_curve(c, poly)
        if not np.all(np.isfinite(d)) or d.max() > self.branch_tol:
            return None
        on = curve_points(c, t)
        if max(distance_to_surface(self.surfaces[f], on).max() for f in e.faces) > self.cfg.analytic_tol:
            return None
        return c

    def place_vertices(self) -> None:
        """Step 3: each vertex's position ``vpos`` (mm): alternating projection onto its incident intersection
        curves (the exact corner where three surfaces meet), else onto its faces' surfaces; a step that would take
        it farther than ``vertex_move_*`` from the VB-Rep's vertex is not taken (`BrepConfig`)."""
        inc_curves: dict[int, list[Geom_Curve]] = defaultdict(list)
        inc_surfs: dict[int, set[int]] = defaultdict(set)
        for e in self.vb.edges:
            if e.id in self.degenerate:
                continue
            for v in {self.vid(e.v0), self.vid(e.v1)}:
                if e.id in self.curves:
                    inc_curves[v].append(self.curves[e.id])
                inc_surfs[v].update(f for f in e.faces if f in self.surfaces)
        size = self.fmap.length(self.vb.scale) if self.vb.scale > 0 else 100.0
        reach = max(self.cfg.vertex_move_abs, self.cfg.vertex_move_rel * size)
        for v in self.vb.vertices:
            if v.id in self.vertex_alias:
                continue
            x = x0 = self.fmap.points(v.position)
            for _ in range(self.cfg.vertex_iterations):
                if inc_curves[v.id]:
                    proj = []
                    for c in inc_curves[v.id]:
                        t, d = project_on_curve(c, x[None])
                        if np.isfinite(d[0]):
                            proj.append(curve_points(c, t)[0])
                elif inc_surfs[v.id]:
                    proj = [self.surfaces[f].project(x[None])[0] for f in sorted(inc_surfs[v.id])]
                else:
                    break
                if not proj:
                    break
                nx = np.mean(proj, axis=0)
                if np.linalg.norm(nx - x0) > reach:
                    break  # drawn along near-parallel curves: the last step within reach of the VB-Rep's vertex
                done = np.linalg.norm(nx - x) < 1e-9
                x = nx
                if done or len(proj) == 1:
                    break
            self.vpos[v.id] = x
        for v, rep in self.vertex_alias.items():
            self.vpos[v] = self.vpos[rep]

    def _curve_geom(self, e: VEdge, curve: Geom_Curve) -> EdgeGeom | None:
        poly = subsample(self.fmap.points(e.polyline), self.cfg.branch_samples)
        period = curve.Period() if curve.IsPeriodic() else None
        t, _ = project_on_curve(curve, poly)
        if not np.all(np.isfinite(t)):
            return None
        if period is not None:
            t = _unwrap_params(t, period)
        (ta,), _ = project_on_curve(curve, self.vpos[e.v0][None])
        (tb,), _ = project_on_curve(curve, self.vpos[e.v1][None])
        if not (np.isfinite(ta) and np.isfinite(tb)):
            return None
        ta = _near(ta, t[0], period)
        if self.vid(e.v0) == self.vid(e.v1):
            if period is None:
                return None
            tb = ta + np.sign(t[-1] - t[0] or 1.0) * period
        else:
            tb = _near(tb, t[-1], period)
        if period is None:
            lo, hi = curve.FirstParameter(), curve.LastParameter()
            ta, tb = float(np.clip(ta, lo, hi)), float(np.clip(tb, lo, hi))
        if abs(tb - ta) < 1e-9:
            return None
        ends = curve_points(curve, np.array([ta, tb]))
        return EdgeGeom(curve=curve, t0=float(ta), t1=float(tb), end0=ends[0], end1=ends[1])

    def _pcurve_geom(self, e: VEdge, face: int, poly: np.ndarray | None = None) -> EdgeGeom | None:
        """The edge as a curve in ``face``'s (u, v) through its polyline (or ``poly``, (K, 3) mm) projected onto
        the surface, from its v0 to its v1."""
        s = self.surfaces[face]
        if poly is None and self.cfg.pcurve_along_rays:
            poly = self._polyline_on_face(e, face)
        poly = self.fmap.points(e.polyline) if poly is None else poly
        poly = subsample(poly, self.cfg.max_fit_points)
        pts = np.concatenate([self.vpos[e.v0][None], poly[1:-1], self.vpos[e.v1][None]])
        uv = s.uv(pts)
        uv = s.unwrap(uv)
        # Characteristic length of one parameter unit: angles scale with the radius.
        unit = max(s.radius, s.minor_radius, 1.0) if s.u_periodic else 1.0
        iso = None
        if np.ptp(uv[:, 0]) <= self.pcurve_tol / unit or np.ptp(uv[:, 1]) <= self.pcurve_tol / unit:
            iso = iso_curve(s, uv[0], uv[-1], self.pcurve_tol / unit)
        if iso is not None:  # along an iso line: an exact circle or line with its matching pcurve
            c3, c2, t0, t1 = iso
            ends = curve_points(c3, np.array([t0, t1]))
            return EdgeGeom(curve=c3, face=face, pcurve=c2, t0=t0, t1=t1, end0=ends[0], end1=ends[1])
        try:
            pc = fit_pcurve(uv, self.pcurve_tol / unit, circles=s.kind is PrimitiveType.PLANE)
        except Exception as exc:  # noqa: BLE001 - OCCT approximation failures
            self.warnings.append(f"edge {e.id}: pcurve fit failed ({exc})")
            return None
        t0, t1 = pc.FirstParameter(), pc.LastParameter()
        ends = s.evaluate(np.array([[pc.Value(t).X(), pc.Value(t).Y()] for t in (t0, t1)]))
        return EdgeGeom(face=face, pcurve=pc, t0=t0, t1=t1, end0=ends[0], end1=ends[1])

    def _free_geom(self, e: VEdge) -> EdgeGeom | None:
        """A 3D curve through the polyline for an edge none of whose faces has a surface."""
        poly = subsample(self.fmap.points(e.polyline), self.cfg.max_fit_points)
        pts = np.concatenate([self.vpos[e.v0][None], poly[1:-1], self.vpos[e.v1][None]])
        arr = TColgp_Array1OfPnt(1, len(pts))
        for i, q in enumerate(pts):
            arr.SetValue(i + 1, gp_Pnt(*map(float, q)))
        fit = GeomAPI_PointsToBSpline(arr, 1 if len(pts) == 2 else 3, 8, GeomAbs_C2, self.fit_tol)
        if not fit.IsDone():
            return None
        c = fit.Curve()
        t0, t1 = c.FirstParameter(), c.LastParameter()
        ends = curve_points(c, np.array([t0, t1]))
        return EdgeGeom(curve=c, t0=t0, t1=t1, end0=ends[0], end1=ends[1])

    def build_edge_geometry(self) -> None:
        """Step 4a: each edge's `EdgeGeom` (``geoms``): its intersection curve trimmed at its vertices, else a
        pcurve fitted in a face's (u, v) space, else a free 3D B-spline; an edge with none is dropped (a warning)."""
        for e in self.vb.edges:
            if e.id not in self.degenerate:
                self._edge_geometry(e)

    def _edge_geometry(self, e: VEdge) -> None:
        """`build_edge_geometry` for one edge (``geoms[e.id]`` set, or left out with a warning)."""
        self.geoms.pop(e.id, None)
        g = None
        if e.id in self.curves:
            g = self._curve_geom(e, self.curves[e.id])
            if g is None:
                self.warnings.append(f"edge {e.id}: its intersection curve could not be trimmed; fitted")
        if g is None:
            faces = sorted(e.faces, key=lambda f: f != self.fit_face.get(e.id, f))
            for f in faces:
                if f in self.surfaces:
                    g = self._pcurve_geom(e, f)
                    if g is not None:
                        break
        if g is not None and e.id in self.fit_face and g.face is not None:
            self.fit_face[e.id] = g.face  # the nearer face's fit failed: the other one carries it
        if g is None:
            g = self._free_geom(e)
        if g is None:
            self.warnings.append(f"edge {e.id}: no geometry could be built; edge dropped")
            return
        self.geoms[e.id] = g

    def refit_lens_loops(self) -> None:
        """Step 4a': a face's loop of two edges between the same two vertices (a thin face whose far end the
        image lost: the edges there were under a pixel) bounds nothing when both follow exact intersection curves:
        two lines meet once, and alternating projection takes both vertices to where they cross. When the region
        such a loop's geometry bounds in the face's (u, v) differs from the region its polylines bound (what the
        face's mesh covers) by more than ``area_tol_rel``, its edges with exact curves are fitted on the face
        along their polylines instead (as an edge without an intersection branch: ``fit_face``, the other face's
        gap covered by `_cover_other_face`), its two vertices are placed on that face's surface alone
        (``lens_vertices``: their VB-Rep positions projected onto it), and the edges at those vertices are built
        again."""
        moved: set[int] = set()
        position = {v.id: v.position for v in self.vb.vertices}
        for f in self.vb.faces:
            s = self.surfaces.get(f.id)
            if s is None:
                continue
            for lp in f.loops:
                if len(lp) != 2 or lp[0][0] == lp[1][0]:
                    continue
                ea, eb = (self.vb.edges[eid] for eid, _ in lp)
                ends = {self.vid(ea.v0), self.vid(ea.v1)}
                if (
                    ends != {self.vid(eb.v0), self.vid(eb.v1)}
                    or len(ends) != 2
                    or not ends.isdisjoint(self.lens_vertices)
                ):
                    continue
                exact = [eid for eid, _ in lp if eid in self.curves and eid in self.geoms]
                if not exact:
                    continue
                built, drawn = self._loop_built_area_uv(s, lp), abs(self.loop_area_uv(s, lp))
                if not (np.isfinite(built) and np.isfinite(drawn)) or drawn <= 0:
                    continue
                if abs(built - drawn) <= self.cfg.area_tol_rel * drawn:
                    continue
                for eid in exact:
                    self.curves.pop(eid)
                    self.fit_face[eid] = f.id
                for v in ends:
                    self.lens_vertices[v] = f.id
                    self.vpos[v] = s.project(self.fmap.points(position[v])[None])[0]
                moved |= ends
        if not moved:
            return
        for v, rep in self.vertex_alias.items():
            if rep in moved:
                self.vpos[v] = self.vpos[rep]
        for e in self.vb.edges:
            if e.id not in self.degenerate and {self.vid(e.v0), self.vid(e.v1)} & moved:
                self._edge_geometry(e)

    def _loop_built_area_uv(self, s: AnalyticSurface, loop: list[tuple[int, bool]], n: int = 33) -> float:
        """The (u, v) area a loop bounds on surface ``s`` along its edges' built geometry (`EdgeGeom`, each
        sampled ``n`` times end to end); NaN when an edge has none."""
        pts = []
        for eid, rev in loop:
            g = self.geoms.get(eid)
            if g is None:
                return float("nan")
            xyz = self._geom_points(g, n)
            pts.append(xyz[::-1] if rev else xyz)
        uv = s.uv(np.concatenate(pts))
        if not np.all(np.isfinite(uv)):
            return float("nan")
        return abs(signed_area(s.unwrap(uv)))

    def loop_area_uv(self, s: AnalyticSurface, loop: list[tuple[int, bool]]) -> float:
        """Signed (u, v) area of a loop from its edges' polylines (positive: counter-clockwise)."""
        pts = []
        for eid, rev in loop:
            poly = np.asarray(self.vb.edges[eid].polyline, float)
            pts.append(poly[::-1] if rev else poly)
        uv = s.uv(self.fmap.points(np.concatenate(pts)))
        return signed_area(s.unwrap(uv))

    def _geom_points(self, g: EdgeGeom, n: int = 33) -> np.ndarray:
        """(n, 3) mm points along an edge geometry, before it is an edge."""
        return self.geom_at(g, np.linspace(g.t0, g.t1, n))

    def geom_at(self, g: EdgeGeom, ts: np.ndarray) -> np.ndarray:
        """(N, 3) mm: an edge geometry's points at its parameters ``ts`` (N,)."""
        if g.curve is not None:
            return curve_points(g.curve, ts)
        return self.surfaces[g.face].evaluate(pcurve_points(g.pcurve, ts))

    def _polyline_on_face(self, e: VEdge, face: int) -> np.ndarray | None:
        """(K, 3) mm: the edge's polyline moved along the camera rays through it onto ``face``'s sheet (as
        `v2c.vbrep.loop_mesh` lifts the face's loops; `_along_rays`), or None."""
        poly = np.asarray(e.polyline, float).reshape(-1, 3)
        if len(poly) < 2:
            return None
        return self._along_rays(poly, face)

    def _along_rays(self, poly: np.ndarray, face: int) -> np.ndarray | None:
        """(K, 3) camera-frame metres -> (K, 3) mm: the points moved along the camera rays through them onto
        ``face``'s sheet (`v2c.vbrep.raycast`), the crossing nearest their own depth. A point stays where it is when
        its ray misses the surface or meets it more than ``ray_move_factor`` times its distance off the surface
        (plus ``fit_tol``) away: a contour generator's point, whose ray grazes the surface there and crosses it
        elsewhere. None when a point lies behind the camera or gets no finite depth."""
        if np.any(poly[:, 2] <= 0):
            return None
        rays = poly / poly[:, 2:3]
        prim = self.vfaces[face].primitive
        sheet = int(self.vb.meta.get("faces", {}).get(str(face), {}).get("sheet", 0))
        window = (0.5 * float(poly[:, 2].min()), 2.0 * float(poly[:, 2].max()))
        hits = intersect(prim, rays, window)
        z = sheet_depth(hits, sheet, poly[:, 2])
        if not np.all(np.isfinite(z)) or np.any(z <= 0):
            return None
        out = rays * z[:, None]
        off = np.abs(as_primitive(prim).signed_distance(poly))
        reach = self.cfg.ray_move_factor * off + self.fit_tol / self.fmap.scale
        keep = ~np.isfinite(hits.depths).any(axis=1) | (np.linalg.norm(out - poly, axis=1) > reach)
        out[keep] = poly[keep]
        return self.fmap.points(out)

    def _measure_off_surface(self) -> None:
        """``off_surface``: for each intersection edge fitted on one face (no exact intersection curve), its other
        face and how far (mm) its geometry lies off that face's surface."""
        for e in self.vb.edges:
            g = self.geoms.get(e.id)
            if g is None or e.id not in self.fit_face:
                continue
            other = next((f for f in e.faces if f != self.fit_face[e.id]), None)
            if other is None or other not in self.surfaces:
                continue
            self.off_surface[e.id] = (
                other,
                float(distance_to_surface(self.surfaces[other], self._geom_points(g)).max()),
            )

    def _face_copies(self) -> None:
        """``copy_geoms``: for each edge of ``off_surface`` farther than ``join_tol`` off its other face, that
        face's own copy of it, on its surface along the camera rays through the polyline (`_polyline_on_face`).
        The faces do not meet there in the reconstruction, so the file does not join them: each is bounded where
        its own mesh ends."""
        if not self.cfg.face_copies:
            return
        for eid, (other, off) in self.off_surface.items():
            if off <= self.join_tol:
                continue
            e = self.vb.edges[eid]
            poly = self._polyline_on_face(e, other)
            g2 = None if poly is None else self._pcurve_geom(e, other, poly)
            if g2 is not None:
                self.copy_geoms[(other, eid)] = g2

    def build_edges(self) -> dict[int, TopoDS_Edge]:
        """Step 4b: VEdge id -> TopoDS_Edge oriented from v0 to v1, on shared TopoDS_Vertex objects whose
        tolerance covers the gap to every edge end (mm)."""
        self._measure_off_surface()
        self._face_copies()
        gap: dict[int, float] = defaultdict(float)
        # (VEdge id, 0 | 1, copy's VFace id or -1): an end beyond join_tol of its vertex
        apart: dict[tuple[int, int, int], float] = {}
        placed = [(e, self.geoms.get(e.id), -1) for e in self.vb.edges]
        placed += [(self.vb.edges[eid], g, fid) for (fid, eid), g in sorted(self.copy_geoms.items())]
        for e, g, fid in placed:
            if g is None:
                continue
            for end, v, x in ((0, self.vid(e.v0), g.end0), (1, self.vid(e.v1), g.end1)):
                d = float(np.linalg.norm(x - self.vpos[v]))
                if d > self.join_tol:
                    apart[(e.id, end, fid)] = d
                else:
                    gap[v] = max(gap[v], d)
        verts: dict[int, TopoDS_Vertex] = {}
        for vid, x in self.vpos.items():
            if vid in self.vertex_alias:
                continue
            verts[vid] = self.vertex(x, max(self.cfg.min_tolerance, 1.05 * gap[vid] + self.cfg.min_tolerance))
        for (eid, end, fid), d in sorted(apart.items()):
            e = self.vb.edges[eid]
            self.warnings.append(
                f"edge {eid}{'' if fid < 0 else f' (face {fid} copy)'}: ends {d:.2f} mm from vertex "
                f"{e.v1 if end else e.v0} (more than {self.join_tol:.2f} mm): it does not join it"
            )
        own = self._own_vertices(placed, apart)
        edges: dict[int, TopoDS_Edge] = {}
        for e, g, fid in placed:
            if g is None:
                continue
            va, vb = verts[self.vid(e.v0)], verts[self.vid(e.v1)]
            # an end too far from its vertex gets a vertex of its own where it ends: a file joins faces only
            # across gaps its tolerances state within join_tol (a 27 mm vertex tolerance joined nothing real)
            va = own.get((e.id, 0, fid), va)
            vb = own.get((e.id, 1, fid), vb)
            made = self.make_edge(e, g, va, vb)
            if made is None:
                continue
            edge, oriented = made
            if fid >= 0:
                self.copies[(fid, e.id)] = oriented
                continue
            if e.id in self.fit_face:
                self._cover_other_face(e, edge, va, vb)
            # Stored oriented from v0 to v1, so a loop entry (id, reversed) is this edge, reversed or not.
            edges[e.id] = oriented
        return edges

    def make_edge(
        self, e: VEdge, g: EdgeGeom, va: TopoDS_Vertex, vb: TopoDS_Vertex
    ) -> tuple[TopoDS_Edge, TopoDS_Edge] | None:
        """The TopoDS_Edge of geometry ``g`` between the vertices ``va`` (at e.v0) and ``vb`` (at e.v1): as built
        (along its curve's parameter) and oriented from v0 to v1; None (a warning) when OCCT cannot make it."""
        forward = g.t1 > g.t0
        lo, hi = (g.t0, g.t1) if forward else (g.t1, g.t0)
        v_lo, v_hi = (va, vb) if forward else (vb, va)
        try:
            if g.curve is None:
                mk = BRepBuilderAPI_MakeEdge(g.pcurve, self.surfaces[g.face].geom, v_lo, v_hi, lo, hi)
            else:
                mk = BRepBuilderAPI_MakeEdge(g.curve, v_lo, v_hi, lo, hi)
            ok = mk.IsDone()
        except Exception as exc:  # noqa: BLE001 - OCCT construction errors: report, skip the edge
            ok, mk = False, exc
        if not ok:
            why = mk.Error() if hasattr(mk, "Error") else mk
            self.warnings.append(f"edge {e.id}: BRepBuilderAPI_MakeEdge failed ({why})")
            return None
        edge = mk.Edge()
        if g.curve is None:
            BRepLib.BuildCurves3d_s(edge)
        elif g.pcurve is not None:  # exact iso curve: attach its pcurve (same parametrisation)
            self.bb.UpdateEdge(
                edge, g.pcurve, self.surfaces[g.face].geom, TopLoc_Location(), BRep_Tool.Tolerance_s(edge)
            )
        return edge, (edge if forward else TopoDS.Edge_s(edge.Reversed()))

    def _own_vertices(
        self, placed: list[tuple[VEdge, EdgeGeom | None, int]], apart: dict[tuple[int, int, int], float]
    ) -> dict[tuple[int, int, int], TopoDS_Vertex]:
        """The vertices of the edge ends in ``apart`` (VEdge id, end, copy's face or -1), each beyond join_tol of
        its VB-Rep vertex. The ends at one VB-Rep vertex that lie on one face's surface (edges fitted in that
        face's (u, v), and that face's copies) share a vertex when they lie within join_tol of their mean, so that
        face's loop still closes there (a face bounded by its own copies, off the corner its neighbours share);
        any other such end gets a vertex of its own."""
        groups: dict[tuple[int, int], list[tuple[tuple[int, int, int], np.ndarray]]] = defaultdict(list)
        out: dict[tuple[int, int, int], TopoDS_Vertex] = {}
        for e, g, fid in placed:
            if g is None:
                continue
            for end, v, x in ((0, e.v0, g.end0), (1, e.v1, g.end1)):
                key = (e.id, end, fid)
                if key not in apart:
                    continue
                if g.face is None or (g.curve is not None and g.pcurve is None):
                    out[key] = self.vertex(x, self.cfg.min_tolerance)
                else:
                    groups[(self.vid(v), g.face)].append((key, x))
        for members in groups.values():
            pts = np.array([x for _, x in members])
            mid = pts.mean(axis=0)
            spread = float(np.linalg.norm(pts - mid, axis=1).max())
            if len(members) > 1 and spread <= self.join_tol:
                vx = self.vertex(mid, max(self.cfg.min_tolerance, 1.05 * spread + self.cfg.min_tolerance))
                out.update({key: vx for key, _ in members})
            else:
                out.update({key: self.vertex(x, self.cfg.min_tolerance) for key, x in members})
        return out

    def vertex(self, x: np.ndarray, tol: float) -> TopoDS_Vertex:
        """A new vertex at ``x`` (mm) of tolerance ``tol`` (mm)."""
        vx = TopoDS_Vertex()
        self.bb.MakeVertex(vx, gp_Pnt(*map(float, x)), tol)
        return vx

    def _cover_other_face(self, e: VEdge, edge: TopoDS_Edge, va: TopoDS_Vertex, vb: TopoDS_Vertex) -> None:
        """An intersection edge fitted on one face (no intersection curve), ``off`` mm off the other face's surface
        (``off_surface``): warn, and raise the edge's (and its vertices') tolerance to cover that gap when it is
        within ``join_tol``; a larger gap is reported as a gap between the faces."""
        if e.id not in self.off_surface:
            return
        other, off = self.off_surface[e.id]
        if off <= self.cfg.min_tolerance:
            return
        if off <= self.join_tol:
            tol = 1.05 * off + self.cfg.min_tolerance
            self.bb.UpdateEdge(edge, max(tol, BRep_Tool.Tolerance_s(edge)))
            for vx in (va, vb):
                self.bb.UpdateVertex(vx, max(tol, BRep_Tool.Tolerance_s(vx)))
            self.warnings.append(
                f"edge {e.id}: fitted on face {self.fit_face[e.id]}, {off:.2f} mm off face "
                f"{other}'s surface; its tolerance covers the gap"
            )
        else:
            self.warnings.append(
                f"edge {e.id}: fitted on face {self.fit_face[e.id]}, {off:.2f} mm off face "
                f"{other}'s surface (more than {self.join_tol:.2f} mm): a gap between the faces"
                + (f"; face {other} is bounded by its own copy" if (other, e.id) in self.copy_geoms else "")
            )
