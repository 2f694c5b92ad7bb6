"""The edge step of VB-Rep extraction: every 2D graph edge typed, split into runs and lifted to 3D.

A graph edge between instances a and b is resampled every ``sample_step_px`` pixels and smoothed (`type_edge`);
each sample is typed by the rule of `v2c.vbrep.classify` (intersection, or silhouette / visibility of the nearer
side), the types are smoothed into runs, and silhouette runs are split again at image corners (`split_runs`).
Each run becomes proto edges with endpoint keys for the vertex step (`edge_protos`):

- intersection: the samples projected onto the intersection curve of both surfaces (`lift.project_to_intersection`,
  kept only where the surfaces meet nearby), or onto the line of contact of a tangent (G1) junction; a run whose
  fitted surfaces do not meet is retyped as a silhouette of the nearer face (``meet_share``, ``retype_gap``);
- silhouette or visibility of the near face (visibility samples on its contour generator) and, when a face lies
  behind it, an occluded edge of that far face over the same samples.

Camera frame, metres; pixels (u, v).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from v2c.camera import pixel_rays
from v2c.vbrep.classify import KIND_INT, FaceGeom, SampleTypes, TypingRule, classify_samples
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.context import ExtractContext
from v2c.vbrep.lift import (
    contact_points,
    intersection_curve,
    normals_angle_deg,
    points_on_curve,
    project_to_intersection,
    surfaces_meet,
    tangent_curve,
)
from v2c.vbrep.model import EdgeType
from v2c.vbrep.postprocess import ProtoEdge
from v2c.vbrep.raycast import intersect, sheet_depth
from v2c.vbrep.sampling import corner_samples, image_normals, read_at, resample_polyline, smooth_codes, smooth_uv

if TYPE_CHECKING:
    from v2c.segment.graph import GraphEdge

# sample codes: intersection; near = a (silhouette / visibility); near = b (silhouette / visibility)
_C_INT, _C_A_SIL, _C_A_VIS, _C_B_SIL, _C_B_VIS = range(5)
_N_CODES = 5


def typing_rule(cfg: VBRepConfig, gap_thr: float) -> TypingRule:
    """The extraction's tolerances of the edge-type rule; ``gap_thr``: the depth-gap threshold (metres)."""
    return TypingRule(
        band_px=cfg.int_band_px,
        band_step_px=cfg.int_band_step_px,
        gap_m=gap_thr,
        vis_px=cfg.vis_px,
        vis_step_px=cfg.vis_step_px,
        vis_bisect=cfg.vis_bisect,
        vis_angle_deg=cfg.vis_angle_deg,
        vis_face_px=cfg.vis_face_px,
        curve_iters=cfg.curve_iters,
        curve_slack_px=cfg.curve_slack_px,
    )


@dataclass
class SideDepth:
    """Observed and fitted depth (metres) at the probe pixels just inside one side of an edge, per sample
    (observed 0: no reading; fitted NaN: no surface)."""

    observed: np.ndarray
    fitted: np.ndarray

    def error(self, sl: slice) -> float:
        """Median |fitted - observed| depth (metres) over the samples ``sl`` (NaN without data)."""
        z_fit, z_obs = self.fitted[sl], self.observed[sl]
        ok = (z_obs > 0) & np.isfinite(z_fit)
        return float(np.median(np.abs(z_fit[ok] - z_obs[ok]))) if ok.any() else np.nan


@dataclass
class TypedEdge:
    """One graph edge resampled and typed.

    gi / gedge: its index in the graph and the graph edge; a, b: the instances on its two sides (0: background or
    no surface); uv_raw: (n, 2) samples every sample_step_px (pixels); uv: the same smoothed (the positions that
    are lifted); raw / codes: (n,) per-sample type codes before / after smoothing; st: the rule's per-sample
    result; side_a / side_b: depths just inside each side.
    """

    gi: int
    gedge: GraphEdge
    a: int
    b: int
    uv_raw: np.ndarray
    uv: np.ndarray
    raw: np.ndarray
    codes: np.ndarray
    st: SampleTypes
    side_a: SideDepth
    side_b: SideDepth


