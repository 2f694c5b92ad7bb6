"""Segmentation metrics against ground-truth faces (BENCHMARK.md definitions, applied to instance masks).

- Face matching: predicted instances and ground-truth faces (gt/faces.png, faces labelled 255 left out) are paired
  greedily by largest image IoU, keeping pairs with IoU >= ``iou_threshold``. Precision = matched predicted
  instances / predicted instances (instances lying mostly on non-analytic faces are left out, as those faces are);
  recall = matched gt faces / gt faces of at least ``min_gt_px`` pixels; ``recall_all`` over every gt face.
- Type / axis accuracy: over matched pairs, the share whose labels agree on the primitive type / the axis class
  (spheres have no axis class: two spheres agree).
- Semantic confusion (per-pixel labels, 255 ignored) for the mean IoU over the 18 classes.
Per-scan numbers are averaged over scans (``summarise``); type/axis accuracies are also pooled over all pairs.

``v2c bench --stage segmentation --scans DIR --n N --segmentation learned,geometric --json OUT`` prints the table of
`run` and writes its JSON.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from v2c.labels import AXIS_OF_LABEL, IGNORE, NUM_CLASSES, TYPE_OF_LABEL

if TYPE_CHECKING:
    from v2c.scan import Scan
    from v2c.segment.types import Segmentation


@dataclass(frozen=True)
class SegMetricConfig:
    """Thresholds of the segmentation metrics: the IoU of a match, the size of a counted ground-truth face (pixels)
    and the share of a predicted instance on non-analytic faces that leaves it out."""

    iou_threshold: float = 0.5  # image IoU for a predicted instance to match a gt face
    min_gt_px: int = 50  # gt faces under this many pixels only count in recall_all (pixels)
    ignore_share: float = 0.5  # predicted instances with more than this share on non-analytic faces are left out


def match_faces(pred: np.ndarray, gt: np.ndarray, iou_threshold: float) -> list[tuple[int, int, float]]:
    """Greedy one-to-one pairs (pred id, gt id, IoU) by decreasing IoU, IoU >= iou_threshold (0 ids excluded)."""
    p = pred.ravel().astype(np.int64)
    g = gt.ravel().astype(np.int64)
    np_, ng = int(p.max()) + 1, int(g.max()) + 1
    both = (p > 0) & (g > 0)
    key = p[both] * ng + g[both]
    uk, inter = np.unique(key, return_counts=True)
    pi, gi = uk // ng, uk % ng
    area_p = np.bincount(p, minlength=np_)
    area_g = np.bincount(g, minlength=ng)
    iou = inter / (area_p[pi] + area_g[gi] - inter)
    order = np.argsort(-iou, kind="stable")
    used_p, used_g, pairs = set(), set(), []
    for k in order:
        if iou[k] < iou_threshold:
            break
        a, b = int(pi[k]), int(gi[k])
        if a in used_p or b in used_g:
            continue
        used_p.add(a)
        used_g.add(b)
        pairs.append((a, b, float(iou[k])))
    return pairs


def semantic_confusion(pred_labels: np.ndarray, gt_labels: np.ndarray) -> np.ndarray:
    """(18, 18) int64 confusion (rows gt, columns predicted) over pixels whose gt label is not 255."""
    ok = gt_labels != IGNORE
    g = gt_labels[ok].astype(np.int64)
    p = np.minimum(pred_labels[ok].astype(np.int64), NUM_CLASSES - 1)
    return np.bincount(g * NUM_CLASSES + p, minlength=NUM_CLASSES**2).reshape(NUM_CLASSES, NUM_CLASSES)


def mean_iou(conf: np.ndarray) -> float:
    """Mean IoU over the classes present in the ground truth or the prediction of a confusion matrix."""
    inter = np.diag(conf).astype(np.float64)
    union = conf.sum(0) + conf.sum(1) - inter
    present = union > 0
    return float((inter[present] / union[present]).mean()) if present.any() else float("nan")


def evaluate_instances(
    instances: np.ndarray,
    inst_labels: np.ndarray,
    gt_faces: np.ndarray,
    gt_labels: np.ndarray,
    cfg: SegMetricConfig = SegMetricConfig(),
) -> dict:
    """Metrics of one scan's instance map against its gt faces.

    instances: (H, W) int ids (0 = none); inst_labels: (N + 1,) label per id; gt_faces: (H, W) faces.png values;
    gt_labels: (H, W) labels.png. Returns counts and per-scan ratios (precision, recall, recall_all, type_acc,
    axis_acc: NaN when undefined) and the semantic confusion matrix.
    """
    faces = gt_faces.astype(np.int64)
    glab = gt_labels.astype(np.int64)
    nonanalytic = (faces > 0) & (glab == IGNORE)
    faces_a = np.where(nonanalytic, 0, faces)
    inst = instances.astype(np.int64)
    pairs = match_faces(inst, faces_a, cfg.iou_threshold)

    # gt label of each face (mode over its pixels) and area
    nf = int(faces.max()) + 1
    gl_hist = np.bincount((faces_a * 256 + glab).ravel(), minlength=nf * 256).reshape(nf, 256)
    g_area = gl_hist.sum(axis=1)
    g_label = gl_hist.argmax(axis=1)
    gt_ids = np.nonzero(g_area > 0)[0]
    gt_ids = gt_ids[gt_ids > 0]
    gt_big = gt_ids[g_area[gt_ids] >= cfg.min_gt_px]

    npi = int(inst.max()) + 1
    p_area = np.bincount(inst.ravel(), minlength=npi)
    p_on_ignored = np.bincount(inst[nonanalytic], minlength=npi)
    pred_ids = np.nonzero(p_area > 0)[0]
    pred_ids = pred_ids[pred_ids > 0]
    counted = pred_ids[p_on_ignored[pred_ids] <= cfg.ignore_share * p_area[pred_ids]]

    counted_set = set(counted.tolist())
    matched_pred = [a for a, _, _ in pairs if a in counted_set]
    big_set = set(gt_big.tolist())
    matched_big = [b for _, b, _ in pairs if b in big_set]
    type_ok = axis_ok = 0
    for a, b, _ in pairs:
        pl, gl = int(inst_labels[a]), int(g_label[b])
        type_ok += int(TYPE_OF_LABEL[pl] == TYPE_OF_LABEL[gl])
        axis_ok += int(AXIS_OF_LABEL[pl] == AXIS_OF_LABEL[gl])
    n_pairs = len(pairs)
    sem = np.asarray(inst_labels)[inst]
    nan = float("nan")
    return {
        "n_pred": len(counted),
        "n_gt": len(gt_big),
        "n_gt_all": len(gt_ids),
        "n_pairs": n_pairs,
        "matched_pred": len(matched_pred),
        "matched_gt": len(matched_big),
        "type_ok": type_ok,
        "axis_ok": axis_ok,
        "precision": len(matched_pred) / len(counted) if len(counted) else nan,
        "recall": len(matched_big) / len(gt_big) if len(gt_big) else nan,
        "recall_all": n_pairs / len(gt_ids) if len(gt_ids) else nan,
        "type_acc": type_ok / n_pairs if n_pairs else nan,
        "axis_acc": axis_ok / n_pairs if n_pairs else nan,
        "confusion": semantic_confusion(sem, gt_labels),
    }


def evaluate_segmentation(seg: Segmentation, scan: Scan, cfg: SegMetricConfig = SegMetricConfig()) -> dict:
    """``evaluate_instances`` of a ``Segmentation`` against a scan's gt/ (ValueError without gt)."""
    if scan.gt is None:
        raise ValueError(f"{scan.path}: segmentation metrics need gt/ (a synthetic scan)")
    return evaluate_instances(seg.instances, seg.labels, scan.gt.faces, scan.gt.labels, cfg)


