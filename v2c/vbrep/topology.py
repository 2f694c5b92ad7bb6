"""Topological and geometric consistency of the extracted VB-Rep (camera frame, metres).

A B-rep consumer (the STEP exporter) trims each face by its own loops; that needs:

- every loop a closed chain of edges whose end vertices coincide (shared vertex ids; `build_loops` chains them,
  `open_loops` counts the chains that do not close);
- every edge polyline starting and ending exactly at its vertices' positions and lying on each of its faces'
  surfaces: an intersection edge on both (on their intersection curve), any other edge on its one face
  (`snap_to_surfaces`);
- valid primitive parameters (`valid_primitive`: positive radii, a cone half angle in (0, pi/2), a torus whose
  tube circle lies on its side of the axis).

`check_topology` measures all of it on a finished `VBRep` (tests, benchmarks).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from v2c.camera import project
from v2c.primitives import from_dict
from v2c.primitives.base import Primitive
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.lift import contact_points, points_on_curve, project_to_intersection
from v2c.vbrep.model import EdgeType, VBRep
from v2c.vbrep.postprocess import ProtoEdge, ProtoVertex, image_length


def valid_primitive(prim: Primitive) -> bool:
    """Whether a primitive's parameters describe a proper surface: finite numbers, positive radii, a cone half
    angle strictly between 0 and pi/2, and a torus with a positive major radius (a negative one describes a tube
    centred on the far side of the axis: a self-intersecting lemon, or nothing at all)."""
    d = prim.to_dict()
    vals = []
    for v in d["params"].values():
        vals += list(np.ravel(np.asarray(v, float)))
    if not np.all(np.isfinite(vals)):
        return False
    p = d["params"]
    if prim.type in ("cylinder", "sphere"):
        return p["radius"] > 0
    if prim.type == "cone":
        return 0 < p["half_angle"] < np.pi / 2
    if prim.type == "torus":
        return p["radius"] > 0 and p["minor_radius"] > 0
    return True


def solve_on_surfaces(prims: list[Primitive], x0: np.ndarray, iters: int) -> tuple[np.ndarray, float]:
    """The point nearest ``x0`` (3,) on all the given surfaces (least squares where they have no common point):
    Gauss-Newton with minimal-norm steps on their signed distances, at most ``iters``. Returns the point and the
    largest |signed distance| left (metres)."""
    x = np.asarray(x0, float).copy()
    if not prims:
        return x, 0.0
    for _ in range(iters):
        f = np.array([float(p.signed_distance(x[None])[0]) for p in prims])
        J = np.stack([p.normal(x[None])[0] for p in prims])
        step = np.linalg.lstsq(J, f, rcond=1e-9)[0]
        if not np.all(np.isfinite(step)):
            break
        x = x - step
        if np.linalg.norm(step) < 1e-12:
            break
    res = max(abs(float(p.signed_distance(x[None])[0])) for p in prims)
    return x, res


#: closest-point steps moving points onto a surface: one is exact for the quadrics, the torus' is approximate
_CLOSEST_STEPS = 3


def _on_surface(prim: Primitive, pts: np.ndarray) -> np.ndarray:
    """Points moved onto a surface (closest point, repeated for surfaces where one step is approximate)."""
    x = np.asarray(pts, float)
    for _ in range(_CLOSEST_STEPS):
        x = prim.closest_point(x)
    return x


def snap_to_surfaces(
    protos: list[ProtoEdge],
    verts: list[ProtoVertex],
    prims: dict[int, Primitive],
    max_move: float,
    K: np.ndarray,
    cfg: VBRepConfig,
) -> dict[str, Any]:
    """Make the edges lie on their surfaces and end at their vertices (in place). Solves take ``cfg.snap_iters``
    steps; ``eps`` below is ``cfg.snap_tol``, ``end_px`` ``cfg.snap_end_px``.

    Vertices: moved onto all the surfaces of the faces of their edges (least squares, `solve_on_surfaces`) if that
    moves them at most ``max_move`` metres. Intersection edges: interior samples onto the intersection curve
    (minimal-norm Gauss-Newton on both signed distances); samples that do not get within ``eps`` of both
    surfaces within ``max_move`` stay where they are (counted). Other edges: interior samples onto their face's
    surface. Interior samples within ``end_px`` pixels of an end vertex's image point are dropped (a
    vertex solved a few pixels off the lifted end would otherwise leave the polyline doubling back across its
    neighbour there). Every polyline then starts and ends exactly at its vertices. prims: instance id ->
    primitive. Returns counts."""
    iters, eps, end_px = cfg.snap_iters, cfg.snap_tol, cfg.snap_end_px
    stats = {"vertices_on_surfaces": 0, "vertices": len(verts), "samples_off_curve": 0}
    faces_at: dict[int, set[int]] = {}
    int_at: dict[int, list[tuple[int, ...]]] = {}
    for p in protos:
        for v in (p.v0, p.v1):
            faces_at.setdefault(v, set()).update(p.faces)
            if p.type is EdgeType.INTERSECTION:
                int_at.setdefault(v, []).append(tuple(sorted(p.faces)))
    for vid, v in enumerate(verts):
        if v.free:  # placed with an edge left between its surfaces (postprocess rule 4)
            continue
        # on all its faces if they meet there; else on the faces of its intersection edges, else on one
        # intersection edge's two faces (that edge's curve), else on its first face
        ints = int_at.get(vid, [])
        cands = [sorted(faces_at.get(vid, ())), sorted({f for fs in ints for f in fs})] + [list(fs) for fs in ints]
        cands += [[f] for f in sorted(faces_at.get(vid, ()))]
        best = None
        for fs in cands:
            if not fs:
                continue
            x, res = solve_on_surfaces([prims[f] for f in fs if f in prims], v.position, iters)
            if np.all(np.isfinite(x)) and np.linalg.norm(x - v.position) <= max_move:
                if res <= eps:
                    best = x
                    break
                if best is None:
                    best = x
        if best is not None:
            v.position = best
            stats["vertices_on_surfaces"] += 1
    for p in protos:
        inner = p.pts[1:-1]
        if len(inner) and not p.apart:  # an edge left between its surfaces stays there (postprocess rule 4)
            if p.type is EdgeType.INTERSECTION and len(p.faces) == 2 and (p.curve or {}).get("tangent"):
                # a tangent junction stays on the surfaces' line of contact (an intersection solve wanders)
                x = points_on_curve(p.curve, inner)
                if x is None:
                    x, _ = contact_points(prims[p.faces[0]], prims[p.faces[1]], inner, iters)
                inner = np.where(np.all(np.isfinite(x), 1)[:, None], x, inner)
            elif p.type is EdgeType.INTERSECTION and len(p.faces) == 2:
                pa, pb = prims[p.faces[0]], prims[p.faces[1]]
                x = project_to_intersection(pa, pb, inner, iters)
                res = np.maximum(np.abs(pa.signed_distance(x)), np.abs(pb.signed_distance(x)))
                ok = np.all(np.isfinite(x), 1) & (res <= eps) & (np.linalg.norm(x - inner, axis=1) <= max_move)
                stats["samples_off_curve"] += int(np.sum(~ok))
                inner = np.where(ok[:, None], x, inner)
            else:
                x = _on_surface(prims[p.faces[0]], inner)
                inner = np.where(np.all(np.isfinite(x), 1)[:, None], x, inner)
        a, b = verts[p.v0].position, verts[p.v1].position
        if end_px > 0 and len(inner):
            uv = project(inner, K)
            ua, ub = project(np.stack([a, b]), K)
            keep = np.ones(len(uv), bool)
            for u_end, order in ((ua, np.arange(len(uv))), (ub, np.arange(len(uv))[::-1])):
                near = np.linalg.norm(uv - u_end, axis=1) <= end_px
                far = order[~near[order]]
                if len(far) == 0:
                    keep &= ~near
                    continue
                # the first sample beyond end_px sets the edge's direction out of the vertex; closer samples
                # that lie behind the vertex (against that direction) double back: dropped
                d = uv[far[0]] - u_end
                keep &= ~(near & ((uv - u_end) @ d <= 0))
            if p.v0 == p.v1 and not keep.any():
                keep[len(keep) // 2] = True  # a closed edge keeps a point between its ends
            inner = inner[keep]
        p.pts = np.concatenate([a[None], inner, b[None]])
        if len(p.uv):
            p.uv = project(p.pts, K)
    return stats


def _turn_back(a: np.ndarray, b: np.ndarray, c: np.ndarray, max_deg: float) -> bool:
    """Whether the image path a -> b -> c (pixels) turns back at b: the angle at b under ``max_deg``."""
    u, w = a - b, c - b
    nu, nw = float(np.linalg.norm(u)), float(np.linalg.norm(w))
    if nu < 1e-9 or nw < 1e-9:
        return False
    return bool(u @ w > nu * nw * np.cos(np.radians(max_deg)))


def drop_end_hooks(protos: list[ProtoEdge], K: np.ndarray, max_deg: float) -> int:
    """Drop (in place) each polyline's first and last interior samples while the path from its end vertex through
    them turns back (the angle at the sample, in the image, under ``max_deg``): a vertex placed a few pixels back
    along the edge (a short edge contracted into it, a corner solved onto three surfaces) leaves the samples
    between it and the old end as a hook past the corner, which crosses the neighbouring edge there (corpus
    training split, oracle, 16 scans: 236 of 1,478 edges; hooks 2-7 px long, a tenth over 14). Closed edges are
    left as they are (a small circle's few samples turn sharply). Returns the count of samples dropped. 0 degrees:
    off."""
    dropped = 0
    if max_deg <= 0:
        return dropped
    for p in protos:
        if len(p.pts) < 3 or p.v0 == p.v1:  # a closed edge's few samples turn sharply by themselves
            continue
        uv = project(p.pts, K)
        keep = list(range(len(p.pts)))
        while len(keep) > 2 and _turn_back(uv[keep[0]], uv[keep[1]], uv[keep[2]], max_deg):
            del keep[1]
        while len(keep) > 2 and _turn_back(uv[keep[-1]], uv[keep[-2]], uv[keep[-3]], max_deg):
            del keep[-2]
        if len(keep) < len(p.pts):
            dropped += len(p.pts) - len(keep)
            p.pts = p.pts[keep]
            if len(p.uv) == len(uv):
                p.uv = p.uv[keep]
    return dropped


def drop_degenerate(protos: list[ProtoEdge], K: np.ndarray, min_px: float) -> list[ProtoEdge]:
    """Edges that start and end at one vertex with fewer than 3 samples (a closed curve needs a point between its
    ends) or shorter than ``min_px`` pixels in the image are removed: such a loop encloses nothing (vertex merges
    in post-processing can close a short edge after its own check). Loops through that vertex stay closed
    without it."""
    return [p for p in protos if p.v0 != p.v1 or (len(p.pts) >= 3 and image_length(p.pts, K) >= min_px)]


def open_loops(vbrep: VBRep) -> list[tuple[int, int]]:
    """(face id, loop index) of every loop that is not a closed chain through shared vertex ids."""
    out = []
    for f in vbrep.faces:
        for k, lp in enumerate(f.loops):
            ends = [
                (vbrep.edges[e].v1, vbrep.edges[e].v0) if r else (vbrep.edges[e].v0, vbrep.edges[e].v1) for e, r in lp
            ]
            if not all(ends[i][1] == ends[(i + 1) % len(ends)][0] for i in range(len(ends))):
                out.append((f.id, k))
    return out


def check_topology(vbrep: VBRep) -> dict[str, Any]:
    """Consistency measures of a VB-Rep: ``open_loops`` (count), ``faces_without_loops``, ``end_gap_m`` (largest
    distance of a polyline end from its vertex), ``off_surface_m`` (largest distance of a polyline sample from one
    of its edge's faces' surfaces), ``invalid_primitives`` (face ids)."""
    prims = {f.id: from_dict(f.primitive) for f in vbrep.faces}
    gap = off = 0.0
    for e in vbrep.edges:
        p = np.asarray(e.polyline, float)
        gap = max(
            gap,
            float(np.linalg.norm(p[0] - vbrep.vertices[e.v0].position)),
            float(np.linalg.norm(p[-1] - vbrep.vertices[e.v1].position)),
        )
        for f in e.faces:
            off = max(off, float(np.abs(prims[f].signed_distance(p)).max()))
    return {
        "open_loops": len(open_loops(vbrep)),
        "faces_without_loops": sum(1 for f in vbrep.faces if not f.loops),
        "end_gap_m": gap,
        "off_surface_m": off,
        "invalid_primitives": [k for k, pr in prims.items() if not valid_primitive(pr)],
    }
