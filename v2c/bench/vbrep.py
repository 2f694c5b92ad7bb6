"""Metrics of a reconstructed VB-Rep against a synthetic scan's ground truth (BENCHMARK.md; docs/vbrep.md).

- `chamfer(vbrep, scan, n=20000, seed=0)`: BENCHMARK.md's Chamfer distance, scaled by the part size (the
  surfaces and ray casts of `v2c.bench.surfaces`, as `v2c.bench.metrics.scan_metrics` measures it).
- `edge_type_accuracy(vbrep, scan)`: the share of ground-truth boundary records (v2c.vbrep.gt_types) whose
  nearest predicted edge on the same face (within ``tol_px``) has the same type.
- `edge_correctness(vbrep, scan)`: the same matching seen from each predicted edge (right or wrong).

Edge positions are compared in pixels of the scan's image (edges projected with ``vbrep.K``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial import cKDTree

from v2c.bench.config import MetricConfig
from v2c.bench.surfaces import chamfer_distance, gt_points, part_size, reconstruction_points
from v2c.camera import project
from v2c.choices import DEFAULT_ABLATION, DEFAULT_SEGMENTATION
from v2c.vbrep.gt_types import GTEdgeSamples, GTTypeConfig, gt_edge_samples
from v2c.vbrep.model import EdgeType, VBRep

if TYPE_CHECKING:
    from v2c.scan import Scan


def chamfer(vbrep: VBRep, scan: Scan, n: int = 20000, seed: int = 0, visible_only: bool = True) -> float:
    """BENCHMARK.md Chamfer distance, divided by the ground-truth part size: 0.5 * (mean over R of the distance
    to G + mean over G of the distance to R), G = ``n`` clean-depth points of the part, R = ``n`` points drawn
    area-uniformly on the reconstructed face meshes, keeping those the camera sees (``visible_only``; else all of
    R, BENCHMARK.md's chamfer_all). Returns inf for an empty reconstruction.

    The exact implementation of v2c.bench.metrics (visibility by an exact ray cast against the meshes,
    `visible_points`): ``chamfer(v, scan)`` equals ``scan_metrics(v, scan)["chamfer"]`` for the same n and seed."""
    cfg = MetricConfig(n_points=n, seed=seed)
    size = part_size(scan)
    G = gt_points(scan, n, seed)
    R = reconstruction_points(
        vbrep,
        n,
        np.random.default_rng(seed),
        visible_only=visible_only,
        eps=cfg.visibility_eps_rel * size,
        max_rounds=cfg.max_draw_rounds,
    )
    return chamfer_distance(R, G, size)


def face_to_gt(vbrep: VBRep, scan: Scan) -> dict[int, int]:
    """Predicted face id -> ground-truth faces.png value it covers most (0 if none), from its projected mesh."""
    faces = np.asarray(scan.gt.faces)
    h, w = faces.shape
    out = {}
    for f in vbrep.faces:
        if len(f.mesh_vertices) == 0:
            out[f.id] = 0
            continue
        uv = np.rint(project(np.asarray(f.mesh_vertices, float), vbrep.K)).astype(int)
        ok = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        vals = faces[uv[ok, 1], uv[ok, 0]]
        vals = vals[vals > 0]
        out[f.id] = int(np.bincount(vals).argmax()) if len(vals) else 0
    return out


def _edge_points(vbrep: VBRep, step_px: float = 0.5) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Projected edge polylines densified to ``step_px``: points (N, 2), edge index (N,), edge type (N,) str."""
    pts, eid, typ = [], [], []
    for k, e in enumerate(vbrep.edges):
        uv = project(np.asarray(e.polyline, float), vbrep.K)
        if len(uv) == 1:
            dense = uv
        else:
            seg = np.linalg.norm(np.diff(uv, axis=0), axis=1)
            s = np.concatenate([[0], np.cumsum(seg)])
            t = np.linspace(0, s[-1], max(2, int(s[-1] / step_px) + 1))
            dense = np.stack([np.interp(t, s, uv[:, 0]), np.interp(t, s, uv[:, 1])], 1)
        pts.append(dense)
        eid.append(np.full(len(dense), k))
        typ.append(np.full(len(dense), EdgeType(e.type).value, dtype=object))
    if not pts:
        return np.zeros((0, 2)), np.zeros(0, int), np.zeros(0, object)
    return np.concatenate(pts), np.concatenate(eid), np.concatenate(typ)


def edge_type_accuracy(
    vbrep: VBRep,
    scan: Scan,
    tol_px: float = 3.0,
    gt: GTEdgeSamples | None = None,
    gt_config: GTTypeConfig | None = None,
) -> dict[str, Any]:
    """Edge-type accuracy against the ground-truth rule (v2c.vbrep.gt_types).

    Every ground-truth record (a boundary pixel crack and the face it bounds) looks for the nearest predicted edge
    point within ``tol_px`` pixels among the edges bounding the predicted face(s) mapped to that ground-truth face
    (`face_to_gt`); it is correct when that edge's type equals the record's. Returns ``accuracy`` (correct / all
    records), ``matched_accuracy`` (correct / records with a predicted edge in reach), ``coverage`` (records with
    one in reach / all), ``n`` and per-type ``accuracy_<type>`` and ``share_<type>`` (of the ground truth)."""
    gt = gt if gt is not None else gt_edge_samples(scan, gt_config or GTTypeConfig())
    fmap = face_to_gt(vbrep, scan)
    pts, eid, typ = _edge_points(vbrep)
    n = len(gt.type)
    pred = np.full(n, "", dtype=object)
    for gface in np.unique(gt.face):
        pf = {fid for fid, g in fmap.items() if g == gface}
        sel_e = (
            np.array([any(f in pf for f in vbrep.edges[k].faces) for k in eid], bool) if len(eid) else np.zeros(0, bool)
        )
        rec = np.flatnonzero(gt.face == gface)
        if not sel_e.any():
            continue
        d, j = cKDTree(pts[sel_e]).query(gt.uv[rec], distance_upper_bound=tol_px)
        hit = np.isfinite(d)
        pred[rec[hit]] = typ[sel_e][j[hit]]
    matched = pred != ""
    correct = pred == gt.type
    out: dict[str, Any] = {
        "accuracy": float(correct.mean()) if n else float("nan"),
        "matched_accuracy": float(correct[matched].mean()) if matched.any() else float("nan"),
        "coverage": float(matched.mean()) if n else float("nan"),
        "n": int(n),
    }
    for t in EdgeType:
        s = gt.type == t.value
        out[f"share_{t.value}"] = float(s.mean()) if n else 0.0
        out[f"accuracy_{t.value}"] = float(correct[s].mean()) if s.any() else float("nan")
    return out


def edge_correctness(
    vbrep: VBRep,
    scan: Scan,
    tol_px: float = 3.0,
    min_share: float = 0.5,
    gt: GTEdgeSamples | None = None,
    gt_config: GTTypeConfig | None = None,
) -> np.ndarray:
    """Per predicted edge, whether its type is right (bool array, one per ``vbrep.edges``).

    The matching of `edge_type_accuracy` seen from the prediction: each point of the edge's projected polyline
    (densified to 0.5 px) looks for the nearest ground-truth record within ``tol_px`` pixels on the ground-truth
    face(s) its own faces map to (`face_to_gt`); the point is right when that record's type equals the edge's.
    The edge is right when at least ``min_share`` of its points are. For an intersection edge this reads: a true
    edge of the part, where two true surfaces meet, lies within ``tol_px`` pixels of it along at least half its
    length. An edge with no record in reach (a spurious edge, or one on a face that matches no true face) is
    wrong."""
    gt = gt if gt is not None else gt_edge_samples(scan, gt_config or GTTypeConfig())
    fmap = face_to_gt(vbrep, scan)
    pts, eid, _ = _edge_points(vbrep)
    ok = np.zeros(len(vbrep.edges), bool)
    trees: dict[int, tuple[cKDTree, np.ndarray]] = {}
    for g in np.unique(gt.face):
        rec = np.flatnonzero(gt.face == g)
        trees[int(g)] = (cKDTree(gt.uv[rec]), gt.type[rec])
    for k, e in enumerate(vbrep.edges):
        sel = eid == k
        if not sel.any():
            continue
        gfaces = {fmap.get(int(f), 0) for f in e.faces} - {0}
        best_d = np.full(int(sel.sum()), np.inf)
        best_t = np.full(int(sel.sum()), "", dtype=object)
        for g in gfaces:
            if g not in trees:
                continue
            tree, types = trees[g]
            d, j = tree.query(pts[sel], distance_upper_bound=tol_px)
            better = np.isfinite(d) & (d < best_d)
            best_d[better] = d[better]
            best_t[better] = types[j[better]]
        right = best_t == EdgeType(e.type).value
        ok[k] = bool(np.mean(right) >= min_share)
    return ok


def evaluate(
    scan_dirs: list[str], segmentation: str = DEFAULT_SEGMENTATION, ablation: str = DEFAULT_ABLATION
) -> list[dict[str, Any]]:
    """Reconstruct each scan and measure it: one row per scan (chamfer, chamfer_all, the edge-type accuracy
    fields, seconds per stage)."""
    from v2c.pipeline import reconstruct
    from v2c.scan import load_scan

    rows = []
    for d in scan_dirs:
        scan = load_scan(d)
        v = reconstruct(scan, segmentation, ablation)
        acc = edge_type_accuracy(v, scan)
        rows.append(
            {
                "scan": str(d),
                "family": scan.gt.meta.get("family"),
                "chamfer": chamfer(v, scan),
                "chamfer_all": chamfer(v, scan, visible_only=False),
                **acc,
                **{f"t_{k}": float(t) for k, t in v.meta["timings"].items()},
            }
        )
    return rows


def summarize(rows: list[dict[str, Any]]) -> dict[str, float]:
    """Means over scans (and the median of the seconds per scan)."""
    keys = ["chamfer", "chamfer_all", "accuracy", "matched_accuracy", "coverage"]
    out = {k: float(np.nanmean([r[k] for r in rows])) for k in keys}
    out["chamfer_max"] = float(np.max([r["chamfer"] for r in rows]))
    for k in ("t_segment", "t_fit", "t_vbrep", "t_total"):
        out[f"{k}_median"] = float(np.median([r[k] for r in rows]))
    out["scans"] = len(rows)
    return out