def _surface_depth(face: FaceGeom | None, uv: np.ndarray, ctx: ExtractContext) -> np.ndarray:
    """Depth (metres) of a face's sheet along the rays through uv (NaN without a face)."""
    if face is None:
        return np.full(len(uv), np.nan)
    return sheet_depth(intersect(face.prim, pixel_rays(uv, ctx.K), ctx.window), face.sheet)


def type_edge(ctx: ExtractContext, gi: int, gedge: GraphEdge, a: int, b: int) -> TypedEdge:
    """Resample, smooth and type the samples of graph edge ``gi`` between instances ``a`` and ``b``."""
    cfg = ctx.cfg
    uv_raw = resample_polyline(gedge.polyline, cfg.sample_step_px)
    uv = smooth_uv(uv_raw, max(1, round(cfg.smooth_uv_px / cfg.sample_step_px)))
    m = image_normals(uv)
    # orient m from a's side into b's side (majority of the samples)
    fwd = read_at(ctx.instances, uv + cfg.side_probe_px * m)
    bwd = read_at(ctx.instances, uv - cfg.side_probe_px * m)
    vote = np.sum((fwd == b) | (bwd == a)) - np.sum((fwd == a) | (bwd == b))
    if vote < 0:
        m = -m
    st = classify_samples(uv, m, a, b, ctx.view, typing_rule(cfg, ctx.gap_thr))
    raw = np.where(
        st.kind == KIND_INT,
        _C_INT,
        np.where(st.kind == 1, np.where(st.vis, _C_A_VIS, _C_A_SIL), np.where(st.vis, _C_B_VIS, _C_B_SIL)),
    )
    min_run = max(1, round(cfg.min_run_px / cfg.sample_step_px))
    codes = smooth_codes(raw, cfg.smooth_samples, min_run, _N_CODES)
    # observed depth just inside each side (for the depth-agreement confidence)
    probe_a, probe_b = uv - cfg.side_probe_px * m, uv + cfg.side_probe_px * m
    side_a = SideDepth(read_at(ctx.depth, probe_a), _surface_depth(ctx.faces.get(a), probe_a, ctx))
    side_b = SideDepth(read_at(ctx.depth, probe_b), _surface_depth(ctx.faces.get(b), probe_b, ctx))
    return TypedEdge(gi, gedge, a, b, uv_raw, uv, raw, codes, st, side_a, side_b)


def split_runs(te: TypedEdge, cfg: VBRepConfig) -> tuple[list[tuple[int, int]], set[int]]:
    """The runs of one type along the edge, silhouette runs split again at image corners: (first sample, start of
    the next piece) per piece, and the samples where a corner cut one."""
    n = len(te.uv)
    codes = te.codes
    starts = np.flatnonzero(np.concatenate([[True], codes[1:] != codes[:-1]]))
    ends = np.concatenate([starts[1:], [n]])
    pieces: list[tuple[int, int]] = []
    corner_cuts: set[int] = set()
    for k0, k1 in zip(starts, ends):
        # outline corners: only where a face ends against something farther (contours of smooth surfaces and
        # intersection curves of smooth surfaces have no corners of their own)
        cuts = corner_samples(te.uv_raw[k0 : min(k1 + 1, n)], cfg) if codes[k0] in (_C_A_SIL, _C_B_SIL) else []
        corner_cuts |= {int(k0 + c) for c in cuts}
        bounds = [k0] + [k0 + c for c in cuts] + [k1]
        pieces += list(itertools.pairwise(bounds))
    return pieces, corner_cuts


def _tangent_lift(ctx: ExtractContext, fa: FaceGeom, fb: FaceGeom, x0: np.ndarray) -> tuple[np.ndarray, dict]:
    """A tangent junction: its samples on the line where the surfaces touch (or come closest), and that curve."""
    cfg = ctx.cfg
    curve = tangent_curve(fa.prim, fb.prim, x0, cfg.parallel_deg)
    on = points_on_curve(curve, x0)
    pts = on if on is not None else contact_points(fa.prim, fb.prim, x0, cfg.tangent_iters)[0]
    ctx.stats["tangent_edges"] = ctx.stats.get("tangent_edges", 0) + 1
    return pts, curve


