"""VB-Rep extraction (paper section "VB-Rep extraction"): fitted primitives + 2D edge graph -> VB-Rep.

`extract_vbrep` runs the steps in order, each in its module:

1. faces.py: each instance's surface (fitted, or a fallback for instances the geometry stage left without one)
   and its sheet (boss or hole, ambiguity.py) from the depth points;
2. edges.py: every 2D graph edge resampled every ``sample_step_px`` pixels, each sample typed (classify.py:
   intersection / visibility / silhouette + occluded), the types smoothed, the edge split where its type changes
   and at outline corners; the samples lifted to 3D: intersection samples onto the intersection curve of both
   surfaces (lift.py), silhouette / occluded samples onto their face's sheet along the ray, visibility samples
   onto the contour generator (visibility.py);
3. vertices.py: edge ends meeting at one image point grouped by shared faces (an occlusion vertex splits into a
   near and a far copy), then optimised in full 3D (corners onto three surfaces, intersection-visibility vertices
   onto two surfaces and the contour), kept if within d_int of the surfaces and ``vertex_px`` of the image point;
4. postprocess.py: labelling rules, short-edge removal, simplification below ``simplify_deg``, plane-plane
   edges that would collapse a loop onto the planes' line split into a silhouette and an occluded edge; topology.py:
   vertices and polylines snapped onto their surfaces, degenerate closed edges dropped;
5. assemble.py: face meshes (mesh.py), loops, edge and face confidences (confidence.py), positional sigmas;
6. a curved face left without a mesh because its surface misses its own readings gets the plane through them
   (faces.py, `planes_for_unseen_surfaces`, where that plane meets them), and steps 2-5 run once more.

Camera frame, metres; pixels (u, v).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from v2c.segment.graph import build_edge_graph
from v2c.vbrep.assemble import assemble
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.context import ExtractContext, depth_window
from v2c.vbrep.edges import edge_protos
from v2c.vbrep.faces import absorb_islands, absorb_specks, face_geoms, planes_for_unseen_surfaces
from v2c.vbrep.model import VBRep
from v2c.vbrep.postprocess import ProtoEdge, postprocess
from v2c.vbrep.topology import drop_degenerate, drop_end_hooks, snap_to_surfaces
from v2c.vbrep.vertices import make_vertices

if TYPE_CHECKING:
    from v2c.fit.result import FitResult
    from v2c.scan import Scan
    from v2c.segment.types import Segmentation

__all__ = ["extract_vbrep"]


def extract_vbrep(scan: Scan, seg: Segmentation, fit: FitResult, config: VBRepConfig | None = None) -> VBRep:
    """VB-Rep of one scan from its segmentation and fit (primitives, edge graph, frame, axis labels, residuals,
    part scale). Camera frame, metres."""
    cfg = config or VBRepConfig()
    K = np.asarray(scan.K, float)
    depth = np.asarray(scan.depth, float)
    window = depth_window(depth, cfg)
    scale = float(fit.scale)
    stats: dict[str, Any] = {}
    # 1. faces: surfaces and sheets
    faces, sheets = face_geoms(fit, seg, depth, K, window, scale, cfg, stats)
    # specks: instances too small for a face merge into their faced neighbours, so they leave no junction clutter
    # islands: stray pieces of a faced instance go to the faced instance around them, in the edges and the meshes
    regions = absorb_islands(np.asarray(seg.instances), set(faces), cfg, stats, np.asarray(seg.scores))
    graph = fit.graph if stats["islands_absorbed"] == 0 else build_edge_graph(regions, cfg.graph_simplify_px)
    instances, graph = absorb_specks(regions, graph, set(faces), cfg, stats)
    stats["planes_for_unseen_surfaces"] = []
    vbrep = _edges_to_vbrep(faces, sheets, graph, instances, regions, fit, seg, depth, K, window, scale, cfg, stats)
    # 6. a curved face its own readings contradict lost its mesh: its plane instead, and steps 2-5 once more
    inst_of = {f.id: f.instance for f in vbrep.faces}
    unseen = [inst_of[fid] for fid in stats.get("faces_off_their_readings", []) if fid in inst_of]
    if cfg.unseen_surface_plane and unseen:
        replaced = planes_for_unseen_surfaces(seg, depth, K, window, scale, cfg, faces, sheets, unseen)
        if replaced:
            stats["planes_for_unseen_surfaces"] = replaced
            vbrep = _edges_to_vbrep(
                faces, sheets, graph, instances, regions, fit, seg, depth, K, window, scale, cfg, stats
            )
    return vbrep


def _edges_to_vbrep(
    faces: dict,
    sheets: dict,
    graph: Any,
    instances: np.ndarray,
    regions: np.ndarray,
    fit: FitResult,
    seg: Segmentation,
    depth: np.ndarray,
    K: np.ndarray,
    window: tuple[float, float],
    scale: float,
    cfg: VBRepConfig,
    stats: dict[str, Any],
) -> VBRep:
    """Steps 2-5 (module docstring) on the faces' surfaces and sheets; ``stats`` gets their counts."""
    gap_thr = max(cfg.int_gap * scale, cfg.int_gap_min_m)
    ctx = ExtractContext(faces, sheets, K, window, scale, gap_thr, depth, instances, cfg, stats)
    ctx.regions = regions  # a face's mesh and measures keep its own pixels
    # 2. edges: typed, split and lifted
    protos: list[ProtoEdge] = []
    for gi, ge in enumerate(graph.edges):
        protos += edge_protos(ctx, gi, ge)
    # 3. vertices: grouped, typed, optimised
    vertices = make_vertices(ctx, protos, graph)
    # 4. clean-up, then every edge on its surfaces and ending at its vertices
    prims = {i: f.prim for i, f in faces.items()}
    protos, vertices = postprocess(
        protos, vertices, K, cfg, same_m=cfg.vertex_merge_gap_share * gap_thr, prims=prims, stats=stats
    )
    stats.update(snap_to_surfaces(protos, vertices, prims, cfg.d_int * scale, K, cfg))
    stats["hook_samples_dropped"] = drop_end_hooks(protos, K, cfg.end_hook_deg)
    protos = drop_degenerate(protos, K, cfg.min_edge_px)
    # 5. the VB-Rep
    return assemble(ctx, protos, vertices, fit, seg)
