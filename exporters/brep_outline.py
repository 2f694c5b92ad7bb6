"""Faces bounded by their mesh outline: the fallback of `exporters.brep_faces` when a face's loops do not bound a
valid face, or bound one whose area disagrees with the reconstruction.

The face's mesh (the VB-Rep's bounded surface mesh) is projected onto its analytic surface, its triangles are
united in the surface's (u, v) parameters (scaled to millimetres, so tolerances mean lengths), and every piece of
that union (outer ring and holes) becomes one OCCT face on the surface, bounded by straight (u, v) segments that
lie on the surface exactly. So the written face covers what the reconstruction covers, to the simplification
tolerance, whatever its loops were. Each boundary segment is named after the nearest VB-Rep edge of the face, so
every edge of the file keeps a type, confidence, layer and colour.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
import shapely
from OCP.BRep import BRep_Builder
from OCP.BRepBuilderAPI import BRepBuilderAPI_MakeEdge
from OCP.BRepCheck import BRepCheck_Analyzer
from OCP.BRepLib import BRepLib
from OCP.GCE2d import GCE2d_MakeSegment
from OCP.gp import gp_Pnt, gp_Pnt2d
from OCP.TopoDS import TopoDS_Edge, TopoDS_Face, TopoDS_Vertex, TopoDS_Wire
from scipy.spatial import cKDTree

from exporters.occ_surfaces import TWO_PI, AnalyticSurface
from v2c.labels import PrimitiveType

if TYPE_CHECKING:
    from exporters.frames import FrameMap
    from v2c.vbrep.model import VBRep, VFace


@dataclass
class OutlinePiece:
    """One OCCT face of an outline-bounded VB-Rep face and the VEdge id each of its boundary edges is named
    after (-1 when the VB-Rep face has no edge to name it after)."""

    face: TopoDS_Face
    edges: list[tuple[TopoDS_Edge, int]] = field(default_factory=list)


def _triangle_areas(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(M,) areas of the triangles (M, 3) of a mesh with vertices (N, 3), in the vertices' units squared."""
    t = np.asarray(triangles, int).reshape(-1, 3)
    v = np.asarray(vertices, float).reshape(-1, 3)
    return np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1) / 2


def mesh_area(vertices: np.ndarray, triangles: np.ndarray) -> float:
    """Total area of a triangle mesh (vertices (N, 3), triangles (M, 3)), in the vertices' units squared."""
    return float(_triangle_areas(vertices, triangles).sum())


#: Samples of the area element over a region's range of v (`_region_area`): its integral is tabulated on them
#: (trapezoids, relative error about 1e-7 over a full turn of a torus's tube).
REGION_ELEMENT_SAMPLES = 4097
#: Gauss-Legendre nodes per boundary segment (`_region_area`).
REGION_GAUSS_NODES = 8


def signed_areas_2d(t: np.ndarray) -> np.ndarray:
    """(M,) signed areas of the 2D triangles ``t`` (M, 3, 2): positive when counter-clockwise."""
    return 0.5 * (
        (t[:, 1, 0] - t[:, 0, 0]) * (t[:, 2, 1] - t[:, 0, 1]) - (t[:, 1, 1] - t[:, 0, 1]) * (t[:, 2, 0] - t[:, 0, 0])
    )


def _surface_triangle_areas(s: AnalyticSurface, t: np.ndarray) -> np.ndarray:
    """(M,) areas (mm²) on ``s`` of the (u, v) triangles ``t`` (M, 3, 2): each one's (u, v) area times the area
    element |S_u x S_v| (central differences) averaged over its edge midpoints (exact for an element quadratic
    in (u, v))."""
    a_uv = np.abs(signed_areas_2d(t))
    if s.kind is PrimitiveType.PLANE:  # one element for the whole plane, exact: |x cross y|
        return a_uv * float(np.linalg.norm(np.cross(s.x, s.y)))
    h = 1e-6
    du, dv = np.array([h, 0.0]), np.array([0.0, h])
    element = np.zeros(len(t))
    for i, j in ((0, 1), (1, 2), (2, 0)):  # the edge-midpoint rule
        c = 0.5 * (t[:, i] + t[:, j])
        su = (s.evaluate(c + du) - s.evaluate(c - du)) / (2 * h)
        sv = (s.evaluate(c + dv) - s.evaluate(c - dv)) / (2 * h)
        element += np.linalg.norm(np.cross(su, sv), axis=1) / 3.0
    return a_uv * element