def _intersection_lift(
    ctx: ExtractContext, te: TypedEdge, sl: slice, fa: FaceGeom, fb: FaceGeom, x0: np.ndarray
) -> tuple[np.ndarray, dict] | None:
    """An intersection run's samples on the curve where its surfaces meet, and that curve; None when the fitted
    surfaces do not meet along the run (``meet_share``, ``retype_gap``)."""
    cfg, st = ctx.cfg, te.st
    pts = project_to_intersection(fa.prim, fb.prim, x0, cfg.curve_iters, ctx.K, cfg.int_band_px + cfg.curve_slack_px)
    tol = max(cfg.meet_tol * ctx.scale, cfg.meet_min_m)
    met, on_curve = surfaces_meet(fa.prim, fb.prim, x0, tol, cfg.snap_iters, cfg.snap_tol)
    miss = np.linalg.norm(st.p_a[sl] - st.p_b[sl], axis=1)  # between the two lifts, along the rays
    miss = float(np.nanmedian(miss)) if np.isfinite(miss).any() else np.inf
    if not (np.mean(met) >= cfg.meet_share or miss <= cfg.retype_gap * ctx.scale):
        return None
    # on the curve where the surfaces meet nearby; elsewhere (a near miss) the projection limited to the image
    # band stays (moving those samples to the midpoint of the two lifts gave 23 instead of 27 faces bounded by
    # their mesh outline on 23 scans but lost 0.2 points of edge coverage)
    pts = np.where(met[:, None], on_curve, pts)
    return pts, intersection_curve(fa.prim, fb.prim, pts, cfg.perpendicular_deg, cfg.parallel_deg)


def _intersection_edge(
    ctx: ExtractContext, te: TypedEdge, sl: slice, agree: float, common: dict[str, Any]
) -> ProtoEdge | None:
    """The intersection edge of run ``sl`` (tangent junction or crossing); None when its surfaces do not meet."""
    st = te.st
    fa, fb = ctx.faces[te.a], ctx.faces[te.b]
    x0 = np.where(np.isfinite(st.p_int[sl]), st.p_int[sl], 0.5 * (st.p_a[sl] + st.p_b[sl]))
    ang = normals_angle_deg(fa.prim, fb.prim, x0)
    if np.isfinite(ang).any() and np.nanmedian(ang) <= ctx.cfg.tangent_deg:
        pts, curve = _tangent_lift(ctx, fa, fb, x0)
    else:
        lifted = _intersection_lift(ctx, te, sl, fa, fb, x0)
        if lifted is None:
            return None
        pts, curve = lifted
    errs = [e for e in (te.side_a.error(sl), te.side_b.error(sl)) if np.isfinite(e)]
    derr = float(np.mean(errs)) if errs else np.nan
    angle = float(np.nanmedian(st.angle[sl])) if np.isfinite(st.angle[sl]).any() else np.nan
    return ProtoEdge(
        EdgeType.INTERSECTION,
        (te.a, te.b),
        pts,
        curve=curve,
        stats={
            "agreement": agree,
            "angle": angle,
            "gap": float(np.median(st.gap[sl])),
            "depth_err": derr,
            "residual": max(fa.residual, fb.residual),
        },
        **common,
    )


def _retyped_code(ctx: ExtractContext, te: TypedEdge, sl: slice) -> int:
    """An intersection run whose fitted surfaces do not meet: where the nearer face ends in front of the farther
    one, a silhouette of the nearer (counted in ``stats["retyped_intersections"]``)."""
    za, zb = np.nanmedian(te.st.p_a[sl, 2]), np.nanmedian(te.st.p_b[sl, 2])
    ctx.stats["retyped_intersections"] = ctx.stats.get("retyped_intersections", 0) + 1
    return _C_A_SIL if not zb < za else _C_B_SIL


def _contour_points(p_vis: np.ndarray, p_near: np.ndarray) -> tuple[np.ndarray, float]:
    """A visibility run's points on the contour generator (a sample without one, merged in by smoothing, takes the
    nearest sample's; none at all: the near face's lifts), and the share of samples with a contour point."""
    good = np.isfinite(p_vis).all(1)
    vis_share = float(np.mean(good))
    pts = p_vis.copy()
    if good.any():
        k = np.flatnonzero(good)
        nearest = k[np.abs(np.arange(len(good))[:, None] - k[None, :]).argmin(1)]
        pts = pts[nearest]
    else:
        pts = p_near
    return pts, vis_share


