"""VB-Rep extraction (paper section "VB-Rep extraction"): fitted primitives + 2D edge graph -> VB-Rep.

Steps, each in its module:
1. ambiguity.py: each face's sheet of its surface (boss or hole) from the depth points;
2. here: every 2D graph edge is resampled every ``sample_step_px`` pixels and each sample typed (classify.py:
   intersection / visibility / silhouette + occluded), the types smoothed, and the edge split where its type
   changes; the samples are lifted to 3D: intersection samples onto the intersection curve of both surfaces
   (lift.py), silhouette / occluded samples onto their face's sheet along the ray, visibility samples onto the
   contour generator (visibility.py);
3. here: vertices: edge ends meeting at one image point are grouped by depth (an occlusion vertex splits into a
   near (silhouette) and a far (occluded) copy), then optimised in full 3D: corners onto the three surfaces,
   intersection-visibility vertices onto the two surfaces and the contour; kept if within d_int of the surfaces
   and ``vertex_px`` of the image point (else the lifted position stays);
4. postprocess.py: labelling rules, short-edge removal, simplification below ``simplify_deg``, loops;
5. mesh.py: face meshes; confidence.py: edge and face confidences.
Camera frame, metres; pixels (u, v).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import cv2
import numpy as np

from v2c.geometry import circle_2d
from v2c.groups import groups_sharing_keys
from v2c.labels import type_axis_of
from v2c.primitives import Cylinder, Plane, Sphere
from v2c.primitives.directions import tangent_basis
from v2c.vbrep.ambiguity import SheetChoice, choose_sheet
from v2c.vbrep.calibration import load_map
from v2c.vbrep.classify import KIND_INT, FaceGeom, classify_samples
from v2c.vbrep.confidence import edge_confidence, face_confidence
from v2c.vbrep.config import VBRepConfig
from v2c.vbrep.lift import (
    contact_points,
    intersection_curve,
    normals_angle_deg,
    points_on_curve,
    project_to_intersection,
    sd_func,
    solve_vertex,
    surfaces_meet,
    tangent_curve,
    visibility_residual,
)
from v2c.vbrep.mesh import face_mesh
from v2c.vbrep.model import EdgeType, VBRep, VEdge, VertexKind, VFace, VVertex
from v2c.vbrep.postprocess import ProtoEdge, ProtoVertex, build_loops, postprocess
from v2c.vbrep.raycast import as_primitive, intersect, pixel_rays, project, sheet_depth
from v2c.vbrep.topology import drop_degenerate, snap_to_surfaces, valid_primitive
from v2c.vbrep.uncertainty import (
    UncertaintyConfig,
    face_covariance,
    face_sigma_m,
    intersection_sigma_m,
    outline_sigma_m,
)

# sample codes: intersection; near = first instance (silhouette / visibility); near = second (silhouette / vis)
_C_INT, _C_A_SIL, _C_A_VIS, _C_B_SIL, _C_B_VIS = range(5)


def depth_window(depth: np.ndarray) -> tuple[float, float]:
    """Depth range (metres) searched by sampled ray casts: around the observed depths."""
    z = depth[depth > 0]
    if len(z) == 0:
        return 0.05, 5.0
    return float(max(0.01, 0.5 * np.percentile(z, 0.5))), float(1.5 * np.percentile(z, 99.5))


def resample_polyline(poly: np.ndarray, step: float) -> np.ndarray:
    """(K, 2) polyline -> points every ``step`` (same unit) from its first to its last point (both kept)."""
    poly = np.asarray(poly, float)
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    total = s[-1]
    if total <= 0:
        return poly[:1].copy()
    n = max(2, int(np.ceil(total / step)) + 1)
    t = np.linspace(0.0, total, n)
    return np.stack([np.interp(t, s, poly[:, 0]), np.interp(t, s, poly[:, 1])], 1)


def smooth_uv(uv: np.ndarray, window: int) -> np.ndarray:
    """Moving average of (K, 2) image points over ``window`` samples, shrinking near the ends (ends kept)."""
    n = len(uv)
    if window <= 1 or n < 3:
        return uv.copy()
    half = window // 2
    cs = np.concatenate([np.zeros((1, 2)), np.cumsum(uv, 0)])
    k = np.arange(n)
    r = np.minimum(half, np.minimum(k, n - 1 - k))  # symmetric window that fits
    return (cs[k + r + 1] - cs[k - r]) / (2 * r + 1)[:, None]


def _normals(pts: np.ndarray) -> np.ndarray:
    t = np.gradient(pts, axis=0) if len(pts) > 1 else np.array([[1.0, 0.0]])
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    return np.stack([-t[:, 1], t[:, 0]], 1)


def _read(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    h, w = img.shape[:2]
    u = np.clip(np.rint(uv[:, 0]).astype(int), 0, w - 1)
    v = np.clip(np.rint(uv[:, 1]).astype(int), 0, h - 1)
    return img[v, u]


def smooth_codes(codes: np.ndarray, window: int, min_run: int, n_codes: int = 5) -> np.ndarray:
    """Mode filter over ``window`` samples, then runs shorter than ``min_run`` samples merged into the longer
    neighbouring run (repeatedly, shortest first)."""
    codes = np.asarray(codes, int).copy()
    n = len(codes)
    if n == 0:
        return codes
    if window > 1 and n > window:
        onehot = np.eye(n_codes)[codes]
        pad = window // 2
        padded = np.concatenate([np.repeat(onehot[:1], pad, 0), onehot, np.repeat(onehot[-1:], pad, 0)])
        cs = np.cumsum(np.concatenate([np.zeros((1, n_codes)), padded]), 0)
        counts = cs[window:] - cs[:-window]
        counts = counts[:n] + 1e-3 * onehot  # ties keep the sample's own code
        codes = np.argmax(counts, 1)
    while True:
        starts = np.flatnonzero(np.concatenate([[True], codes[1:] != codes[:-1]]))
        ends = np.concatenate([starts[1:], [n]])
        lens = ends - starts
        if len(starts) == 1 or lens.min() >= min_run:
            return codes
        r = int(np.argmin(lens))
        left = lens[r - 1] if r > 0 else -1
        right = lens[r + 1] if r + 1 < len(starts) else -1
        src = r - 1 if left >= right else r + 1
        codes[starts[r]:ends[r]] = codes[starts[src]]


@dataclass
class ExtractContext:
    faces: dict[int, FaceGeom]
    sheets: dict[int, SheetChoice]
    K: np.ndarray
    window: tuple[float, float]
    scale: float
    gap_thr: float
    depth: np.ndarray
    instances: np.ndarray
    cfg: VBRepConfig
    stats: dict[str, Any] = field(default_factory=dict)


def measured_points(mask: np.ndarray, depth: np.ndarray, K: np.ndarray) -> np.ndarray:
    """(N, 3) camera-frame points (metres) of the pixels of ``mask`` that have a depth reading."""
    vs, us = np.nonzero(mask & (depth > 0))
    return pixel_rays(np.stack([us, vs], 1).astype(float), K) * depth[vs, us, None]


def fit_plane_points(X: np.ndarray, trim: float = 0.8) -> tuple[Plane, float, float] | None:
    """Total-least-squares plane through (N, 3) points, refitted on the ``trim`` share closest to the first fit.
    Returns the plane (normal towards the camera), its RMS distance (metres) and its flatness (second singular
    value over the first: near 0 when the points lie on one line, so the plane is undetermined); None with fewer
    than 3 points."""
    if len(X) < 3:
        return None
    for _ in range(2):
        c = X.mean(0)
        sv, vt = np.linalg.svd(X - c, full_matrices=False)[1:]
        n = vt[-1]
        d = np.abs((X - c) @ n)
        if len(X) > 10:
            X = X[d <= np.quantile(d, trim)]
    c = X.mean(0)
    if n @ c > 0:  # outward normal towards the camera
        n = -n
    rms = float(np.sqrt(np.mean(((X - c) @ n) ** 2)))
    return Plane(c, n), rms, float(sv[1] / max(sv[0], 1e-15))


def fit_sphere_points(X: np.ndarray, trim: float = 0.8) -> tuple[Sphere, float] | None:
    """Algebraic least-squares sphere through (N, 3) points (camera frame, metres), refitted on the ``trim``
    share closest to the first fit. Returns the sphere and its RMS distance (metres); None with fewer than 10
    points or a degenerate fit."""
    if len(X) < 10:
        return None
    for _ in range(2):
        A = np.concatenate([2 * X, np.ones((len(X), 1))], 1)
        sol = np.linalg.lstsq(A, np.sum(X**2, 1), rcond=None)[0]
        c = sol[:3]
        r2 = float(sol[3] + c @ c)
        if not (np.all(np.isfinite(sol)) and r2 > 0):
            return None
        d = np.abs(np.linalg.norm(X - c, axis=1) - np.sqrt(r2))
        X = X[d <= np.quantile(d, trim)]
    d = np.linalg.norm(X - c, axis=1) - np.sqrt(r2)
    return Sphere(c, float(np.sqrt(r2))), float(np.sqrt(np.mean(d**2)))


def fit_axis_cylinder_points(X: np.ndarray, axis: np.ndarray) -> tuple[Cylinder, float] | None:
    """Least-squares cylinder with a given unit axis through (N, 3) points: an algebraic circle fit of the points
    projected on the plane normal to the axis (`fit.ransac.circle_2d`), refined by Gauss-Newton on the geometric
    distance. Returns the cylinder and its RMS distance (metres); None with fewer than 5 points or a degenerate
    fit."""
    if len(X) < 5:
        return None
    a = axis / np.linalg.norm(axis)
    t1, t2 = tangent_basis(a)
    q = np.stack([X @ t1, X @ t2], 1)
    c, r = circle_2d(q)
    if not (np.all(np.isfinite(c)) and r > 0):
        return None
    for _ in range(10):  # geometric (Gauss-Newton) refinement: the algebraic fit shrinks short noisy arcs
        v = q - c
        dist = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
        J = np.concatenate([-v / dist[:, None], -np.ones((len(q), 1))], 1)
        step = np.linalg.lstsq(J, -(dist - r), rcond=None)[0]
        c, r = c + step[:2], r + float(step[2])
        if not np.isfinite(r) or r <= 0:
            return None
    d = np.linalg.norm(q - c, axis=1) - r
    origin = c[0] * t1 + c[1] * t2 + float(np.mean(X @ a)) * a
    return Cylinder(origin, a, r), float(np.sqrt(np.mean(d**2)))


def fit_axis_plane_points(X: np.ndarray, normal: np.ndarray) -> tuple[Plane, float] | None:
    """Least-squares plane with a given unit normal through (N, 3) points: the mean offset along the normal.
    Returns the plane and its RMS distance (metres); None with fewer than 3 points."""
    if len(X) < 3:
        return None
    n = normal / np.linalg.norm(normal)
    return Plane(X.mean(axis=0), n), float(np.std(X @ n))


def fit_plane_normal_across(X: np.ndarray, axis: np.ndarray) -> tuple[Plane, float] | None:
    """Least-squares plane whose normal is perpendicular to the unit ``axis`` (a face parallel to that axis)
    through (N, 3) points: a line fitted to the points projected along the axis. Returns the plane and its RMS
    distance (metres); None with fewer than 3 points."""
    if len(X) < 3:
        return None
    t1, t2 = tangent_basis(axis / np.linalg.norm(axis))
    q = np.stack([X @ t1, X @ t2], 1)
    c = q.mean(axis=0)
    _, _, vt = np.linalg.svd(q - c, full_matrices=False)
    n = vt[1, 0] * t1 + vt[1, 1] * t2
    return Plane(X.mean(axis=0), n), float(np.std(X @ n))


def _labelled_fallback(inst: int, seg: Any, fit: Any, X: np.ndarray, scale: float, cfg: VBRepConfig
                       ) -> tuple[Cylinder | Plane, float, str | None] | None:
    """An unfitted instance labelled cylinder or plane with an aligned axis class (X / Y / Z): the cylinder on
    that axis of the shared frame (radius at most the part size: a tiny wall patch keeps its type instead of
    becoming a plane), or the plane normal to it, that fits its evidence within fallback_rms; else None. A face
    seen at a grazing angle has hardly any depth; its label's axis fixes the plane that its edges alone cannot.
    When the fit found faces of one axis class only, the frame's other two axes are a guess about it: a plane
    labelled with another class is then fitted with its normal across the one found (it is parallel to it), and
    a cylinder is left to the rules for unlabelled faces."""
    labels = np.asarray(getattr(seg, "labels", ()))
    frame = getattr(fit, "frame", None)
    if frame is None or inst >= len(labels) or not 1 <= int(labels[inst]) <= 16:
        return None
    ptype, ax = type_axis_of(int(labels[inst]))
    if ptype.value not in ("cylinder", "plane") or ax is None or ax.value == "U":
        return None
    row = {"X": 0, "Y": 1, "Z": 2}
    frame = np.asarray(frame, float)
    axis = frame[row[ax.value]]
    found = {v for v in getattr(fit, "axis_labels", {}).values() if v in row}
    if len(found) == 1 and ax.value not in found:
        if ptype.value != "plane":
            return None
        got = fit_plane_normal_across(X, frame[row[found.pop()]])
        if got is None or got[1] > cfg.fallback_rms * scale:
            return None
        return got[0], got[1], None
    if ptype.value == "plane":
        got = fit_axis_plane_points(X, axis)
    else:
        got = fit_axis_cylinder_points(X, axis)
        if got is not None and got[0].radius > scale:
            return None
    if got is None or got[1] > cfg.fallback_rms * scale:
        return None
    return got[0], got[1], ax.value


def fallback_plane_points(inst: int, inst_map: np.ndarray, depth: np.ndarray, K: np.ndarray,
                          faces: dict[int, FaceGeom], window: tuple[float, float]) -> list[np.ndarray]:
    """3D evidence (camera frame, metres) for an instance the geometry stage could not fit (e.g. a face seen at a
    grazing angle, where the sensor returns no depth): its own depth points, plus its boundary pixels next to each
    fitted neighbour lifted onto that neighbour's surface (where two faces meet, the edge lies on both). Returns
    the point sets of each source with at least 3 points."""
    m = inst_map == inst
    pts = [measured_points(m, depth, K)]
    ring = cv2.dilate(m.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & ~m
    for j in np.unique(inst_map[ring]):
        if int(j) not in faces:
            continue
        nb = cv2.dilate((inst_map == j).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool) & m
        bv, bu = np.nonzero(nb)
        uv = np.stack([bu, bv], 1).astype(float)
        pts.append(pixel_rays(uv, K) * sheet_depth(intersect(faces[int(j)].prim, pixel_rays(uv, K), window),
                                                   faces[int(j)].sheet)[:, None])
    return [p for p in pts if len(p) >= 3]


def _face_geoms(fit: Any, seg: Any, depth: np.ndarray, K: np.ndarray, window: tuple[float, float], scale: float,
                cfg: VBRepConfig, stats: dict[str, Any] | None = None,
                ) -> tuple[dict[int, FaceGeom], dict[int, SheetChoice]]:
    """Each face's geometry and sheet; fitted primitives with invalid parameters (`valid_primitive`) are
    rejected (``stats["rejected_primitives"]``, instance ids) and treated like instances without a fit."""
    rng = np.random.default_rng(cfg.seed)
    faces: dict[int, FaceGeom] = {}
    sheets: dict[int, SheetChoice] = {}
    inst_map = np.asarray(seg.instances)

    def add(inst: int, prim: Any, res: float, axl: str | None, extra: dict) -> None:
        vs, us = np.nonzero(inst_map == inst)
        if len(us) == 0:
            return
        ch = choose_sheet(prim, np.stack([us, vs], 1).astype(float), depth[vs, us], K, window, rng,
                          cfg.sheet_max_pixels)
        faces[inst] = FaceGeom(inst, prim, ch.sheet, res, axl, extra)
        sheets[inst] = ch

    rejected = []
    for inst in sorted(fit.primitives):
        if not valid_primitive(as_primitive(fit.primitives[inst])):
            rejected.append(int(inst))
            # a curved face with invalid parameters (e.g. a torus with a negative major radius): the nearest
            # valid surface, a least-squares sphere through its depth points, if it fits them; else it is left
            # to the unfitted-face rule below
            got = fit_sphere_points(measured_points(inst_map == inst, depth, K))
            if got is not None and got[1] <= cfg.fallback_rms * scale:
                add(int(inst), got[0], got[1], None, {"refit": "sphere"})
            continue
        add(int(inst), as_primitive(fit.primitives[inst]),
            float(getattr(fit, "residuals", {}).get(inst, 0.0) or 0.0), getattr(fit, "axis_labels", {}).get(inst),
            {})
    def coincides(plane: Plane) -> bool:  # with a fitted plane (within fallback_min_angle_deg, fallback_rms)
        return any(f.prim.type == "plane" and abs(float(f.prim.axis_vector @ plane.axis_vector))
                   > np.cos(np.deg2rad(cfg.fallback_min_angle_deg))
                   and abs(float(f.prim.axis_vector @ (plane.origin - f.prim.origin))) < cfg.fallback_rms * scale
                   for f in faces.values())

    counts = np.bincount(inst_map.ravel())
    for inst in np.flatnonzero(counts >= cfg.fallback_min_px):
        if inst == 0 or int(inst) in faces:
            continue
        sources = fallback_plane_points(int(inst), inst_map, depth, K, faces, window)
        if not sources:
            continue
        evidence = np.concatenate(sources)
        # one source (one neighbour's edge, no depth of its own) places a surface whose axis the label gives
        lab = _labelled_fallback(int(inst), seg, fit, evidence, scale, cfg)
        if lab is not None and not (lab[0].type == "plane" and coincides(lab[0])):
            add(int(inst), lab[0], lab[1], lab[2], {"fallback": True})
            continue
        if len(sources) < 2:  # one neighbour's edge alone does not fix a free plane (it may lie in that neighbour)
            continue
        got = fit_plane_points(evidence)
        if got is None:
            continue
        plane, rms, flat = got
        if rms <= cfg.fallback_rms * scale and flat >= cfg.fallback_flatness and not coincides(plane):
            add(int(inst), plane, rms, None, {"fallback": True})
    if stats is not None:
        stats["rejected_primitives"] = rejected
    return faces, sheets


def _edge_protos(ctx: ExtractContext, gi: int, gedge: Any) -> list[ProtoEdge]:
    """Type, split and lift one 2D graph edge; returns proto edges with endpoint keys."""
    cfg = ctx.cfg
    a, b = (int(x) for x in gedge.instances)
    a = a if a in ctx.faces else 0
    b = b if b in ctx.faces else 0
    if a == 0 and b == 0:
        return []
    uv_raw = resample_polyline(gedge.polyline, cfg.sample_step_px)
    uv = smooth_uv(uv_raw, max(1, round(cfg.smooth_uv_px / cfg.sample_step_px)))
    n = len(uv)
    m = _normals(uv)
    # orient m from a's side into b's side (majority of the samples)
    fwd = _read(ctx.instances, uv + cfg.side_probe_px * m)
    bwd = _read(ctx.instances, uv - cfg.side_probe_px * m)
    vote = np.sum((fwd == b) | (bwd == a)) - np.sum((fwd == a) | (bwd == b))
    if vote < 0:
        m = -m
    st = classify_samples(uv, m, a, b, ctx.faces, ctx.K, ctx.window, cfg.int_band_px, ctx.gap_thr,
                          cfg.vis_px, cfg.vis_step_px, cfg.curve_iters, cfg.vis_angle_deg, ctx.instances)
    raw = np.where(st.kind == KIND_INT, _C_INT,
                   np.where(st.kind == 1, np.where(st.vis, _C_A_VIS, _C_A_SIL),
                            np.where(st.vis, _C_B_VIS, _C_B_SIL)))
    min_run = max(1, round(cfg.min_run_px / cfg.sample_step_px))
    codes = smooth_codes(raw, cfg.smooth_samples, min_run)
    # observed depth just inside each side (for the depth-agreement confidence)
    probe_a, probe_b = uv - cfg.side_probe_px * m, uv + cfg.side_probe_px * m
    za_obs, zb_obs = _read(ctx.depth, probe_a), _read(ctx.depth, probe_b)
    za_fit = _surface_depth(ctx.faces.get(a), probe_a, ctx)
    zb_fit = _surface_depth(ctx.faces.get(b), probe_b, ctx)
    starts = np.flatnonzero(np.concatenate([[True], codes[1:] != codes[:-1]]))
    ends = np.concatenate([starts[1:], [n]])
    pieces = []  # (first sample, start of the next piece) after splitting runs at image corners
    corner_cuts: set[int] = set()
    for k0, k1 in zip(starts, ends):
        # outline corners: only where a face ends against something farther (contours of smooth surfaces and
        # intersection curves of smooth surfaces have no corners of their own)
        cuts = corner_samples(uv_raw[k0:min(k1 + 1, n)], cfg) if codes[k0] in (_C_A_SIL, _C_B_SIL) else []
        corner_cuts |= {int(k0 + c) for c in cuts}
        bounds = [k0] + [k0 + c for c in cuts] + [k1]
        pieces += list(itertools.pairwise(bounds))
    protos: list[ProtoEdge] = []
    for r, (k0, k1) in enumerate(pieces):
        last = r == len(pieces) - 1
        sl = slice(k0, n if last else k1 + 1)
        key0 = ("g", int(gedge.v0)) if k0 == 0 else ("c" if k0 in corner_cuts else "s", gi, int(k0))
        key1 = ("g", int(gedge.v1)) if last else ("c" if k1 in corner_cuts else "s", gi, int(k1))
        code = int(codes[k0])
        agree = float(np.mean(raw[sl] == code))
        uvr = uv[sl]
        common = {"uv": uvr, "key0": key0, "key1": key1, "graph_edge": gi}
        retyped = False
        tangent = False
        if code == _C_INT:
            fa, fb = ctx.faces[a], ctx.faces[b]
            x0 = np.where(np.isfinite(st.p_int[sl]), st.p_int[sl], 0.5 * (st.p_a[sl] + st.p_b[sl]))
            ang = normals_angle_deg(fa.prim, fb.prim, x0)
            tangent = bool(np.isfinite(ang).any() and np.nanmedian(ang) <= cfg.tangent_deg)
        if tangent:
            # a tangent junction: the line where the surfaces touch (or come closest)
            curve = tangent_curve(fa.prim, fb.prim, x0, cfg.parallel_deg)
            on = points_on_curve(curve, x0)
            pts = on if on is not None else contact_points(fa.prim, fb.prim, x0, cfg.tangent_iters)[0]
            ctx.stats["tangent_edges"] = ctx.stats.get("tangent_edges", 0) + 1
        elif code == _C_INT:
            pts = project_to_intersection(fa.prim, fb.prim, x0, cfg.curve_iters, ctx.K, cfg.int_band_px + 1.0)
            tol = max(cfg.meet_tol * ctx.scale, cfg.meet_min_m)
            met, on_curve = surfaces_meet(fa.prim, fb.prim, x0, tol, cfg.snap_iters)
            miss = np.linalg.norm(st.p_a[sl] - st.p_b[sl], axis=1)  # between the two lifts, along the rays
            miss = float(np.nanmedian(miss)) if np.isfinite(miss).any() else np.inf
            if np.mean(met) >= cfg.meet_share or miss <= cfg.retype_gap * ctx.scale:
                # on the curve where the surfaces meet nearby; elsewhere (a near miss) the projection limited to
                # the image band stays (moving those samples to the midpoint of the two lifts gave 23 instead of
                # 27 faces bounded by their mesh outline on 23 scans but lost 0.2 points of edge coverage)
                pts = np.where(met[:, None], on_curve, pts)
            else:
                # the fitted surfaces do not meet along this run: it is where the nearer face ends in front
                # of the farther one (typed with less confidence)
                retyped = True
                za, zb = np.nanmedian(st.p_a[sl, 2]), np.nanmedian(st.p_b[sl, 2])
                code = _C_A_SIL if not zb < za else _C_B_SIL
                ctx.stats["retyped_intersections"] = ctx.stats.get("retyped_intersections", 0) + 1
        if code == _C_INT:
            if not tangent:
                curve = intersection_curve(fa.prim, fb.prim, pts, cfg.perpendicular_deg, cfg.parallel_deg)
            errs = [e for e in (_depth_err(za_fit[sl], za_obs[sl]), _depth_err(zb_fit[sl], zb_obs[sl]))
                    if np.isfinite(e)]
            derr = float(np.mean(errs)) if errs else np.nan
            protos.append(ProtoEdge(EdgeType.INTERSECTION, (a, b), pts, curve=curve, stats={
                "agreement": agree, "angle": float(np.nanmedian(st.angle[sl])) if np.isfinite(st.angle[sl]).any()
                else np.nan, "gap": float(np.median(st.gap[sl])), "depth_err": derr,
                "residual": max(fa.residual, fb.residual)}, **common))
            continue
        near, far = (a, b) if code in (_C_A_SIL, _C_A_VIS) else (b, a)
        p_near = st.p_a[sl] if near == a else st.p_b[sl]
        p_far = st.p_b[sl] if near == a else st.p_a[sl]
        err_near = _depth_err(*((za_fit, za_obs) if near == a else (zb_fit, zb_obs)), sl)
        err_far = _depth_err(*((zb_fit, zb_obs) if near == a else (za_fit, za_obs)), sl)
        jump = float(np.median(np.abs(p_far[:, 2] - p_near[:, 2]))) if far else np.inf
        vis = code in (_C_A_VIS, _C_B_VIS)
        if vis:
            good = np.isfinite(st.p_vis[sl]).all(1)
            vis_share = float(np.mean(good))
            pts = st.p_vis[sl].copy()
            if good.any():  # samples without a contour point (merged in by smoothing): the nearest one's
                k = np.flatnonzero(good)
                nearest = k[np.abs(np.arange(len(good))[:, None] - k[None, :]).argmin(1)]
                pts = pts[nearest]
            else:
                pts = p_near
        else:
            pts, vis_share = p_near, 0.0
        etype = EdgeType.VISIBILITY if vis else EdgeType.SILHOUETTE
        factor = cfg.retype_conf if retyped else 1.0
        protos.append(ProtoEdge(etype, (near,), pts, stats={
            "agreement": agree, "jump": jump, "vis_share": vis_share, "depth_err": err_near,
            "residual": ctx.faces[near].residual, "factor": factor}, **common))
        if far:
            protos.append(ProtoEdge(EdgeType.OCCLUDED, (far,), p_far, stats={
                "agreement": agree, "jump": jump, "depth_err": err_far,
                "residual": ctx.faces[far].residual, "factor": factor}, **common))
    return protos


def _turn_deg(uv: np.ndarray, L: int) -> np.ndarray:
    """Turn angle (degrees) of a polyline at each sample, over arms of L samples (0 within L of the ends)."""
    n = len(uv)
    out = np.zeros(n)
    if n < 2 * L + 1:
        return out
    k = np.arange(L, n - L)
    t_in, t_out = uv[k] - uv[k - L], uv[k + L] - uv[k]
    c = np.einsum("ij,ij->i", t_in, t_out) / np.maximum(
        np.linalg.norm(t_in, axis=1) * np.linalg.norm(t_out, axis=1), 1e-12)
    out[k] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return out


def corner_samples(uv: np.ndarray, cfg: VBRepConfig) -> list[int]:
    """Indices (into uv) of the image corners of a polyline: the turn over arms of ``corner_scale_px`` exceeds
    ``corner_deg`` on both scales and is concentrated there (at least ``corner_concentration`` of the turn over
    arms twice as long; a circular arc turns in proportion to the arm length, a corner does not, and pixel
    staircase kinks vanish on the longer arms). Local maxima at least
    ``min_edge_px`` from the ends and from each other."""
    n = len(uv)
    L = max(1, round(cfg.corner_scale_px / cfg.sample_step_px))
    m = max(L, int(np.ceil(cfg.min_edge_px / cfg.sample_step_px)))
    if n < 2 * m + 1:
        return []
    turn, wide = _turn_deg(uv, L), _turn_deg(uv, 2 * L)
    # a corner turns at every scale (pixel staircase kinks fade on the wide scale); an arc turns more on the
    # wide scale than on the narrow one
    ok = (turn > cfg.corner_deg) & (wide > cfg.corner_deg) & (turn >= cfg.corner_concentration * wide)
    cuts: list[int] = []
    for c in np.argsort(-turn):
        if turn[c] <= cfg.corner_deg:
            break
        if not ok[c] or c < m or c > n - 1 - m or any(abs(c - x) < max(m, 2 * L) for x in cuts):
            continue
        cuts.append(int(c))
    return sorted(cuts)


def _surface_depth(face: FaceGeom | None, uv: np.ndarray, ctx: ExtractContext) -> np.ndarray:
    if face is None:
        return np.full(len(uv), np.nan)
    return sheet_depth(intersect(face.prim, pixel_rays(uv, ctx.K), ctx.window), face.sheet)


def _depth_err(z_fit: np.ndarray, z_obs: np.ndarray, sl: slice = slice(None)) -> float:
    """Median |fitted - observed| depth (metres) at the probe pixels beside an edge (NaN without data)."""
    z_fit, z_obs = z_fit[sl], z_obs[sl]
    ok = (z_obs > 0) & np.isfinite(z_fit)
    return float(np.median(np.abs(z_fit[ok] - z_obs[ok]))) if ok.any() else np.nan


_END_PRIORITY = {EdgeType.INTERSECTION: 0, EdgeType.SILHOUETTE: 1, EdgeType.VISIBILITY: 2, EdgeType.OCCLUDED: 3}


def _key_pixel(key: tuple, graph: Any, protos: list[ProtoEdge], ends: list[tuple[int, int]]) -> np.ndarray:
    if key[0] == "g":
        return np.asarray(graph.vertices[key[1]], float)
    pi, e = ends[0]
    return protos[pi].uv[0] if e == 0 else protos[pi].uv[-1]


def _face_groups(faces: list[tuple[int, ...]]) -> list[np.ndarray]:
    """Split the edge ends meeting at one image point into vertices: ends whose edges share a face (directly or
    through other ends) are one vertex, so every face's boundary passes through one vertex there and its loops
    close. At an occlusion T-junction the near face's ends (its silhouette or visibility edges) and the far
    face's ends (its occluded edge and its other edges) share no face: two vertices, a near and a far copy."""
    return groups_sharing_keys(faces)


