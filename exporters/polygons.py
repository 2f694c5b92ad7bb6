"""Polyline and polygon helpers on numpy arrays (no OCCT): simplification, resampling, distances, crossings,
mesh boundaries, connected groups."""

from __future__ import annotations

import numpy as np
import shapely
from shapely.geometry.polygon import signed_area as _ring_signed_area

from v2c.groups import groups_sharing_keys
from v2c.polyline import segment_distances


def simplify_polyline(points: np.ndarray, tol: float) -> np.ndarray:
    """The points (M, 2) of a 2D polyline (N, 2) kept by Douglas-Peucker within ``tol`` (GEOS, through shapely),
    distances to the chord as a segment (a polyline that doubles back beyond an end keeps its turning point),
    its first and last points always kept."""
    points = np.asarray(points, float)
    if len(points) <= 2:
        return points
    return shapely.get_coordinates(shapely.simplify(shapely.LineString(points), tol, preserve_topology=False))


def subsample(points: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` points of a polyline, evenly by index, first and last kept."""
    if len(points) <= n:
        return points
    return points[np.unique(np.round(np.linspace(0, len(points) - 1, n)).astype(int))]


def densify(pts: np.ndarray, n_max: int = 120) -> np.ndarray:
    """A polyline (N, D) resampled by linear interpolation to about ``n_max`` points, its vertices kept."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    total = seg.sum()
    if total <= 0 or len(pts) >= n_max:
        return pts
    out = [pts[:1]]
    for a, b, ln in zip(pts[:-1], pts[1:], seg):
        k = max(1, int(np.ceil(n_max * ln / total)))
        t = np.linspace(0.0, 1.0, k + 1)[1:, None]
        out.append(a + t * (b - a))
    return np.concatenate(out)


def dist_to_polyline_2d(q: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """(M,) distances of 2D points to a 2D polyline."""
    return segment_distances(q, poly).min(1)


def polygon_crossings(polygons: list[np.ndarray]) -> np.ndarray:
    """(K, 2) points where edges of closed 2D polygons (each (M, 2), implicitly closed) cross properly
    (touching at shared end points does not count), within one polygon or between two."""
    # kept by hand, not shapely's STRtree + crosses: GEOS's exact predicate has no tolerance and also reports the
    # near-degenerate crossings of short or near-coincident edges that ``eps`` ignores (13 of 276 calls over 33
    # reconstructed scans, changing two STEP files)
    segs = np.concatenate([np.stack([p, np.roll(p, -1, axis=0)], 1) for p in polygons])  # (S, 2, 2)
    a, b = segs[:, None, 0], segs[:, None, 1]
    c, d = segs[None, :, 0], segs[None, :, 1]

    def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])

    d1, d2 = orient(a, b, c), orient(a, b, d)
    d3, d4 = orient(c, d, a), orient(c, d, b)
    scale = np.abs(segs.reshape(-1, 2)).max() + 1.0
    eps = 1e-12 * scale * scale
    i, j = np.nonzero(np.triu((d1 * d2 < -eps) & (d3 * d4 < -eps), 1))
    if len(i) == 0:
        return np.zeros((0, 2))
    t = d1[i, j] / (d1[i, j] - d2[i, j])  # where segment j crosses the line of segment i
    return segs[j, 0] + t[:, None] * (segs[j, 1] - segs[j, 0])


def connected_groups(face_edges: dict[int, set[int]]) -> list[list[int]]:
    """Groups of faces connected through shared edge ids (union-find), each sorted, in first-face order."""
    faces = list(face_edges)
    groups = groups_sharing_keys([face_edges[f] for f in faces])
    return sorted((sorted(faces[k] for k in g) for g in groups), key=lambda g: g[0])


def signed_area(uv: np.ndarray) -> float:
    """Signed area of a closed 2D polygon (M, 2), implicitly closed (positive: counter-clockwise); 0 below three
    points."""
    if len(uv) < 3:
        return 0.0
    return float(_ring_signed_area(shapely.LinearRing(np.asarray(uv, float))))
