"""A face's bounded surface mesh made from its boundary loops: the trimmed analytic face.

`v2c.vbrep.mesh.face_mesh` meshes a face's pixel region; its outline is the segmentation's, while the face's
edges lie where the surfaces meet (intersection), where they turn away (visibility) or along the smoothed outline
(silhouette). So the region mesh and the loops disagree by up to a few pixels along every edge, and a face written
as its loops (the STEP file, `exporters`) differs from the mesh the figure and the benchmark draw: on small faces
by far more than 2 % of its area. Where a face's loops bound a valid region of the image, its mesh is made from
them instead: the polygon the loops' image projections enclose (outer loop, holes), cut into the pixel grid's
cells (cells wholly inside: two triangles; cells the boundary crosses: the cell clipped to the polygon,
triangulated), every vertex back-projected onto the face's sheet (`v2c.vbrep.mesh.lift_points`). Its boundary
is the edges' polylines (a curved face's followed on its surface between their samples), so the VB-Rep's face,
its figure and its STEP face are one geometry.

Image pixels (u, v) with pixel centres at integers (the crack lattice of `v2c.segment.graph` at half integers);
camera frame, metres.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import shapely
from scipy.ndimage import binary_dilation

from v2c.camera import project
from v2c.vbrep.mesh import finish_mesh, lift_points

if TYPE_CHECKING:
    from v2c.primitives.base import Primitive
    from v2c.vbrep.postprocess import ProtoEdge

Loop = list[tuple[int, bool]]


def _on_surface_between(pts: np.ndarray, prim: Primitive, pieces: int) -> np.ndarray:
    """A polyline (K, 3) with every segment cut into ``pieces``, the new points moved onto ``prim``'s surface (its
    closest points): where a curved face turns away from the camera a straight image segment between two of its
    edge's samples cuts inside the curve the edge follows on the surface (the written edge, fitted on the surface
    through those samples), and the band between them, seen edge-on, is a few per cent of the face's area."""
    if pieces <= 1 or len(pts) < 2:
        return pts
    t = np.arange(pieces) / pieces
    a, b = pts[:-1], pts[1:]
    dense = (a[:, None, :] + t[None, :, None] * (b - a)[:, None, :]).reshape(-1, 3)
    inner = np.ones(len(dense), bool)
    inner[::pieces] = False
    moved = dense.copy()
    if inner.any():
        q = prim.closest_point(dense[inner])
        ok = np.all(np.isfinite(q), axis=1)
        moved[np.flatnonzero(inner)[ok]] = q[ok]
    return np.concatenate([moved, pts[-1:]])


def _loop_ring(
    loop: Loop, protos: list[ProtoEdge], K: np.ndarray, prim: Primitive | None = None, pieces: int = 1
) -> np.ndarray | None:
    """The image ring (M, 2) of one loop (its edges' projected polylines in loop order, joints once); None when
    the loop does not close through its vertices. With a curved ``prim`` (the face's surface), each polyline
    segment is first cut into ``pieces`` on it (`_on_surface_between`)."""
    pts, ends = [], []
    for eid, rev in loop:
        p = protos[eid]
        x = p.pts if prim is None or prim.type == "plane" else _on_surface_between(p.pts, prim, pieces)
        uv = project(x, K)
        pts.append(uv[::-1] if rev else uv)
        ends.append((p.v1, p.v0) if rev else (p.v0, p.v1))
    if any(ends[i][1] != ends[(i + 1) % len(ends)][0] for i in range(len(ends))):
        return None
    ring = np.concatenate([q[:-1] for q in pts])
    return ring if len(ring) >= 3 and np.all(np.isfinite(ring)) else None


def loop_polygon(
    loops: list[Loop], protos: list[ProtoEdge], K: np.ndarray, prim: Primitive | None = None, pieces: int = 1
) -> shapely.Polygon | shapely.MultiPolygon | None:
    """The image region (pixels) a face's loops bound: the first loop (the largest, `build_loops`) the outer
    ring, the others holes; None when a loop does not close or the region is empty.

    Rings that cross themselves or each other (an edge's projected polyline running a pixel past the corner
    where the next one starts, a hole's ring crossing the outer one) are repaired rather than refused: each
    ring's own region (``buffer(0)``: the twist a crossing near a corner makes, wound the other way, is no area
    of it), the holes' regions taken from the outer one's. Refusing them gave 31 of the 103 faces of 12 in-family
    validation scans (oracle) their pixel region's mesh instead, whose outline differs from the loops that bound
    the STEP face: each of those went to the STEP as its mesh outline. Whether the repaired region is the face
    seen is `assemble._loops_cover_region`'s to judge, as for any loop polygon. ``prim``, ``pieces``: a curved
    face's polylines are followed on its surface (`_loop_ring`)."""
    rings = [_loop_ring(lp, protos, K, prim, pieces) for lp in loops]
    if not rings or any(r is None for r in rings):
        return None
    poly = shapely.Polygon(rings[0], rings[1:])
    if not poly.is_valid:
        poly = shapely.Polygon(rings[0]).buffer(0)
        for hole in rings[1:]:
            poly = poly.difference(shapely.Polygon(hole).buffer(0))
        parts = [g for g in shapely.get_parts(poly) if isinstance(g, shapely.Polygon) and g.area > 0]
        if not parts:
            return None
        poly = parts[0] if len(parts) == 1 else shapely.MultiPolygon(parts)
    if poly.is_empty or poly.area <= 0:
        return None
    return poly