def _make_vertices(ctx: ExtractContext, protos: list[ProtoEdge], graph: Any) -> list[ProtoVertex]:
    """Group edge ends by image point and depth, choose kinds, optimise positions, snap the edge ends."""
    cfg, scale = ctx.cfg, ctx.scale
    by_key: dict[tuple, list[tuple[int, int]]] = {}
    for pi, p in enumerate(protos):
        by_key.setdefault(p.key0, []).append((pi, 0))
        by_key.setdefault(p.key1, []).append((pi, 1))
    vertices: list[ProtoVertex] = []
    n_opt = n_kept = 0
    for key, ends in by_key.items():
        pos = np.array([protos[pi].pts[0 if e == 0 else -1] for pi, e in ends])
        clusters = _face_groups([protos[pi].faces for pi, _ in ends])
        pixel = _key_pixel(key, graph, protos, ends)
        for cl in clusters:
            cl_ends = [ends[i] for i in cl]
            types = [protos[pi].type for pi, _ in cl_ends]
            best = min(_END_PRIORITY[t] for t in types)
            x0 = pos[[i for i in cl if _END_PRIORITY[protos[ends[i][0]].type] == best]].mean(0)
            int_faces: list[int] = []
            for pi, _ in cl_ends:
                if protos[pi].type is EdgeType.INTERSECTION:
                    int_faces += [f for f in protos[pi].faces if f not in int_faces]
            vis_faces = [protos[pi].faces[0] for pi, _ in cl_ends if protos[pi].type is EdgeType.VISIBILITY]
            kind = VertexKind.OTHER
            funcs = None
            if len(int_faces) >= 3:
                kind = VertexKind.CORNER
                funcs = [sd_func(ctx.faces[f].prim) for f in int_faces[:3]]
            elif len(int_faces) == 2 and any(f in int_faces for f in vis_faces):
                kind = VertexKind.INTERSECTION_VISIBILITY
                c = next(f for f in vis_faces if f in int_faces)
                funcs = [sd_func(ctx.faces[f].prim) for f in int_faces] + [visibility_residual(ctx.faces[c].prim)]
            elif len(clusters) > 1:
                kind = VertexKind.OCCLUSION
            x = x0
            if funcs is not None:
                n_opt += 1
                xs, _ = solve_vertex(funcs, x0, cfg.vertex_iters)
                surf = max(abs(float(sd_func(ctx.faces[f].prim)(xs[None])[0])) for f in int_faces[:3])
                px = float(np.linalg.norm(project(xs[None], ctx.K)[0] - pixel))
                if (np.all(np.isfinite(xs)) and surf <= cfg.d_int * scale and px <= cfg.vertex_px
                        and np.linalg.norm(xs - x0) <= cfg.d_int * scale):
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