def area_element(
    kind: PrimitiveType, v: np.ndarray, radius: float, minor_radius: float = 0.0, half_angle: float = 0.0
) -> np.ndarray:
    """The area element |S_u x S_v| (the radius's units squared per unit of u and v) at ``v`` of a cylinder, cone,
    sphere or torus in OCCT's parametrisation (u the angle round the axis, so the element does not depend on u;
    ``radius`` a cone's at v = 0, a torus's major one)."""
    v = np.asarray(v, float)
    if kind is PrimitiveType.CYLINDER:
        return np.full(v.shape, abs(radius))
    if kind is PrimitiveType.CONE:
        return np.abs(radius + v * np.sin(half_angle))
    if kind is PrimitiveType.SPHERE:
        return radius**2 * np.abs(np.cos(v))
    if kind is PrimitiveType.TORUS:
        return minor_radius * np.abs(radius + minor_radius * np.cos(v))
    raise ValueError(f"no area element of one parameter for a {kind.value}")


def _element(s: AnalyticSurface, v: np.ndarray) -> np.ndarray:
    """`area_element` of a surface of revolution ``s`` at ``v`` (mm² per unit of u and v)."""
    return area_element(s.kind, v, s.radius, s.minor_radius, s.half_angle)


def _region_area(s: AnalyticSurface, region: shapely.Geometry) -> float:
    """Area (mm²) on ``s`` of a (u, v) region (polygons), by Green's theorem: the element J depends on v alone
    (`_element`), so the area is the integral of -G(v) du round the region's rings, G the integral of J
    (tabulated over the region's v, `REGION_ELEMENT_SAMPLES`), each straight (u, v) segment by Gauss-Legendre
    (`REGION_GAUSS_NODES`); holes count negative whatever their orientation. No triangulation: a constrained
    Delaunay triangulation of the region, used before, failed outright (GEOS) on some simplified outlines and
    folded-mesh unions."""
    polys = [g for g in shapely.get_parts(region) if isinstance(g, shapely.Polygon) and not g.is_empty]
    if not polys:
        return 0.0
    if s.kind is PrimitiveType.PLANE:
        return float(sum(g.area for g in polys)) * float(np.linalg.norm(np.cross(s.x, s.y)))
    rings = [(np.asarray(g.exterior.coords, float), 1.0) for g in polys]
    rings += [(np.asarray(r.coords, float), -1.0) for g in polys for r in g.interiors]
    v_all = np.concatenate([r[:, 1] for r, _ in rings])
    lo, hi = float(v_all.min()), float(v_all.max())
    if hi - lo <= 0:
        return 0.0
    grid = np.linspace(lo, hi, REGION_ELEMENT_SAMPLES)
    jv = _element(s, grid)
    g_tab = np.concatenate([[0.0], np.cumsum(0.5 * (jv[1:] + jv[:-1]) * np.diff(grid))])
    x, w = np.polynomial.legendre.leggauss(REGION_GAUSS_NODES)
    t, w = 0.5 * (x + 1.0), 0.5 * w  # nodes and weights on [0, 1]
    total = 0.0
    for ring, sign in rings:  # loop over the rings, outer ones positive
        a, b = ring[:-1], ring[1:]
        v = a[:, 1, None] + t[None] * (b[:, 1] - a[:, 1])[:, None]
        g = np.interp(v, grid, g_tab)
        total += sign * abs(float(np.sum(-(g @ w) * (b[:, 0] - a[:, 0]))))
    return total


def _fold_triangles(tris: np.ndarray) -> np.ndarray:
    """(M,) bool: the triangles of ``tris`` (M, 3) that run along an edge another one runs along in the same
    direction: with the same orientation the two lie on the same side of it, one over the other (a mesh lifted from
    the pixel grid can fold so where a slanted cone or torus turns away, without turning a triangle over: corpus
    training split, oracle, a cone face of 60 triangles counted 89.1 mm² where it covers 82.3 mm²)."""
    n = int(tris.max()) + 1 if len(tris) else 1
    e = np.concatenate([tris[:, 0] * n + tris[:, 1], tris[:, 1] * n + tris[:, 2], tris[:, 2] * n + tris[:, 0]])
    order = np.argsort(e, kind="stable")
    dup = np.zeros(len(e), bool)
    same = e[order][1:] == e[order][:-1]
    dup[order[1:][same]] = True
    dup[order[:-1][same]] = True
    return dup.reshape(3, -1).any(axis=0)