def summarise(rows: list[dict]) -> dict:
    """Mean over scans of the per-scan ratios (NaNs skipped), pooled type/axis accuracy and the set's mean IoU."""
    out: dict = {"scans": len(rows)}
    for k in ("precision", "recall", "recall_all", "type_acc", "axis_acc"):
        v = np.array([r[k] for r in rows], float)
        out[k] = float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")
    pairs = sum(r["n_pairs"] for r in rows)
    out["type_acc_pooled"] = sum(r["type_ok"] for r in rows) / pairs if pairs else float("nan")
    out["axis_acc_pooled"] = sum(r["axis_ok"] for r in rows) / pairs if pairs else float("nan")
    conf = sum(r["confusion"] for r in rows)
    out["miou"] = mean_iou(conf) if rows else float("nan")
    if rows and "seconds" in rows[0]:
        out["seconds_median"] = float(np.median([r["seconds"] for r in rows]))
        out["seconds_mean"] = float(np.mean([r["seconds"] for r in rows]))
    if rows and "cpu_seconds" in rows[0]:
        out["cpu_seconds_median"] = float(np.median([r["cpu_seconds"] for r in rows]))
    return out


def run(
    scan_dirs: list[Path],
    methods: list[str],
    segment_fn: Callable[[Scan, str], Segmentation] | None = None,
    log: Callable[[str], None] = print,
) -> dict:
    """Segment every scan with every method, time it (seconds), and return {method: {"summary": ..., "scans":
    [...]}}. ``segment_fn(scan, method)``: the segmenter (default `v2c.segment.segment`); ``log`` gets a progress
    line every 25 scans."""
    from v2c.scan import load_scan
    from v2c.segment import segment

    segment_fn = segment_fn or segment
    results: dict = {}
    for method in methods:
        rows = []
        for i, d in enumerate(scan_dirs):
            scan = load_scan(d)
            t0, c0 = time.perf_counter(), time.process_time()
            seg = segment_fn(scan, method)
            dt, dc = time.perf_counter() - t0, time.process_time() - c0
            r = evaluate_segmentation(seg, scan)
            r["seconds"] = dt
            r["cpu_seconds"] = dc  # CPU time of this process (all threads): what the work costs on a loaded machine
            r["scan"] = str(d)
            rows.append(r)
            if (i + 1) % 25 == 0:
                log(f"{method}: {i + 1}/{len(scan_dirs)} {summarise(rows)}")
        results[method] = {
            "summary": summarise(rows),
            "scans": [{k: v for k, v in r.items() if k != "confusion"} for r in rows],
        }
    return results


def format_table(results: dict) -> str:
    """Markdown table of the summaries of ``run``."""
    cols = (
        "scans",
        "precision",
        "recall",
        "recall_all",
        "type_acc",
        "axis_acc",
        "miou",
        "seconds_median",
        "cpu_seconds_median",
    )
    lines = ["| method | " + " | ".join(cols) + " |", "|" + " --- |" * (len(cols) + 1)]
    for m, r in results.items():
        s = r["summary"]
        cells = [str(s["scans"])] + [f"{s.get(c, float('nan')):.3f}" for c in cols[1:]]
        lines.append(f"| {m} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
