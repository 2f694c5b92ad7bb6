"""Every metric of ../shared/BENCHMARK.md on one synthetic scan and its reconstructed VB-Rep.

`scan_metrics(vbrep, scan)` returns one flat dict per scan (the run averages them over scans):

- ``chamfer`` / ``chamfer_all``: 0.5 * (mean over R of the distance to G + mean over G of the distance to R),
  divided by the ground-truth part size. G: 20,000 clean-depth points of the part's pixels (`gt_points` of
  v2c.bench.surfaces, seeded); R: 20,000 points drawn area-uniformly on the face meshes, keeping (``chamfer``) those
  the camera sees, i.e. whose camera ray meets no triangle of the reconstruction before the point (exact ray
  cast, `visible_points`), or (``chamfer_all``) all of them.
- face matching: the reconstruction is rendered from the scan's camera with a z-buffer (`render_vbrep`: one ray
  per pixel centre, the nearest triangle wins), giving each predicted face its pixel set; predicted faces and
  analytic ground-truth faces are paired greedily by largest IoU (`v2c.bench.segmentation.match_faces`) at IoU
  >= 0.5 (``precision``, ``recall``, ``recall_all``) and >= 0.75 (``..._75``). Precision's denominator: predicted
  faces covering >= 1 pixel, less those lying mostly on non-analytic ground truth (left out as those faces are);
  recall's: ground-truth faces of >= 50 pixels; ``recall_all``: every analytic ground-truth face seen.
- ``type_accuracy`` / ``axis_accuracy`` over the IoU-0.5 pairs: same primitive type; same axis class, the
  predicted class read from the predicted axis against meta.json ``axes_cam`` within 1.5 degrees
  (`v2c.labels.axis_class`), the ground-truth class from primitives.json ``axis_label`` (spheres: none).
- ``alignment``: over IoU-0.5 pairs where both faces have an axis (plane normal; cylinder, cone, torus axis),
  min(|a - b|, |a + b|) of the unit axes; mean over the pairs.
- ``depth_error``: median |rendered depth - clean depth| over part pixels both cover, / part size.
- ``edge_type_accuracy``: `v2c.bench.vbrep.edge_type_accuracy` (the ground-truth rule of v2c.vbrep.gt_types).
- ``runtime``: the stage timings of the VB-Rep's meta (seconds), merged with the caller's.

`vbrep_from_gt(scan)` builds the ideal VB-Rep of a synthetic scan (faces = the ground-truth primitives, meshes
through the pixel corners of each face's region, on the true surface): the floor of every metric.

Units: metres and the camera frame (OpenCV) inside; lengths in the results are divided by the part size.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation

from v2c.bench.config import MetricConfig
from v2c.bench.segmentation import match_faces
from v2c.bench.surfaces import (
    MeshCaster,
    Rendering,
    chamfer_distance,
    gt_points,
    part_size,
    reconstruction_points,
    render_vbrep,
    vbrep_mesh,
)
from v2c.bench.vbrep import edge_correctness, edge_type_accuracy
from v2c.camera import backproject, pixel_rays
from v2c.labels import AXIS_ALIGN_TOL_DEG, IGNORE, axis_class
from v2c.vbrep.model import EdgeType, VBRep, VFace
from v2c.vbrep.raycast import intersect

if TYPE_CHECKING:
    from v2c.scan import Scan

ANALYTIC_TYPES = ("plane", "cylinder", "cone", "sphere", "torus")


# --------------------------------------------------------------------------------------- face matching & co


def _gt_tables(scan: Scan) -> tuple[dict[int, dict], np.ndarray]:
    """faces.png value -> primitives.json entry, and the faces.png map with non-analytic faces set to 0."""
    gt = scan.gt
    prims = {int(p.get("pixel_value", int(p.get("id", k)) + 1)): p for k, p in enumerate(gt.primitives)}
    faces = np.asarray(gt.faces).astype(np.int64)
    non = np.zeros(int(faces.max()) + 1, bool)
    for v, p in prims.items():
        if v < len(non) and p.get("type") not in ANALYTIC_TYPES:
            non[v] = True
    labels = np.asarray(gt.labels)
    nonanalytic = non[faces] | ((faces > 0) & (labels == IGNORE))
    return prims, np.where(nonanalytic, 0, faces)


def _axis(prim: dict) -> np.ndarray | None:
    p = prim.get("params", {})
    a = p.get("normal") if prim.get("type") == "plane" else p.get("axis")
    if a is None or prim.get("type") == "sphere":
        return None
    a = np.asarray(a, float)
    return a / np.linalg.norm(a)


def axis_alignment(a: np.ndarray, b: np.ndarray) -> float:
    """min(|a - b|, |a + b|) of two unit axes (sign-free; 0 = parallel, sqrt(2) = orthogonal)."""
    return float(min(np.linalg.norm(a - b), np.linalg.norm(a + b)))


def predicted_axis_class(face: VFace, axes_cam: np.ndarray, tol_deg: float = AXIS_ALIGN_TOL_DEG) -> str | None:
    """Axis class (X, Y, Z, U) of a predicted face read from its primitive's axis against the ground-truth part
    axes (rows X, Y, Z, camera frame) within ``tol_deg`` degrees; None for spheres and axis-less faces."""
    a = _axis(face.primitive)
    return None if a is None else axis_class(a, axes_cam, tol_deg).value


def face_matching(vbrep: VBRep, scan: Scan, rendering: Rendering, config: MetricConfig | None = None) -> dict[str, Any]:
    """Precision / recall at every IoU threshold of ``config``, and type accuracy, axis accuracy and primitive
    alignment over the pairs at the first threshold (module docstring). Counts are returned too. ``config``:
    None for the BENCHMARK.md defaults."""
    config = config or MetricConfig()
    prims, gt_map = _gt_tables(scan)
    faces_png = np.asarray(scan.gt.faces).astype(np.int64)
    pred_map = rendering.face + 1  # 0 = nothing rendered
    n_faces = len(vbrep.faces)
    counts = rendering.pixel_counts(n_faces)
    on_non = np.bincount(rendering.face[(rendering.face >= 0) & (faces_png > 0) & (gt_map == 0)], minlength=n_faces)[
        :n_faces
    ]
    counted = np.flatnonzero((counts > 0) & (on_non <= config.ignore_share * counts)) + 1
    g_area = np.bincount(gt_map.ravel(), minlength=1)
    gt_all = np.flatnonzero(g_area > 0)
    gt_all = gt_all[gt_all > 0]
    gt_big = gt_all[g_area[gt_all] >= config.min_gt_px]
    nan = float("nan")
    out: dict[str, Any] = {
        "n_pred": len(counted),
        "n_pred_rendered": int((counts > 0).sum()),
        "n_gt": len(gt_big),
        "n_gt_all": len(gt_all),
    }
    counted_set, big_set = set(counted.tolist()), set(gt_big.tolist())
    first_pairs: list[tuple[int, int, float]] = []
    for k, thr in enumerate(config.iou_thresholds):
        pairs = match_faces(pred_map, gt_map, thr) if gt_map.any() and pred_map.any() else []
        if k == 0:
            first_pairs = pairs
        suffix = "" if k == 0 else f"_{round(thr * 100):d}"
        mp = sum(1 for a, _, _ in pairs if a in counted_set)
        mg = sum(1 for _, b, _ in pairs if b in big_set)
        out["precision" + suffix] = mp / len(counted) if len(counted) else nan
        out["recall" + suffix] = mg / len(gt_big) if len(gt_big) else nan
        out["recall_all" + suffix] = len(pairs) / len(gt_all) if len(gt_all) else nan
        out["n_pairs" + suffix] = len(pairs)
    axes_cam = np.asarray(scan.gt.meta["axes_cam"], float)
    type_ok = axis_ok = 0
    align: list[float] = []
    for a, b, _ in first_pairs:
        pf, gp = vbrep.faces[a - 1], prims[b]
        type_ok += int(pf.primitive.get("type") == gp.get("type"))
        g_cls = gp.get("axis_label") if gp.get("type") != "sphere" else None
        axis_ok += int(predicted_axis_class(pf, axes_cam, config.axis_tol_deg) == g_cls)
        pa, ga = _axis(pf.primitive), _axis(gp)
        if pa is not None and ga is not None:
            align.append(axis_alignment(pa, ga))
    n = len(first_pairs)
    out.update(
        {
            "type_accuracy": type_ok / n if n else nan,
            "axis_accuracy": axis_ok / n if n else nan,
            "type_ok": type_ok,
            "axis_ok": axis_ok,
            "alignment": float(np.mean(align)) if align else nan,
            "n_align_pairs": len(align),
        }
    )
    return out


def depth_error(rendering: Rendering, scan: Scan) -> tuple[float, float]:
    """Median |rendered depth - clean depth| over the part pixels (gt faces > 0, clean depth > 0) both cover,
    divided by the part size; and the share of part pixels the rendering covers."""
    clean = np.asarray(scan.gt.depth_clean, float)
    part = (np.asarray(scan.gt.faces) > 0) & (clean > 0)
    both = part & (rendering.depth > 0)
    cover = float(both.sum() / part.sum()) if part.any() else float("nan")
    if not both.any():
        return float("nan"), cover
    return float(np.median(np.abs(rendering.depth[both] - clean[both])) / part_size(scan)), cover


def far_faces(vbrep: VBRep, scan: Scan, config: MetricConfig | None = None) -> dict[str, Any]:
    """How far the faces reach from what the scan measured (issue 16: no face beyond 0.05 part sizes).

    Per face, the median over its mesh vertices of the distance to the nearest measured point of the part (the
    scan's valid pixels back-projected: its noisy depth inside the mask), over the part size: a face placed away
    from the part is far, one whose margin runs over pixels without depth (the far wall of a hole seen at a
    grazing angle, an edge-on strip) is not. Returns ``face_far_max`` (the largest over the faces; NaN without
    faces or points), ``faces_far`` (faces beyond ``far_face_rel``) and ``far_face_ids``.

    A face seen nearly edge-on can have almost no readings (the sensor's dropout at grazing incidence: 7-39 valid
    of 262-599 pixels on the far faces of the in-family validation scans) and still lie on the part, so the same
    median is also taken to the true visible surface (the ground truth's noise-free depth of the part's pixels):
    ``face_off_part_max``, ``faces_off_part`` and ``off_part_face_ids`` (NaN / 0 / [] without ground truth). A
    face far from the measured points but on the true surface is a correct face where the sensor read nothing; one
    off the true surface is placed wrong.
    """
    from scipy.spatial import cKDTree

    config = config or MetricConfig()
    meshes = [(f.id, np.asarray(f.mesh_vertices, float).reshape(-1, 3)) for f in vbrep.faces]
    meshes = [(fid, V) for fid, V in meshes if len(V)]

    def medians(points: np.ndarray) -> list[tuple[int, float]]:
        """(face id, median distance of its mesh vertices to the nearest of ``points``) per face with a mesh."""
        tree = cKDTree(points)
        return [(fid, float(np.median(tree.query(V, k=1)[0]))) for fid, V in meshes]

    pts = scan.points()[scan.valid]
    dists = medians(pts) if len(pts) else []
    size = part_size(scan)
    rel = np.array([d for _, d in dists]) / size
    far = [fid for (fid, _), r in zip(dists, rel, strict=True) if r > config.far_face_rel]
    out: dict[str, Any] = {
        "face_far_max": float(rel.max()) if len(rel) else float("nan"),
        "faces_far": len(far),
        "far_face_ids": far,
        "face_off_part_max": float("nan"),
        "faces_off_part": 0,
        "off_part_face_ids": [],
    }
    if scan.gt is None:
        return out
    clean = np.asarray(scan.gt.depth_clean, float)
    truth = backproject(clean, scan.K)[(np.asarray(scan.gt.faces) > 0) & (clean > 0)]
    if not len(truth):
        return out
    off = [(fid, d / size) for fid, d in medians(truth)]
    out["face_off_part_max"] = max((r for _, r in off), default=float("nan"))
    out["off_part_face_ids"] = [fid for fid, r in off if r > config.far_face_rel]
    out["faces_off_part"] = len(out["off_part_face_ids"])
    return out


def runtime_split(vbrep: VBRep, extra: dict[str, float] | None = None) -> dict[str, float]:
    """Seconds per stage: the VB-Rep's ``meta["timings"]`` (segment, fit, vbrep, total) updated with ``extra``
    (e.g. load, step); fit sub-stages as ``fit.<name>``."""
    out = {k: float(v) for k, v in (vbrep.meta.get("timings") or {}).items()}
    out.update({f"fit.{k}": float(v) for k, v in (vbrep.meta.get("fit_timings") or {}).items()})
    out.update({k: float(v) for k, v in (extra or {}).items()})
    return out


# ------------------------------------------------------------------------------------------------- one scan


def scan_metrics(
    vbrep: VBRep, scan: Scan, config: MetricConfig | None = None, timings: dict[str, float] | None = None
) -> dict[str, Any]:
    """Every BENCHMARK.md metric of one VB-Rep against its synthetic scan's ground truth (module docstring).
    Lengths are divided by the ground-truth part size. ValueError without ground truth. ``config``: None for the
    BENCHMARK.md defaults; ``timings``: seconds per stage measured by the caller (`runtime_split`)."""
    config = config or MetricConfig()
    if getattr(scan, "gt", None) is None:
        raise ValueError(f"{getattr(scan, 'path', 'scan')}: metrics need gt/ (a synthetic scan)")
    size = part_size(scan)
    V, T, _ = vbrep_mesh(vbrep)
    caster = MeshCaster(V, T)
    rendering = render_vbrep(vbrep, caster)
    rng = np.random.default_rng(config.seed)
    G = gt_points(scan, config.n_points, config.seed)
    eps = config.visibility_eps_rel * size
    R_vis = reconstruction_points(vbrep, config.n_points, rng, caster, True, eps, config.max_draw_rounds)
    R_all = reconstruction_points(vbrep, config.n_points, rng, caster, False)
    out: dict[str, Any] = {
        "chamfer": chamfer_distance(R_vis, G, size),
        "chamfer_all": chamfer_distance(R_all, G, size),
        "n_visible_points": len(R_vis),
        "n_faces": len(vbrep.faces),
    }
    out.update(face_matching(vbrep, scan, rendering, config))
    out["depth_error"], out["depth_coverage"] = depth_error(rendering, scan)
    out.update(far_faces(vbrep, scan, config))
    if config.edge_types:
        try:
            et = edge_type_accuracy(vbrep, scan, tol_px=config.edge_tol_px)
            out["edge_type_accuracy"] = et["accuracy"]
            out["edge_type"] = et
            # per edge: type, confidence (calibrated), raw confidence, right or not: the bench's ECE
            ok = edge_correctness(vbrep, scan, tol_px=config.edge_tol_px)
            out["edge_labels"] = {
                "type": [EdgeType(e.type).value for e in vbrep.edges],
                "confidence": [float(e.confidence) for e in vbrep.edges],
                "confidence_raw": [
                    float(e.confidence if e.confidence_raw is None else e.confidence_raw) for e in vbrep.edges
                ],
                "ok": [int(k) for k in ok],
            }
        except Exception as exc:  # noqa: BLE001 - another stage's metric must not hide the others; reported
            out["edge_type_accuracy"] = float("nan")
            out["edge_type_error"] = f"{type(exc).__name__}: {exc}"
    out["runtime"] = runtime_split(vbrep, timings)
    return out


# ---------------------------------------------------------------------------------- ground-truth VB-Rep


def _corner_mesh(
    region: np.ndarray, depth: np.ndarray, prim: dict | None, K: np.ndarray, window: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """Mesh of one pixel region: every pixel becomes the quad of its four corners (u +- 0.5, v +- 0.5), each corner
    at the depth of the primitive's crossing nearest the mean clean depth of the region's pixels around it (that
    mean itself without a primitive or a crossing). Pixel centres fall strictly inside their quads, so rendering
    the mesh gives back exactly the region."""
    h, w = region.shape
    vs, us = np.nonzero(region)
    if len(us) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    dsum = np.zeros((h + 1, w + 1))
    dcnt = np.zeros((h + 1, w + 1))
    z = np.where(region, depth, 0.0)
    m = region.astype(float)
    for dv in (0, 1):
        for du in (0, 1):
            dsum[dv : dv + h, du : du + w] += z
            dcnt[dv : dv + h, du : du + w] += m
    used = dcnt > 0
    cv, cu = np.nonzero(used)
    prior = dsum[cv, cu] / dcnt[cv, cu]
    rays = pixel_rays(np.stack([cu - 0.5, cv - 0.5], 1).astype(float), K)
    zc = prior.copy()
    if prim is not None:
        hits = intersect(prim, rays, window).depths
        dd = np.abs(hits - prior[:, None])
        ok = np.isfinite(dd).any(1)
        k = np.argmin(np.where(np.isfinite(dd), dd, np.inf), 1)
        best = hits[np.arange(len(hits)), k]
        close = ok & (np.abs(best - prior) < 0.05 * prior)  # a crossing of the same sheet, not a far one
        zc[close] = best[close]
    idx = np.full((h + 1, w + 1), -1, np.int64)
    idx[cv, cu] = np.arange(len(cv))
    a, b, c, d = idx[vs, us], idx[vs, us + 1], idx[vs + 1, us + 1], idx[vs + 1, us]
    tris = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return rays * zc[:, None], tris


def vbrep_from_gt(scan: Scan, tilt: dict[int, tuple[np.ndarray, float]] | None = None) -> VBRep:
    """The ideal VB-Rep of a synthetic scan: one face per analytic ground-truth face seen in gt/faces.png, its
    primitive the exact one of primitives.json, its mesh the pixel-corner mesh of its pixels on that surface
    (`_corner_mesh`). ``tilt`` = {faces.png value: (rotation axis, angle in radians)} rotates that face's
    primitive axis (normal) about its origin, leaving the mesh, to test alignment. No edges; camera frame."""
    gt = scan.gt
    prims, gt_map = _gt_tables(scan)
    clean = np.asarray(gt.depth_clean, float)
    K = np.asarray(scan.K, float)
    z = clean[clean > 0]
    window = (0.5 * float(z.min()), 1.5 * float(z.max())) if len(z) else (0.05, 5.0)
    axes_cam = np.asarray(gt.meta["axes_cam"], float)
    faces: list[VFace] = []
    for v in sorted(int(x) for x in np.unique(gt_map) if x > 0):
        p = prims[v]
        region = (gt_map == v) & (clean > 0)
        verts, tris = _corner_mesh(region, clean, p, K, window)
        prim = {
            "type": p["type"],
            "params": {k: (list(map(float, x)) if isinstance(x, (list, tuple)) else x) for k, x in p["params"].items()},
        }
        if tilt and v in tilt:
            axis, angle = tilt[v]
            key = "normal" if p["type"] == "plane" else "axis"
            prim["params"][key] = _rotate(
                np.asarray(prim["params"][key], float), np.asarray(axis, float), float(angle)
            ).tolist()
        a = _axis(prim)
        label = None if a is None else axis_class(a, axes_cam).value
        faces.append(
            VFace(id=len(faces), instance=v, primitive=prim, axis_label=label, mesh_vertices=verts, mesh_triangles=tris)
        )
    h, w = clean.shape
    return VBRep(
        faces=faces,
        edges=[],
        vertices=[],
        frame=axes_cam.copy(),
        K=K.copy(),
        image_size=(w, h),
        scale=part_size(scan),
        meta={"source": "ground truth"},
    )


def _rotate(v: np.ndarray, axis: np.ndarray, angle: float) -> np.ndarray:
    """``v`` rotated about ``axis`` (any length) by ``angle`` radians."""
    return Rotation.from_rotvec(angle * axis / np.linalg.norm(axis)).apply(v)