def surface_area(s: AnalyticSurface, vertices: np.ndarray, triangles: np.ndarray, max_stretch: float = np.inf) -> float:
    """The area (mm²) of the region a face mesh covers on its analytic surface ``s``, each point of it once.

    The triangles are taken whole in the periodic parameters (`_unwrap_triangles`); each one's area on the surface
    is its (u, v) area times the area element averaged over its edge midpoints (`_surface_triangle_areas`). A
    triangle whose area on the surface exceeds ``max_stretch`` times its flat area spans two sheets of the
    surface (a torus patch lifted onto both sides of its tube) and covers no region of it: it is left out, as the
    outline faces leave it out (`outline_polygons`). Where the remaining triangles overlap in (u, v) (the mesh
    folds over itself, as pixel-grid meshes do where a thin tube turns away from the camera), the area is that of
    their union (`_region_area`), not the sum, which counted the folded part twice. NaN where the vertices have
    no finite (u, v). A VB-Rep mesh is built on the pixel grid, its vertices on the surface, so its flat triangles
    are chords: on a small torus or cone seen at a slant they miss the surface's area by several per cent (a torus
    blend of the in-family validation scans: 80.36 mm² flat, 78.77 mm² on the torus), which is the area a face
    written on the surface is to be compared with."""
    pts = np.asarray(vertices, float).reshape(-1, 3)
    tris0 = np.asarray(triangles, int).reshape(-1, 3)
    if not len(tris0):
        return 0.0
    uv = s.uv(pts)
    if not np.all(np.isfinite(uv)):
        return float("nan")
    uv, tris = _unwrap_triangles(s, uv, tris0)
    t = uv[tris]
    on_surface = _surface_triangle_areas(s, t)
    keep = on_surface <= max_stretch * _triangle_areas(pts, tris0) + 1e-12
    if not keep.any():
        return 0.0
    signed = signed_areas_2d(t)
    # A mesh wound to face the camera keeps one orientation in (u, v) until it folds over the surface's contour:
    # with no triangle turned over, and no two triangles on the same side of an edge they share, none overlaps
    # another and the sum is the region's area.
    major = np.sign(np.sum(signed[keep]))
    tiny = 1e-9 * float(np.abs(signed[keep]).max())
    flipped = keep & (signed * major < -tiny)
    folded = _fold_triangles(tris) & keep
    if not flipped.any() and not folded.any():
        return float(on_surface[keep].sum())
    sel = keep & (np.abs(signed) > tiny)
    idx = np.flatnonzero(sel)
    polys = shapely.polygons(np.concatenate([t[idx], t[idx, :1]], axis=1))
    # The overlaps start where the mesh turns over or folds: from those triangles, the ones whose interiors meet
    # theirs (one overlaps or contains the other; triangles that share an edge do neither), and so on, are united;
    # the rest add their own areas (uniting every triangle of a large face cost the STEP writer a fifth of its time)
    tree = shapely.STRtree(polys)
    over = np.isin(idx, np.flatnonzero(flipped | folded))
    frontier = np.flatnonzero(over)
    while len(frontier):  # loop over the rings of triangles that meet the cluster found so far
        q = polys[frontier]
        met = np.concatenate([tree.query(q, predicate="overlaps")[1], tree.query(q, predicate="contains")[1]])
        met = np.unique(met[~over[met]])
        over[met] = True
        frontier = met
    alone = float(on_surface[idx][~over].sum())
    return alone + _region_area(s, shapely.union_all(polys[over]))


def reconstructed_area(
    s: AnalyticSurface | None, vertices: np.ndarray, triangles: np.ndarray, max_stretch: float = np.inf
) -> float:
    """A VB-Rep face's area (mm²) as the file's face is to hold it: its mesh's region on its surface
    (`surface_area`, two-sheet triangles of more than ``max_stretch`` left out), or the flat mesh's area where
    there is no surface or no finite (u, v)."""
    if s is not None:
        a = surface_area(s, vertices, triangles, max_stretch)
        if np.isfinite(a):
            return a
    return mesh_area(np.asarray(vertices, float).reshape(-1, 3), triangles)