def extract_vbrep(scan: Any, seg: Any, fit: Any, config: VBRepConfig | None = None) -> VBRep:
    """VB-Rep of one scan from its segmentation and fit (FitResult contract: primitives, graph, frame,
    axis_labels, residuals, scale). Camera frame, metres."""
    cfg = config or VBRepConfig()
    K = np.asarray(scan.K, float)
    depth = np.asarray(scan.depth, float)
    window = depth_window(depth)
    scale = float(fit.scale)
    stats: dict[str, Any] = {}
    faces, sheets = _face_geoms(fit, seg, depth, K, window, scale, cfg, stats)
    ctx = ExtractContext(faces, sheets, K, window, scale, max(cfg.int_gap * scale, cfg.int_gap_min_m), depth,
                         np.asarray(seg.instances), cfg, stats)
    protos: list[ProtoEdge] = []
    for gi, ge in enumerate(fit.graph.edges):
        protos += _edge_protos(ctx, gi, ge)
    vertices = _make_vertices(ctx, protos, fit.graph)
    protos, vertices = postprocess(protos, vertices, K, cfg, same_m=0.25 * ctx.gap_thr)
    ctx.stats.update(snap_to_surfaces(protos, vertices, {i: f.prim for i, f in faces.items()}, cfg.d_int * scale,
                                      cfg.snap_iters, cfg.snap_tol, K, cfg.snap_end_px))
    protos = drop_degenerate(protos, K, cfg.min_edge_px)
    return assemble(ctx, protos, vertices, fit, seg, scan)


