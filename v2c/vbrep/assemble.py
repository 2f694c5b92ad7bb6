"""The last step of VB-Rep extraction: the `VBRep` dataclasses from the cleaned proto edges and vertices.

Faces get their meshes (`v2c.vbrep.mesh`, clipped to the part's box), loops and confidences; edges their
confidences (raw and calibrated, `v2c.vbrep.confidence`, `v2c.vbrep.calibration`) and positional sigmas
(`v2c.vbrep.uncertainty`). A face none of whose edges survived post-processing is left out. Camera frame, metres.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import shapely
from scipy.spatial import cKDTree

from v2c.camera import project
from v2c.primitives import Plane
from v2c.vbrep.calibration import CalibrationMap, load_map, record_edges
from v2c.vbrep.classify import FaceGeom
from v2c.vbrep.confidence import edge_confidence, face_confidence
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.context import ExtractContext
from v2c.vbrep.loop_mesh import loop_mesh, loop_polygon
from v2c.vbrep.mesh import (
    beyond_measured,
    clip_to_measured,
    drop_stray_islands,
    face_mesh,
    grazing,
    read_vertices,
    refine_curved,
)
from v2c.vbrep.model import EdgeType, VBRep, VEdge, VFace, VVertex
from v2c.vbrep.pointfit import measured_points
from v2c.vbrep.postprocess import ProtoEdge, ProtoVertex, build_loops
from v2c.vbrep.uncertainty import (
    FaceCovariance,
    UncertaintyConfig,
    face_covariance,
    face_sigma_m,
    intersection_sigma_m,
    outline_sigma_m,
)

if TYPE_CHECKING:
    from v2c.fit.result import FitResult
    from v2c.segment.types import Segmentation


def uncertainty_config(cfg: VBRepConfig) -> UncertaintyConfig:
    """The positional-uncertainty model from the sigma_* fields of the config."""
    return UncertaintyConfig(
        depth_sigma_coeff_per_m=cfg.sigma_depth_coeff_per_m,
        depth_correlated=cfg.sigma_depth_correlated,
        min_angle_deg=cfg.sigma_min_angle_deg,
    )


def _calibration(cfg: VBRepConfig) -> CalibrationMap | None:
    """The confidence calibration map the config names (None: raw confidences)."""
    if cfg.conf_calibration is None:
        return None
    return load_map(None if cfg.conf_calibration == "shipped" else cfg.conf_calibration)


def _edge_sigma_m(
    p: ProtoEdge, covs: dict[int, FaceCovariance | None], focal: float, ucfg: UncertaintyConfig
) -> float | None:
    """An edge's 1-sigma position error (metres) from its faces' covariances; None without them."""
    fc = [covs.get(f) for f in p.faces]
    if any(c is None for c in fc):
        return None
    if len(fc) == 2:
        return intersection_sigma_m(fc[0], fc[1], p.pts, ucfg)
    return outline_sigma_m(fc[0], p.pts, focal, ucfg)


def _edge_quantities(
    ctx: ExtractContext,
    p: ProtoEdge,
    seg: Segmentation,
    face_px: np.ndarray,
    raw: float,
    length_px: float,
    sig_mm: float | None,
) -> dict[str, Any]:
    """What the calibration may read of one edge (`v2c.vbrep.calibration.FEATURE_FUNCTIONS` turn these into features):
    its raw confidence and the quantities behind it, made relative where a scale exists (residual and
    edge-to-depth error over the sensor's depth noise at the edge's depth, gaps over the intersection threshold),
    and what shows an unfamiliar reconstruction: its faces' segmentation scores and sizes (pixels), the part's
    mean segmentation score and number of faces, its positional sigma (mm). NaN where a quantity does not apply."""
    s = p.stats
    inst = [int(f) for f in p.faces]
    scores = np.asarray(seg.scores, float)
    part_px = float(np.sum(face_px[1:]))
    n = min(len(scores), len(face_px))
    z = float(np.median(p.pts[:, 2])) if len(p.pts) else float("nan")
    noise = max(ctx.cfg.sigma_depth_coeff_per_m * z * z, 1e-6)  # metres: the sensor's depth sigma at the edge
    return {
        "type": p.type.value,
        "method": seg.method,
        "raw": raw,
        "length_px": length_px,
        "agreement": float(s.get("agreement", 1.0)),
        "angle_deg": float(np.rad2deg(s.get("angle", np.nan))),
        "gap_rel": float(s.get("gap", np.nan)) / ctx.gap_thr,
        "jump_rel": float(s.get("jump", np.nan)) / ctx.gap_thr,
        "vis_share": float(s.get("vis_share", np.nan)),
        "residual_noise": float(s.get("residual", np.nan)) / noise,
        "depth_err_noise": float(s.get("depth_err", np.nan)) / noise,
        "seg_score_min": float(min(scores[i] for i in inst)),
        "face_px_min": float(min(face_px[i] for i in inst)),
        "part_px": part_px,
        "part_score_mean": float(np.sum(scores[1:n] * face_px[1:n]) / max(part_px, 1.0)),
        "n_faces": float(len(ctx.faces)),
        "sigma_mm": float("nan") if sig_mm is None else float(sig_mm),
        "depth_m": z,
    }


def _vedges(
    ctx: ExtractContext,
    protos: list[ProtoEdge],
    fid: dict[int, int],
    covs: dict[int, FaceCovariance | None],
    ucfg: UncertaintyConfig,
    seg: Segmentation,
) -> list[VEdge]:
    """The VB-Rep edges with their confidences (raw and calibrated), analytic curves and sigmas (mm)."""
    cfg = ctx.cfg
    cmap = _calibration(cfg)
    focal = float(np.sqrt(ctx.K[0, 0] * ctx.K[1, 1]))
    face_px = np.bincount(np.asarray(ctx.face_map).ravel().clip(0))
    edges = []
    quantities = []
    for k, p in enumerate(protos):
        s = p.stats
        length_px = float(np.sum(np.linalg.norm(np.diff(project(p.pts, ctx.K), axis=0), axis=1)))
        raw = edge_confidence(
            p.type,
            residual=s.get("residual", 0.0),
            depth_err=s.get("depth_err", np.nan),
            length_px=length_px,
            angle=s.get("angle", np.nan),
            gap=s.get("gap", np.nan),
            jump=s.get("jump", np.inf),
            vis_share=s.get("vis_share", 0.0),
            agreement=s.get("agreement", 1.0),
            gap_thr=ctx.gap_thr,
            scale=ctx.scale,
            cfg=cfg,
        )
        raw = round(raw * s.get("factor", 1.0), 4)
        curve = dict(p.curve) if p.type is EdgeType.INTERSECTION and p.curve is not None else None
        tangent = bool(curve.pop("tangent", False)) if curve is not None else False
        sig = _edge_sigma_m(p, covs, focal, ucfg)
        sig_mm = round(1000.0 * sig, 5) if sig is not None and np.isfinite(sig) else None
        q = _edge_quantities(ctx, p, seg, face_px, raw, length_px, sig_mm)
        quantities.append(q)
        conf = raw if cmap is None else round(float(cmap.apply(p.type, raw, q)), 4)
        edges.append(
            VEdge(
                k,
                p.type,
                conf,
                tuple(fid[f] for f in p.faces),
                p.pts,
                p.v0,
                p.v1,
                curve,
                tangent=tangent,
                confidence_raw=raw,
                sigma_mm=sig_mm,
            )
        )
    record_edges(quantities)
    return edges


def _part_box(ctx: ExtractContext, q: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The part's box (camera frame, metres): what its observed points ``q`` (N, 3) span (mesh_bound_percentile),
    unpadded; None when mesh_bound_pad is negative or nothing was observed."""
    cfg = ctx.cfg
    if cfg.mesh_bound_pad < 0:
        return None
    if not len(q):
        return None
    return (
        np.percentile(q, cfg.mesh_bound_percentile, axis=0),
        np.percentile(q, 100.0 - cfg.mesh_bound_percentile, axis=0),
    )