def mesh_centroid(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray | None:
    """Area-weighted centroid (3,) of a triangle mesh, in the vertices' units; None for a mesh of no area."""
    w = _triangle_areas(vertices, triangles)
    if w.sum() <= 0:
        return None
    v = np.asarray(vertices, float).reshape(-1, 3)
    t = np.asarray(triangles, int).reshape(-1, 3)
    return (v[t].mean(axis=1) * w[:, None]).sum(axis=0) / w.sum()


def _smallest_within(areas: list[float], below: float, budget: float, keep: int = 0) -> set[int]:
    """Indices of ``areas`` to drop: those under ``below``, smallest first, as long as together they stay within
    ``budget`` (the same units squared) and at least ``keep`` are left."""
    dropped = 0.0
    drop: set[int] = set()
    for k in sorted(range(len(areas)), key=lambda k: areas[k]):  # loop over the areas, smallest first
        a = areas[k]
        if a >= below or dropped + a > budget or len(drop) == len(areas) - keep:
            break
        dropped += a
        drop.add(k)
    return drop


def _drop_specks(polys: list[shapely.Polygon], speck_area: float, budget: float) -> list[shapely.Polygon]:
    """``polys`` without its specks (pieces under ``speck_area``), smallest first, as long as the dropped area
    stays within ``budget`` (the same units squared) and one piece is left: a speck beside a large face goes, an
    island that holds a visible share of a small face stays."""
    drop = _smallest_within([p.area for p in polys], speck_area, budget, keep=1)
    return [p for k, p in enumerate(polys) if k not in drop]


def _metric_scale(s: AnalyticSurface, uv0: np.ndarray, step: float = 1e-4) -> np.ndarray:
    """Millimetres per unit of u and of v at ``uv0`` (finite differences of the surface)."""
    d = []
    for k in range(2):
        du = np.zeros(2)
        du[k] = step
        p = s.evaluate(np.stack([uv0 - du, uv0 + du]))
        d.append(np.linalg.norm(p[1] - p[0]) / (2 * step))
    return np.maximum(np.array(d), 1e-9)


def _covers(tri: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(K,) bool: whether each point of ``q`` (K, 2) lies in (or on the edge of) any of the triangles ``tri``
    (M, 3, 2). Each point is tested against the triangles whose centroid lies within the largest
    centroid-to-corner distance of it (a KD-tree query): the only ones that can hold it."""
    q = np.asarray(q, float).reshape(-1, 2)
    out = np.zeros(len(q), bool)
    if len(q) == 0 or len(tri) == 0:
        return out
    cen = tri.mean(axis=1)
    reach = float(np.linalg.norm(tri - cen[:, None], axis=2).max())
    pairs = cKDTree(cen).query_ball_point(q, reach * (1 + 1e-9) + 1e-12)
    pi = np.repeat(np.arange(len(q)), [len(p) for p in pairs])
    if len(pi) == 0:
        return out
    ti = np.concatenate([np.asarray(p, np.int64) for p in pairs])
    a, b, c, x = tri[ti, 0], tri[ti, 1], tri[ti, 2], q[pi]

    def side(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return (v[:, 0] - u[:, 0]) * (x[:, 1] - u[:, 1]) - (v[:, 1] - u[:, 1]) * (x[:, 0] - u[:, 0])

    d1, d2, d3 = side(a, b), side(b, c), side(c, a)
    inside = ((d1 >= 0) & (d2 >= 0) & (d3 >= 0)) | ((d1 <= 0) & (d2 <= 0) & (d3 <= 0))
    out[np.unique(pi[inside])] = True
    return out


def _union_from_boundary(
    uv: np.ndarray,
    tris: np.ndarray,
    area: float,
    rel_tol: float = 1e-6,
) -> shapely.Geometry | None:
    """The union of a triangle mesh in 2D from its boundary (the edges one triangle uses): the boundary's
    segments noded and polygonised, the cells the mesh covers kept. Five times faster than uniting the
    triangles; exact when no two triangles overlap, which the returned area (= the triangles' total ``area``)
    confirms; None when they do."""
    e = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    _, inv, cnt = np.unique(np.sort(e, axis=1), axis=0, return_inverse=True, return_counts=True)
    bnd = e[cnt[inv.ravel()] == 1]
    if len(bnd) < 3:
        return None
    noded = shapely.union_all(shapely.linestrings(uv[bnd]))
    cells = shapely.get_parts(shapely.polygonize(shapely.get_parts(noded)))
    tri = uv[tris]
    reps = shapely.get_coordinates(shapely.point_on_surface(cells)) if len(cells) else np.zeros((0, 2))
    kept = [p for p, inside in zip(cells, _covers(tri, reps), strict=True) if inside]
    union = shapely.union_all(kept) if kept else None
    if union is None or abs(union.area - area) > rel_tol * area:
        return None
    return union


def _unwrap_triangles(s: AnalyticSurface, uv: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u, v) vertices and triangles with every triangle whole in the periodic parameters: a triangle that
    straddles the seam (its corners a period apart, ``uv`` wrapped within pi of the surface's centre) gets its
    corners within half a period of its first one, shifted by whole periods so that its centroid lies within pi
    of the centre; such corners become vertices of their own. Before, these triangles were dropped, and a torus
    blend whose tube the seam crossed lost up to a fifth of its area (corpus validation, oracle)."""
    periodic = [(0, s.u_center)] if s.u_periodic else []
    if s.v_periodic:
        periodic.append((1, s.v_center))
    if not periodic or len(tris) == 0:
        return uv, tris
    corners = uv[tris]  # (M, 3, 2)
    out = corners.copy()
    for k, centre in periodic:  # loop over periodic parameters
        rel = out[:, :, k] - out[:, :1, k]
        out[:, :, k] = out[:, :1, k] + rel - TWO_PI * np.round(rel / TWO_PI)
        shift = TWO_PI * np.round((out[:, :, k].mean(axis=1) - centre) / TWO_PI)
        out[:, :, k] -= shift[:, None]
    moved = np.any(out != corners, axis=(1, 2))
    if not moved.any():
        return uv, tris
    extra = out[moved].reshape(-1, 2)
    new_tris = tris.copy()
    new_tris[moved] = len(uv) + np.arange(len(extra)).reshape(-1, 3)
    return np.concatenate([uv, extra]), new_tris


def outline_polygons(
    s: AnalyticSurface,
    points: np.ndarray,
    triangles: np.ndarray,
    tol: float,
    min_area: float,
    max_stretch: float = 4.0,
    hole_budget: float = np.inf,
    piece_budget: float = np.inf,
) -> tuple[list[shapely.Polygon], np.ndarray]:
    """The union of a mesh's triangles in the surface's scaled (u, v) (millimetres), simplified within ``tol``
    mm, as polygons (pieces under ``min_area`` mm² dropped, smallest first, while together they hold at most
    ``piece_budget`` mm², and holes under it while together they hold at most ``hole_budget`` mm²); and the
    (u, v) -> scaled factors (2,).

    points: (N, 3) mesh vertices in millimetres (output frame); triangles: (M, 3) indices.
    """
    uv = s.uv(points)
    if not np.all(np.isfinite(uv)):
        return [], np.ones(2)
    scale = _metric_scale(s, np.median(uv, axis=0))
    uv, tris = _unwrap_triangles(s, uv, np.asarray(triangles, int).reshape(-1, 3))
    tri = (uv * scale)[tris]
    area = np.abs(signed_areas_2d(tri))
    # a triangle still much larger in (u, v) than in space spans two sheets of the surface (a torus patch lifted
    # onto both sides of its tube): it is no part of the face's outline
    # (measured on the surface at each triangle, not by one scale: a cone's or a fat torus's (u, v) stretch varies
    # over the face, and one scale took sound triangles far from the median for two-sheet ones)
    area3d = _triangle_areas(points, triangles)
    keep = (area > 1e-12) & (_surface_triangle_areas(s, uv[tris]) <= max_stretch * area3d + 1e-12)
    if not keep.any():
        return [], scale
    tris = tris[keep]
    union = _union_from_boundary(uv * scale, tris, float(area[keep].sum()))
    if union is None:  # triangles overlap in (u, v) (a folded mesh): unite them one by one (slower, exact)
        tri = tri[keep]
        union = shapely.union_all(shapely.polygons(np.concatenate([tri, tri[:, :1]], axis=1)))
    union = shapely.simplify(union, tol, preserve_topology=True)
    polys = [p for p in getattr(union, "geoms", [union]) if isinstance(p, shapely.Polygon) and not p.is_empty]
    small = _smallest_within([p.area for p in polys], min_area, piece_budget)
    polys = [p for k, p in enumerate(polys) if k not in small]
    holes = [(k, j) for k, p in enumerate(polys) for j in range(len(p.interiors))]
    drop = _smallest_within([shapely.Polygon(polys[k].interiors[j]).area for k, j in holes], min_area, hole_budget)
    dropped = {holes[i] for i in drop}
    out = [
        shapely.Polygon(p.exterior, [r for j, r in enumerate(p.interiors) if (k, j) not in dropped])
        for k, p in enumerate(polys)
    ]
    return out, scale


def edge_candidates(vbrep: VBRep, fmap: FrameMap, face_id: int) -> list[tuple[int, np.ndarray]]:
    """The VB-Rep edges an edge of face ``face_id`` that is no VB-Rep edge of its own (an outline segment, a
    seam OCCT added) is named after, with their polylines in ``fmap``'s output frame (mm): the face's own edges,
    else (a face without edges) every edge of the VB-Rep, so that no edge of the file goes untyped."""
    own = [e for e in vbrep.edges if face_id in e.faces] or list(vbrep.edges)
    return [(e.id, fmap.points(np.asarray(e.polyline, float).reshape(-1, 3))) for e in own]


def nearest_edge_ids(midpoints: np.ndarray, candidates: list[tuple[int, np.ndarray]]) -> np.ndarray:
    """For each midpoint (K, 3) the id of the candidate edge (id, polyline (P, 3)) whose polyline passes
    nearest; -1 without candidates."""
    if not candidates:
        return np.full(len(midpoints), -1)
    best = np.full(len(midpoints), np.inf)
    ids = np.full(len(midpoints), -1)
    for eid, poly in candidates:
        if len(poly) == 0:
            continue
        a, b = poly[:-1], poly[1:]
        if len(a) == 0:
            d = np.linalg.norm(midpoints - poly[0], axis=1)
        else:
            ab = b - a
            t = np.einsum("kpj,pj->kp", midpoints[:, None] - a[None], ab) / np.maximum((ab * ab).sum(1), 1e-300)
            q = a[None] + np.clip(t, 0, 1)[..., None] * ab[None]
            d = np.linalg.norm(midpoints[:, None] - q, axis=2).min(1)
        better = d < best
        best[better], ids[better] = d[better], eid
    return ids


def _simplify_keeping_area(
    poly: shapely.Polygon,
    tol: float,
    area_rel: float,
    tries: int = 6,
    measure: Callable[[shapely.Geometry], float] | None = None,
) -> shapely.Geometry:
    """``poly`` simplified within ``tol`` (its units), the tolerance halved (up to ``tries`` times) until the
    area moves by at most ``area_rel`` of it. A pixel staircase simplifies to its centre line at the first
    try; only fine detail needs the smaller tolerances. measure: the area of a polygon (default its plane area;
    the outline passes the area on the surface, which the scaled (u, v) of a torus or cone follow only near
    the scale's point)."""
    area = measure or (lambda g: float(g.area))
    target = area(poly)
    for _ in range(tries):
        simple = shapely.simplify(poly, tol, preserve_topology=True)
        if abs(area(simple) - target) <= area_rel * target:
            return simple
        tol /= 2
    return poly


def _separate_rings(poly: shapely.Geometry, gap: float, min_area: float) -> list[shapely.Polygon]:
    """Polygons whose rings do not touch, as OCCT wants a face's wires: a hole touching the outer ring (or
    another hole) at a point is opened by shrinking the polygon by ``gap`` (a sharp-cornered inward offset:
    the pinch becomes a notch or splits the piece); a hole still touching after that is dropped. Pieces under
    ``min_area`` are dropped (holes were chosen before, `outline_polygons`). A polygon whose rings are already
    ``gap`` apart is kept as it is: the shrink takes its perimeter times ``gap`` off every piece, 1-5 % of a
    torus blend's pieces of a few tenths of a mm² (corpus training split, oracle)."""
    parts = [p for p in getattr(poly, "geoms", [poly]) if isinstance(p, shapely.Polygon) and not p.is_empty]
    if parts and all(_rings_apart(p, gap) for p in parts):
        return [p for p in parts if p.area >= min_area]
    shrunk = shapely.buffer(poly, -gap, join_style="mitre", mitre_limit=10.0)
    out = []
    for part in getattr(shrunk, "geoms", [shrunk]):
        if not isinstance(part, shapely.Polygon) or part.is_empty or part.area < min_area:
            continue
        holes = []
        for ring in part.interiors:
            hole = shapely.Polygon(ring)
            if part.exterior.distance(ring) < gap:
                continue
            if any(shapely.Polygon(h).distance(hole) < gap for h in holes):
                continue
            holes.append(ring)
        out.append(shapely.Polygon(part.exterior, holes))
    return out


def _cut_pinches(
    poly: shapely.Geometry, gap: float, min_area: float, max_cuts: int = 32
) -> list[shapely.Polygon] | None:
    """`_separate_rings` by cuts instead of a shrink: where two rings of a piece come within ``gap`` of each other
    (a hole touching the outer ring at a point), a disc of twice ``gap`` round the closest pair of points is cut
    out, until every piece's rings lie ``gap`` apart; pieces under ``min_area`` are dropped. Only the pinches lose
    area (about 4 pi gap^2 each), where the shrink takes the perimeter times ``gap`` off the whole piece. None when
    ``max_cuts`` cuts do not part the rings (rings that run side by side for a stretch) or the cuts leave an
    invalid piece."""
    geom = shapely.make_valid(poly)
    for _ in range(max_cuts):  # loop over cuts, one pinch at a time
        parts = [p for p in getattr(geom, "geoms", [geom]) if isinstance(p, shapely.Polygon) and not p.is_empty]
        pinch = next((q for q in (_pinch(p, gap) for p in parts) if q is not None), None)
        if pinch is None:
            out = [p for p in parts if p.area >= min_area]
            return out if all(p.is_valid for p in out) else None
        geom = shapely.make_valid(shapely.difference(geom, pinch.buffer(2.0 * gap)))
    return None


def _pinch(poly: shapely.Polygon, gap: float) -> shapely.Point | None:
    """The midpoint of the closest pair of points of the first two rings of ``poly`` (outer and holes) that lie
    within ``gap`` of each other, or None when every pair of its rings is at least ``gap`` apart."""
    rings = [poly.exterior, *poly.interiors]
    for k, a in enumerate(rings):  # loop over ring pairs
        for b in rings[k + 1 :]:
            if a.distance(b) < gap:
                return shapely.shortest_line(a, b).centroid
    return None


def _rings_apart(poly: shapely.Polygon, gap: float) -> bool:
    """Whether ``poly`` is valid and its rings (outer and holes) lie at least ``gap`` from one another."""
    return poly.is_valid and _pinch(poly, gap) is None


def _distinct(ring: np.ndarray, tol: float) -> np.ndarray:
    """A closed ring (K, 2), first point repeated last, without the points within ``tol`` of the point kept
    before them: shapely's inward offset can leave two points 1e-15 apart, a zero-length edge that fails the
    whole face (corpus validation: a 13,541 mm² plane written with nothing)."""
    keep = [0]
    for k in range(1, len(ring) - 1):  # loop over the ring's points but the repeated last
        if np.linalg.norm(ring[k] - ring[keep[-1]]) > tol:
            keep.append(k)
    while len(keep) > 1 and np.linalg.norm(ring[keep[-1]] - ring[0]) <= tol:
        keep.pop()
    out = ring[keep]
    return np.concatenate([out, out[:1]])


class OutlineBuilder:
    """Builds the outline faces of one VB-Rep (output frame ``fmap``, millimetres).

    tol: simplification tolerance (mm); tol_area_rel: it is halved until simplification moves a piece's area
    by at most this fraction;
    min_piece_rel: pieces smaller than this fraction of the face's mesh area are dropped, and holes smaller than
    it while together they hold at most ``hole_budget_rel`` of that area;
    min_piece_tris, speck_budget_rel: pieces smaller than this many of its median mesh triangles are specks,
    dropped smallest first while together they hold at most this fraction of the face's mesh area;
    precision: OCCT face/vertex precision (mm); rings of one face are kept ``gap_factor`` precisions apart;
    max_stretch: see `outline_polygons`.
    """

    def __init__(
        self,
        vbrep: VBRep,
        fmap: FrameMap,
        tol: float,
        tol_area_rel: float,
        min_piece_rel: float,
        precision: float,
        gap_factor: float = 20.0,
        max_stretch: float = 4.0,
        min_piece_tris: float = 0.0,
        speck_budget_rel: float = 0.0,
        hole_budget_rel: float = np.inf,
    ) -> None:
        self.vb = vbrep
        self.fmap = fmap
        self.tol = tol
        self.tol_area_rel = tol_area_rel
        self.min_piece_rel = min_piece_rel
        self.precision = precision
        self.gap = gap_factor * precision
        self.max_stretch = max_stretch
        self.min_piece_tris = min_piece_tris
        self.speck_budget_rel = speck_budget_rel
        self.hole_budget_rel = hole_budget_rel
        self.bb = BRep_Builder()

    def build(self, f: VFace, s: AnalyticSurface, raw: bool = False, whole: bool = False) -> list[OutlinePiece]:
        """The outline faces of ``f`` on surface ``s`` (empty when none can be built); ``raw``: the outline as the
        mesh gives it, not simplified (`exporters.step.write` asks for it for a face OCCT's mesher drew short);
        ``whole``: no piece dropped as a speck, and touching rings parted by cuts at their pinches
        (`_cut_pinches`) rather than a shrink of the whole piece (`exporters.brep.build_brep` asks for it, with
        ``raw``, for a face whose outline came out more than ``area_tol_rel`` off its mesh's area)."""
        pts = self.fmap.points(np.asarray(f.mesh_vertices, float).reshape(-1, 3))
        tris = np.asarray(f.mesh_triangles, int).reshape(-1, 3)
        areas = _triangle_areas(pts, tris)
        total = float(areas.sum())
        if total <= 0:
            return []
        min_area = self.min_piece_rel * total
        # A first pass at the cap finds the pieces (all of them); each is then simplified within its own area
        # budget. Small pieces (under min_area, or specks of a few triangles) go smallest first within one budget,
        # so a face broken into many small islands is not written short of its area.
        polys, scale = outline_polygons(
            s, pts, tris, 0.0, min_area, self.max_stretch, self.hole_budget_rel * total, piece_budget=0.0
        )
        speck = max(self.min_piece_tris * float(np.median(areas)), min_area)
        if not whole:
            polys = _drop_specks(polys, speck, self.speck_budget_rel * total)
        cands = edge_candidates(self.vb, self.fmap, f.id)
        out = []

        def on_surface(g: shapely.Geometry) -> float:
            return _region_area(s, shapely.transform(g, lambda c: c / scale))

        for poly in polys:
            simple = poly if raw else _simplify_keeping_area(poly, self.tol, self.tol_area_rel, measure=on_surface)
            # coordinates on a grid of the ring gap: a ring that runs out and back along a line a thousandth of a
            # millimetre wide (a cylinder's contour, where the mesh's vertices crowd one u) is valid to shapely
            # and a self-intersecting wire to OCCT at its precision; snapped, the spike collapses and goes
            simple = shapely.set_precision(simple, self.gap)
            cut = _cut_pinches(simple, self.gap, min(min_area, 0.5 * simple.area)) if whole else None
            parts = cut if cut is not None else _separate_rings(simple, self.gap, min(min_area, 0.5 * simple.area))
            target = on_surface(poly)
            if abs(sum(on_surface(q) for q in parts) - target) > 2 * self.tol_area_rel * target:
                # the ring separation filled a hole that simplification brought within the gap of the outer ring
                # (corpus training split: a torus face 4 % over): the unsimplified outline instead
                parts = _separate_rings(poly, self.gap, min(min_area, 0.5 * poly.area))
            for part in parts:
                piece = self._face(s, part, scale, cands)
                if piece is not None:
                    out.append(piece)
        return out

    def _ring_edges(
        self,
        s: AnalyticSurface,
        ring: np.ndarray,
        ccw: bool,
        cands: list[tuple[int, np.ndarray]],
    ) -> tuple[TopoDS_Wire, list[tuple[TopoDS_Edge, int]]] | None:
        uv = np.asarray(ring, float)[:-1]  # shapely rings repeat the first point
        area2 = np.sum(uv[:, 0] * np.roll(uv[:, 1], -1) - np.roll(uv[:, 0], -1) * uv[:, 1])
        if (area2 > 0) != ccw:
            uv = uv[::-1]
        if len(uv) < 3:
            return None
        xyz = s.evaluate(uv)
        mids = s.evaluate((uv + np.roll(uv, -1, axis=0)) / 2)
        names = nearest_edge_ids(mids, cands)
        verts = []
        for q in xyz:
            vx = TopoDS_Vertex()
            self.bb.MakeVertex(vx, gp_Pnt(*map(float, q)), self.precision)
            verts.append(vx)
        w = TopoDS_Wire()
        self.bb.MakeWire(w)
        edges = []
        for i in range(len(uv)):
            j = (i + 1) % len(uv)
            seg = GCE2d_MakeSegment(gp_Pnt2d(*uv[i]), gp_Pnt2d(*uv[j])).Value()
            mk = BRepBuilderAPI_MakeEdge(seg, s.geom, verts[i], verts[j], seg.FirstParameter(), seg.LastParameter())
            if not mk.IsDone():
                return None
            edge = mk.Edge()
            BRepLib.BuildCurves3d_s(edge)
            self.bb.Add(w, edge)
            edges.append((edge, int(names[i])))
        w.Closed(True)
        return w, edges

    def _face(
        self, s: AnalyticSurface, poly: shapely.Polygon, scale: np.ndarray, cands: list[tuple[int, np.ndarray]]
    ) -> OutlinePiece | None:
        rings = [(_distinct(np.asarray(poly.exterior.coords), self.precision) / scale, True)]
        rings += [(_distinct(np.asarray(r.coords), self.precision) / scale, False) for r in poly.interiors]
        face = TopoDS_Face()
        self.bb.MakeFace(face, s.geom, self.precision)
        piece = OutlinePiece(face)
        try:
            for ring, outer in rings:
                made = self._ring_edges(s, ring, outer, cands)
                if made is None:
                    if outer:
                        return None
                    continue
                self.bb.Add(face, made[0])
                piece.edges.extend(made[1])
        except Exception:  # noqa: BLE001 - any OCCT construction failure: this piece is not built
            return None
        if not BRepCheck_Analyzer(face).IsValid():
            return None
        return piece
