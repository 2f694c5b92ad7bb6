"""Polyline and polygon helpers on numpy arrays (no OCCT): simplification, resampling, distances, crossings,
mesh boundaries, connected groups."""

from __future__ import annotations

import numpy as np

from v2c.groups import groups_sharing_keys
from v2c.polyline import rdp_indices as _rdp_indices


def rdp_indices(points: np.ndarray, tol: float) -> np.ndarray:
    """Ramer-Douglas-Peucker indices with distances to the chord segment (`v2c.polyline.rdp_indices`)."""
    return _rdp_indices(points, tol, clamp=True)


def subsample(points: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` points of a polyline, evenly by index, first and last kept."""
    if len(points) <= n:
        return points
    return points[np.unique(np.round(np.linspace(0, len(points) - 1, n)).astype(int))]


def simplify_closed(points: np.ndarray, tol: float, max_points: int = 64) -> np.ndarray:
    """Indices of a closed polyline's points kept by Ramer-Douglas-Peucker within ``tol`` (same units), at
    most ``max_points`` (the tolerance doubles until they fit). The loop is split at the point farthest from
    its first one."""
    n = len(points)
    if n <= 3:
        return np.arange(n)
    far = int(np.argmax(np.linalg.norm(points - points[0], axis=1)))
    ext = np.concatenate([points, points[:1]])  # index n is point 0 again
    t = tol
    while True:
        first = rdp_indices(ext[: far + 1], t)
        second = far + rdp_indices(ext[far:], t)
        keep = np.unique(np.concatenate([first, second[second < n]]))
        if len(keep) <= max_points:
            return keep
        t *= 2


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
    a, d = poly[:-1], np.diff(poly, axis=0)
    dd = np.maximum(np.einsum("kj,kj->k", d, d), 1e-300)
    t = np.clip(np.einsum("mkj,kj->mk", q[:, None] - a[None], d) / dd, 0.0, 1.0)
    return np.linalg.norm(q[:, None] - (a[None] + t[..., None] * d[None]), axis=2).min(1)


def polygon_crossings(polygons: list[np.ndarray]) -> np.ndarray:
    """(K, 2) points where edges of closed 2D polygons (each (M, 2), implicitly closed) cross properly
    (touching at shared end points does not count), within one polygon or between two."""
    segs = np.concatenate([np.stack([p, np.roll(p, -1, axis=0)], 1) for p in polygons])  # (S, 2, 2)
    a, b = segs[:, None, 0], segs[:, None, 1]
    c, d = segs[None, :, 0], segs[None, :, 1]

    def orient(p: np.ndarray, q: np.ndarray, r: np.ndarray) -> np.ndarray:
        return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
            r[..., 0] - p[..., 0]
        )

    d1, d2 = orient(a, b, c), orient(a, b, d)
    d3, d4 = orient(c, d, a), orient(c, d, b)
    scale = np.abs(segs.reshape(-1, 2)).max() + 1.0
    eps = 1e-12 * scale * scale
    i, j = np.nonzero(np.triu((d1 * d2 < -eps) & (d3 * d4 < -eps), 1))
    if len(i) == 0:
        return np.zeros((0, 2))
    t = d1[i, j] / (d1[i, j] - d2[i, j])  # where segment j crosses the line of segment i
    return segs[j, 0] + t[:, None] * (segs[j, 1] - segs[j, 0])


def mesh_boundary_loop(triangles: np.ndarray) -> np.ndarray | None:
    """Vertex indices of the longest closed boundary loop of a triangle mesh (edges used by one triangle)."""
    if len(triangles) == 0:
        return None
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    key = np.sort(e, axis=1)
    _, inv, cnt = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    bnd = e[cnt[inv.ravel()] == 1]
    nxt: dict[int, int] = {}
    for a, b in bnd:
        nxt.setdefault(int(a), int(b))
    best: list[int] = []
    seen: set[int] = set()
    for start in list(nxt):
        if start in seen:
            continue
        loop, v = [], start
        while v in nxt and v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        if v == start and len(loop) > len(best):
            best = loop
    return np.asarray(best, int) if best else None


def connected_groups(face_edges: dict[int, set[int]]) -> list[list[int]]:
    """Groups of faces connected through shared edge ids (union-find), each sorted, in first-face order."""
    faces = list(face_edges)
    groups = groups_sharing_keys([face_edges[f] for f in faces])
    return sorted((sorted(faces[k] for k in g) for g in groups), key=lambda g: g[0])


def signed_area(uv: np.ndarray) -> float:
    """Signed area of a closed 2D polygon (M, 2) (positive: counter-clockwise)."""
    u, v = uv[:, 0], uv[:, 1]
    return 0.5 * float(np.sum(u * np.roll(v, -1) - np.roll(u, -1) * v))
