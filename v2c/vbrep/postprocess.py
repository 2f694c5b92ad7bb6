"""Post-processing of the extracted edges and vertices (the supplement's clean-up), and face loops.

Rules, in order:
1. labelling: an intersection edge needs two faces, every other type one; an occluded edge must have a partner
   silhouette or visibility edge over the same image samples (it is dropped otherwise);
2. corner correction: vertices of one kind optimised onto the same point merge; short edges (image length
   < ``min_edge_px``) are contracted: their end vertex merges into their start vertex (the kind with the higher
   priority, corner first, survives); closed loops shorter than ``min_loop_edges`` times ``min_edge_px`` are
   dropped;
3. simplification: two edges of the same type and faces meeting at a vertex no other edge uses are merged into one
   when the polyline turns there by less than ``simplify_deg`` degrees;
4. collapsed loops: an intersection edge of two planes lies on their line, so a closed one (a face enclosed in
   the image by one neighbour, or an edge closed by a contraction or a merge) encloses nothing once lifted onto
   it; such an edge keeps its type but is lifted from its image samples to midway between its two planes along
   the rays and left there (`lift_collapsed`), on a vertex of its own when it is alone on its vertex, so both
   faces keep a loop that bounds them (the STEP exporter fits it on the nearer face, its tolerance covering the
   gap to the other);
5. polylines are thinned with Ramer-Douglas-Peucker in the image (``polyline_px``), keeping both ends;
6. unused vertices are removed and ids compacted.
Camera frame, metres; pixels (u, v).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from v2c.camera import pixel_rays, project
from v2c.polyline import rdp_indices, segment_distances
from v2c.primitives import Plane
from v2c.primitives.base import Primitive
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.model import EdgeType, VertexKind


@dataclass
class ProtoEdge:
    """An edge under construction: ``faces`` are instance ids; pts (K, 3) camera metres; uv (K, 2) pixels."""

    type: EdgeType
    faces: tuple[int, ...]
    pts: np.ndarray
    uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    key0: tuple | None = None  # endpoint keys (`v2c.vbrep.edges.edge_protos`): ends with one key share a vertex
    key1: tuple | None = None
    graph_edge: int = -1
    curve: dict | None = None
    stats: dict = field(default_factory=dict)
    v0: int = -1
    v1: int = -1
    apart: bool = False  # an intersection edge left between its two surfaces, not on a common curve (rule 4)


@dataclass
class ProtoVertex:
    """A vertex under construction: position (3,) camera metres, pixel (2,) its image point."""

    kind: VertexKind
    position: np.ndarray
    pixel: np.ndarray
    outline_corner: bool = False  # a corner of an image outline (never merged away)
    free: bool = False  # stays where it was placed (not moved onto its faces' surfaces; rule 4)


_KIND_PRIORITY = {
    VertexKind.CORNER: 0,
    VertexKind.INTERSECTION_VISIBILITY: 1,
    VertexKind.OCCLUSION: 2,
    VertexKind.OTHER: 3,
}


def image_length(pts: np.ndarray, K: np.ndarray) -> float:
    """Length (pixels) of a 3D polyline's projection."""
    if len(pts) < 2:
        return 0.0
    return float(np.sum(np.linalg.norm(np.diff(project(pts, K), axis=0), axis=1)))


def _labelling(protos: list[ProtoEdge]) -> list[ProtoEdge]:
    near = {(p.graph_edge, p.key0, p.key1) for p in protos if p.type in (EdgeType.SILHOUETTE, EdgeType.VISIBILITY)}
    out = []
    for p in protos:
        if p.type is EdgeType.INTERSECTION and len(p.faces) != 2:
            continue
        if p.type is not EdgeType.INTERSECTION and len(p.faces) != 1:
            continue
        if p.type is EdgeType.OCCLUDED and (p.graph_edge, p.key0, p.key1) not in near:
            continue
        out.append(p)
    return out