def _cells_crossed(boundary: np.ndarray, origin: np.ndarray, stride: int, shape: tuple[int, int]) -> np.ndarray:
    """(shape) bool: grid cells that a closed ring's segments pass through (sampled at a quarter cell), with
    their 8 neighbours (a cell the boundary only grazes is clipped too, which is exact either way)."""
    seg = np.diff(np.concatenate([boundary, boundary[:1]]), axis=0)
    n = np.maximum(1, np.ceil(np.linalg.norm(seg, axis=1) / (0.25 * stride)).astype(int))
    t = np.concatenate([np.arange(k) / k for k in n])
    start = np.repeat(boundary, n, axis=0)
    pts = start + np.repeat(seg, n, axis=0) * t[:, None]
    ij = np.floor((pts - origin) / stride).astype(int)
    hit = np.zeros(shape, bool)
    ok = (ij[:, 0] >= 0) & (ij[:, 0] < shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < shape[0])
    hit[ij[ok, 1], ij[ok, 0]] = True
    return binary_dilation(hit, np.ones((3, 3), bool))


def polygon_triangles(poly: shapely.Polygon | shapely.MultiPolygon, stride: int) -> np.ndarray:
    """Triangles (M, 3, 2) covering ``poly`` exactly (image pixels): the grid cells of ``stride`` pixels (corners
    on multiples of it) wholly inside as two triangles each, the cells its boundary crosses clipped to it and
    triangulated (constrained Delaunay)."""
    lo = np.floor(np.array(poly.bounds[:2]) / stride) * stride - stride
    hi = np.ceil(np.array(poly.bounds[2:]) / stride) * stride + stride
    nx, ny = int(round((hi[0] - lo[0]) / stride)), int(round((hi[1] - lo[1]) / stride))
    crossed = np.zeros((ny, nx), bool)
    for part in shapely.get_parts(poly):
        for ring in [part.exterior, *part.interiors]:
            crossed |= _cells_crossed(np.asarray(ring.coords)[:-1], lo, stride, (ny, nx))
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    x0, y0 = lo[0] + jj * stride, lo[1] + ii * stride
    centre_in = shapely.contains_xy(poly, x0 + 0.5 * stride, y0 + 0.5 * stride)
    full = centre_in & ~crossed
    a = np.stack([x0[full], y0[full]], 1)
    b, c, d = a + [stride, 0], a + [stride, stride], a + [0, stride]
    tris = [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    cells = shapely.box(x0[crossed], y0[crossed], x0[crossed] + stride, y0[crossed] + stride)
    pieces = shapely.get_parts(shapely.intersection(cells, poly))
    pieces = pieces[(shapely.get_type_id(pieces) == 3) & (shapely.area(pieces) > 1e-9 * stride * stride)]
    if len(pieces):
        tri = shapely.get_parts(shapely.constrained_delaunay_triangles(pieces))
        xy = shapely.get_coordinates(shapely.get_exterior_ring(tri)).reshape(len(tri), 4, 2)[:, :3]
        tris.append(xy)
    return np.concatenate(tris) if tris else np.zeros((0, 3, 2))


def loop_mesh(
    prim: Primitive,
    sheet: int,
    poly: shapely.Polygon | shapely.MultiPolygon,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    stride: int,
    max_edge: float,
    surface_tol: float,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    long_in_bounds: bool = False,
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh of the part of the face's sheet that ``poly`` (image pixels, `loop_polygon`) covers; the other
    arguments as `v2c.vbrep.mesh.face_mesh`. A triangle with a vertex that cannot be lifted is left out.
    Returns vertices (n, 3) camera-frame metres and triangles (m, 3) int64."""
    tri_uv = polygon_triangles(poly, stride)
    if len(tri_uv) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    # shared corners once: the cells' corners lie on the grid, the clipped pieces' on the polygon
    uv, tri = np.unique(np.round(tri_uv.reshape(-1, 2), 6), axis=0, return_inverse=True)
    tri = tri.reshape(-1, 3).astype(np.int64)
    verts, good = lift_points(prim, sheet, uv, depth, K, window, surface_tol)
    tri = tri[good[tri].all(axis=1)]
    return finish_mesh(verts, tri, max_edge, bounds, long_in_bounds)