def assemble(ctx: ExtractContext, protos: list[ProtoEdge], vertices: list[ProtoVertex], fit: Any, seg: Any,
             scan: Any) -> VBRep:
    """Build the VBRep dataclasses: faces with meshes and loops, edges with confidences, vertices."""
    cfg, scale = ctx.cfg, ctx.scale
    # a face none of whose edges survived post-processing (a sliver of a few pixels) has no boundary to be
    # trimmed by: it is left out (counted in meta["extract"]["faces_without_edges"])
    bounded = {f for p in protos for f in p.faces}
    inst_ids = sorted(i for i in ctx.faces if i in bounded)
    ctx.stats["faces_without_edges"] = sorted(int(i) for i in ctx.faces if i not in bounded)
    fid = {inst: k for k, inst in enumerate(inst_ids)}
    cmap = None if cfg.conf_calibration is None else \
        load_map(None if cfg.conf_calibration == "shipped" else cfg.conf_calibration)
    # positional uncertainty: each face's fit covariance from its observed points (v2c.vbrep.uncertainty)
    ucfg = UncertaintyConfig(depth_sigma_coeff_per_m=cfg.sigma_depth_coeff_per_m,
                             depth_correlated=cfg.sigma_depth_correlated, min_angle_deg=cfg.sigma_min_angle_deg)
    face_pts = {i: measured_points(ctx.instances == i, ctx.depth, ctx.K) for i in inst_ids}
    covs = {i: face_covariance(ctx.faces[i].prim, face_pts[i], ctx.faces[i].residual, ucfg) for i in inst_ids}
    focal = float(np.sqrt(ctx.K[0, 0] * ctx.K[1, 1]))
    edges = []
    for k, p in enumerate(protos):
        s = p.stats
        length_px = float(np.sum(np.linalg.norm(np.diff(project(p.pts, ctx.K), axis=0), axis=1)))
        raw = edge_confidence(p.type, residual=s.get("residual", 0.0), depth_err=s.get("depth_err", np.nan),
                              length_px=length_px, angle=s.get("angle", np.nan), gap=s.get("gap", np.nan),
                              jump=s.get("jump", np.inf), vis_share=s.get("vis_share", 0.0),
                              agreement=s.get("agreement", 1.0), gap_thr=ctx.gap_thr, scale=scale, cfg=cfg)
        raw = round(raw * s.get("factor", 1.0), 4)
        conf = raw if cmap is None else round(float(cmap.apply(p.type, raw)), 4)
        curve = dict(p.curve) if p.type is EdgeType.INTERSECTION and p.curve is not None else None
        tangent = bool(curve.pop("tangent", False)) if curve is not None else False
        fc = [covs.get(f) for f in p.faces]
        if any(c is None for c in fc):
            sig = None
        elif len(fc) == 2:
            sig = intersection_sigma_m(fc[0], fc[1], p.pts, ucfg)
        else:
            sig = outline_sigma_m(fc[0], p.pts, focal, ucfg)
        sig_mm = round(1000.0 * sig, 5) if sig is not None and np.isfinite(sig) else None
        edges.append(VEdge(k, p.type, conf, tuple(fid[f] for f in p.faces), p.pts, p.v0, p.v1,
                           curve, tangent=tangent, confidence_raw=raw, sigma_mm=sig_mm))
    vverts = [VVertex(k, v.kind, v.position, v.pixel) for k, v in enumerate(vertices)]
    loops = build_loops(protos, fid, ctx.K)
    bounds = None  # the part's box: what its observed points span, padded
    if cfg.mesh_bound_pad >= 0:
        q = measured_points(ctx.instances > 0, ctx.depth, ctx.K)
        if len(q):
            bounds = (np.percentile(q, 0.5, axis=0), np.percentile(q, 99.5, axis=0))
    vfaces = []
    for inst in inst_ids:
        fg = ctx.faces[inst]
        region = ctx.instances == inst
        ch = ctx.sheets[inst]
        conf = face_confidence(fg.residual, ch.errors, ch.sheet, scale, cfg)
        box = None
        if bounds is not None:  # a sure face with few depth readings of its own is placed by its edges: looser box
            loose = float(np.mean(ctx.depth[region] <= 0)) > cfg.mesh_unmeasured_share \
                and conf >= cfg.mesh_loose_min_conf
            pad = (cfg.mesh_bound_pad_unmeasured if loose else cfg.mesh_bound_pad) * scale
            lo, hi = bounds[0] - pad, bounds[1] + pad
            if not isinstance(fg.prim, Plane):  # a hole's wall may run deeper than any point seen: up to one part
                hi[2] = max(hi[2], bounds[0][2] + scale + pad)  # size past the part's nearest point
            box = (lo, hi)
        mv, mt = face_mesh(fg.prim, fg.sheet, region, ctx.depth, ctx.K, ctx.window, cfg.mesh_stride_px,
                           cfg.mesh_max_edge * scale, cfg.mesh_surface_tol * scale, box,
                           cfg.mesh_plane_long and isinstance(fg.prim, Plane) and conf >= cfg.mesh_loose_min_conf)
        fsig = face_sigma_m(covs[inst], face_pts[inst]) if covs[inst] is not None else float("nan")
        vfaces.append(VFace(fid[inst], inst, fg.prim.to_dict(), fg.axis_label, loops.get(fid[inst], []), mv, mt,
                            round(conf, 4), sigma_mm=round(1000.0 * fsig, 5) if np.isfinite(fsig) else None))
    meta = {
        "segmentation": getattr(seg, "method", None),
        "faces": {str(fid[i]): {"sheet": ctx.sheets[i].sheet, "concave": ctx.sheets[i].concave,
                                "residual_m": ctx.faces[i].residual,
                                "fallback_plane": bool(ctx.faces[i].extra.get("fallback")),
                                "refit": ctx.faces[i].extra.get("refit")} for i in inst_ids},
        "extract": dict(ctx.stats, gap_threshold_m=ctx.gap_thr),
    }
    frame = np.asarray(getattr(fit, "frame", np.eye(3)), float)
    h, w = ctx.instances.shape
    return VBRep(vfaces, edges, vverts, frame=frame, K=ctx.K.copy(), image_size=(int(w), int(h)),
                 scale=scale, meta=meta)