def _contract_short(
    protos: list[ProtoEdge], verts: list[ProtoVertex], K: np.ndarray, min_px: float, loop_min_px: float, same_m: float
) -> list[ProtoEdge]:
    parent = list(range(len(verts)))
    # vertices optimised onto the same 3D point (junction clutter of the 2D graph) are one vertex
    pos = np.array([v.position for v in verts]) if verts else np.zeros((0, 3))
    for i in range(len(verts)):
        d = np.linalg.norm(pos[i + 1 :] - pos[i], axis=1)
        for j in np.flatnonzero(d < same_m) + i + 1:
            if verts[j].kind is verts[i].kind and parent[j] == j:
                parent[j] = i

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    keep = []
    for p in protos:
        a, b = find(p.v0), find(p.v1)
        length = image_length(p.pts, K)
        short = length < min_px
        if a == b and length < loop_min_px:  # a tiny closed loop (junction clutter)
            continue
        if a != b and short:
            # the higher-priority kind survives (corner correction)
            if _KIND_PRIORITY[verts[b].kind] < _KIND_PRIORITY[verts[a].kind]:
                a, b = b, a
            parent[b] = a
            continue
        keep.append(p)
    for p in keep:
        p.v0, p.v1 = find(p.v0), find(p.v1)
        p.pts[0], p.pts[-1] = verts[p.v0].position, verts[p.v1].position
    return keep


