"""The vertex step of VB-Rep extraction: edge ends grouped into vertices, typed and placed in 3D.

Edge ends meeting at one image point (one endpoint key) are grouped by the faces their edges share
(`face_groups`): an occlusion vertex splits into a near (silhouette) and a far (occluded) copy. Each vertex's
kind follows from its edges; corners (three intersection faces) are solved onto the three surfaces and
intersection-visibility vertices onto the two surfaces and the contour (`lift.solve_vertex`); a solution is kept
if within ``d_int`` of the surfaces and of its initial lift and within ``vertex_px`` of the image point (else the
lifted position stays). The edge ends are then moved onto their vertex. Camera frame, metres; pixels (u, v).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from v2c.camera import project
from v2c.groups import groups_sharing_keys
from v2c.vbrep.context import ExtractContext
from v2c.vbrep.lift import sd_func, solve_vertex, visibility_residual
from v2c.vbrep.model import EdgeType, VertexKind
from v2c.vbrep.postprocess import ProtoEdge, ProtoVertex

if TYPE_CHECKING:
    from v2c.segment.graph import EdgeGraph

# which edge ends place a vertex's initial position: the best-determined type present
_END_PRIORITY = {EdgeType.INTERSECTION: 0, EdgeType.SILHOUETTE: 1, EdgeType.VISIBILITY: 2, EdgeType.OCCLUDED: 3}

Residual = Callable[[np.ndarray], np.ndarray]


def _key_pixel(key: tuple, graph: EdgeGraph, protos: list[ProtoEdge], ends: list[tuple[int, int]]) -> np.ndarray:
    """The image point (pixels) of an endpoint key: the graph vertex, or the first end's sample."""
    if key[0] == "g":
        return np.asarray(graph.vertices[key[1]], float)
    pi, e = ends[0]
    return protos[pi].uv[0] if e == 0 else protos[pi].uv[-1]


def face_groups(faces: list[tuple[int, ...]]) -> list[np.ndarray]:
    """Split the edge ends meeting at one image point into vertices: ends whose edges share a face (directly or
    through other ends) are one vertex, so every face's boundary passes through one vertex there and its loops
    close. At an occlusion T-junction the near face's ends (its silhouette or visibility edges) and the far
    face's ends (its occluded edge and its other edges) share no face: two vertices, a near and a far copy."""
    return groups_sharing_keys(faces)


def _vertex_kind(
    ctx: ExtractContext, types_faces: list[tuple[EdgeType, tuple[int, ...]]], n_groups: int
) -> tuple[VertexKind, list[Residual] | None, list[int]]:
    """A vertex's kind from the (type, faces) of its edges, with the residuals it is solved on (None: not
    solved) and the faces of its intersection edges, in order."""
    int_faces: list[int] = []
    for t, faces in types_faces:
        if t is EdgeType.INTERSECTION:
            int_faces += [f for f in faces if f not in int_faces]
    vis_faces = [faces[0] for t, faces in types_faces if t is EdgeType.VISIBILITY]
    if len(int_faces) >= 3:
        return VertexKind.CORNER, [sd_func(ctx.faces[f].prim) for f in int_faces[:3]], int_faces
    if len(int_faces) == 2 and any(f in int_faces for f in vis_faces):
        c = next(f for f in vis_faces if f in int_faces)
        funcs = [sd_func(ctx.faces[f].prim) for f in int_faces] + [visibility_residual(ctx.faces[c].prim)]
        return VertexKind.INTERSECTION_VISIBILITY, funcs, int_faces
    if n_groups > 1:
        return VertexKind.OCCLUSION, None, int_faces
    return VertexKind.OTHER, None, int_faces


def _solved_position(
    ctx: ExtractContext, funcs: list[Residual], int_faces: list[int], x0: np.ndarray, pixel: np.ndarray
) -> np.ndarray | None:
    """The solved position of a vertex, or None where the solution leaves its surfaces, its initial lift (by
    more than d_int) or its image point (by more than vertex_px)."""
    cfg = ctx.cfg
    xs, _ = solve_vertex(funcs, x0, cfg.vertex_iters)
    surf = max(abs(float(sd_func(ctx.faces[f].prim)(xs[None])[0])) for f in int_faces[:3])
    px = float(np.linalg.norm(project(xs[None], ctx.K)[0] - pixel))
    if (
        np.all(np.isfinite(xs))
        and surf <= cfg.d_int * ctx.scale
        and px <= cfg.vertex_px
        and np.linalg.norm(xs - x0) <= cfg.d_int * ctx.scale
    ):
        return xs
    return None


def make_vertices(ctx: ExtractContext, protos: list[ProtoEdge], graph: EdgeGraph) -> list[ProtoVertex]:
    """Group edge ends by image point and shared faces, choose kinds, optimise positions, snap the edge ends
    (in place: each proto edge's v0 / v1 and its first / last point)."""
    by_key: dict[tuple, list[tuple[int, int]]] = {}
    for pi, p in enumerate(protos):
        by_key.setdefault(p.key0, []).append((pi, 0))
        by_key.setdefault(p.key1, []).append((pi, 1))
    vertices: list[ProtoVertex] = []
    n_opt = n_kept = 0
    for key, ends in by_key.items():
        pos = np.array([protos[pi].pts[0 if e == 0 else -1] for pi, e in ends])
        clusters = face_groups([protos[pi].faces for pi, _ in ends])
        pixel = _key_pixel(key, graph, protos, ends)
        for cl in clusters:
            cl_ends = [ends[i] for i in cl]
            best = min(_END_PRIORITY[protos[pi].type] for pi, _ in cl_ends)
            x0 = pos[[i for i in cl if _END_PRIORITY[protos[ends[i][0]].type] == best]].mean(0)
            kind, funcs, int_faces = _vertex_kind(
                ctx, [(protos[pi].type, protos[pi].faces) for pi, _ in cl_ends], len(clusters)
            )
            x = x0
            if funcs is not None:
                n_opt += 1
                xs = _solved_position(ctx, funcs, int_faces, x0, pixel)
                if xs is not None:
                    x = xs
                    n_kept += 1
            vid = len(vertices)
            vertices.append(ProtoVertex(kind, x, project(x[None], ctx.K)[0], outline_corner=key[0] == "c"))
            for pi, e in cl_ends:
                p = protos[pi]
                if e == 0:
                    p.v0 = vid
                    p.pts[0] = x
                else:
                    p.v1 = vid
                    p.pts[-1] = x
    ctx.stats["vertices_optimised"] = n_opt
    ctx.stats["vertices_kept"] = n_kept
    return vertices