def _outline_edges(
    ctx: ExtractContext, te: TypedEdge, sl: slice, code: int, agree: float, retyped: bool, common: dict[str, Any]
) -> list[ProtoEdge]:
    """The silhouette or visibility edge of the near face of run ``sl`` and, with a face behind, its occluded
    edge; a retyped intersection's confidence is scaled by ``retype_conf``."""
    a, b, st = te.a, te.b, te.st
    near, far = (a, b) if code in (_C_A_SIL, _C_A_VIS) else (b, a)
    p_near = st.p_a[sl] if near == a else st.p_b[sl]
    p_far = st.p_b[sl] if near == a else st.p_a[sl]
    err_near = (te.side_a if near == a else te.side_b).error(sl)
    err_far = (te.side_b if near == a else te.side_a).error(sl)
    jump = float(np.median(np.abs(p_far[:, 2] - p_near[:, 2]))) if far else np.inf
    vis = code in (_C_A_VIS, _C_B_VIS)
    pts, vis_share = _contour_points(st.p_vis[sl], p_near) if vis else (p_near, 0.0)
    etype = EdgeType.VISIBILITY if vis else EdgeType.SILHOUETTE
    factor = ctx.cfg.retype_conf if retyped else 1.0
    protos = [
        ProtoEdge(
            etype,
            (near,),
            pts,
            stats={
                "agreement": agree,
                "jump": jump,
                "vis_share": vis_share,
                "depth_err": err_near,
                "residual": ctx.faces[near].residual,
                "factor": factor,
            },
            **common,
        )
    ]
    if far:
        protos.append(
            ProtoEdge(
                EdgeType.OCCLUDED,
                (far,),
                p_far,
                stats={
                    "agreement": agree,
                    "jump": jump,
                    "depth_err": err_far,
                    "residual": ctx.faces[far].residual,
                    "factor": factor,
                },
                **common,
            )
        )
    return protos


def _run_protos(ctx: ExtractContext, te: TypedEdge, sl: slice, code: int, common: dict[str, Any]) -> list[ProtoEdge]:
    """The proto edges of one run of samples ``sl`` whose smoothed type code is ``code``."""
    agree = float(np.mean(te.raw[sl] == code))
    if code != _C_INT:
        return _outline_edges(ctx, te, sl, code, agree, False, common)
    edge = _intersection_edge(ctx, te, sl, agree, common)
    if edge is not None:
        return [edge]
    return _outline_edges(ctx, te, sl, _retyped_code(ctx, te, sl), agree, True, common)


def edge_protos(ctx: ExtractContext, gi: int, gedge: GraphEdge) -> list[ProtoEdge]:
    """Type, split and lift graph edge ``gi``; returns its proto edges with endpoint keys: ("g", graph vertex) at
    the graph edge's ends, ("c", gi, sample) at an image corner, ("s", gi, sample) where the type changes."""
    a, b = (int(x) for x in gedge.instances)
    a = a if a in ctx.faces else 0
    b = b if b in ctx.faces else 0
    if a == 0 and b == 0:
        return []
    te = type_edge(ctx, gi, gedge, a, b)
    pieces, corner_cuts = split_runs(te, ctx.cfg)
    n = len(te.uv)
    protos: list[ProtoEdge] = []
    for r, (k0, k1) in enumerate(pieces):
        last = r == len(pieces) - 1
        sl = slice(k0, n if last else k1 + 1)
        key0 = ("g", int(gedge.v0)) if k0 == 0 else ("c" if k0 in corner_cuts else "s", gi, int(k0))
        key1 = ("g", int(gedge.v1)) if last else ("c" if k1 in corner_cuts else "s", gi, int(k1))
        common = {"uv": te.uv[sl], "key0": key0, "key1": key1, "graph_edge": gi}
        protos += _run_protos(ctx, te, sl, int(te.codes[k0]), common)
    return protos