def _end_dir(p: ProtoEdge, at_start: bool) -> np.ndarray:
    """Unit tangent of the polyline leaving vertex (v0 if at_start else v1) into the edge."""
    pts = p.pts if at_start else p.pts[::-1]
    k = min(len(pts) - 1, max(1, len(pts) // 4))
    d = pts[k] - pts[0]
    return d / max(np.linalg.norm(d), 1e-12)


def _same_kind_pairs(protos: list[ProtoEdge], verts: list[ProtoVertex]) -> list[tuple[int, bool, int, bool]]:
    """(i, si, j, sj) for each vertex that exactly two distinct edges use, of the same type and faces, and that is
    not an outline corner: the two edges' indices, each with True where it starts at that vertex (vertex order)."""
    inc: dict[int, list[tuple[int, bool]]] = {}
    for i, p in enumerate(protos):
        inc.setdefault(p.v0, []).append((i, True))
        inc.setdefault(p.v1, []).append((i, False))
    out = []
    for v, ends in inc.items():  # loop over vertices
        if len(ends) != 2 or ends[0][0] == ends[1][0] or verts[v].outline_corner:
            continue
        (i, si), (j, sj) = ends
        p, q = protos[i], protos[j]
        if p.type is q.type and tuple(sorted(p.faces)) == tuple(sorted(q.faces)):
            out.append((i, si, j, sj))
    return out


def _join_pairs(
    protos: list[ProtoEdge],
    verts: list[ProtoVertex],
    join: Callable[[ProtoEdge, bool, ProtoEdge, bool], ProtoEdge | None],
) -> list[ProtoEdge]:
    """``protos`` with the first pair of `_same_kind_pairs` that ``join`` makes one edge (``join(p, si, q, sj)``:
    the edge, or None to leave the pair) replaced by that edge, again and again until no pair joins."""
    changed = True
    while changed:
        changed = False
        for i, si, j, sj in _same_kind_pairs(protos, verts):
            merged = join(protos[i], si, protos[j], sj)
            if merged is not None:
                protos = [x for k, x in enumerate(protos) if k not in (i, j)] + [merged]
                changed = True
                break
    return protos


def _merge_degree_two(protos: list[ProtoEdge], verts: list[ProtoVertex], simplify_deg: float) -> list[ProtoEdge]:
    cos_lim = np.cos(np.deg2rad(simplify_deg))

    def join(p: ProtoEdge, si: bool, q: ProtoEdge, sj: bool) -> ProtoEdge | None:
        # leaving v into p and into q: a straight continuation has these opposite
        if -_end_dir(p, si) @ _end_dir(q, sj) < cos_lim:
            return None
        a = p.pts[::-1] if si else p.pts  # ends at v
        b = q.pts if sj else q.pts[::-1]  # starts at v
        ua = p.uv[::-1] if si else p.uv
        ub = q.uv if sj else q.uv[::-1]
        v_start = p.v1 if si else p.v0
        v_end = q.v1 if sj else q.v0
        n_a, n_b = len(a), len(b)
        stats = {
            k: (p.stats[k] * n_a + q.stats[k] * n_b) / (n_a + n_b)
            if k in q.stats and np.isfinite(p.stats[k]) and np.isfinite(q.stats[k])
            else p.stats[k]
            for k in p.stats
        }
        return ProtoEdge(
            p.type,
            p.faces,
            np.concatenate([a, b[1:]]),
            np.concatenate([ua, ub[1:]]) if len(ua) and len(ub) else ua,
            p.key0,
            q.key1,
            p.graph_edge,
            p.curve,
            stats,
            v_start,
            v_end,
        )

    return _join_pairs(protos, verts, join)


def _drop_fold_backs(
    protos: list[ProtoEdge], verts: list[ProtoVertex], K: np.ndarray, fold_deg: float, fold_px: float
) -> list[ProtoEdge]:
    """Rule 3a: two edges of the same type and faces that meet at a vertex no other edge uses and leave it the same
    way (their directions within ``fold_deg`` degrees in 3D) where the shorter one's far end projects within
    ``fold_px`` pixels of the longer one's image path: one boundary that ran past where it turns and came back
    along itself (a vertex placed a few pixels beyond the junction it belongs to). The two become one edge, the
    longer one's polyline up to the point nearest that far end, then the far end; the vertex between them goes."""
    if fold_deg <= 0:
        return protos
    cos_lim = np.cos(np.deg2rad(fold_deg))

    def join(p: ProtoEdge, si: bool, q: ProtoEdge, sj: bool) -> ProtoEdge | None:
        if _end_dir(p, si) @ _end_dir(q, sj) < cos_lim:
            return None
        (lng, sl), (sht, ss) = (
            ((p, si), (q, sj)) if image_length(p.pts, K) >= image_length(q.pts, K) else ((q, sj), (p, si))
        )
        far = sht.v1 if ss else sht.v0
        near_end = lng.v1 if sl else lng.v0  # the longer edge's other end
        if far == near_end:
            return None
        a = lng.pts[::-1] if sl else lng.pts  # from its other end to v
        ua = project(a, K)
        b = project(np.asarray(verts[far].position, float)[None], K)[0]
        dist = segment_distances(b[None], ua)[0]
        k = int(np.argmin(dist))
        if dist[k] > fold_px:
            return None
        pts = np.concatenate([a[: k + 1], np.asarray(verts[far].position, float)[None]])
        uv_l = lng.uv[::-1] if sl else lng.uv
        uv = np.concatenate([uv_l[: k + 1], b[None]]) if len(uv_l) == len(a) else np.zeros((0, 2))
        return ProtoEdge(
            lng.type,
            lng.faces,
            pts,
            uv,
            lng.key1 if sl else lng.key0,
            sht.key1 if ss else sht.key0,
            lng.graph_edge,
            lng.curve,
            dict(lng.stats),
            near_end,
            far,
            lng.apart,
        )

    return _join_pairs(protos, verts, join)


def _plane_pair(p: ProtoEdge, prims: dict[int, Primitive]) -> bool:
    """Whether ``p`` is an intersection edge of two planes (its curve a line)."""
    return (
        p.type is EdgeType.INTERSECTION and len(p.faces) == 2 and all(isinstance(prims.get(f), Plane) for f in p.faces)
    )


def collapsed_edges(protos: list[ProtoEdge], prims: dict[int, Primitive]) -> list[int]:
    """Indices of the closed plane-plane intersection edges: lifted onto their planes' line they enclose
    nothing. (Two plane-plane edges of one face between the same two vertices collapse too, but are mostly the
    long sides of a thin face whose short ends were contracted: they are true intersection edges and stay.)"""
    return [k for k, p in enumerate(protos) if p.v0 == p.v1 and _plane_pair(p, prims)]


def _plane_depth(plane: Plane, rays: np.ndarray) -> np.ndarray:
    """Depth (metres, z) where each ray (z = 1) meets the plane; NaN where it runs parallel or behind."""
    n = plane.axis_vector
    den = rays @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        z = float(n @ np.asarray(plane.origin, float)) / den
    return np.where((np.abs(den) > 1e-12) & (z > 0), z, np.nan)


def lift_collapsed(
    protos: list[ProtoEdge], verts: list[ProtoVertex], prims: dict[int, Primitive], K: np.ndarray
) -> int:
    """Rule 4, in place: every edge of `collapsed_edges` lifted from its image samples to midway between its two
    planes along the rays and marked ``apart`` (the snap leaves it there); one alone on its vertex gets a vertex
    of its own at its first sample, marked ``free``. An edge whose samples do not meet both planes in front of
    the camera stays. Returns the number lifted."""
    uses: dict[int, int] = {}
    for p in protos:
        for v in {p.v0, p.v1}:
            uses[v] = uses.get(v, 0) + 1
    n = 0
    for k in collapsed_edges(protos, prims):
        p = protos[k]
        if len(p.uv) < 3:
            continue
        rays = pixel_rays(p.uv, K)
        z = 0.5 * (_plane_depth(prims[p.faces[0]], rays) + _plane_depth(prims[p.faces[1]], rays))
        ok = np.isfinite(z)
        if ok.sum() < 3:
            continue
        pts = rays[ok] * z[ok, None]
        if uses[p.v0] == 1:
            p.v0 = p.v1 = len(verts)
            verts.append(ProtoVertex(VertexKind.OTHER, pts[0].copy(), p.uv[ok][0].copy(), free=True))
        pts[0] = pts[-1] = verts[p.v0].position
        p.pts, p.uv, p.apart = pts, p.uv[ok], True
        p.curve = {"kind": "intersection"}
        n += 1
    return n


def postprocess(
    protos: list[ProtoEdge],
    verts: list[ProtoVertex],
    K: np.ndarray,
    cfg: VBRepConfig,
    same_m: float,
    prims: dict[int, Primitive] | None = None,
    stats: dict | None = None,
) -> tuple[list[ProtoEdge], list[ProtoVertex]]:
    """Apply the rules of the module docstring; returns edges and vertices with compact vertex ids.
    same_m: vertices of one kind closer than this (metres) are merged first; prims: instance id -> primitive
    (rule 4 needs them; without, it is skipped); stats: gets ``collapsed_lifted`` (edges lifted by rule 4)."""
    protos = _labelling(protos)
    protos = _contract_short(protos, verts, K, cfg.min_edge_px, cfg.min_loop_edges * cfg.min_edge_px, same_m)
    protos = _drop_fold_backs(protos, verts, K, cfg.fold_deg, cfg.fold_px)
    protos = _merge_degree_two(protos, verts, cfg.simplify_deg)
    if prims is not None:
        n_lifted = lift_collapsed(protos, verts, prims, K)
        if stats is not None:
            stats["collapsed_lifted"] = n_lifted
    for p in protos:
        if len(p.pts) > 2:
            idx = rdp_indices(project(p.pts, K), cfg.polyline_px)
            if len(p.uv) == len(p.pts):
                p.uv = p.uv[idx]
            p.pts = p.pts[idx]
    used = sorted({p.v0 for p in protos} | {p.v1 for p in protos})
    remap = {v: k for k, v in enumerate(used)}
    for p in protos:
        p.v0, p.v1 = remap[p.v0], remap[p.v1]
    return protos, [verts[v] for v in used]


def build_loops(protos: list[ProtoEdge], fid: dict[int, int], K: np.ndarray) -> dict[int, list[list[tuple[int, bool]]]]:
    """Boundary loops of each face (face id -> loops of (edge id, reversed)), chained through shared vertices;
    the loop with the largest image area first (outer loop). A chain that cannot close is kept as it is."""
    by_face: dict[int, list[int]] = {}
    for k, p in enumerate(protos):
        for f in p.faces:
            by_face.setdefault(fid[f], []).append(k)
    out: dict[int, list[list[tuple[int, bool]]]] = {}
    for f, eids in by_face.items():
        unused = list(eids)
        loops = []
        while unused:
            e0 = unused.pop(0)
            loop = [(e0, False)]
            start, cur = protos[e0].v0, protos[e0].v1
            while cur != start:
                nxt = next(((e, False) for e in unused if protos[e].v0 == cur), None) or next(
                    ((e, True) for e in unused if protos[e].v1 == cur), None
                )
                if nxt is None:
                    break
                unused.remove(nxt[0])
                loop.append(nxt)
                cur = protos[nxt[0]].v0 if nxt[1] else protos[nxt[0]].v1
            loops.append(loop)

        def area(loop: list[tuple[int, bool]]) -> float:
            pts = np.concatenate([protos[e].pts[::-1] if r else protos[e].pts for e, r in loop])
            uv = project(pts, K)
            x, y = uv[:, 0], uv[:, 1]
            return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))

        loops.sort(key=area, reverse=True)
        out[f] = loops
    return out