def _face_box(
    ctx: ExtractContext, fg: FaceGeom, region: np.ndarray, conf: float, bounds: tuple[np.ndarray, np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """The box a face's mesh must lie in: the part's box, padded (more for a sure face with few depth readings of
    its own, which its edges place) and, for a curved face, deep enough for a hole's wall."""
    cfg, scale = ctx.cfg, ctx.scale
    loose = _mostly_unread(ctx, region) and conf >= cfg.mesh_loose_min_conf
    pad = (cfg.mesh_bound_pad_unmeasured if loose else cfg.mesh_bound_pad) * scale
    lo, hi = bounds[0] - pad, bounds[1] + pad
    if not isinstance(fg.prim, Plane):  # a hole's wall may run deeper than any point seen: up to one part
        hi[2] = max(hi[2], bounds[0][2] + scale + pad)  # size past the part's nearest point
    return lo, hi


def _vfaces(
    ctx: ExtractContext,
    inst_ids: list[int],
    fid: dict[int, int],
    loops: dict,
    covs: dict,
    face_pts: dict[int, np.ndarray],
    protos: list[ProtoEdge],
) -> list[VFace]:
    """The VB-Rep faces with their meshes, loops, confidences and sigmas (mm). A face whose loops bound a valid
    image region gets the mesh of that region (`v2c.vbrep.loop_mesh`: the trimmed face; noted in
    ``ctx.stats["loop_meshes"]``), any other the mesh of its pixel region, kept to what its pixels measured; one
    whose pixel mesh misses its own readings gets none (``ctx.stats["faces_off_their_readings"]``)."""
    cfg, scale = ctx.cfg, ctx.scale
    part_pts = measured_points(ctx.face_map > 0, ctx.depth, ctx.K)
    bounds = _part_box(ctx, part_pts)
    measured = cKDTree(part_pts) if len(part_pts) and cfg.mesh_island_max_share > 0 else None
    vfaces = []
    from_loops = []
    off_readings = []  # faces left without a mesh: their surface misses their own readings
    for inst in inst_ids:
        fg = ctx.faces[inst]
        region = ctx.face_map == inst
        ch = ctx.sheets[inst]
        conf = face_confidence(fg.residual, ch.errors, ch.sheet, scale, cfg)
        box = None if bounds is None else _face_box(ctx, fg, region, conf, bounds)
        args = (
            ctx.depth,
            ctx.K,
            ctx.window,
            cfg.mesh_stride_px,
            cfg.mesh_max_edge * scale,
            cfg.mesh_surface_tol * scale,
            box,
            cfg.mesh_plane_long and isinstance(fg.prim, Plane) and conf >= cfg.mesh_loose_min_conf,
        )
        mv = mt = None
        own = _own_points(ctx, region, face_pts[inst])
        evidence = cfg.mesh_evidence_tol * scale
        poly = (
            loop_polygon(loops.get(fid[inst], []), protos, ctx.K, fg.prim, cfg.loop_ring_pieces)
            if cfg.mesh_from_loops
            else None
        )
        if poly is not None and _loops_cover_region(poly, inst, ctx.face_map, set(inst_ids), cfg):
            mv, mt = loop_mesh(fg.prim, fg.sheet, poly, *args)
            if len(mt) and not beyond_measured(mv, read_vertices(mv, region, ctx.depth, ctx.K), own, evidence):
                from_loops.append(fid[inst])
            else:  # no trimmed face, or one lying where the sensor did not see the face: its pixels' mesh
                mv = mt = None
        if mv is None:
            mv, mt = face_mesh(fg.prim, fg.sheet, region, *args)
            read = read_vertices(mv, region, ctx.depth, ctx.K)
            judged = grazing(fg.prim, mv, np.cos(np.radians(cfg.mesh_evidence_graze_deg)))
            if cfg.mesh_evidence_median and beyond_measured(mv, read, own, evidence):
                mv, mt = mv[:0], mt[:0]  # its surface misses its own readings at most of its pixels: a wrong primitive
                off_readings.append(fid[inst])
            mv, mt = clip_to_measured(mv, mt, read, own, evidence, cfg.mesh_evidence_min_share, judged)
        if cfg.mesh_chord_angle_rad > 0:
            mv, mt = refine_curved(
                fg.prim,
                mv,
                mt,
                cfg.mesh_chord_angle_rad,
                cfg.mesh_refine_levels,
                cfg.mesh_refine_max_triangles,
            )
        mv, mt = drop_stray_islands(mv, mt, measured, cfg.mesh_island_max_share, cfg.mesh_island_max_dist * scale)
        fsig = face_sigma_m(covs[inst], face_pts[inst]) if covs[inst] is not None else float("nan")
        vfaces.append(
            VFace(
                fid[inst],
                inst,
                fg.prim.to_dict(),
                fg.axis_label,
                loops.get(fid[inst], []),
                mv,
                mt,
                round(conf, 4),
                sigma_mm=round(1000.0 * fsig, 5) if np.isfinite(fsig) else None,
            )
        )
    ctx.stats["loop_meshes"] = from_loops
    ctx.stats["faces_off_their_readings"] = off_readings
    return vfaces


def _own_points(ctx: ExtractContext, region: np.ndarray, pts: np.ndarray) -> cKDTree | None:
    """A KD-tree of the points ``pts`` (N, 3) a face's own pixels ``region`` measured, for `clip_to_measured`;
    None (no clipping) when mesh_evidence_tol is 0 or the face has no reading on more than mesh_unmeasured_share
    of its pixels."""
    cfg = ctx.cfg
    if cfg.mesh_evidence_tol <= 0 or not len(pts):
        return None
    if _mostly_unread(ctx, region):
        return None
    return cKDTree(pts)


def _mostly_unread(ctx: ExtractContext, region: np.ndarray) -> bool:
    """Whether a face (its pixels ``region``) has no depth reading on more than mesh_unmeasured_share of its
    pixels: a face its edges place."""
    return float(np.mean(ctx.depth[region] <= 0)) > ctx.cfg.mesh_unmeasured_share


def _loops_cover_region(
    poly: shapely.Polygon | shapely.MultiPolygon, inst: int, instances: np.ndarray, faced: set[int], cfg: VBRepConfig
) -> bool:
    """Whether a face's loop polygon (image pixels) is the face seen: its intersection over union with the face's
    pixel region (pixel centres inside the polygon, the polygon's area) at least ``loop_mesh_min_iou``, and no
    other face losing ``loop_mesh_max_take`` or more of its pixels to it (a loop a pixel or two off its outline
    swallows a small neighbour, which its mesh would then hide)."""
    sizes = np.bincount(instances.ravel().clip(0))
    n = int(sizes[inst]) if inst < len(sizes) else 0
    if n == 0:
        return False
    h, w = instances.shape
    x0, y0, x1, y1 = poly.bounds
    u0, v0 = max(0, int(np.floor(x0))), max(0, int(np.floor(y0)))
    u1, v1 = min(w - 1, int(np.ceil(x1))), min(h - 1, int(np.ceil(y1)))
    if u1 < u0 or v1 < v0:
        return False
    vs, us = np.mgrid[v0 : v1 + 1, u0 : u1 + 1]
    inside = shapely.contains_xy(poly, us.ravel().astype(float), vs.ravel().astype(float))
    labels = instances[vs.ravel()[inside], us.ravel()[inside]]
    covered = np.bincount(labels.clip(0), minlength=len(sizes))
    if covered[inst] < cfg.loop_mesh_min_iou * (n + poly.area - covered[inst]):
        return False
    other = [k for k in np.flatnonzero(covered) if k != inst and k in faced]
    return all(covered[k] < cfg.loop_mesh_max_take * sizes[k] for k in other)


def assemble(
    ctx: ExtractContext, protos: list[ProtoEdge], vertices: list[ProtoVertex], fit: FitResult, seg: Segmentation
) -> VBRep:
    """Build the VBRep dataclasses: faces with meshes and loops, edges with confidences, vertices; meta with the
    per-face sheet and fallback notes and the extraction's counts."""
    # a face none of whose edges survived post-processing (a sliver of a few pixels) has no boundary to be
    # trimmed by: it is left out (counted in meta["extract"]["faces_without_edges"])
    bounded = {f for p in protos for f in p.faces}
    inst_ids = sorted(i for i in ctx.faces if i in bounded)
    ctx.stats["faces_without_edges"] = sorted(int(i) for i in ctx.faces if i not in bounded)
    fid = {inst: k for k, inst in enumerate(inst_ids)}
    # positional uncertainty: each face's fit covariance from its observed points (v2c.vbrep.uncertainty)
    ucfg = uncertainty_config(ctx.cfg)
    face_pts = {i: measured_points(ctx.face_map == i, ctx.depth, ctx.K) for i in inst_ids}
    covs = {i: face_covariance(ctx.faces[i].prim, face_pts[i], ctx.faces[i].residual, ucfg) for i in inst_ids}
    edges = _vedges(ctx, protos, fid, covs, ucfg, seg)
    vverts = [VVertex(k, v.kind, v.position, v.pixel) for k, v in enumerate(vertices)]
    loops = build_loops(protos, fid, ctx.K)
    vfaces = _vfaces(ctx, inst_ids, fid, loops, covs, face_pts, protos)
    meta = {
        "segmentation": seg.method,
        "faces": {
            str(fid[i]): {
                "sheet": ctx.sheets[i].sheet,
                "concave": ctx.sheets[i].concave,
                "residual_m": ctx.faces[i].residual,
                "fallback_plane": bool(ctx.faces[i].extra.get("fallback")),
                "refit": ctx.faces[i].extra.get("refit"),
            }
            for i in inst_ids
        },
        "extract": dict(ctx.stats, gap_threshold_m=ctx.gap_thr),
    }
    h, w = ctx.face_map.shape
    return VBRep(
        vfaces,
        edges,
        vverts,
        frame=np.asarray(fit.frame, float),
        K=ctx.K.copy(),
        image_size=(int(w), int(h)),
        scale=ctx.scale,
        meta=meta,
    )
